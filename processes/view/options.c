/* options: nudge-view's command line (view.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_opt.h"
#include "nd_parse.h"
#include "view.h"

/* --size WxH: even sizes, as H.264 in yuv420p needs them. */
static int parse_size(const char *s, const char *what, void *dst, char *err, int errlen) {
  int *wh = dst;
  char a[16], b[16], extra;
  if (sscanf(s, "%15[0-9]x%15[0-9]%c", a, b, &extra) != 2 ||
      nd_parse_int(a, what, 16, 7680, &wh[0], err, errlen) ||
      nd_parse_int(b, what, 16, 4320, &wh[1], err, errlen)) {
    snprintf(err, errlen, "%s: '%.40s' is not a size WxH from 16x16 to 7680x4320", what, s);
    return -1;
  }
  if (wh[0] % 2 || wh[1] % 2) {
    snprintf(err, errlen, "%s: '%.40s': width and height must be even (H.264 video)", what, s);
    return -1;
  }
  return 0;
}

int view_options(int argc, char **argv, view_opts *o) {
  *o = (view_opts){.png_at = -1.0, .speed = 1.0, .trail = 1.5, .w = 1280, .h = 720,
                   .fps = 30, .nice = 10};
  int size[2] = {1280, 720};
  double cam[6];
  nd_opt opts[] = {
      {"world", ND_OPT_CHOICE, &o->world, .choices = view_worlds,
       .help = "ideal: the planning model's scene (table, box, sphere); lab: the emulated "
               "Panda arm too, posed from ARM_STATE"},
      {"log", ND_OPT_STRING, &o->log, .arg = "FILE.lcmlog", .def = "",
       .help = "draw an lcm-logger log instead of the live system, frames timed by its "
               "timestamps; ends at the log's end (with a window: when it is closed)"},
      {"speed", ND_OPT_DOUBLE, &o->speed, 0.0, 1000.0, .arg = "S",
       .help = "--log playback speed: 1 real time, 0 as fast as it can (an MP4 holds the "
               "log's time at any speed)"},
      {"record", ND_OPT_STRING, &o->record, .arg = "FILE.mp4", .def = "",
       .help = "encode the frames as H.264 MP4 through ffmpeg"},
      {"png", ND_OPT_STRING, &o->png, .arg = "FILE.png", .def = "",
       .help = "write one frame as PNG (through ffmpeg) at --png-at, else at exit; SIGUSR1 "
               "writes it again at the next frame"},
      {"png-at", ND_OPT_DOUBLE, &o->png_at, 0.0, 1e6, .arg = "S", .def = "at exit",
       .help = "--png after S seconds of view time"},
      {"size", ND_OPT_CUSTOM, size, .parse = parse_size, .arg = "WxH", .def = "1280x720",
       .help = "frame size in pixels (even numbers)"},
      {"fps", ND_OPT_INT, &o->fps, 1, 240, .help = "frames per second of view time"},
      {"samples", ND_OPT_INT, &o->samples, 0, 16,
       .help = "multisampling (anti-aliasing): 4 draws smoother edges at ~2.5 times the "
               "render time of software OpenGL; worth it for a log at --speed 0"},
      {"seconds", ND_OPT_DOUBLE, &o->seconds, 0.001, 1e6, .arg = "S", .def = "until stopped",
       .help = "end after S seconds of view time (live: wall time; --log: log time)"},
      {"hidden", ND_OPT_FLAG, &o->hidden,
       .help = "no visible window: render offscreen only (needs an X server all the same: "
               "xvfb-run -a over SSH and in CI)"},
      {"camera", ND_OPT_LIST, cam, -1000, 1000, 6, .arg = "X,Y,Z,DIST,AZ,EL",
       .def = "per world",
       .help = "camera looking at (X, Y, Z) m from DIST m, azimuth AZ and elevation EL in "
               "degrees (EL -90: straight down, image right = +x for AZ 90)"},
      {"trail", ND_OPT_DOUBLE, &o->trail, 0.0, 10.0, .arg = "S",
       .help = "seconds of EE_CMD setpoints drawn as the trail (0: none)"},
      {"no-overlay", ND_OPT_FLAG, &o->no_overlay, .help = "draw no text"},
      {"nice", ND_OPT_INT, &o->nice, 0, 19,
       .help = "scheduling niceness (ffmpeg inherits it): the view is the least important "
               "process, so by default it takes only CPU the planner leaves"},
      {"lcm-url", ND_OPT_STRING, &o->url, .arg = "URL", .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL,
       .help = "LCM URL: the live inputs and the heartbeat"},
  };
  nd_opt_spec spec = {
      PROG, "[options]",
      "Draw the world (MOCAP, ARM_STATE), the goal (TASK), the plan (PLAN: keypoints, the "
      "minimum-snap path from the newest EE_CMD setpoint, the predicted object pose) and the "
      "setpoint trail (EE_CMD) with MuJoCo's renderer, with the task's error, plans/s, theta "
      "(PARAMS), the last EPISODE event and every heartbeat (STATUS) as text. Live, or from "
      "an lcm-logger log; to a window, an MP4 or a PNG.",
      "Mouse: left drag rotates, right drag moves, middle drag or scroll zooms (shift: in\n"
      "the horizontal plane); R resets the camera, Q or Escape closes.\n"
      "Subscribes MOCAP TASK PLAN EE_CMD PARAMS STATUS EPISODE ARM_STATE; publishes STATUS.\n"
      "Prints figures at exit on stdout (view_fps, view_frame_ms_*, ...).\n"
      "Exit status 0, 1 on a failure (no display, ffmpeg, LCM), 2 on bad arguments.\n"
      "Example: xvfb-run -a nudge-view --hidden --log run.lcmlog --speed 0 --record run.mp4\n",
      opts, sizeof(opts) / sizeof(opts[0])};
  const int rc = nd_opt_parse(&spec, argc, argv);
  if (rc != ND_OPT_RUN) return rc;
  o->w = size[0];
  o->h = size[1];
  if (nd_opt_find(&spec, "speed")->given && !o->log) return nd_opt_fail(&spec, "--speed needs --log");
  if (nd_opt_find(&spec, "png-at")->given && !o->png) return nd_opt_fail(&spec, "--png-at needs --png");
  /* Ideal: over where the default goal chain runs (x 0..0.25, y 0..0.3 m, nudge-tasks);
   * lab: the arm beside the table too. */
  const view_camera cams[2] = {{{0.08, 0.1, 0.0}, 0.9, 90.0, -50.0},
                               {{-0.1, 0.05, 0.1}, 1.3, 120.0, -30.0}};
  o->cam = cams[o->world];
  if (nd_opt_find(&spec, "camera")->given) {
    if (!(cam[3] > 0.0) || fabs(cam[5]) > 90.0)
      return nd_opt_fail(&spec, "--camera: DIST must be > 0 and EL within [-90, 90]");
    o->cam = (view_camera){{cam[0], cam[1], cam[2]}, cam[3], cam[4], cam[5]};
  }
  return ND_OPT_RUN;
}
