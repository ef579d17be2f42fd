/* run: nudge-view's frame loop (view.h).
 *
 * Frame k stands for the slot [k, k + 1) / fps of view time and shows the world as of the
 * slot's end. Live, slots are wall time: a frame that comes late also stands for the
 * slots it missed (it is written to the MP4 that many times), so a recording lasts as
 * long as the run. From a log, slots are log time: the events stamped up to the slot's
 * end are handed over, then the frame is drawn; --speed only paces the wall clock, so an
 * MP4 of a log has ceil(duration x fps) frames at any speed. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "view.h"

static volatile sig_atomic_t shot;  /* SIGUSR1: write the --png file at the next frame */

static void on_usr1(int sig) {
  (void)sig;
  shot = 1;
}

/* One frame: the model posed from the inputs, our geoms, the render, the overlay; the
 * pixels read back if read. */
static void draw(view_app *v, int64_t now_us, int read) {
  const double t = ndp_mono();
  view_scene_pose(&v->sc, &v->in);
  view_gl_scene(&v->g, v->sc.m, v->sc.d);
  view_scene_hide_unseen(&v->sc, &v->in, &v->g.scn);
  v->dropped += view_draw(&v->sc, &v->in, &v->g.scn);
  view_gl_render(&v->g);
  if (!v->o->no_overlay) view_overlay(&v->in, now_us, view_gl_viewport(&v->g), &v->g.con, &v->g.text);
  view_gl_finish(&v->g, read);
  v->renders++;
  v->last_us = now_us;
  const double dt = ndp_mono() - t;
  v->work_s += dt;
  nd_jitter_add(&v->work, 1e6 * dt, 1e6 / v->o->fps);
}

static int write_png(view_app *v, const char *when, char *err, int errlen) {
  if (view_png(v->o->png, v->g.rgb, v->o->w, v->o->h, v->rows, err, errlen)) return -1;
  fprintf(stderr, PROG ": wrote %s (%s, frame %lld)\n", v->o->png, when, (long long)v->frames);
  return 0;
}

/* Heartbeat, with the frames' lateness as its loop timing. */
static int beat(view_app *v) {
  if (!v->lcm) return 0;
  v->loop.p50_us = (int32_t)nd_jitter_quantile(&v->lateness, 0.5);
  v->loop.p99_us = (int32_t)nd_jitter_quantile(&v->lateness, 0.99);
  v->loop.max_us = (int32_t)v->lateness.max_us;
  v->loop.overruns = v->late;
  v->in.st.loop = &v->loop;
  return ndp_status_tick(v->lcm, &v->in.st, 0) < 0 ? -1 : 0;
}

/* Serve the window, LCM (live) and the heartbeat until ndp_mono() reaches due. Return 1 if
 * the window was closed, -1 on an LCM error, else 0 (due, or a signal). */
static int wait_until(view_app *v, double due, int live) {
  for (;;) {
    if (view_gl_poll(&v->g)) return 1;
    const double left = due - ndp_mono();
    if (left <= 0.0 || ndp_quit) return 0;
    const double dt = fmin(left, 0.01);
    if (live) {
      if (ndp_handle(v->lcm, dt)) return -1;
    } else {
      const struct timespec ts = {0, (long)(dt * 1e9)};
      nanosleep(&ts, NULL);
    }
    if (beat(v)) return -1;
  }
}

/* The outputs that end with the frames: the MP4 finished, the PNG written at exit. */
static int finish(view_app *v, char *err, int errlen) {
  int rc = 0;
  if (v->rec.pid && view_ffmpeg_close(&v->rec, err, errlen)) rc = -1;
  if (v->o->png && !v->png_done && v->renders) {
    draw(v, v->last_us, 1);  /* the last frame again, read back this time */
    v->png_done = 1;
    if (write_png(v, "at exit", err, errlen)) rc = -1;
  }
  return rc;
}

/* From a log, with a window: the last frame stays up, the camera still moves, until the
 * window is closed. */
static int hold(view_app *v, char *err, int errlen) {
  v->in.st.state = "holding";
  fprintf(stderr, PROG ": log ended after %lld events; close the window to exit\n",
          (long long)v->lg.events);
  for (;;) {
    const int r = wait_until(v, ndp_mono() + 1.0 / v->o->fps, 0);
    if (r || ndp_quit) return r < 0 ? -1 : 0;
    const int snap = shot && v->o->png;
    if (snap) shot = 0;
    draw(v, v->last_us, snap);
    if (snap && write_png(v, "SIGUSR1", err, errlen)) return -1;
  }
}

int view_run(view_app *v, char *err, int errlen) {
  const view_opts *o = v->o;
  const int live = !o->log;
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_usr1;
  sigaction(SIGUSR1, &sa, NULL);
  const double period = 1.0 / o->fps, scale = live ? 1.0 : o->speed;
  const int64_t k_max = o->seconds > 0.0 ? (int64_t)ceil(o->seconds * o->fps - 1e-9) : INT64_MAX;
  const int64_t k_png = o->png_at >= 0.0 ? (int64_t)ceil(o->png_at * o->fps - 1e-9) : -1;
  v->in.st.state = live ? "drawing" : "replaying";
  v->t0 = ndp_mono();
  int more = 1, rc = 0, warned = 0;
  while (!ndp_quit && more && v->frames < k_max) {
    const double due = scale > 0.0 ? v->t0 + (v->frames + 1) * period / scale : 0.0;
    const int w = scale > 0.0 ? wait_until(v, due, live) : view_gl_poll(&v->g);
    if (w < 0) {
      snprintf(err, errlen, "LCM receive or heartbeat failed: %s", strerror(errno));
      return -1;
    }
    if (w || ndp_quit) break;
    const double now = ndp_mono();
    if (scale > 0.0) nd_jitter_add(&v->lateness, 1e6 * (now - due), 1e6 * period / scale);
    int64_t slots = 1, now_us;
    if (live) {
      ndp_drain(v->lcm);
      slots = (int64_t)floor((now - v->t0) / period) - v->frames;
      if (slots < 1) slots = 1;
      if (slots > k_max - v->frames) slots = k_max - v->frames;
      v->late += slots - 1;
      now_us = ndp_utime();
    } else {
      now_us = v->lg.t0 + (int64_t)llround((double)(v->frames + 1) * 1e6 / o->fps);
      more = view_log_feed(&v->lg, &v->in, now_us);
    }
    const int png_now = o->png && !v->png_done && k_png >= 0 && v->frames + slots >= k_png;
    const int snap = shot;  /* taken once: a signal during this frame counts for the next */
    if (snap) shot = 0;
    draw(v, now_us, v->rec.pid || png_now || (snap && o->png));
    for (int64_t i = 0; i < slots && v->rec.pid; i++)
      if (view_ffmpeg_frame(&v->rec, v->g.rgb, err, errlen)) return -1;
    v->frames += slots;
    if (png_now) {
      v->png_done = 1;
      if (write_png(v, "--png-at", err, errlen)) return -1;
    }
    if (snap && o->png && write_png(v, "SIGUSR1", err, errlen)) return -1;
    if (snap && !o->png && !warned++)
      fprintf(stderr, PROG ": SIGUSR1 writes the --png file; none given\n");
    if (beat(v)) {
      snprintf(err, errlen, "publishing on %s failed", NDP_CH_STATUS);
      return -1;
    }
  }
  v->t1 = ndp_mono();
  rc = finish(v, err, errlen);
  if (rc == 0 && !live && !more && v->g.visible && !ndp_quit) rc = hold(v, err, errlen);
  v->in.st.state = "stopped";
  if (v->lcm) ndp_status_tick(v->lcm, &v->in.st, 1);
  return rc;
}
