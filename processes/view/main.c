/* nudge-view: a 3D view of the world, the goal and the plan, live or from a log, drawn
 * with MuJoCo's renderer (view.h says what each file does). */
#include <malloc.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "nd_opt.h"
#include "view.h"

const char *const view_worlds[] = {"ideal", "lab", NULL};

int main(int argc, char **argv) {
  static view_opts o;
  const int rc = view_options(argc, argv, &o);
  if (rc != ND_OPT_RUN) return rc;

  /* Software OpenGL (Mesa's llvmpipe, what Xvfb offers) starts a rasterizer thread per
   * core; one keeps the view off the planner's cores. A value set by the user stands. */
  setenv("LP_NUM_THREADS", "1", 0);
  /* Mesa allocates and frees buffers of several MB every frame. Above glibc's mmap
   * threshold each is a fresh mapping whose pages fault in as they are first written;
   * kept in the heap they are reused (decisions: view-cpu). */
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  /* Take only CPU the other processes leave. */
  if (o.nice) ndp_nice(PROG, o.nice);
  ndp_signals();
  ndp_mujoco_handlers(PROG);
  static view_app v;
  v.o = &o;
  char err[1024] = "";
  int status = 1;
  view_inputs_init(&v.in, o.trail);
  nd_jitter_reset(&v.lateness);
  nd_jitter_reset(&v.work);
  if ((o.record || o.png) && view_ffmpeg_check(err, sizeof err)) goto done;
  if (view_scene_init(&v.sc, o.world, o.w, o.h, o.samples, err, sizeof err) ||
      view_gl_init(&v.g, v.sc.m, o.w, o.h, !o.hidden, &o.cam, err, sizeof err))
    goto done;
  if (o.log) {
    if (view_log_open(&v.lg, o.log, err, sizeof err)) goto done;
    /* A log draws without the network; the heartbeat is published if LCM opens. */
    if (!(v.lcm = ndp_lcm_create(o.url, err, sizeof err)))
      fprintf(stderr, PROG ": no heartbeat: %s\n", err);
  } else if (!(v.lcm = ndp_lcm_create(o.url, err, sizeof err)) ||
             view_inputs_subscribe(&v.in, v.lcm, err, sizeof err)) {
    goto done;
  }
  if (o.png && !(v.rows = malloc((size_t)o.w * o.h * 3))) {
    snprintf(err, sizeof err, "out of memory for a %dx%d frame", o.w, o.h);
    goto done;
  }
  if (o.record && view_ffmpeg_mp4(&v.rec, o.record, o.w, o.h, o.fps, err, sizeof err)) goto done;
  fprintf(stderr, PROG ": %s world, %dx%d at %d fps on %s, %s%s%s%s%s, %s window\n",
          view_worlds[o.world], o.w, o.h, o.fps, view_gl_renderer(), o.log ? "log " : "live on ",
          o.log ? o.log : ndp_url(o.url), o.record ? ", recording " : "",
          o.record ? o.record : "", o.png ? ", screenshot to --png" : "",
          o.hidden ? "hidden" : "visible");
  status = view_run(&v, err, sizeof err) ? 1 : 0;
  if (status == 0) err[0] = '\0';

done:
  if (status && err[0]) fprintf(stderr, PROG ": %s\n", err);
  if (!v.t1) v.t1 = ndp_mono();
  if (v.rec.pid) view_ffmpeg_close(&v.rec, err, sizeof err);
  if (v.renders) {
    const double wall = v.t1 > v.t0 ? v.t1 - v.t0 : 0.0;
    printf("view_frames %lld count\nview_renders %lld count\nview_frames_late %lld count\n"
           "view_wall %.3f s\nview_fps %.2f per_s\nview_frame_ms_mean %.2f ms\n"
           "view_frame_ms_p99 %.2f ms\nview_received %lld count\nview_rejected %lld count\n"
           "view_geoms_dropped %lld count\n",
           (long long)v.frames, (long long)v.renders, (long long)v.late, wall,
           wall > 0 ? v.renders / wall : 0.0, 1e3 * v.work_s / v.renders,
           1e-3 * nd_jitter_quantile(&v.work, 0.99), (long long)v.in.st.received,
           (long long)v.in.st.rejected, (long long)v.dropped);
    if (o.log)
      printf("view_log_events %lld count\nview_log_span %.6f s\n", (long long)v.lg.events,
             1e-6 * (double)(v.lg.t_last - v.lg.t0));
  }
  free(v.rows);
  view_log_close(&v.lg);
  if (v.lcm) lcm_destroy(v.lcm);
  view_gl_free(&v.g);
  view_scene_free(&v.sc);
  return status;
}
