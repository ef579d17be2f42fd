/* nd_recorder: a task's rollout (nd_rollout.h) from the live sensor streams.
 *
 * The start state comes from the newest robot state and object frame when the task is
 * issued (the object at rest after the runner's settle pause). Then one step per robot
 * state (the robot's control step: u = what it applied during the step, the force or the
 * end-effector velocity as the rollout's control says; ee = the sphere after it), sp = the
 * newest setpoint seen before that state, obj = the object's pose interpolated to the
 * step's time (frames come at the motion-capture rate, 240 Hz, steps at 1 kHz; joined as
 * `join` says, held beyond the first and last frame).
 *
 * Messages lost on the way show as gaps in the states' sequence numbers: a gap of up to
 * ND_REC_GAP_FILL_MAX steps is filled by linear interpolation between its neighbours; a
 * longer one, more than ND_REC_FILL_MAX_FRAC of the steps filled, or a step period off the
 * expected dt by more than ND_REC_DT_TOLERANCE, and the task is not recorded (an
 * interpolated second of pushing would be made-up data, a replay at the wrong rate wrong).
 * The arrays are allocated once for the longest task; adding samples never allocates. */
#ifndef ND_RECORDER_H
#define ND_RECORDER_H

#include <stdint.h>

#include "nd_rollout.h"
#include "nd_theta.h"

#define ND_REC_GAP_FILL_MAX 20     /* states one filled gap may span */
#define ND_REC_FILL_MAX_FRAC 0.02  /* of a task's steps, at most this many filled */
#define ND_REC_DT_TOLERANCE 0.1    /* measured step period vs dt, relative */

/* How the object's frames are joined between their times; both pass through every frame.
 * A line gives every step of a frame interval one rate, the interval's mean. A cubic
 * Hermite curve (three-point rates at the frames, quaternions normalised) follows an
 * accelerating object, exactly if its pose is quadratic in time, and its rates average a
 * noisy frame over two intervals (doc/decisions.md#frames-per-world). */
enum { ND_REC_JOIN_LINE = 0, ND_REC_JOIN_CUBIC = 1 };

/* One robot state (ROBOT_STATE). */
typedef struct {
  int64_t seq;           /* +1 per control step of the robot */
  int64_t utime;         /* us, the step's time */
  double ee_pos[2], ee_vel[2], force[2];
} nd_rec_state;

/* One setpoint the executor commanded (EE_CMD). */
typedef struct {
  double p[2], v[2], a[2];
} nd_rec_setpoint;

typedef struct {
  double dt;             /* the robot's control step, s */
  int cap;               /* steps (and frames: at most one per step) the arrays hold */
  nd_rollout r;          /* r.n is the capacity except in nd_recorder_finish's result */
  int64_t *step_us;      /* cap: each step's utime */
  int64_t *frame_us;     /* cap: the task's object frames ... */
  double *frame;         /* cap x ND_ROLLOUT_OBJ: ... their poses */
  int nframes;
  int on;                /* recording a task */
  int steps;
  int64_t last_seq, last_us, start_us;
  double last_u[2], last_ee[2];
  int64_t filled, longest_gap;
  int dropped;           /* steps past cap */
  char broken[200];      /* why this task cannot be recorded; "" if it can */
  nd_rec_setpoint sp;    /* the newest setpoint */
  int have_sp;
  int join;              /* ND_REC_JOIN_*: LINE after init; set before a task to change */
} nd_recorder;

/* Allocate for tasks of up to tau s (plus a margin for overruns) at step dt. Return 0, or
 * -1 with a message (no memory). */
int nd_recorder_init(nd_recorder *rc, double tau, double dt, char *err, int errlen);
void nd_recorder_free(nd_recorder *rc);

/* Start recording task id toward goal (x, y, yaw) from robot state s and object pose
 * pose[7] (position, w-first quaternion) captured at frame_us, with the planner's theta;
 * control is ND_CTRL_FORCE or ND_CTRL_VELOCITY. s NULL: no robot state yet, the task will
 * not be recorded (nd_recorder_finish says why). */
void nd_recorder_begin(nd_recorder *rc, const nd_rec_state *s, int64_t frame_us,
                       const double pose[ND_ROLLOUT_OBJ], int64_t id, const double goal[3],
                       const double theta[ND_NTHETA], int control);

/* The newest setpoint (kept across tasks). */
void nd_recorder_setpoint(nd_recorder *rc, const nd_rec_setpoint *sp);

/* One robot state: a step (gaps filled). Ignored while not recording. */
void nd_recorder_state(nd_recorder *rc, const nd_rec_state *s);

/* One object frame: pose[7] captured at utime. Ignored while not recording. */
void nd_recorder_frame(nd_recorder *rc, int64_t utime, const double pose[ND_ROLLOUT_OBJ]);

/* Stop recording with outcome (ND_OUTCOME_*). Return 0 with *out, the finished rollout
 * (valid until the next nd_recorder_begin), or -1 with why it cannot be recorded. */
int nd_recorder_finish(nd_recorder *rc, int outcome, const nd_rollout **out, char *why,
                       int len);

/* The poses obj[n][7] at times t[n] (increasing) of nframes frames frame[nframes][7] taken
 * at frame_us (increasing), joined as join (ND_REC_JOIN_*) says, held beyond the first
 * and last frame. */
void nd_recorder_join(const int64_t *frame_us, const double *frame, int nframes, int join,
                      const int64_t *t, int n, double *obj);

#endif
