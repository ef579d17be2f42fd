/* nd_rollout: one recorded task execution, the unit of the replay buffer.
 *
 * What the adapter needs to replay a task in the model: the initial state, the control
 * actually applied at every control step (the force on the sphere in simulation, the
 * end-effector velocity on a real robot), the setpoint the executor commanded during the
 * step, and what was observed after each step. Plain arrays, owned by the struct
 * (nd_rollout_alloc / nd_rollout_free).
 *
 * The refit replays the recorded force, re-anchored on the observations
 * (doc/design.md#refit); the setpoints are kept so a rollout can also be replayed through
 * the robot's tracking controller (SETPOINT replay, sim/nds_replay.h), an option.
 *
 * The object is observed as motion capture sees it: its full pose, position and
 * orientation. The loss compares only x, y and yaw, but the replay puts the whole observed
 * pose back into the model at every re-anchoring: a sliding box hops on MuJoCo's soft
 * contact, and a replay that kept its own height and tilt would start each window from a
 * different hop than the recording did (sim/nds_replay.h).
 *
 * Encoding (the payload of a replay-buffer record, see nd_rfile.h), version 3, every
 * field little-endian, doubles as IEEE-754 binary64 bit patterns (bitwise round trip):
 *
 *   offset  size  field
 *        0     4  u32 encoding version (3)
 *        4     4  i32 n, steps
 *        8     8  i64 task_id
 *       16     8  i64 utime
 *       24     4  i32 outcome
 *       28     4  i32 control
 *       32     8  f64 dt
 *       40    24  f64 goal[3]
 *       64    32  f64 theta[4]
 *       96    24  f64 obj_pos[3]
 *      120    32  f64 obj_quat[4]
 *      152    48  f64 obj_vel[6]
 *      200    16  f64 ee_pos[2]
 *      216    16  f64 ee_vel[2]
 *      232  16 n  f64 u[n][2]
 *              56 n  f64 obj[n][7]
 *              16 n  f64 ee[n][2]
 *              48 n  f64 sp[n][6]
 *   total 232 + 136 n bytes, exactly.
 *
 * A rollout is valid when n is in [1, ND_ROLLOUT_MAX_STEPS] (the adapter divides by the
 * duration), outcome and control are known values, dt > 0, every double is finite, and
 * every quaternion (obj_quat, obj[i][3..6]) has a norm within ND_ROLLOUT_QUAT_TOL of 1.
 * Encoding refuses an invalid rollout, so nothing a decoder would reject is ever written.
 * Version 2 (obj[n][3]: x, y, yaw) is refused by name: its records lack the height and
 * tilt the replay needs, and cannot be re-derived (doc/decisions.md#rollout-encoding;
 * the format: doc/file-format.md). */
#ifndef ND_ROLLOUT_H
#define ND_ROLLOUT_H

#include <stddef.h>
#include <stdint.h>

#include "nd_theta.h"

/* What u holds. */
enum { ND_CTRL_FORCE = 0, ND_CTRL_VELOCITY = 1 };

/* How the task ended (as nd_task_status, plus aborted). */
enum { ND_OUTCOME_SUCCESS = 1, ND_OUTCOME_TIMEOUT = 2, ND_OUTCOME_ABORTED = 3 };

/* 8 min at 1 kHz: the longest rollout whose encoding (65.3 MB) fits one record of the
 * replay buffer (ND_RFILE_MAX_PAYLOAD, 64 MiB), so every valid rollout can be appended. */
#define ND_ROLLOUT_MAX_STEPS 480000

#define ND_ROLLOUT_ENC_VERSION 3
#define ND_ROLLOUT_ENC_FIXED 232      /* bytes before the step arrays */
#define ND_ROLLOUT_ENC_STEP 136       /* bytes per step */
_Static_assert(ND_ROLLOUT_ENC_FIXED + (unsigned long long)ND_ROLLOUT_ENC_STEP *
                                            ND_ROLLOUT_MAX_STEPS <= 64ull << 20,
               "the longest rollout must fit one replay-buffer record");
#define ND_ROLLOUT_OBJ 7              /* obj columns: x, y, z, qw, qx, qy, qz */
#define ND_ROLLOUT_QUAT_TOL 1e-2      /* |norm - 1| a stored quaternion may have (MOCAP's) */

typedef struct {
  /* metadata */
  int64_t task_id;
  int64_t utime;          /* when the task started, microseconds since the epoch */
  double goal[3];         /* x, y, yaw */
  double theta[ND_NTHETA_PAPER]; /* the paper's four of the planner's theta (the box's
                                   entries are in the adapter's history, not here) */
  int32_t outcome;        /* ND_OUTCOME_* */
  int32_t control;        /* ND_CTRL_* */
  double dt;              /* control step, s */
  /* state before the first step */
  double obj_pos[3], obj_quat[4], obj_vel[6];
  double ee_pos[2], ee_vel[2];
  /* per step i in [0, n): control applied during the step, observation after it */
  int32_t n;
  double *u;              /* n x 2 */
  double *obj;            /* n x 7: object position x, y, z, quaternion w, x, y, z */
  double *ee;             /* n x 2: end-effector x, y */
  double *sp;             /* n x 6: commanded setpoint px, py, vx, vy, ax, ay */
} nd_rollout;

/* Allocate zeroed step arrays of r for n in [0, ND_ROLLOUT_MAX_STEPS] steps and set r->n
 * (metadata untouched). r must not hold arrays (they would leak). Return 0, or -1. */
int nd_rollout_alloc(nd_rollout *r, int n);

/* Free the step arrays; r's metadata stays, n becomes 0, the pointers NULL. */
void nd_rollout_free(nd_rollout *r);

/* Copy src (metadata and steps) into dst, which receives fresh arrays (its previous
 * contents are ignored, not freed). Return 0, or -1 (no memory; dst then holds none). */
int nd_rollout_copy(nd_rollout *dst, const nd_rollout *src);

/* The object's pose after step i (ND_ROLLOUT_OBJ values), i in [0, n). */
double *nd_rollout_obj(const nd_rollout *r, int i);

/* Duration n * dt, s. */
double nd_rollout_duration(const nd_rollout *r);

/* 0 if r is valid (see above), else -1 and err names the first offending field. */
int nd_rollout_check(const nd_rollout *r, char *err, int errlen);

/* Bytes of the encoding of a rollout of n steps (n >= 0). */
size_t nd_rollout_encoded_size(int n);

/* Encode a valid r into buf (cap bytes) and set *len. Return 0, or -1 and a message
 * (r invalid, or cap smaller than nd_rollout_encoded_size(r->n)). */
int nd_rollout_encode(const nd_rollout *r, unsigned char *buf, size_t cap, size_t *len,
                      char *err, int errlen);

/* Decode len bytes into r, which receives fresh arrays (its previous contents are
 * ignored, not freed). Return 0; or -1 and a message naming the field (wrong version,
 * n out of bounds, length inconsistent with n, unknown outcome/control, dt <= 0, a
 * number not finite), r then holding no arrays. */
int nd_rollout_decode(nd_rollout *r, const unsigned char *buf, size_t len, char *err,
                      int errlen);

#endif
