/* planner: what the files of nudge-planner share.
 *
 *   main.c    options and wiring: models, pool, LCM, the plan loop
 *   inputs.c  the input channels: validation, the newest of each, the task in hand
 *   plan.c    one plan from the newest inputs, and the release, published on PLAN
 *
 * The process keeps the newest world state from MOCAP (object pose) and ROBOT_STATE
 * (end-effector), the executor's setpoint from EE_CMD, the goal from TASK and theta from
 * PARAMS. While a task is active and the state is fresh it plans back to back; when the
 * task ends, one release plan takes the sphere clear of the object, and while idle the
 * planner sends it clear again if the object, still sliding, comes back near; a PLACE
 * (the object to be put at a pose) sends it clear of that pose. Planning
 * runs in the main thread between LCM drains: it is not a 1 kHz process, and the queues
 * are sized so a plan's duration of input fits in them. */
#ifndef PLANNER_H
#define PLANNER_H

#include "nd_objest.h"
#include "nd_parse.h"
#include "nds_planner.h"
#include "ndp.h"
#include "ndp_validate.h"

#define PROG "nudge-planner"

typedef struct {
  const char *url;
  int threads, pop, iters;
  double plan_dt;
  uint64_t seed;
  double max_rate;       /* Hz */
  double state_timeout;  /* s */
  double theta[ND_NTHETA];
  nd_box ws;             /* keypoint box, m */
  int lead;              /* 1: plans start when they reach the executor (PLANNER_LEAD_*) */
  double release;        /* m the sphere rests clear of the object after a task */
} planner_opts;

/* Latency compensation: a plan starts lead seconds after planning begins, predicted from
 * the state and the executor's committed trajectory (EE_CMD's future), and the executor
 * waits for that moment. lead = the recent plan time x LEAD_GAIN + LEAD_MARGIN (s): a
 * plan that takes longer arrives late and the executor shortens its segment, one that
 * is quicker waits. The prefix is at most PLANNER_PRE_MAX model steps. */
#define PLANNER_LEAD_GAIN 1.2
#define PLANNER_LEAD_MARGIN 0.004
/* An object centre this far (m) beyond the keypoint box, and beyond its goal, is logged
 * once per task: the sphere cannot get behind it to push it back. */
#define PLANNER_EDGE_WARN 0.005
#define PLANNER_PRE_MAX 256
/* The release's shortest segment, s; lengthened to the planner's limits and arm load. */
#define PLANNER_RELEASE_T 0.1
/* The executor brakes at its own Cartesian limits once no plan has come for its plan
 * timeout (0.3 s by default): a release segment that lasts longer is re-sent every
 * PLANNER_RELEASE_RENEW s until it ends, and the same keypoint only renews it. */
#define PLANNER_RELEASE_RENEW 0.1
/* After a release the object may still slide and turn a corner onto the resting sphere:
 * while idle, a gap below PLANNER_RECLEAR x --release sends the sphere clear again, at
 * most once per PLANNER_RECLEAR_WAIT s (a release's segment gets time to move it first).
 * A target the keypoint box keeps within PLANNER_RECLEAR_MIN m of the sphere ends it. */
#define PLANNER_RECLEAR 0.75
#define PLANNER_RECLEAR_WAIT 0.25
#define PLANNER_RECLEAR_MIN 1e-3

/* A PLACE (an operator resets the object) needs the sphere clear of the new pose: while
 * idle, the release and keep-clear go by that pose, PLANNER_PLACE_EXTRA beyond the
 * PLACE's clear (tracking error), until MOCAP shows the object within PLANNER_PLACE_AT of
 * it, or for as long as the request stands (NUDGE_PLACE_T_WAIT). */
#define PLANNER_PLACE_EXTRA 0.003
#define PLANNER_PLACE_AT 0.005

/* A PLACE with park: once the object is seen at its pose, the sphere goes to the park
 * point along the shortest way round it (nd_cost_round_next), found once from that pose
 * and one move at rest per point, each as quick as a release. The way keeps
 * PLANNER_PARK_EXTRA beyond nd_cost's margin: tracking lags a setpoint that turns at a
 * corner. A way of more than PLANNER_PARK_LEGS points is given up (it has at most a step out
 * of the grown box, three corners and the park point). */
#define PLANNER_PARK_EXTRA 0.01
#define PLANNER_PARK_LEGS 6
/* A move's end is checked on ROBOT_STATE before the next: a sphere not within
 * PLANNER_PARK_AT of it (the executor braked a move whose renewal came late, or it lags)
 * is sent there again from where it is, at most PLANNER_PARK_TRIES times per point. */
#define PLANNER_PARK_AT 0.005
#define PLANNER_PARK_TRIES 5

/* Niceness the planning threads add to the process's: below its LCM receive thread. */
#define PLANNER_COMPUTE_NICE 5

/* The process's mutable state, owned by the main thread (LCM handlers run inside
 * lcm_handle on it, never during a plan). */
typedef struct {
  const planner_opts *o;
  lcm_t *lcm;
  nds_planner *planner;
  ndp_status st;

  /* newest inputs */
  nudge_mocap_t mocap;
  ndp_input in_mocap;
  nd_objest est;               /* the object's velocity from the MOCAP frames */
  int64_t mocap_lost;          /* frames missing by seq */
  int64_t overflows;           /* drains that found a full queue */
  nudge_robot_state_t rs;
  ndp_input in_rs;
  nudge_ee_cmd_t cmd;
  ndp_input in_cmd;

  /* task */
  int active;
  nudge_task_t task;
  int have_ended;
  int64_t ended_id;            /* last task an EPISODE ended: a repeated TASK for it is old */
  double task_t0;
  int64_t task_plans, task_mocap_lost0, task_overflows0;
  double task_ms_sum, task_ms_max;
  int64_t task_evals, task_over_limits, task_over_arm; /* candidates, and those penalised */
  int64_t task_rollouts, task_redrawn; /* candidates simulated, and fresh draws drawn again */
  double task_stale;           /* s of the task spent without fresh state */
  int edge_warned;             /* the task's object was logged beyond the sphere's reach */
  int release_due;             /* the task ended: one PLAN sends the sphere clear (nd_release) */
  int keep_clear;              /* released and idle: the sphere is kept clear of the object */
  double released_at;          /* when the last release was published, s (ndp_mono) */
  double release_until;        /* when its segment ends, s (ndp_mono) */
  double release_key[2];       /* where it rests the sphere */
  double stopped_at;           /* the newest ROBOT_STATE saying STOPPED came, s (ndp_mono) */
  double obj_half[2], ee_radius; /* the model's object half sides and sphere radius, m */
  nudge_place_t place;         /* the newest PLACE (place_id -1: none) */
  int place_due;               /* a new PLACE: send the sphere clear of its pose */
  int place_pending;           /* the object is not yet seen at its pose */
  double place_at;             /* when it came, s (ndp_mono) */
  int parking;                 /* the PLACE's park is under way (PLANNER_PARK_*) */
  int park_n, park_next;       /* the way's points, and the next one to move to */
  int park_tries;              /* moves sent to the point before park_next */
  double park_way[PLANNER_PARK_LEGS][2];

  double plan_s;               /* recent plan time, s (moving average) */
  double pre_sp[PLANNER_PRE_MAX][2][4]; /* the prefix's setpoints, one per model step */
  double lead_sum;             /* s of prediction over the task's plans */
  int64_t theta_version;       /* params_t.version in use; -1 = --theta */
  int64_t plan_id;
  int64_t last_start_utime;    /* when the last plan started (nds_planner_retime) */
  ndp_ratelog rejected;        /* rate-limited log of refused inputs */
  ndp_ratelog lost;            /* rate-limited log of queue overflows */
} planner_proc;

/* Count a refused input in the heartbeat and log it, rate-limited. */
void planner_reject(planner_proc *p, const char *channel, const char *why);

/* Subscribe every input channel of p on p->lcm, with queues that hold a plan's worth of
 * input. Return 0, or -1 with a message. */
int planner_subscribe(planner_proc *p, char *err, int errlen);

/* After a drain: count the streams whose queue overflowed. */
void planner_drained(planner_proc *p);

/* 1 if a plan may start now: MOCAP and ROBOT_STATE fresh, and the setpoint not known to be
 * behind while the executor is live. */
int planner_state_fresh(const planner_proc *p, double now);

/* Print the active task's summary line ("succeeded", "interrupted", ...). */
void planner_task_summary(planner_proc *p, const char *how);

/* Plan from the newest inputs and publish PLAN. Return 0, or -1 with a message (LCM). */
int planner_plan_once(planner_proc *p, double now, char *err, int errlen);

/* Once the task has ended and MOCAP and ROBOT_STATE are fresh: publish the release, a
 * PLAN of one keypoint at rest clear of the object (iterations 0; nd_release). Return 0,
 * or -1 with a message (LCM). */
int planner_release(planner_proc *p, double now, char *err, int errlen);

/* While idle after a new PLACE, once MOCAP and ROBOT_STATE are fresh: publish a release
 * that rests the sphere clear of the PLACE's pose, if it is not already. Return 0, or -1
 * with a message (LCM). */
int planner_place(planner_proc *p, double now, char *err, int errlen);

/* While idle after a release: re-send it until its segment ends (PLANNER_RELEASE_RENEW);
 * then the next move of a PLACE's park (PLANNER_PARK_*); otherwise, if the object has come
 * closer to the sphere than PLANNER_RECLEAR x --release, publish the release again
 * (PLANNER_RECLEAR_*); nothing while the arm is stopped. Return 0, or -1 with a message
 * (LCM). */
int planner_keep_clear(planner_proc *p, double now, char *err, int errlen);

#endif
