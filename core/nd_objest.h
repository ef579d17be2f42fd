/* nd_objest: the pushed object's velocity from motion-capture poses.
 *
 * Motion capture gives poses only. A difference of consecutive frames (4.2 ms at 240 Hz)
 * turns 0.2 mm of marker noise into ~0.07 m/s, as large as a push; differencing over at
 * least `window` (25 ms, six frames) cuts that to ~0.01 m/s at the price of ~12 ms lag,
 * small next to the 0.3 s segments planned. The result is clamped to what the robot can
 * cause (v_max, w_max): faster readings are glitches (a swapped marker, a jump). Vertical
 * and roll/pitch rates are zero: a pushed box stays flat, and mocap differences there are
 * noise the model would turn into a bounce. Frames more than max_gap apart say nothing
 * about the present motion: the estimate is then zero (a box left alone comes to rest
 * within tens of ms under friction). Allocation-free. */
#ifndef ND_OBJEST_H
#define ND_OBJEST_H

#include <stdint.h>

#define ND_OBJEST_HIST 32  /* frames kept: > window at the fastest mocap rate expected */

typedef struct {
  double window;   /* s: difference over the newest frame and one at least this much older */
  double max_gap;  /* s: beyond it the estimate is zero */
  double v_max;    /* m/s: planar speed bound */
  double w_max;    /* rad/s: yaw rate bound */
} nd_objest_cfg;

/* window 0.025 s, max_gap 0.1 s; v_max and w_max from the caller (no default). */
void nd_objest_cfg_default(nd_objest_cfg *cfg, double v_max, double w_max);

typedef struct {
  int64_t utime;   /* capture time, us */
  double x, y, yaw;
  double quat[4];  /* w-first orientation */
} nd_objest_frame;

typedef struct {
  nd_objest_cfg cfg;
  nd_objest_frame hist[ND_OBJEST_HIST];
  int head, n;
} nd_objest;

void nd_objest_init(nd_objest *e, const nd_objest_cfg *cfg);

/* Forget every frame (a restarted publisher, a clock that stepped back). */
void nd_objest_reset(nd_objest *e);

/* Add the frame of pose pos[3], quat[4] (w-first) captured at utime; a frame not newer than
 * the newest resets the history first (time went back). */
void nd_objest_add(nd_objest *e, int64_t utime, const double pos[3], const double quat[4]);

/* Velocity at the newest frame in MuJoCo's free-joint convention: linear (world) in
 * v[0..2], angular (body frame) in v[3..5]; zero with fewer than two frames. */
void nd_objest_velocity(const nd_objest *e, double v[6]);

#endif
