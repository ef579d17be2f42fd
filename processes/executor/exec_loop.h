/* exec_loop: one cycle of nudge-executor's 1 kHz loop, without the clock.
 *
 * The loop's body lives here, apart from the thread that sleeps to deadlines, so a test
 * can run it on synthetic time and check what it does between two deadlines: take the
 * newest robot state and plan from their mailboxes, apply the plan (core/nd_exec.h,
 * limits enforced there), brake and hold when an input is stale, encode the setpoint as
 * EE_CMD into the ring. A cycle never allocates, locks, prints or waits on I/O; what it
 * has to say (mode, stale spells, refused plans, loop statistics) goes into the report
 * mailbox.
 *
 * Threads: an I/O thread posts exec_loop_state_in / exec_loop_plan_in into io->state
 * / io->plan, drains io->ring and takes io->report; only the loop thread touches the
 * exec_loop itself. */
#ifndef EXEC_LOOP_H
#define EXEC_LOOP_H

#include <stdint.h>

#include "nd_exec.h"
#include "nd_rtio.h"
#include "ndp.h"

#define EXEC_LOOP_REPORT_PERIOD 0.1  /* s between routine report posts */

/* Newest robot state: only what the loop needs, stamped with when it was sent. */
typedef struct {
  double t_arrive;     /* ndp_mono() when it was sent (ndp_sent_mono): ages count from there */
  double ee_pos[3];
  int stopped;         /* a reflex stopped the robot (robot_state_t.MODE_STOPPED) */
} exec_loop_state_in;

/* Newest plan: its keypoints (the first is followed, every one must lie in the workspace)
 * and segment duration. */
typedef struct {
  double t_arrive;     /* as exec_loop_state_in's */
  int64_t plan_id;
  double t_start;      /* ndp_mono() at which its segment starts (<= t_arrive: at once) */
  double start_p[2];   /* setpoint position the planner's rollouts started from, m */
  int64_t utime;       /* plan_t.utime, passed on in EE_CMD.plan_utime */
  int M;               /* keypoints used, 1..ND_MAX_KEYS (clamped if not) */
  double keys[ND_MAX_KEYS][4];  /* (x, y, vx, vy) */
  double T;
} exec_loop_plan_in;

/* Why the executor is stale: bits. */
enum { EXEC_STALE_NO_PLAN = 1, EXEC_STALE_PLAN = 2, EXEC_STALE_STATE = 4 };

/* What the loop tells the I/O thread: posted every EXEC_LOOP_REPORT_PERIOD and at once
 * on a stale transition or a refused plan. Counters only grow, so a reader that misses a
 * post still sees every event in the next one. */
typedef struct {
  int mode;                 /* ND_EXEC_* mode, or -1 before the first robot state */
  int stale;                /* EXEC_STALE_* bits, 0 when live */
  int64_t n_stale, n_resume;/* transitions to stale and back */
  int64_t cycles, sent;     /* loop cycles; setpoints committed to the ring */
  int64_t accepted, refused;/* plans taken / refused by nd_exec (limits or workspace) */
  int64_t refused_box;      /* of the refused: a keypoint or trajectory outside the workspace */
  int64_t kept;             /* of the accepted: re-sent keypoints, their segment kept */
  double start_err_sum, start_err_max; /* m: the setpoint's distance from start_p when a
                                        * plan's segment starts (the latency the planner
                                        * did not foresee), over the accepted */
  int64_t late;             /* plans already stale when the loop took them: dropped */
  int64_t refused_id;       /* plan_id of the last refused plan */
  int refused_rc;           /* its ND_EXEC_* code (ND_EXEC_EBOX: the workspace) */
  char refused_why[160];    /* nd_exec's reason for it */
  int64_t plan_id;          /* plan being followed, -1 before the first */
  int64_t plan_utime;       /* its utime, 0 before the first */
} exec_loop_report;

_Static_assert(sizeof(exec_loop_state_in) <= ND_RTIO_MAX &&
                   sizeof(exec_loop_plan_in) <= ND_RTIO_MAX &&
                   sizeof(exec_loop_report) <= ND_RTIO_MAX,
               "mailbox payloads must fit an nd_mailbox");

/* Tag of EE_CMD messages in the ring (the only kind the loop publishes). */
enum { EXEC_LOOP_TAG_EE_CMD = 1 };

/* The hand-over objects between the loop and the I/O thread. */
typedef struct {
  nd_mailbox state, plan, report;
  nd_ring ring;
} exec_loop_io;

/* The loop's state; only the loop thread touches it once the loop runs. */
typedef struct {
  nd_exec_cfg cfg;              /* limits; passed nd_exec_cfg_check */
  double timeout;               /* s: robot state older than this is stale */
  double plan_timeout;          /* s: a plan older than this is stale */
  exec_loop_io *io;
  uint64_t v_state, v_plan;     /* mailbox versions taken */
  int have_state;               /* first robot state seen: nd_exec initialised */
  double z;                     /* sphere height: the first measured ee z */
  double t_state;               /* send time of the newest robot state */
  int pending;                  /* plan taken but not yet applied */
  int stopped;                  /* the robot says a reflex stopped it */
  exec_loop_plan_in plan;
  int have_plan;                /* a plan has been accepted */
  double t_plan;                /* send time of the newest accepted plan */
  nd_exec ex;
  int64_t seq;
  double next_report;
  exec_loop_report rep;
} exec_loop;

/* Empty mailboxes and ring. */
void exec_loop_io_init(exec_loop_io *io);

/* Set up the loop on io with limits cfg (must pass nd_exec_cfg_check), the robot state's
 * timeout and the plan's (s). Also does what would otherwise happen lazily on the first cycle (lcm-gen's type
 * hash), so the cycles that follow allocate nothing. */
void exec_loop_init(exec_loop *s, const nd_exec_cfg *cfg, double timeout, double plan_timeout,
                    exec_loop_io *io);

/* One cycle at monotonic time now (s), which is wall-clock time utime (us): take inputs,
 * apply a new plan, step the executor, commit the setpoint for that instant to the ring.
 * A plan with any keypoint outside cfg's workspace is refused like one nd_exec_plan
 * refuses (counted, the running trajectory unchanged, the plan clock not renewed).
 * A new plan starts a new segment from the setpoint at its t_start (waiting for it, the
 * running segment goes on; a newer plan replaces a waiting one), except one that re-sends
 * the keypoint the running segment is heading for (ND_EXEC_SAME_KEY): that segment
 * goes on, so the keypoint stays due when it was first due.
 * Returns 1 if a setpoint was committed, 0 before the first robot state, -1 if the ring
 * was full (counted by the ring). No allocation, no locks, no I/O. */
int exec_loop_cycle(exec_loop *s, double now, int64_t utime);

/* Post the report: now if force, else when EXEC_LOOP_REPORT_PERIOD has passed. */
void exec_loop_report_post(exec_loop *s, double now, int force);

#endif
