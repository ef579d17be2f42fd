/* bridge_loop: one step of nudge-bridge's 1 kHz loop, without the clock.
 *
 * Place the object where a PLACE asks, once the sphere is clear of the pose;
 * take the newest EE_CMD from its mailbox and track the trajectory it commits to, sampled at
 * the step's time (joined, when it left the one a step followed), until it is stale; then
 * hold where the sphere is, as before the first;
 * step the world (sim/nds_world.h);
 * encode ROBOT_STATE and the motion-capture frames the step released into the ring. A step
 * never allocates, locks, prints or waits on I/O (tests/unit/test_rtloop.c counts it);
 * what it has to say goes into the report mailbox.
 *
 * Threads: the I/O thread posts bridge_cmd into cmd, drains out and takes report; only the
 * loop thread touches the bridge_loop itself. */
#ifndef BRIDGE_LOOP_H
#define BRIDGE_LOOP_H

#include <stdint.h>

#include "nd_exec.h"
#include "nd_rtio.h"
#include "nd_rtloop.h"
#include "nds_world.h"
#include "nudge/nudge_place_t.h"

/* A validated EE_CMD as the loop needs it, stamped with its local arrival. */
typedef struct {
  double sp[2][4];      /* the setpoint [axis][p, v, a, j] at utime */
  nd_exec_future f;    /* what the executor committed to after it, times in s after utime */
  int64_t utime;       /* the time the setpoint is for, us */
  double arrival;      /* monotonic s */
  int64_t seq;
} bridge_cmd;

/* A command is applied at the step's own time, as a robot's interface samples a setpoint
 * stream at its own clock (doc/lab-world.md#commands): for h the step's utime less the
 * command's, p + v h + a h^2/2 + j h^3/6 up to BRIDGE_CMD_TAYLOR, and beyond it the
 * trajectory the command's future describes (nd_exec_future_eval), exactly. Taking the
 * newest command as it is would step the setpoint by v times the network's jitter (0.1 mm
 * at 0.5 m/s and 0.2 ms: 100 m/s^2 to the robot's acceleration reflex); the Taylor terms
 * drift from a live segment by snap h^4/24 (0.1 mm after 13 ms), which is why a stalled
 * commander or machine is bridged by the future, not the terms. A step before the newest
 * command's time (a catch-up after the bridge stalled) samples the newest command whose
 * time the steps have reached. */
#define BRIDGE_CMD_TAYLOR 0.002

/* The commands' stamps and the robot's clock may disagree by this much (s): h beyond the
 * commander's silence plus this is not silence but clocks apart (a wall-clock step), and
 * the robot holds its last setpoint until they agree again; each hold and resume starts a
 * new motion for the reflexes. A commander silent this long is reported, and followed. */
#define BRIDGE_CMD_HORIZON 0.02

/* A command off the trajectory a step sampled from the command before's future (the
 * executor switched plans while its commands were late) is joined, not stepped to: the
 * setpoint is the newest trajectory plus an offset that starts at what separates the two
 * (p, v, a, j) and decays to 0 in BRIDGE_JOIN_S along a min-snap segment. Stepped to, 6.5 um
 * in one step is 6500 m/s^3 to the jerk reflex; joined, ~10 um adds tens of m/s^3.
 * An offset over BRIDGE_JOIN_MAX is a jump the executor made; the robot gets it as it is. */
#define BRIDGE_JOIN_S 0.03
#define BRIDGE_JOIN_MAX 0.005

/* A validated PLACE (a new place_id), stamped with its local arrival. */
typedef struct {
  int64_t id;
  double pose[3];      /* x, y, yaw */
  double clear;        /* m */
  double arrival;      /* monotonic s */
} bridge_place;

/* A PLACE waits until the sphere is its clear from the pose (the planner moves it there
 * while idle), at most NUDGE_PLACE_T_WAIT s; then it is dropped and reported. */

/* How a step's setpoint was sampled, for telling what a reflex stop followed. */
typedef enum {
  BRIDGE_SAMPLE_HOLD = 0,    /* holding */
  BRIDGE_SAMPLE_TAYLOR = 1,  /* the newest command's Taylor terms */
  BRIDGE_SAMPLE_FUTURE = 2,  /* the newest command's future */
  BRIDGE_SAMPLE_PREV = 3     /* the newest reached (a step before the newest's time) */
} bridge_sample_how;

typedef struct {
  int32_t how;          /* bridge_sample_how */
  double h;             /* s after the sampled command's time */
  double silence;       /* s since the newest command arrived */
  int64_t cmd_seq;      /* the sampled command's seq */
  double join;          /* s into a join (BRIDGE_JOIN_S), or -1 */
} bridge_sample;

/* What the loop reports, every BRIDGE_LOOP_REPORT_STEPS steps and at every hold or stop
 * change. Counters only grow. */
typedef struct {
  int64_t steps, resets, hold_events, apart_events, silent_events, stops, joins;
  int64_t places, places_dropped;
  int64_t place_id;     /* the newest placed or dropped PLACE */
  double place_pose[3], place_gap; /* its pose and the sphere's gap to it, m */
  int64_t robot_states, frames, arm_states;
  int64_t unpublished;  /* steps of a replay older than BRIDGE_PUBLISH_S: no messages */
  double hold_pos[2];  /* the setpoint while holding */
  int32_t holding, have_cmd, stopped;
  int32_t apart;       /* the hold is for stamps apart by over BRIDGE_CMD_HORIZON */
  nds_panda_reflex reflex;  /* the newest stop's */
  bridge_sample stop_sample[2]; /* how its step's setpoint was sampled, and the step's before */
} bridge_report;

#define BRIDGE_LOOP_REPORT_STEPS 100

/* A PLACE also waits for the sphere and its command at rest (under BRIDGE_PLACE_REST), as an
 * operator waits for the arm to stop: a sphere passing clear of the pose on its way may
 * come back through it. */
#define BRIDGE_PLACE_REST 0.01  /* m/s */

#define BRIDGE_LOOP_ARM_STEPS 20  /* ARM_STATE every 20 steps: 50 Hz, for drawing */

enum { BRIDGE_TAG_ROBOT_STATE = 0, BRIDGE_TAG_MOCAP = 1, BRIDGE_TAG_ARM_STATE = 2 };

typedef struct {
  nds_world *world;
  double cmd_timeout;  /* s: a command older than this is stale */
  nd_mailbox cmd;      /* I/O -> loop */
  nd_mailbox place;    /* I/O -> loop: the newest PLACE */
  nd_mailbox report;   /* loop -> I/O */
  nd_ring out;         /* loop -> I/O: encoded ROBOT_STATE / MOCAP / ARM_STATE */
  atomic_uint_fast64_t resume_req;  /* I/O -> loop: +1 per new task or PLACE (a stopped arm
                                     * resumes) */
  /* the loop thread's own */
  bridge_cmd last, prev; /* the newest command, and the newest one whose time a step has
                          * reached (the one before it, unless it is ahead of the steps) */
  int have_prev;
  bridge_cmd src;      /* the command the last step sampled */
  bridge_place pl;     /* the PLACE waiting for the sphere to clear its pose (pl_pending) */
  int pl_pending;
  uint64_t pl_version;
  nd_snap_seg join;    /* the offset being joined, from join_utime on (joining) */
  int64_t join_utime;
  int joining;
  int silent;          /* the newest command's silence is reported */
  double awake_since;  /* monotonic s: the latest wake-up after a stall (BRIDGE_STALL_S) */
  int quiet;           /* this step publishes nothing (BRIDGE_PUBLISH_S) */
  bridge_sample sample[2]; /* this step's, and the step's before */
  uint64_t cmd_version;
  int have_cmd, holding;
  double hold[2];
  double sp_last[2];   /* the setpoint position of the last step */
  double ee_speed;     /* the sphere's speed after the last step, m/s */
  uint64_t resume_seen;
  int64_t rs_seq, mc_seq, arm_seq;
  bridge_report rep;
} bridge_loop;

/* Set up the loop on world w (which it steps from now on). Also does what would otherwise
 * happen lazily on the first step (lcm-gen's type hashes), so the steps that follow
 * allocate nothing. */
void bridge_loop_init(bridge_loop *b, nds_world *w, double cmd_timeout);

/* One world step for monotonic time now (s), which is wall-clock time utime (us). */
void bridge_loop_step(bridge_loop *b, double now, int64_t utime);

/* bridge_loop_step for nd_rtloop (ctx: the bridge_loop): one step per deadline, at the
 * deadline's time, so world time keeps up with real time. */
void bridge_loop_tick(void *ctx, const nd_rtloop_tick *t);

/* How long a stall of the machine the loop replays whole (s). Every deadline the commands
 * are stamped for gets its world step, so the robot lives through the stall as the
 * commands did; a deadline skipped would move the sampled setpoint by the skipped time in
 * one step (3 mm at 0.3 m/s and 10 ms, 3 m/s to the velocity reflex). On the loaded 2-core
 * VM stalls reach 0.27 s (decisions#long-stall). */
#define BRIDGE_CATCH_UP_S 1.0

/* A replayed step publishes its messages only if its deadline is at most this old (s): the
 * newest 0.15 s of a replay (150 states, 36 frames, 8 arm states) fit the out ring unread,
 * and older states are of use to no receiver. The rest show as gaps in seq. */
#define BRIDGE_PUBLISH_S 0.15

/* A wake-up this late (s) ends a stall of the whole machine: the commander was frozen with
 * the loop, so if its commands were timely when the stall began, their timeout counts from
 * the wake-up, and until it has passed the robot follows the trajectory the last command
 * committed to (which ends at rest), not a hold that the commander's next command would
 * jump away from. Commands stale before the stall stay stale. */
#define BRIDGE_STALL_S 0.02

/* nd_rtloop_cfg.catch_up_max for a loop at rate Hz: BRIDGE_CATCH_UP_S of deadlines. */
int bridge_loop_catch_up_max(double rate);

/* Post the report now. */
void bridge_loop_report_post(bridge_loop *b);

#endif
