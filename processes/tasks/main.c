/* nudge-tasks: the episode runner. Publishes one pushing task (TASK) at a time, watches
 * the object on MOCAP, ends the task on the terminal condition (DESIGN.md sec. 4) and
 * reports it on EPISODE and as one line on stdout.
 *
 * The object is not reset between tasks (a real robot cannot do that): each goal starts
 * where the previous task left the object, so the default goals form a chain of short
 * pushes. Times are measured on this host's monotonic clock, from the TASK publication to
 * the arrival of the MOCAP frame that met the condition.
 *
 * With --record FILE each task's rollout goes into the replay buffer the adapter refits
 * theta on (nd_rbuf.h), built from the live channels: the start state from the newest
 * ROBOT_STATE (sphere) and MOCAP (object, at rest) when the task is issued, then one step
 * per ROBOT_STATE (the bridge's world step: u = the force the robot applied during it, ee
 * = the sphere after it), sp = the newest EE_CMD handled before that message (the bridge
 * steps on the newest command it holds, which may be one message apart), obj = MOCAP's
 * pose interpolated to the step's time (frames come at 240 Hz, steps at 1 kHz, both stamped
 * with the world step's time). Messages lost on the way show as gaps in ROBOT_STATE.seq:
 * a gap of up to GAP_FILL_MAX steps is filled by linear interpolation between its two
 * neighbours; a longer one, or more than FILL_MAX_FRAC of the steps filled, and the task
 * is not recorded (an interpolated second of pushing would be made-up data). The arrays
 * are allocated once for the longest task; the handlers only write into them; the
 * append (encode, one write, fdatasync) happens after the task.
 *
 * A full or read-only file system (or an I/O error) does not stop the tasks: recording
 * is what the runner does besides its job, and a robot mid-way through a chain of pushes
 * should finish it. The failed append is reported with the file and the reason, the
 * records already in the file stay as they were (nd_rfile cuts a partial write back),
 * the next task tries again (reopening the file if needed), and the summary and the exit
 * status (3) say how many tasks were lost. A buffer that is not ours to write (another
 * recorder holds it, not a record file, no permission, no such directory) is refused at
 * the start instead: that is a wrong argument, not a condition that may pass. */
#define _GNU_SOURCE /* strerrorname_np */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_cost.h"
#include "nd_math.h"
#include "nd_parse.h"
#include "nd_rbuf.h"
#include "nds_model.h"
#include "ndp.h"
#include "nd_goal.h"
#include "ndp_validate.h"

#define PROG "nudge-tasks"
#define MAX_GOALS 1000
#define MOCAP_GAP_WARN 0.5 /* s without a frame during a task before saying so */
#define GAP_FILL_MAX 20    /* ROBOT_STATE steps a single filled gap may span */
#define FILL_MAX_FRAC 0.02 /* of a task's steps, at most this many filled */
#define DT_TOLERANCE 0.1   /* measured step period vs --record-dt, relative */
#define RATE_QUEUE 1000    /* queue of the 1 kHz channels: a second of them */

/* Start: object at rest at the origin, the bridge's sphere at (-0.10, 0). Each goal is a
 * 14-16 cm push from the previous one, so every task starts with the object near the last
 * goal and a push of about one object length ahead: straight ahead, a diagonal push with a
 * quarter turn, a push sideways onto the long face, a pull back that needs the sphere to go
 * around the object, and a diagonal push back with a turn the other way. All stay well
 * inside the default 0.5 m workspace, so the sphere has room behind the object. */
static const nd_goal default_goals[] = {
    {0.15, 0.00, 0.0, 0, 0, 0},  {0.25, 0.10, 0.4, 0, 0, 0}, {0.25, 0.25, 0.8, 0, 0, 0},
    {0.10, 0.30, 0.8, 0, 0, 0},  {0.00, 0.20, 0.3, 0, 0, 0},
};

/* What the runner was asked to do; constant once parsed. */
typedef struct {
  double eps, tau;  /* defaults for goals that set none */
  double workspace; /* goals need |x|, |y| <= workspace, m */
  double wait;      /* for the first MOCAP frame, s */
  double settle;    /* between tasks, s */
  const char *url;
  const char *record;            /* replay buffer to append to; NULL: no recording */
  double record_dt;              /* the bridge's world step, s */
  double theta[ND_NTHETA];      /* recorded as the planner's theta until PARAMS arrives */
  double await_fit;              /* s to wait for the adapter's refit after a record; 0 none */
  nd_goal goals[MAX_GOALS];
  int n;
} tasks_cfg;

/* The rollout being recorded: arrays for cap steps allocated at start; the handlers only
 * write into them. */
typedef struct {
  nd_rfile_writer w;
  double dt;
  int cap;               /* steps (and MOCAP frames: at most one per step) the arrays hold */
  nd_rollout r;          /* r.n is the capacity except during the append */
  int64_t *step_us;      /* cap: each step's utime */
  int64_t *frame_us;     /* cap: the task's MOCAP frames ... */
  double *frame;         /* cap x ND_ROLLOUT_OBJ: ... object pose */
  int nframes;
  int on;                /* recording a task now */
  int steps;
  int64_t last_seq;      /* ROBOT_STATE.seq of the last step (the start state's at first) */
  int64_t last_us;
  double last_u[2], last_ee[2];
  int64_t start_us;
  int64_t filled, longest_gap;
  int dropped;           /* steps past cap */
  char broken[200];      /* why this task cannot be recorded; "" if it can */
  /* the newest inputs, kept across tasks */
  nudge_robot_state_t rs;
  int have_rs;
  nudge_ee_cmd_t cmd;
  int have_cmd;
  double theta[ND_NTHETA];
  int64_t theta_version; /* -1: --theta */
  int32_t params_n;      /* rollouts the newest PARAMS was fitted on */
  int64_t appended;
  int last_ok;           /* the last task was appended */
  int64_t failed;        /* finished rollouts whose append failed (file system, I/O) */
  char last_err[600];    /* why the newest of them failed */
  const char *path;      /* the buffer, also while it cannot be opened */
} recorder;

/* What the LCM handlers update. */
typedef struct {
  nudge_mocap_t last; /* newest valid frame */
  double t_last;      /* its arrival, ndp_mono() */
  int64_t frames;     /* valid frames received */
  int fresh;          /* a valid frame arrived since the runner last looked */
  ndp_status st;
  ndp_ratelog refused;
  recorder *rec;      /* NULL without --record */
} tasks_io;

/* How one task ended. */
typedef struct {
  int event;         /* NUDGE_EPISODE_T_EVENT_* */
  int interrupted;   /* ended by SIGINT/SIGTERM */
  double time;       /* s since the task started */
  double task_error;
  double pos_err;    /* m */
  double yaw_err;    /* rad, modulo the cuboid's half-turn, in [0, pi/2] */
  char reason[200];
} task_result;

/* Count a refused message in status and log it, rate-limited. */
static void refuse(tasks_io *io, const char *what, const char *why) {
  io->st.rejected++;
  ndp_refused(&io->refused, PROG, what, why);
}

/* ---- recording ---- */

/* A condition of the file system that may pass while the runner works (full, over
 * quota, read-only, failing): the tasks go on without recording. */
static int storage_error(int e) {
  return e == ENOSPC || e == EDQUOT || e == EROFS || e == EIO || e == EFBIG;
}

/* "ENOSPC" for ENOSPC: what people grep logs for; "" for 0. */
static const char *errno_name(int e) {
  const char *n = e ? strerrorname_np(e) : "";
  return n ? n : "?";
}

/* Allocate the recorder for tasks of up to tau s at step dt and open the buffer (a second
 * writer is refused by its lock). A file system that refuses writes now (storage_error)
 * is reported and leaves the buffer closed for the appends to retry. Return 0, or -1
 * with a message. */
static int rec_init(recorder *rc, const char *path, double tau, double dt,
                    const double theta[ND_NTHETA], char *err, int errlen) {
  memset(rc, 0, sizeof(*rc));
  rc->w.fd = -1;
  rc->dt = dt;
  memcpy(rc->theta, theta, sizeof(rc->theta));
  rc->theta_version = -1;
  /* Room for a task that overruns its limit a little (the runner checks it at 50 Hz) and
   * for a bridge somewhat faster than dt says; what does not fit is cut off. */
  const double n = ceil(1.25 * tau / dt) + 1000;
  rc->cap = n > ND_ROLLOUT_MAX_STEPS ? ND_ROLLOUT_MAX_STEPS : (int)n;
  rc->step_us = malloc(sizeof(int64_t) * rc->cap);
  rc->frame_us = malloc(sizeof(int64_t) * rc->cap);
  rc->frame = malloc(sizeof(double) * ND_ROLLOUT_OBJ * rc->cap);
  if (nd_rollout_alloc(&rc->r, rc->cap) || !rc->step_us || !rc->frame_us || !rc->frame) {
    snprintf(err, errlen, "%s: out of memory for %d steps", path, rc->cap);
    return -1;
  }
  rc->path = path;
  nd_rfile_tail repair;
  if (nd_rbuf_open(&rc->w, path, &repair, err, errlen)) {
    if (storage_error(rc->w.sys_errno)) {
      fprintf(stderr, PROG ": cannot record into %s now: %s [%s]; running the tasks anyway, "
              "each one's append tries again\n", path, err, errno_name(rc->w.sys_errno));
      return 0;
    }
    if (strstr(err, "locked"))
      snprintf(err + strlen(err), errlen - strlen(err),
               ": another nudge-tasks is recording into it");
    return -1;
  }
  if (repair.status != ND_RFILE_END)
    fprintf(stderr, PROG ": %s: cut off a %s tail: %s\n", path,
            nd_rfile_status_name(repair.status), repair.why);
  fprintf(stderr, PROG ": recording into %s (%lld rollouts there), up to %d steps of %g s\n",
          path, (long long)rc->w.records, rc->cap, dt);
  return 0;
}

/* Open the buffer again if it is not open, or after a failed sync left the writer
 * unusable (the reopen checks and repairs the tail). 0 when ready to append, or -1 with
 * a message (rc->w.sys_errno says whether a system call failed). */
static int rec_reopen(recorder *rc, char *err, int errlen) {
  if (rc->w.fd >= 0 && !rc->w.broken) return 0;
  nd_rfile_writer_close(&rc->w);
  nd_rfile_tail repair;
  if (nd_rbuf_open(&rc->w, rc->path, &repair, err, errlen)) return -1;
  if (repair.status != ND_RFILE_END)
    fprintf(stderr, PROG ": %s: cut off a %s tail: %s\n", rc->path,
            nd_rfile_status_name(repair.status), repair.why);
  fprintf(stderr, PROG ": %s is writable again: recording into it (%lld rollouts there)\n",
          rc->path, (long long)rc->w.records);
  return 0;
}

static void rec_free(recorder *rc) {
  nd_rfile_writer_close(&rc->w);
  rc->r.n = rc->cap;
  nd_rollout_free(&rc->r);
  free(rc->step_us);
  free(rc->frame_us);
  free(rc->frame);
}

static void rec_frame(recorder *rc, const nudge_mocap_t *m) {
  if (rc->nframes >= rc->cap) return;
  if (rc->nframes > 0 && m->utime <= rc->frame_us[rc->nframes - 1]) return;
  rc->frame_us[rc->nframes] = m->utime;
  double *f = rc->frame + ND_ROLLOUT_OBJ * rc->nframes;
  memcpy(f, m->obj_pos, 3 * sizeof(double));
  memcpy(f + 3, m->obj_quat, 4 * sizeof(double));
  rc->nframes++;
}

/* Start recording task id toward goal g from the newest ROBOT_STATE and MOCAP frame m. */
static void rec_begin(recorder *rc, const nudge_mocap_t *m, int64_t id, const nd_goal *g) {
  nd_rollout *r = &rc->r;
  rc->on = 1;
  rc->steps = rc->nframes = rc->dropped = 0;
  rc->filled = rc->longest_gap = 0;
  rc->broken[0] = '\0';
  if (!rc->have_rs) {
    snprintf(rc->broken, sizeof(rc->broken),
             "no ROBOT_STATE received before the task: is nudge-bridge publishing?");
    return;
  }
  r->task_id = id;
  r->utime = rc->rs.utime;
  r->goal[0] = g->x;
  r->goal[1] = g->y;
  r->goal[2] = g->yaw;
  memcpy(r->theta, rc->theta, sizeof(r->theta));
  r->outcome = ND_OUTCOME_ABORTED;
  r->control = ND_CTRL_FORCE;
  r->dt = rc->dt;
  memcpy(r->obj_pos, m->obj_pos, sizeof(r->obj_pos));
  memcpy(r->obj_quat, m->obj_quat, sizeof(r->obj_quat));
  memset(r->obj_vel, 0, sizeof(r->obj_vel));  /* at rest after the settle pause */
  for (int k = 0; k < 2; k++) {
    r->ee_pos[k] = rc->rs.ee_pos[k];
    r->ee_vel[k] = rc->rs.ee_vel[k];
    rc->last_u[k] = rc->rs.ee_force[k];
    rc->last_ee[k] = rc->rs.ee_pos[k];
  }
  rc->last_seq = rc->rs.seq;
  rc->last_us = rc->start_us = rc->rs.utime;
  rec_frame(rc, m);
}

/* One step: control u during it, sphere ee after it, at utime us. */
static void rec_push(recorder *rc, const double u[2], const double ee[2], int64_t us) {
  if (rc->steps >= rc->cap) {
    rc->dropped++;
    return;
  }
  nd_rollout *r = &rc->r;
  const int i = rc->steps++;
  r->u[2 * i] = u[0];
  r->u[2 * i + 1] = u[1];
  r->ee[2 * i] = ee[0];
  r->ee[2 * i + 1] = ee[1];
  double *sp = r->sp + 6 * i;
  if (rc->have_cmd) {
    sp[0] = rc->cmd.p[0], sp[1] = rc->cmd.p[1];
    sp[2] = rc->cmd.v[0], sp[3] = rc->cmd.v[1];
    sp[4] = rc->cmd.a[0], sp[5] = rc->cmd.a[1];
  } else {  /* no executor: the bridge holds the sphere where it started */
    sp[0] = r->ee_pos[0], sp[1] = r->ee_pos[1];
    sp[2] = sp[3] = sp[4] = sp[5] = 0.0;
  }
  rc->step_us[i] = us;
}

static void rec_step(recorder *rc, const nudge_robot_state_t *m) {
  if (!rc->on || rc->broken[0]) return;
  if (m->seq <= rc->last_seq) {
    snprintf(rc->broken, sizeof(rc->broken),
             "ROBOT_STATE seq went back from %lld to %lld (bridge restarted?)",
             (long long)rc->last_seq, (long long)m->seq);
    return;
  }
  const int64_t gap = m->seq - rc->last_seq - 1;
  const double u[2] = {m->ee_force[0], m->ee_force[1]}, ee[2] = {m->ee_pos[0], m->ee_pos[1]};
  if (gap > GAP_FILL_MAX) {
    snprintf(rc->broken, sizeof(rc->broken),
             "%lld ROBOT_STATE messages lost in a row after seq %lld (at most %d are filled)",
             (long long)gap, (long long)rc->last_seq, GAP_FILL_MAX);
    return;
  }
  for (int64_t j = 1; j <= gap; j++) {
    const double f = (double)j / (double)(gap + 1);
    const double uf[2] = {rc->last_u[0] + f * (u[0] - rc->last_u[0]),
                          rc->last_u[1] + f * (u[1] - rc->last_u[1])};
    const double ef[2] = {rc->last_ee[0] + f * (ee[0] - rc->last_ee[0]),
                          rc->last_ee[1] + f * (ee[1] - rc->last_ee[1])};
    rec_push(rc, uf, ef, rc->last_us + (int64_t)llround(f * (double)(m->utime - rc->last_us)));
  }
  rc->filled += gap;
  if (gap > rc->longest_gap) rc->longest_gap = gap;
  rec_push(rc, u, ee, m->utime);
  rc->last_seq = m->seq;
  rc->last_us = m->utime;
  memcpy(rc->last_u, u, sizeof(u));
  memcpy(rc->last_ee, ee, sizeof(ee));
}

/* The object at every step: MOCAP frames interpolated to the step's time, held beyond the
 * first and last frame. */
static void rec_objects(recorder *rc) {
  int j = 0;
  for (int i = 0; i < rc->steps; i++) {
    const int64_t t = rc->step_us[i];
    while (j + 1 < rc->nframes && rc->frame_us[j + 1] <= t) j++;
    const double *a = rc->frame + ND_ROLLOUT_OBJ * j;
    double *o = nd_rollout_obj(&rc->r, i);
    if (j + 1 < rc->nframes && rc->frame_us[j] <= t) {
      const double *b = a + ND_ROLLOUT_OBJ;
      const double f = (double)(t - rc->frame_us[j]) / (double)(rc->frame_us[j + 1] - rc->frame_us[j]);
      for (int c = 0; c < 3; c++) o[c] = a[c] + f * (b[c] - a[c]);
      nd_quat_nlerp(a + 3, b + 3, f, o + 3);
    } else {
      memcpy(o, a, ND_ROLLOUT_OBJ * sizeof(double));
    }
  }
}

/* Stop recording the task and append it with outcome (ND_OUTCOME_*), or say why not.
 * A failure is reported and the runner goes on. */
static void rec_finish(recorder *rc, int64_t id, int outcome) {
  rc->last_ok = 0;
  if (!rc->on) return;
  rc->on = 0;
  char why[600] = "";
  const double period = rc->steps ? 1e-6 * (double)(rc->last_us - rc->start_us) / (rc->steps + 0.0) : 0;
  if (rc->broken[0])
    snprintf(why, sizeof(why), "%s", rc->broken);
  else if (rc->steps == 0)
    snprintf(why, sizeof(why), "no ROBOT_STATE arrived during the task");
  else if (rc->filled > FILL_MAX_FRAC * rc->steps)
    snprintf(why, sizeof(why), "%lld of %d steps lost (more than %.0f%% would be filled in)",
             (long long)rc->filled, rc->steps, 100 * FILL_MAX_FRAC);
  else if (rc->steps >= 100 && fabs(period - rc->dt) > DT_TOLERANCE * rc->dt)
    snprintf(why, sizeof(why), "ROBOT_STATE came every %.3f ms, --record-dt is %.3f ms: a "
             "replay would run at the wrong rate", 1e3 * period, 1e3 * rc->dt);
  if (!why[0]) {
    rc->r.outcome = outcome;
    rec_objects(rc);
    rc->r.n = rc->steps;
    char err[512];
    const int ok = rec_reopen(rc, err, sizeof(err)) == 0 &&
                   nd_rbuf_append(&rc->w, &rc->r, err, sizeof(err)) == 0;
    rc->r.n = rc->cap;
    if (ok) {
      rc->appended++;
      rc->last_ok = 1;
      fprintf(stderr, PROG ": task %lld recorded: %d steps (%lld filled, %d cut off), %d "
              "MOCAP frames, record %lld of %s\n", (long long)id, rc->steps,
              (long long)rc->filled, rc->dropped, rc->nframes, (long long)rc->w.records,
              rc->w.path);
      return;
    }
    /* The rollout was sound; the file took none of it. */
    rc->failed++;
    if (rc->w.sys_errno)
      snprintf(rc->last_err, sizeof(rc->last_err), "%s [%s]", err,
               errno_name(rc->w.sys_errno));
    else
      snprintf(rc->last_err, sizeof(rc->last_err), "%s", err);
    snprintf(why, sizeof(why), "%s", rc->last_err);
  }
  fprintf(stderr, PROG ": task %lld not recorded: %s\n", (long long)id, why);
}

static void on_mocap(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_mocap_t *m,
                     void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_mocap(m, why, sizeof(why))) {
    refuse(io, "MOCAP frame", why);
    return;
  }
  io->last = *m;
  io->t_last = ndp_mono();
  io->frames++;
  io->fresh = 1;
  io->st.received++;
  if (io->rec && io->rec->on) rec_frame(io->rec, m);
}

static void on_robot_state(const lcm_recv_buf_t *rbuf, const char *ch,
                           const nudge_robot_state_t *m, void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_robot_state(m, why, sizeof(why))) {
    refuse(io, "ROBOT_STATE", why);
    return;
  }
  io->st.received++;
  io->rec->rs = *m;
  io->rec->have_rs = 1;
  rec_step(io->rec, m);
}

static void on_ee_cmd(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_ee_cmd_t *m,
                      void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_ee_cmd(m, why, sizeof(why))) {
    refuse(io, "EE_CMD", why);
    return;
  }
  io->st.received++;
  io->rec->cmd = *m;
  io->rec->have_cmd = 1;
}

static void on_params(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_params_t *m,
                      void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_params(m, why, sizeof(why))) {
    refuse(io, "PARAMS", why);
    return;
  }
  io->st.received++;
  memcpy(io->rec->theta, m->theta_mean, sizeof(io->rec->theta));
  io->rec->theta_version = m->version;
  io->rec->params_n = m->buffer_size;
}

/* Bytes on a typed channel that are not one message of its type. */
static void undecodable(void *user, const char *ch, const char *why) {
  refuse(user, ch, why);
}

NDP_TYPED_HANDLER(nudge_mocap_t, on_mocap_raw, on_mocap, undecodable)
NDP_TYPED_HANDLER(nudge_robot_state_t, on_robot_state_raw, on_robot_state, undecodable)
NDP_TYPED_HANDLER(nudge_ee_cmd_t, on_ee_cmd_raw, on_ee_cmd, undecodable)
NDP_TYPED_HANDLER(nudge_params_t, on_params_raw, on_params, undecodable)

static double yaw_error(double yaw, double goal_yaw) {
  double e = fabs(nd_wrap_angle(yaw - goal_yaw));
  return e > 0.5 * ND_PI ? ND_PI - e : e;
}

/* Errors of the newest frame against goal g. */
static void measure(const tasks_io *io, const nd_cost_weights *w, const nd_goal *g,
                    task_result *r) {
  const double yaw = nd_quat_yaw(io->last.obj_quat);
  r->task_error = nd_task_error(w, g, io->last.obj_pos, yaw);
  r->pos_err = hypot(io->last.obj_pos[0] - g->x, io->last.obj_pos[1] - g->y);
  r->yaw_err = yaw_error(yaw, g->yaw);
}

static int publish_episode(lcm_t *lcm, tasks_io *io, int64_t task_id, int event,
                           const char *reason, double time, double task_error) {
  nudge_episode_t e;
  memset(&e, 0, sizeof(e));
  e.utime = ndp_utime();
  e.task_id = task_id;
  e.event = (int8_t)event;
  e.reason = (char *)reason;
  e.time = time;
  e.task_error = task_error;
  if (nudge_episode_t_publish(lcm, NDP_CH_EPISODE, &e) != 0) return -1;
  io->st.published++;
  return 0;
}

/* Handle LCM and the heartbeat for up to dt seconds. 0, or -1 with a message. */
static int pump(lcm_t *lcm, tasks_io *io, double dt, char *err, int errlen) {
  if (ndp_handle(lcm, dt) || ndp_status_tick(lcm, &io->st, 0) < 0) {
    snprintf(err, errlen, "LCM failed while receiving or publishing");
    return -1;
  }
  return 0;
}

/* Wait until a valid MOCAP frame arrives (and, when recording, a ROBOT_STATE: the first
 * task's start state needs one), up to wait s. 1 if they did, 0 if not (or interrupted),
 * -1 on an LCM failure. */
static int wait_mocap(lcm_t *lcm, tasks_io *io, double wait, char *err, int errlen) {
  const double t_end = ndp_mono() + wait;
  /* MOCAP alone would do for a runner started long after the bridge, but one started (or
   * restarted) while both streams flow may see a MOCAP frame first and would begin its
   * first task without a start state: that task would not be recorded. */
  while ((!io->frames || (io->rec && !io->rec->have_rs)) && !ndp_quit) {
    const double left = t_end - ndp_mono();
    if (left <= 0.0) return 0;
    if (pump(lcm, io, fmin(left, 0.1), err, errlen)) return -1;
  }
  return io->frames > 0 && (!io->rec || io->rec->have_rs);
}

/* Run goal g as task id: publish it, follow MOCAP to the terminal condition, publish the
 * outcome. 0 with r filled, or -1 with a message on an LCM failure. */
static int run_task(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, const nd_goal *g,
                    int64_t id, task_result *r, char *err, int errlen) {
  const nd_cost_weights w = nd_cost_weights_default();
  const nd_goal goal = {.x = g->x, .y = g->y, .yaw = g->yaw};
  const double eps = g->eps > 0.0 ? g->eps : c->eps;
  const double tau = g->tau > 0.0 ? g->tau : c->tau;
  memset(r, 0, sizeof(*r));
  measure(io, &w, &goal, r);

  if (fabs(g->x) > c->workspace || fabs(g->y) > c->workspace) {
    r->event = NUDGE_EPISODE_T_EVENT_REJECTED;
    snprintf(r->reason, sizeof(r->reason),
             "goal (%.3f, %.3f) m is outside the workspace |x|, |y| <= %.2f m", g->x, g->y,
             c->workspace);
    if (publish_episode(lcm, io, id, r->event, r->reason, 0.0, r->task_error)) goto fail;
    return 0;
  }

  nudge_task_t t;
  memset(&t, 0, sizeof(t));
  t.utime = ndp_utime();
  t.task_id = id;
  t.goal_x = g->x;
  t.goal_y = g->y;
  t.goal_yaw = g->yaw;
  t.eps = eps;
  t.time_limit = tau;
  if (io->rec) rec_begin(io->rec, &io->last, id, &goal);
  const double t0 = ndp_mono();
  if (nudge_task_t_publish(lcm, NDP_CH_TASK, &t) != 0) goto fail;
  io->st.published++;
  if (publish_episode(lcm, io, id, NUDGE_EPISODE_T_EVENT_START, "", 0.0, r->task_error))
    goto fail;
  io->st.state = "running";
  io->fresh = 0;

  double next_task = t0 + 1.0;
  int gap_warned = 0;
  nd_task_status s = ND_TASK_RUNNING;
  for (;;) {
    if (pump(lcm, io, 0.02, err, errlen)) return -1;
    const double now = ndp_mono();
    if (ndp_quit) {
      r->interrupted = 1;
      r->time = now - t0;
      break;
    }
    if (io->fresh) {
      io->fresh = 0;
      measure(io, &w, &goal, r);
      r->time = io->t_last - t0;
      s = nd_task_check(r->task_error, r->time, eps, tau);
      gap_warned = 0;
    }
    /* The limit holds even when frames stop coming: judge the last frame at the clock. */
    if (s == ND_TASK_RUNNING && now - t0 > tau) {
      r->time = now - t0;
      s = ND_TASK_TIMEOUT;
    }
    if (s != ND_TASK_RUNNING) break;
    if (!gap_warned && now - io->t_last > MOCAP_GAP_WARN) {
      fprintf(stderr, PROG ": no MOCAP frame for %.1f s during task %lld\n", now - io->t_last,
              (long long)id);
      gap_warned = 1;
    }
    /* Unchanged, so a planner that starts late or restarts picks the task up. */
    if (now >= next_task) {
      if (nudge_task_t_publish(lcm, NDP_CH_TASK, &t) != 0) goto fail;
      io->st.published++;
      next_task += 1.0;
    }
  }

  const double age = ndp_mono() - io->t_last;
  if (r->interrupted) {
    r->event = NUDGE_EPISODE_T_EVENT_TIMEOUT;
    snprintf(r->reason, sizeof(r->reason), "interrupted: the runner was stopped at %.2f s",
             r->time);
  } else if (s == ND_TASK_SUCCESS) {
    r->event = NUDGE_EPISODE_T_EVENT_SUCCESS;
    snprintf(r->reason, sizeof(r->reason), "task error %.3g < eps %.3g", r->task_error, eps);
  } else {
    r->event = NUDGE_EPISODE_T_EVENT_TIMEOUT;
    snprintf(r->reason, sizeof(r->reason), "task error %.3g >= eps %.3g after %.2f s%s",
             r->task_error, eps, tau, age > MOCAP_GAP_WARN ? " (MOCAP stale)" : "");
  }
  if (publish_episode(lcm, io, id, r->event, r->reason, r->time, r->task_error)) goto fail;
  return 0;
fail:
  snprintf(err, errlen, "cannot publish on LCM");
  return -1;
}

/* "task 3/5 goal (+0.20, +0.00, +0.0 deg): reached in 2.41 s, pos err ..." */
static void print_result(int i, int n, const nd_goal *g, const task_result *r) {
  printf("task %d/%d goal (%+.2f, %+.2f, %+.1f deg): ", i + 1, n, g->x, g->y,
         g->yaw * 180.0 / ND_PI);
  if (r->event == NUDGE_EPISODE_T_EVENT_REJECTED) {
    printf("rejected: %s\n", r->reason);
  } else {
    const char *what = r->interrupted ? "interrupted after"
                       : r->event == NUDGE_EPISODE_T_EVENT_SUCCESS ? "reached in"
                                                                   : "timed out after";
    printf("%s %.2f s, pos err %.3f m, yaw err %.1f deg\n", what, r->time, r->pos_err,
           r->yaw_err * 180.0 / ND_PI);
  }
  fflush(stdout);
}

static void usage(FILE *f) {
  fprintf(f,
          "usage: " PROG " [options]\n"
          "Run pushing tasks one after another: publish each goal on TASK, follow the object\n"
          "on MOCAP until the task error L_pos + l1 L_rot falls below eps (reached) or the\n"
          "time limit passes (timed out), report it on EPISODE and as a line on stdout.\n"
          "The object is not reset between tasks: each starts where the last one ended.\n\n"
          "  --goal X,Y,YAW[,EPS[,TIME_LIMIT]]\n"
          "                      a goal pose (m, m, rad); repeatable, run in order\n"
          "  --goals FILE        goals from FILE, one per line: x y yaw [eps [time_limit]]\n"
          "                      ('#' comments, blank lines ignored); repeatable\n"
          "                      without goals: a chain of 5 pushes of 14-16 cm from the origin\n"
          "  --eps E             success threshold, default 1e-2 (per-goal values override)\n"
          "  --tau S             time limit per task, s, default 5 (per-goal values override)\n"
          "  --workspace M       goals beyond |x| or |y| > M are rejected, default 0.5 m\n"
          "  --wait S            wait for the first MOCAP frame (with --record: and\n"
          "                      ROBOT_STATE), default 10 s\n"
          "  --settle S          pause between tasks so the object comes to rest, default 0.5 s\n"
          "  --record FILE       append each task's rollout (start state, 1 kHz forces,\n"
          "                      setpoints, observed path) to the replay buffer FILE, created\n"
          "                      if missing, for nudge-adapter; one writer at a time\n"
          "  --record-dt S       the bridge's world step, s (default 0.001 = its --rate 1000);\n"
          "                      a task whose ROBOT_STATE period differs is not recorded\n"
          "  --theta S,T,R,M     theta recorded as the planner's until PARAMS arrives\n"
          "                      (default: the simulation's ground truth, as the planner)\n"
          "  --await-fit S       with --record: after appending a task, wait up to S s for\n"
          "                      PARAMS fitted on it before the next task (the paper's\n"
          "                      protocol: refit between episodes); default 0, no wait\n"
          "  --lcm-url URL       default $LCM_DEFAULT_URL, else " NDP_DEFAULT_URL "\n"
          "  -h, --help          this text\n\n"
          "Prints one line per task, summary figures as 'name value unit' lines, and ends with\n"
          "'reached K/N goals'. Exit status: 0 every task ran (reached, timed out or rejected),\n"
          "1 the tasks could not be run (no MOCAP, LCM failure), 2 bad arguments, 3 every\n"
          "task ran but appending some to the --record buffer failed (disk full, read-only,\n"
          "I/O error: the tasks go on, each failure is reported, earlier records stay intact),\n"
          "128+n when stopped by signal n (SIGINT: 130), after printing what ran.\n");
}

/* Parse argv into c. 0 to run, 1 for --help, -1 with a message on a bad argument. */
static int parse_args(int argc, char **argv, tasks_cfg *c, char *err, int errlen) {
  c->eps = 1e-2;
  c->tau = 5.0;
  c->workspace = 0.5;
  c->wait = 10.0;
  c->settle = 0.5;
  c->url = NULL;
  c->record = NULL;
  c->record_dt = 0.001;
  c->await_fit = 0.0;
  memcpy(c->theta, nd_theta_true, sizeof(c->theta));
  c->n = 0;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) return 1;
    int known = !strcmp(a, "--goal") || !strcmp(a, "--goals") || !strcmp(a, "--eps") ||
                !strcmp(a, "--tau") || !strcmp(a, "--workspace") || !strcmp(a, "--wait") ||
                !strcmp(a, "--settle") || !strcmp(a, "--lcm-url") || !strcmp(a, "--record") ||
                !strcmp(a, "--record-dt") || !strcmp(a, "--theta") ||
                !strcmp(a, "--await-fit");
    if (!known) {
      snprintf(err, errlen, "unknown argument: %s", a);
      return -1;
    }
    if (i + 1 >= argc) {
      snprintf(err, errlen, "%s needs a value", a);
      return -1;
    }
    const char *v = argv[++i];
    int rc = 0;
    if (!strcmp(a, "--goal")) {
      if (c->n >= MAX_GOALS) {
        snprintf(err, errlen, "more than %d goals", MAX_GOALS);
        return -1;
      }
      if ((rc = nd_goal_parse_arg(v, &c->goals[c->n], err, errlen)) == 0) c->n++;
    } else if (!strcmp(a, "--goals")) {
      const int n0 = c->n;
      rc = nd_goal_list_load(v, c->goals, MAX_GOALS, &c->n, err, errlen);
      if (!rc && c->n == n0) {
        snprintf(err, errlen, "%s: no goals in the file", v);
        rc = -1;
      }
    } else if (!strcmp(a, "--eps")) {
      rc = nd_parse_double(v, "--eps", 1e-12, 1.0, &c->eps, err, errlen);
    } else if (!strcmp(a, "--tau")) {
      rc = nd_parse_double(v, "--tau", 1e-3, ND_GOAL_MAX_TAU, &c->tau, err, errlen);
    } else if (!strcmp(a, "--workspace")) {
      rc = nd_parse_double(v, "--workspace", 1e-3, ND_GOAL_MAX_POS, &c->workspace, err, errlen);
    } else if (!strcmp(a, "--wait")) {
      rc = nd_parse_double(v, "--wait", 0.0, 3600.0, &c->wait, err, errlen);
    } else if (!strcmp(a, "--settle")) {
      rc = nd_parse_double(v, "--settle", 0.0, 3600.0, &c->settle, err, errlen);
    } else if (!strcmp(a, "--record")) {
      c->record = v;
      if (!*v) {
        snprintf(err, errlen, "--record: empty file name");
        rc = -1;
      }
    } else if (!strcmp(a, "--record-dt")) {
      rc = nd_parse_double(v, "--record-dt", 1e-5, 0.05, &c->record_dt, err, errlen);
    } else if (!strcmp(a, "--theta")) {
      rc = nd_theta_parse(v, a, c->theta, err, errlen);
    } else if (!strcmp(a, "--await-fit")) {
      rc = nd_parse_double(v, "--await-fit", 0.0, 3600.0, &c->await_fit, err, errlen);
    } else {
      c->url = v;
    }
    if (rc) return -1;
  }
  if (c->await_fit > 0 && !c->record) {
    snprintf(err, errlen, "--await-fit needs --record (it waits for the fit of a record)");
    return -1;
  }
  if (c->n == 0) {
    c->n = (int)(sizeof(default_goals) / sizeof(default_goals[0]));
    memcpy(c->goals, default_goals, sizeof(default_goals));
  }
  return 0;
}

static tasks_cfg cfg; /* static: the goal list is large */

int main(int argc, char **argv) {
  char err[512];
  const int pa = parse_args(argc, argv, &cfg, err, sizeof(err));
  if (pa == 1) {
    usage(stdout);
    return 0;
  }
  if (pa < 0) {
    fprintf(stderr, PROG ": %s\n", err);
    usage(stderr);
    return 2;
  }
  ndp_signals();
  /* A file-size limit must fail the append (EFBIG, reported), not kill the runner. */
  signal(SIGXFSZ, SIG_IGN);

  static recorder rec;
  if (cfg.record) {
    double tau_max = cfg.tau;
    for (int i = 0; i < cfg.n; i++) tau_max = fmax(tau_max, cfg.goals[i].tau);
    if (rec_init(&rec, cfg.record, tau_max, cfg.record_dt, cfg.theta, err, sizeof(err))) {
      fprintf(stderr, PROG ": --record %s\n", err);
      rec_free(&rec);
      return 1;
    }
  }

  const char *url = ndp_url(cfg.url);
  lcm_t *lcm = ndp_lcm_create(url, err, sizeof(err));
  if (!lcm) {
    fprintf(stderr, PROG ": %s\n", err);
    if (cfg.record) rec_free(&rec);
    return 1;
  }
  static tasks_io io;
  ndp_status_init(&io.st, PROG);
  io.st.state = "waiting";
  lcm_subscription_t *sub = lcm_subscribe(lcm, NDP_CH_MOCAP, on_mocap_raw, &io);
  lcm_subscription_t *sub_rs = NULL;
  lcm_subscription_t *sub_cmd = NULL;
  lcm_subscription_t *sub_par = NULL;
  if (cfg.record) {
    io.rec = &rec;
    sub_rs = lcm_subscribe(lcm, NDP_CH_ROBOT_STATE, on_robot_state_raw, &io);
    sub_cmd = lcm_subscribe(lcm, NDP_CH_EE_CMD, on_ee_cmd_raw, &io);
    sub_par = lcm_subscribe(lcm, NDP_CH_PARAMS, on_params_raw, &io);
    /* The runner handles input every 20 ms and appends (one fdatasync) between tasks: a
     * default queue of 30 would drop 1 kHz messages (the newest, as seq gaps). */
    if (!sub_rs || !sub_cmd || !sub_par ||
        lcm_subscription_set_queue_capacity(sub_rs, RATE_QUEUE) ||
        lcm_subscription_set_queue_capacity(sub_cmd, RATE_QUEUE)) {
      fprintf(stderr, PROG ": subscribing to ROBOT_STATE, EE_CMD, PARAMS failed\n");
      lcm_destroy(lcm);
      rec_free(&rec);
      return 1;
    }
  }
  fprintf(stderr, PROG ": %d goal(s), eps %g, tau %g s, workspace %.2f m, settle %g s, lcm %s\n",
          cfg.n, cfg.eps, cfg.tau, cfg.workspace, cfg.settle, url);

  int status = 1, ran = 0, reached = 0, attempted = 0;
  double t_sum = 0.0, pos_sum = 0.0;
  const int w = wait_mocap(lcm, &io, cfg.wait, err, sizeof(err));
  if (w < 0) {
    fprintf(stderr, PROG ": %s\n", err);
    goto done;
  }
  if (w == 0 && !ndp_quit) {
    fprintf(stderr,
            PROG ": no %s within %g s on %s: is nudge-bridge running on the same LCM URL?\n",
            io.frames ? "ROBOT_STATE" : "MOCAP frame", cfg.wait, url);
    goto done;
  }

  /* Task ids continue from the wall clock in ms, so a restarted runner never reuses an id
   * a planner may still hold. */
  const int64_t id0 = ndp_utime() / 1000;
  for (int i = 0; i < cfg.n && !ndp_quit; i++) {
    task_result r;
    if (run_task(lcm, &io, &cfg, &cfg.goals[i], id0 + i, &r, err, sizeof(err))) {
      fprintf(stderr, PROG ": %s\n", err);
      goto done;
    }
    print_result(i, cfg.n, &cfg.goals[i], &r);
    if (cfg.record)
      rec_finish(&rec, id0 + i,
                 r.interrupted ? ND_OUTCOME_ABORTED
                 : r.event == NUDGE_EPISODE_T_EVENT_SUCCESS ? ND_OUTCOME_SUCCESS
                                                           : ND_OUTCOME_TIMEOUT);
    if (r.interrupted) break;
    ran++;
    if (r.event != NUDGE_EPISODE_T_EVENT_REJECTED) {
      attempted++;
      pos_sum += r.pos_err;
    }
    if (r.event == NUDGE_EPISODE_T_EVENT_SUCCESS) {
      reached++;
      t_sum += r.time;
    }
    if (i + 1 < cfg.n && cfg.await_fit > 0 && rec.last_ok) {
      /* The adapter's PARAMS says how many rollouts its fit used; the count may stay
       * below ours if it refused one, hence the limit. */
      io.st.state = "awaiting fit";
      const double t0 = ndp_mono(), t_end = t0 + cfg.await_fit;
      while (!ndp_quit && ndp_mono() < t_end && rec.params_n < rec.w.records)
        if (pump(lcm, &io, fmin(0.05, t_end - ndp_mono()), err, sizeof(err))) {
          fprintf(stderr, PROG ": %s\n", err);
          goto done;
        }
      if (rec.params_n >= rec.w.records)
        fprintf(stderr, PROG ": PARAMS version %lld (fitted on %d rollouts) after %.2f s\n",
                (long long)rec.theta_version, (int)rec.params_n, ndp_mono() - t0);
      else if (!ndp_quit)
        fprintf(stderr, PROG ": no PARAMS fitted on %lld rollouts within %g s; going on\n",
                (long long)rec.w.records, cfg.await_fit);
    }
    if (i + 1 < cfg.n && r.event != NUDGE_EPISODE_T_EVENT_REJECTED) {
      io.st.state = "settling";
      const double t_end = ndp_mono() + cfg.settle;
      while (!ndp_quit && ndp_mono() < t_end)
        if (pump(lcm, &io, fmin(0.05, t_end - ndp_mono()), err, sizeof(err))) {
          fprintf(stderr, PROG ": %s\n", err);
          goto done;
        }
    }
  }
  io.st.state = "done";
  ndp_status_tick(lcm, &io.st, 1);

  /* name value unit lines for scripts, then the line people read. */
  printf("tasks_run %d count\n", ran);
  printf("tasks_reached %d count\n", reached);
  if (reached) printf("reach_time_mean %.3f s\n", t_sum / reached);
  if (attempted) printf("final_pos_err_mean %.4f m\n", pos_sum / attempted);
  if (cfg.record) {
    printf("tasks_recorded %lld count\n", (long long)rec.appended);
    printf("tasks_record_failed %lld count\n", (long long)rec.failed);
  }
  if (ndp_quit)
    printf("reached %d/%d goals (interrupted: %d of %d tasks ran)\n", reached, ran, ran,
           cfg.n);
  else
    printf("reached %d/%d goals\n", reached, ran);
  fflush(stdout);
  status = ndp_quit ? 128 + ndp_quit : 0;
  if (rec.failed) {
    fprintf(stderr, PROG ": %lld task(s) not recorded: appending to %s failed; the last "
            "error: %s\n", (long long)rec.failed, rec.path, rec.last_err);
    if (status == 0) status = 3;
  }
done:
  if (status == 1 && ndp_quit) status = 128 + ndp_quit;
  lcm_unsubscribe(lcm, sub);
  if (sub_rs) lcm_unsubscribe(lcm, sub_rs);
  if (sub_cmd) lcm_unsubscribe(lcm, sub_cmd);
  if (sub_par) lcm_unsubscribe(lcm, sub_par);
  lcm_destroy(lcm);
  if (cfg.record) rec_free(&rec);
  return status;
}
