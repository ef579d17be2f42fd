/* ndp_execloop: one cycle of nudge-executor's 1 kHz loop, without the clock.
 *
 * The loop's body lives here, apart from the thread that sleeps to deadlines, so a test
 * can run it on synthetic time and check what it does between two deadlines: take the
 * newest robot state and plan from their mailboxes, apply the plan (core/nd_exec.h,
 * limits enforced there), brake and hold when an input is stale, encode the setpoint as
 * EE_CMD into the ring. A cycle never allocates, locks, prints or waits on I/O; what it
 * has to say (mode, stale spells, refused plans, loop statistics) goes into the report
 * mailbox.
 *
 * Threads: an I/O thread posts ndp_execloop_state_in / ndp_execloop_plan_in into io->state
 * / io->plan, drains io->ring and takes io->report; only the loop thread touches the
 * ndp_execloop itself. */
#ifndef NDP_EXECLOOP_H
#define NDP_EXECLOOP_H

#include <stdint.h>

#include "nd_exec.h"
#include "nd_jitter.h"
#include "nd_rtio.h"
#include "ndp.h"

#define NDP_EXECLOOP_REPORT_PERIOD 0.1  /* s between routine report posts */

/* Newest robot state: only what the loop needs, stamped with when it was sent. */
typedef struct {
  double t_arrive;     /* ndp_mono() when it was sent (ndp_sent_mono): ages count from there */
  double ee_pos[3];
} ndp_execloop_state_in;

#define NDP_EXECLOOP_MAX_KEYS 8  /* plan_t.MAX_KEYPOINTS */

/* Newest plan: its keypoints (the first is followed, every one must lie in the workspace)
 * and segment duration. */
typedef struct {
  double t_arrive;     /* as ndp_execloop_state_in's */
  int64_t plan_id;
  int64_t utime;       /* plan_t.utime, passed on in EE_CMD.plan_utime */
  int M;               /* keypoints used, 1..NDP_EXECLOOP_MAX_KEYS (clamped if not) */
  double keys[NDP_EXECLOOP_MAX_KEYS][4];  /* (x, y, vx, vy) */
  double T;
} ndp_execloop_plan_in;

/* Why the executor is stale: bits. */
enum { NDP_STALE_NO_PLAN = 1, NDP_STALE_PLAN = 2, NDP_STALE_STATE = 4 };

/* What the loop tells the I/O thread: posted every NDP_EXECLOOP_REPORT_PERIOD and at once
 * on a stale transition or a refused plan. Counters only grow, so a reader that misses a
 * post still sees every event in the next one. */
typedef struct {
  int mode;                 /* ND_EXEC_* mode, or -1 before the first robot state */
  int stale;                /* NDP_STALE_* bits, 0 when live */
  int64_t n_stale, n_resume;/* transitions to stale and back */
  int64_t cycles, sent;     /* loop cycles; setpoints committed to the ring */
  int64_t accepted, refused;/* plans taken / refused by nd_exec (limits or workspace) */
  int64_t refused_box;      /* of the refused: a keypoint or trajectory outside the workspace */
  int64_t kept;             /* of the accepted: re-sent keypoints, their segment kept */
  int64_t late;             /* plans already stale when the loop took them: dropped */
  int64_t refused_id;       /* plan_id of the last refused plan */
  int refused_rc;           /* its ND_EXEC_* code (ND_EXEC_EBOX: the workspace) */
  char refused_why[160];    /* nd_exec's reason for it */
  int64_t plan_id;          /* plan being followed, -1 before the first */
  int64_t plan_utime;       /* its utime, 0 before the first */
  int64_t missed;           /* deadlines skipped after overruns */
  ndp_loop_stats loop;      /* period error (us) and overruns */
} ndp_execloop_report;

_Static_assert(sizeof(ndp_execloop_state_in) <= ND_RTIO_MAX &&
                   sizeof(ndp_execloop_plan_in) <= ND_RTIO_MAX &&
                   sizeof(ndp_execloop_report) <= ND_RTIO_MAX,
               "mailbox payloads must fit an nd_mailbox");

/* Tag of EE_CMD messages in the ring (the only kind the loop publishes). */
enum { NDP_EXECLOOP_TAG_EE_CMD = 1 };

/* The hand-over objects between the loop and the I/O thread. */
typedef struct {
  nd_mailbox state, plan, report;
  nd_ring ring;
} ndp_execloop_io;

/* The loop's state; only the loop thread touches it once the loop runs. */
typedef struct {
  nd_exec_cfg cfg;              /* limits; passed nd_exec_cfg_check */
  double timeout;               /* s: inputs older than this are stale */
  ndp_execloop_io *io;
  uint64_t v_state, v_plan;     /* mailbox versions taken */
  int have_state;               /* first robot state seen: nd_exec initialised */
  double z;                     /* sphere height: the first measured ee z */
  double t_state;               /* send time of the newest robot state */
  int pending;                  /* plan taken but not yet applied */
  ndp_execloop_plan_in plan;
  int have_plan;                /* a plan has been accepted */
  double t_plan;                /* send time of the newest accepted plan */
  nd_exec ex;
  int64_t seq;
  nd_jitter jit;                /* wake-up errors, added by the caller's clock loop */
  double next_report;
  ndp_execloop_report rep;      /* the caller adds missed deadlines and overruns */
} ndp_execloop;

/* Empty mailboxes and ring. */
void ndp_execloop_io_init(ndp_execloop_io *io);

/* Set up the loop on io with limits cfg (must pass nd_exec_cfg_check) and input timeout
 * (s). Also does what would otherwise happen lazily on the first cycle (lcm-gen's type
 * hash), so the cycles that follow allocate nothing. */
void ndp_execloop_init(ndp_execloop *s, const nd_exec_cfg *cfg, double timeout,
                       ndp_execloop_io *io);

/* One cycle at monotonic time now (s), which is wall-clock time utime (us): take inputs,
 * apply a new plan, step the executor, commit the setpoint for that instant to the ring.
 * A plan with any keypoint outside cfg's workspace is refused like one nd_exec_plan
 * refuses (counted, the running trajectory unchanged, the plan clock not renewed).
 * A new plan starts a new segment from the current setpoint, except one that re-sends
 * the keypoint the running segment is heading for (ND_EXEC_SAME_KEY): that segment
 * goes on, so the keypoint stays due when it was first due.
 * Returns 1 if a setpoint was committed, 0 before the first robot state, -1 if the ring
 * was full (counted by the ring). No allocation, no locks, no I/O. */
int ndp_execloop_cycle(ndp_execloop *s, double now, int64_t utime);

/* Post the report: now if force, else when NDP_EXECLOOP_REPORT_PERIOD has passed. */
void ndp_execloop_report_post(ndp_execloop *s, double now, int force);

#endif
