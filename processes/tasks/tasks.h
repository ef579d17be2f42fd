/* tasks: what the files of nudge-tasks, the episode runner, share.
 *
 *   main.c    wiring: the tasks one after another, the summary
 *   options.c the command line and the default goal chain
 *   inputs.c  the channels: MOCAP for the terminal condition, and with --record the
 *             robot's and executor's streams and PARAMS
 *   run.c     one task: TASK out, the object followed to the terminal condition, EPISODE
 *   record.c  the replay buffer: each task's rollout (core/nd_recorder.h) appended
 *
 * The runner publishes one pushing task at a time, watches the object on MOCAP, ends the
 * task on the terminal condition (L_pos + w_rot L_rot < eps, or the time limit) and reports
 * it on EPISODE and as one line on stdout. The object is not reset between tasks unless
 * --place asks for it at one pose before each (PLACE: an emulating bridge puts it there, on
 * a robot a person does); else each goal starts where the previous task left the object. Times
 * are measured on this host's monotonic clock, from the TASK publication to the arrival of
 * the MOCAP frame that met the condition.
 *
 * A full or read-only file system (or an I/O error) does not stop the tasks: recording is
 * what the runner does besides its job. The failed append is reported with the file and
 * the reason, the records already in the file stay as they were (nd_rfile cuts a partial
 * write back), the next task tries again, and the summary and the exit status (3) say how
 * many tasks were lost. A buffer that is not ours to write (another recorder holds it, not
 * a record file, no permission, no such directory) is refused at the start instead: that
 * is a wrong argument, not a condition that may pass. */
#ifndef TASKS_H
#define TASKS_H

#include "nd_goal.h"
#include "nd_rbuf.h"
#include "nd_recorder.h"
#include "ndp.h"
#include "ndp_validate.h"

#define PROG "nudge-tasks"
#define MAX_GOALS 1000
#define MOCAP_GAP_WARN 0.5 /* s without a frame during a task before saying so */
/* A record starts from the object at rest (nd_recorder.h): before each task the runner
 * waits until the object moved less than REST_SPEED (its yaw times REST_ARM counted too)
 * over REST_SPAN of frames, at most SETTLE_MAX; motion capture noise of 0.1 mm and 2 mrad
 * per frame reads as ~2 mm/s over the span. */
#define REST_SPEED 0.01  /* m/s */
#define REST_SPAN 0.1    /* s */
#define REST_ARM 0.05    /* m: about the object's half length */
#define SETTLE_MAX 5.0   /* s */
/* ... and until the commands (EE_CMD) have held the sphere at rest for SETTLE_CMD_REST,
 * longer than the planner waits before sending it clear again (PLANNER_RECLEAR_WAIT): an
 * object at rest against a sphere still on its way out, or about to be sent out, would
 * start a record in contact. Without EE_CMD (no executor yet) only the object counts. */
#define SETTLE_CMD_REST 0.3  /* s */
/* --place: the PLACE is re-sent every PLACE_RESEND s until a MOCAP frame captured after it
 * shows the object within PLACE_POS and PLACE_YAW of the pose, at most --place-wait s. The
 * sphere must keep PLACE_CLEAR from the placed object's sides (the planner's release). */
#define PLACE_RESEND 0.25  /* s */
#define PLACE_POS 0.005    /* m */
#define PLACE_YAW 0.05     /* rad */
#define PLACE_CLEAR 0.01   /* m */
#define PLACE_SAY 3.0      /* s: a placement not seen by then is announced (for a person) */
/* A record assumes the object at the placed pose: one moved off it before the task (a
 * sphere still on its way out, a hand) is placed again, at most PLACE_TRIES times. Each
 * PLACE has a new place_id, the wall clock in us (ids only increase). */
#define PLACE_TRIES 3
/* A reflex stop while placing is acknowledged with a new PLACE once ROBOT_STATE has shown
 * the sphere under REST_SPEED for STOP_REST: the stopped arm brakes back to where the reflex
 * read it, and one resumed while it still brakes meets its held setpoint in a jump. */
#define STOP_REST 0.3      /* s */
/* --park: every PLACE also asks the planner to take the sphere round the placed object to
 * the park point; placed means the sphere within PARK_AT of it too. */
#define PARK_AT 0.01       /* m */

/* What the runner was asked to do; constant once parsed. */
typedef struct {
  double eps, tau;  /* defaults for goals that set none */
  double v_max;     /* m/s, the end-effector speed limit sent with each task; 0: the planner's */
  double workspace; /* goals need |x|, |y| <= workspace, m */
  double wait;      /* for the first MOCAP frame, s */
  double settle;    /* before each task, at least, s */
  const char *url;
  const char *record;            /* replay buffer to append to; NULL: no recording */
  double record_dt;              /* the robot's control step, s */
  int record_control;            /* ND_CTRL_FORCE or ND_CTRL_VELOCITY: what u records */
  int record_join;               /* ND_REC_JOIN_*: how the object's frames are joined */
  double theta[ND_NTHETA];       /* recorded as the planner's theta until PARAMS arrives */
  double await_fit;              /* s to wait for the adapter's refit after a record; 0 none */
  int place;                     /* 1: put the object at place_pose before each task */
  nd_goal place_pose;
  double place_wait;             /* s */
  int park;                      /* 1: every placement also parks the sphere at park_xy */
  double park_xy[2];             /* m */
  nd_goal goals[MAX_GOALS];
  int n;
} tasks_cfg;

/* The replay buffer and the rollout being recorded into it. */
typedef struct {
  nd_rfile_writer w;
  nd_recorder rec;
  nd_rec_state rs;       /* the newest robot state, kept across tasks */
  int have_rs;
  double theta[ND_NTHETA];
  int control;           /* ND_CTRL_*: the robot state's force or velocity as u */
  int64_t theta_version; /* -1: --theta */
  int32_t params_n;      /* rollouts the newest PARAMS was fitted on */
  int64_t appended;
  int last_ok;           /* the last task was appended */
  int64_t failed;        /* finished rollouts whose append failed (file system, I/O) */
  char last_err[600];    /* why the newest of them failed */
  const char *path;      /* the buffer, also while it cannot be opened */
} tasks_buffer;

#define TASKS_PATH_STEP 0.002 /* m: paths are summed in steps of at least this */

/* A task whose object moved less than this (m, MOCAP path) is not recorded: the sphere
 * barely touched it, so a refit learns next to nothing from it yet pays for its replays,
 * and a study would count it as an episode's push (decisions#untouched-push). */
#define TASKS_RECORD_MOVED_MIN 0.01

/* The push begins where the object is first this far (m, tasks_frame_shift) off its pose
 * at the task's start: fifty times motion capture's 0.1 mm noise, so the time before it is
 * the approach (the way to the object and the first contact's build-up). */
#define TASKS_MOVED 0.005

#define MAX_PLAN_AGES 100000 /* plan ages kept for the percentiles: hours of plans */

/* What happened during the running task, as the handlers see it. */
typedef struct {
  int64_t id;         /* the task; -1 between tasks */
  int64_t plans;      /* PLANs for it */
  double obj_path, ee_path;  /* m travelled by object and sphere (MOCAP) */
  double ee_speed_max;       /* m/s, the sphere's top speed (ROBOT_STATE ee_vel) */
  double cmd_speed_max;      /* m/s, the commanded top speed (EE_CMD v) */
  double last_obj[2], last_ee[2];
  int have_last;
  nudge_mocap_t start; /* the frame the task started from */
  int moved;          /* it has moved TASKS_MOVED since */
  double moved_at;    /* then: the arrival (ndp_mono()) of the first frame that showed it */
  int resumed;        /* ROBOT_STATE has said the robot is not stopped since the task began */
  int stopped;        /* a reflex stopped the robot after that */
  int reflex, reflex_joint;  /* robot_state_t.REFLEX_*, joint 1..7 or 0 */
} tasks_running;

/* What the LCM handlers update. */
typedef struct {
  nudge_mocap_t last; /* newest valid frame */
  double t_last;      /* its arrival, ndp_mono() */
  int64_t frames;     /* valid frames received */
  int fresh;          /* a valid frame arrived since the runner last looked */
  ndp_status st;
  ndp_ratelog refused;
  tasks_buffer *buf;  /* NULL without --record */
  tasks_running run;
  double *ages;       /* MAX_PLAN_AGES: publication minus state time of each plan, ms */
  int nages;
  int no_record;      /* the next task is not recorded: the object was not at rest */
  int robot_stopped;  /* the newest ROBOT_STATE said STOPPED (1) or not (0); -1 before one */
  int stops_between;  /* reflex stops that began while no task ran (a release, idle) */
  double cmd_moving_at; /* ndp_mono() of the newest EE_CMD not HOLDING; -inf before one */
  double ee_moving_at;  /* ndp_mono() of the newest ROBOT_STATE at REST_SPEED or faster;
                           -inf before one */
} tasks_io;

/* How one task ended. */
typedef struct {
  int event;         /* NUDGE_EPISODE_T_EVENT_* */
  int interrupted;   /* ended by SIGINT/SIGTERM */
  double time;       /* s since the task started */
  double task_error;
  double pos_err;    /* m */
  double yaw_err;    /* rad, modulo the cuboid's half-turn, in [0, pi/2] */
  int64_t plans;     /* PLANs received for the task */
  double obj_path, ee_path;  /* m */
  double ee_speed_max;       /* m/s */
  double cmd_speed_max;      /* m/s */
  double moved_at;   /* s since the start until the object had moved TASKS_MOVED; -1: never */
  int met_at_start;  /* the goal was met before anything moved: nothing recorded */
  char reason[200];
} tasks_result;

/* options.c: parse argv into c. ND_OPT_RUN, or the exit status (usage or refusal
 * printed). */
int tasks_options(int argc, char **argv, tasks_cfg *c);

/* inputs.c: subscribe MOCAP, and with io->buf the recording's channels. 0 or -1. */
int tasks_subscribe(tasks_io *io, lcm_t *lcm, char *err, int errlen);

/* record.c */
int tasks_buffer_open(tasks_buffer *b, const char *path, double tau, double dt, int control,
                      const double theta[ND_NTHETA], char *err, int errlen);
void tasks_buffer_close(tasks_buffer *b);
void tasks_buffer_begin(tasks_buffer *b, const nudge_mocap_t *m, int64_t id, const nd_goal *g);
void tasks_buffer_finish(tasks_buffer *b, int64_t id, int outcome, double obj_path);

/* run.c */
int tasks_pump(lcm_t *lcm, tasks_io *io, double dt, char *err, int errlen);
int tasks_wait_mocap(lcm_t *lcm, tasks_io *io, double wait, char *err, int errlen);
int tasks_run(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, const nd_goal *g, int64_t id,
              tasks_result *r, char *err, int errlen);
void tasks_print(int i, int n, const nd_goal *g, const tasks_result *r);
/* How far (m) the object is in frame a from where it is in frame b: the larger of its
 * travel and its turn times REST_ARM. */
double tasks_frame_shift(const nudge_mocap_t *a, const nudge_mocap_t *b);
/* What a ROBOT_STATE reflex code names: "joint 4 velocity", "Cartesian jerk". */
const char *tasks_reflex_name(int reflex, int joint);
/* After a task: await the fit of its record (--await-fit). */
int tasks_pause(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, char *err, int errlen);
/* Before a task, with c->place: ask for the object at c->place_pose (PLACE; with
 * c->park, the sphere at c->park_xy too) and wait until MOCAP shows it there, then settle
 * (tasks_settle); an object moved off the pose meanwhile is placed again, at most
 * PLACE_TRIES times, then the task is not recorded. 1 if placed, 0 if not within
 * c->place_wait (or interrupted), -1 with a message on an LCM failure. */
int tasks_place(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, char *err, int errlen);
/* Before a task: wait c->settle s, then until the object is at rest and the commands have
 * held the sphere for SETTLE_CMD_REST (at most SETTLE_MAX); if not, say so and set
 * io->no_record. 0, or -1 with a message on an LCM failure. */
int tasks_settle(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, char *err, int errlen);

#endif
