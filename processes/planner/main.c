/* nudge-planner: the MPC planner process (DESIGN.md sec. 3).
 *
 * Keeps the newest world state from MOCAP (object pose) and ROBOT_STATE (end-effector),
 * the executor's setpoint from EE_CMD, the goal from TASK and theta from PARAMS. While a
 * task is active and the state is fresh it plans back to back, each plan from the newest
 * state and setpoint (iCEM over minimum-snap keypoints, MuJoCo rollouts on a pool), and
 * publishes PLAN. Planning runs in the main thread between LCM drains: it is not a 1 kHz
 * process, and the queues are sized so a plan's duration of input fits in them. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "nd_math.h"
#include "nd_parse.h"
#include "nds_planner.h"
#include "ndp.h"
#include "ndp_validate.h"

#define PROG "nudge-planner"

/* Object velocity estimate: difference over the newest frame and the newest one at
 * least VEL_WINDOW older (see obj_velocity). */
#define VEL_HIST 32
#define VEL_WINDOW 0.025   /* s */
#define VEL_MAX_GAP 0.1    /* s; beyond it the frames say nothing about the present motion */

/* Rejection reasons on stderr: the first few, then one summary per interval. */

/* ---------------------------------------------------------------------------------- */
/* Options: constant once parsed. */

typedef struct {
  const char *url;
  int threads, pop, iters;
  double plan_dt;
  uint64_t seed;
  double max_rate;       /* Hz */
  double state_timeout;  /* s */
  double theta[ND_NTHETA];
  double ws_lo[2], ws_hi[2]; /* keypoint box, m */
} opts;

static void usage(FILE *f) {
  nds_planner_cfg d;
  nds_planner_cfg_default(&d);
  fprintf(f,
          "usage: " PROG " [options]\n"
          "MPC planner: plans minimum-snap keypoints with iCEM on MuJoCo rollouts from the\n"
          "newest MOCAP / ROBOT_STATE / EE_CMD, toward the active TASK, with theta from\n"
          "PARAMS; publishes PLAN back to back (at most --max-rate) until the task's EPISODE\n"
          "ends it.\n\n"
          "  --lcm-url URL        LCM URL (default: $LCM_DEFAULT_URL, else %s)\n"
          "  --threads N          rollout workers, 1..256 (default: cores - 1 up to 4 cores,\n"
          "                       cores - 2 above, at least 1: the 1 kHz processes need a core)\n"
          "  --pop N              iCEM population N, 4..100000 (default 50, the paper's robot\n"
          "                       setting)\n"
          "  --iters N            iCEM iterations C, 1..100 (default 2, the paper's robot setting)\n"
          "  --plan-dt S          planning model timestep, 0.0001..0.01 s (default 0.01: ~19\n"
          "                       plans/s on one core; 0.005 halves the prediction error and\n"
          "                       the rate, see nudge-bench)\n"
          "  --seed N             planner seed (default 1)\n"
          "  --max-rate HZ        at most this many plans per second, 0.1..1000 (default 20)\n"
          "  --state-timeout S    plan only from MOCAP and ROBOT_STATE younger than this,\n"
          "                       0.001..10 s (default 0.1)\n"
          "  --theta S,T,R,M      initial theta: sliding, torsional, rolling friction, sphere\n"
          "                       mass in kg (default: the simulation's ground truth); used\n"
          "                       until PARAMS arrives, plans then carry theta_version -1\n"
          "  --workspace XLO,YLO,XHI,YHI\n"
          "                       box in metres the keypoints are drawn in (default\n"
          "                       %g,%g,%g,%g); nudge-executor refuses plans with a keypoint\n"
          "                       outside its own --workspace, nudge-bridge commands beyond\n"
          "                       its own: give all three the same box (nudge-up\n"
          "                       --workspace does)\n"
          "  -h, --help           this text\n",
          NDP_DEFAULT_URL, d.ws_lo[0], d.ws_lo[1], d.ws_hi[0], d.ws_hi[1]);
}

/* Return 0, 1 for --help, or 2 after printing what is wrong. */
static int parse_opts(int argc, char **argv, opts *o) {
  char err[256];
  memset(o, 0, sizeof(*o));
  o->threads = ndp_default_threads();
  o->pop = 50;
  o->iters = 2;
  /* 10 ms keeps one core at ~19 plans/s while pushing, twice the executor's 0.1 s plan
   * timeout; at 5 ms a single core manages 7-10 plans/s in contact, and the executor would
   * brake between plans. The prediction error this costs is in nudge-bench. */
  o->plan_dt = 0.01;
  o->seed = 1;
  o->max_rate = 20.0;
  o->state_timeout = 0.1;
  memcpy(o->theta, nd_theta_true, sizeof(o->theta));
  nds_planner_cfg d;
  nds_planner_cfg_default(&d);
  memcpy(o->ws_lo, d.ws_lo, sizeof(o->ws_lo));
  memcpy(o->ws_hi, d.ws_hi, sizeof(o->ws_hi));

  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 1;
    }
    int known = !strcmp(a, "--lcm-url") || !strcmp(a, "--threads") || !strcmp(a, "--pop") ||
                !strcmp(a, "--iters") || !strcmp(a, "--plan-dt") || !strcmp(a, "--seed") ||
                !strcmp(a, "--max-rate") || !strcmp(a, "--state-timeout") ||
                !strcmp(a, "--theta") || !strcmp(a, "--workspace");
    if (!known) {
      fprintf(stderr, PROG ": unknown option: %s\n", a);
      usage(stderr);
      return 2;
    }
    if (i + 1 >= argc) {
      fprintf(stderr, PROG ": %s needs a value\n", a);
      usage(stderr);
      return 2;
    }
    const char *v = argv[++i];
    int rc = 0;
    if (!strcmp(a, "--lcm-url")) o->url = v;
    else if (!strcmp(a, "--threads")) rc = nd_parse_int(v, a, 1, 256, &o->threads, err, sizeof(err));
    else if (!strcmp(a, "--pop")) rc = nd_parse_int(v, a, 4, 100000, &o->pop, err, sizeof(err));
    else if (!strcmp(a, "--iters")) rc = nd_parse_int(v, a, 1, 100, &o->iters, err, sizeof(err));
    /* The tracking controller is stable up to 10 ms steps (nds_ctrl.h). */
    else if (!strcmp(a, "--plan-dt")) rc = nd_parse_double(v, a, 1e-4, 0.01, &o->plan_dt, err, sizeof(err));
    else if (!strcmp(a, "--seed")) rc = nd_parse_u64(v, a, &o->seed, err, sizeof(err));
    else if (!strcmp(a, "--max-rate")) rc = nd_parse_double(v, a, 0.1, 1000, &o->max_rate, err, sizeof(err));
    else if (!strcmp(a, "--state-timeout")) rc = nd_parse_double(v, a, 1e-3, 10, &o->state_timeout, err, sizeof(err));
    else if (!strcmp(a, "--workspace")) rc = ndp_parse_workspace(v, a, o->ws_lo, o->ws_hi, err, sizeof(err));
    else rc = nd_theta_parse(v, a, o->theta, err, sizeof(err));
    if (rc) {
      fprintf(stderr, PROG ": %s\n", err);
      usage(stderr);
      return 2;
    }
  }
  return 0;
}

/* ---------------------------------------------------------------------------------- */
/* The process's mutable state, owned by the main thread (LCM handlers run inside
 * lcm_handle on it, never during a plan). */

typedef struct {
  int64_t utime;
  double x, y, yaw;
} mocap_frame;

/* Bookkeeping of one periodic input stream. */
typedef struct {
  int have;       /* a valid message has arrived */
  double t;       /* when the newest was sent (ndp_sent_mono), ndp_mono */
  int cap;        /* queue capacity of its subscription */
  int batch;      /* messages handled in the current drain */
  int behind;     /* the last drain filled the queue: newer messages may have been dropped */
} input;

/* A message stamped utime arrived: its age counts from its sending (ndp_sent_mono). */
static void input_got(input *in, int64_t utime) {
  in->have = 1;
  in->t = ndp_sent_mono(utime);
  in->batch++;
  in->behind = 0;
}

/* After a drain. LCM drops the newest message when a queue is full, so a drain that
 * emptied a full queue ended on an old message, however fresh its handling time: the
 * stream is behind until its next message. Return 1 if that happened. */
static int input_drained(input *in) {
  int full = in->batch >= in->cap;
  if (full) in->behind = 1;
  in->batch = 0;
  return full;
}

/* Heard from within timeout, and not behind. */
static int input_fresh(const input *in, double now, double timeout) {
  return in->have && !in->behind && now - in->t <= timeout;
}

typedef struct {
  const opts *o;
  lcm_t *lcm;
  nds_planner *planner;
  const nds_model *pm;       /* planning model (for the object's size) */
  ndp_status st;

  /* newest inputs and their local arrival times (ndp_mono) */
  nudge_mocap_t mocap;
  input in_mocap;
  mocap_frame hist[VEL_HIST];  /* ring of recent object poses, hist_n valid */
  int hist_head, hist_n;
  int64_t mocap_lost;          /* frames missing by seq */
  int64_t overflows;            /* drains that found a full queue */
  nudge_robot_state_t rs;
  input in_rs;
  nudge_ee_cmd_t cmd;
  input in_cmd;

  /* task */
  int active;
  nudge_task_t task;
  int have_ended;
  int64_t ended_id;            /* last task an EPISODE ended: a repeated TASK for it is old */
  double task_t0;
  int64_t task_plans, task_mocap_lost0, task_overflows0;
  double task_ms_sum, task_ms_max;
  double task_stale;           /* s of the task spent without fresh state */

  /* theta */
  int64_t theta_version;       /* params_t.version in use; -1 = --theta */

  int64_t plan_id;

  ndp_ratelog rejected;         /* rate-limited log of refused inputs */
} proc;

static void reject(proc *p, const char *channel, const char *why) {
  p->st.rejected++;
  ndp_refused(&p->rejected, PROG, channel, why);
}

/* Object velocity in the free-joint qvel convention of nds_state: linear (world) in
 * v[0..2], angular (body frame) in v[3..5].
 *
 * Mocap gives poses only. A difference of consecutive frames (4.2 ms at 240 Hz) turns
 * 0.2 mm of marker noise into ~0.07 m/s, as large as a push; differencing over >= 25 ms
 * (6 frames) cuts that to ~0.01 m/s at the price of ~12 ms lag, small next to the 0.3 s
 * segments planned. This box-filter difference is the low-pass. The result is then
 * clamped to what the robot can cause: the object only moves when pushed by a sphere
 * limited to v_max, and its surface points are at least the smaller half side from its
 * centre, so faster readings are glitches (a swapped marker, a jump) and are capped
 * rather than planned on. Vertical and roll/pitch rates are left at zero: a pushed box
 * stays flat on the table, so mocap differences there are noise the model would turn
 * into a bounce. A gap of more than VEL_MAX_GAP says nothing about the present motion:
 * zero then (a box left alone comes to rest within tens of ms under friction). */
static void obj_velocity(const proc *p, double v[6]) {
  memset(v, 0, 6 * sizeof(double));
  if (p->hist_n < 2) return;
  const mocap_frame *cur = &p->hist[(p->hist_head + VEL_HIST - 1) % VEL_HIST];
  const mocap_frame *old = NULL;
  for (int k = 2; k <= p->hist_n; k++) {
    old = &p->hist[(p->hist_head + VEL_HIST - k) % VEL_HIST];
    if (1e-6 * (double)(cur->utime - old->utime) >= VEL_WINDOW) break;
  }
  const double dt = 1e-6 * (double)(cur->utime - old->utime);
  if (!(dt > 0.0) || dt > VEL_MAX_GAP) return;

  const nds_planner_cfg *pc = nds_planner_config(p->planner);
  const double *half = p->pm->cfg.obj_half;
  const double w_max = pc->v_max / fmin(half[0], half[1]);
  double vx = (cur->x - old->x) / dt, vy = (cur->y - old->y) / dt;
  double speed = hypot(vx, vy);
  if (speed > pc->v_max) vx *= pc->v_max / speed, vy *= pc->v_max / speed;
  double wz = nd_clamp(nd_wrap_angle(cur->yaw - old->yaw) / dt, -w_max, w_max);

  /* World yaw rate (0, 0, wz) in the body frame: R^T e_z wz, the third row of R. */
  double q[4], r[9];
  mju_copy4(q, p->mocap.obj_quat);
  mju_normalize4(q);
  mju_quat2Mat(r, q);
  v[0] = vx;
  v[1] = vy;
  v[3] = r[6] * wz;
  v[4] = r[7] * wz;
  v[5] = r[8] * wz;
}

/* ---------------------------------------------------------------------------------- */
/* Handlers: validate, count, keep the newest. */

static void on_mocap(const lcm_recv_buf_t *rb, const char *ch, const nudge_mocap_t *m,
                     void *user) {
  (void)rb;
  proc *p = user;
  char why[160];
  p->st.received++;
  if (ndp_check_mocap(m, why, sizeof(why))) {
    reject(p, ch, why);
    return;
  }
  if (p->in_mocap.have && m->utime <= p->mocap.utime) {
    /* Time went back: a restarted publisher or a stepped clock. The old frames cannot be
     * differenced with the new ones. */
    p->hist_n = 0;
  } else if (p->in_mocap.have && m->seq > p->mocap.seq + 1) {
    p->mocap_lost += m->seq - p->mocap.seq - 1;
  }
  p->mocap = *m;
  input_got(&p->in_mocap, m->utime);
  mocap_frame *f = &p->hist[p->hist_head];
  f->utime = m->utime;
  f->x = m->obj_pos[0];
  f->y = m->obj_pos[1];
  f->yaw = nd_quat_yaw(m->obj_quat);
  p->hist_head = (p->hist_head + 1) % VEL_HIST;
  if (p->hist_n < VEL_HIST) p->hist_n++;
}

static void on_robot_state(const lcm_recv_buf_t *rb, const char *ch,
                           const nudge_robot_state_t *m, void *user) {
  (void)rb;
  proc *p = user;
  char why[160];
  p->st.received++;
  if (ndp_check_robot_state(m, why, sizeof(why))) {
    reject(p, ch, why);
    return;
  }
  p->rs = *m;
  input_got(&p->in_rs, m->utime);
}

static void on_ee_cmd(const lcm_recv_buf_t *rb, const char *ch, const nudge_ee_cmd_t *m,
                      void *user) {
  (void)rb;
  proc *p = user;
  char why[160];
  p->st.received++;
  if (ndp_check_ee_cmd(m, why, sizeof(why))) {
    reject(p, ch, why);
    return;
  }
  p->cmd = *m;
  input_got(&p->in_cmd, m->utime);
}

static void task_summary(proc *p, const char *how) {
  double dt = ndp_mono() - p->task_t0, live = dt - p->task_stale;
  fprintf(stderr,
          PROG ": task %lld %s after %.2f s: %lld plans, %.1f plans/s over %.2f s of fresh "
          "state, plan %.1f ms mean / %.1f max, %lld mocap frames lost, %lld queue overflows\n",
          (long long)p->task.task_id, how, dt, (long long)p->task_plans,
          live > 0 ? p->task_plans / live : 0.0, live, p->task_plans ? p->task_ms_sum / p->task_plans : 0.0,
          p->task_ms_max, (long long)(p->mocap_lost - p->task_mocap_lost0),
          (long long)(p->overflows - p->task_overflows0));
}

static void on_task(const lcm_recv_buf_t *rb, const char *ch, const nudge_task_t *m,
                    void *user) {
  (void)rb;
  proc *p = user;
  char why[160];
  p->st.received++;
  if (ndp_check_task(m, why, sizeof(why))) {
    reject(p, ch, why);
    return;
  }
  /* A repeated TASK (re-sent for late joiners) neither restarts the warm start nor
   * revives a task whose end we have seen; its goal is the same by contract. */
  if ((p->active && m->task_id == p->task.task_id) ||
      (p->have_ended && m->task_id == p->ended_id))
    return;
  if (p->active) task_summary(p, "superseded");
  p->task = *m;
  p->active = 1;
  p->task_t0 = ndp_mono();
  p->task_plans = 0;
  p->task_ms_sum = p->task_ms_max = p->task_stale = 0.0;
  p->task_mocap_lost0 = p->mocap_lost;
  p->task_overflows0 = p->overflows;
  nds_planner_reset(p->planner);
  fprintf(stderr, PROG ": task %lld started: goal (%+.3f, %+.3f) m, yaw %+.1f deg, eps %g, "
          "limit %.1f s\n", (long long)m->task_id, m->goal_x, m->goal_y,
          m->goal_yaw * 180.0 / ND_PI, m->eps, m->time_limit);
}

/* ndp_validate has no check for EPISODE; only task_id and event are used here. */
static int check_episode(const nudge_episode_t *m, char *why, int len) {
  if (m->utime <= 0) {
    snprintf(why, len, "utime = %lld is not a time", (long long)m->utime);
    return -1;
  }
  if (m->task_id < 0) {
    snprintf(why, len, "task_id = %lld is negative", (long long)m->task_id);
    return -1;
  }
  if (m->event < NUDGE_EPISODE_T_EVENT_START || m->event > NUDGE_EPISODE_T_EVENT_REJECTED) {
    snprintf(why, len, "event = %d is not a known event", m->event);
    return -1;
  }
  return 0;
}

/* Raw subscription: lcm-gen's stub would decode a lying string length and crash
 * (ndp_decode_episode); an undecodable message counts as rejected like a bad one. */
static void on_episode(const lcm_recv_buf_t *rb, const char *ch, void *user) {
  proc *p = user;
  char why[160];
  nudge_episode_t m;
  p->st.received++;
  if (ndp_decode_episode(rb->data, (int)rb->data_size, &m, why, sizeof(why))) {
    reject(p, ch, why);
    return;
  }
  const int bad = check_episode(&m, why, sizeof(why));
  if (bad) reject(p, ch, why);
  if (bad || m.event == NUDGE_EPISODE_T_EVENT_START) {
    nudge_episode_t_decode_cleanup(&m);
    return;
  }
  p->have_ended = 1;
  p->ended_id = m.task_id;
  if (p->active && m.task_id == p->task.task_id) {
    p->active = 0;
    task_summary(p, m.event == NUDGE_EPISODE_T_EVENT_SUCCESS   ? "succeeded"
                    : m.event == NUDGE_EPISODE_T_EVENT_TIMEOUT ? "timed out"
                                                                : "was rejected");
  }
  nudge_episode_t_decode_cleanup(&m);
}

static void on_params(const lcm_recv_buf_t *rb, const char *ch, const nudge_params_t *m,
                      void *user) {
  (void)rb;
  proc *p = user;
  char why[160];
  p->st.received++;
  if (ndp_check_params(m, why, sizeof(why))) {
    reject(p, ch, why);
    return;
  }
  if (m->version == p->theta_version) return;
  if (nds_planner_set_theta(p->planner, m->theta_mean, why, sizeof(why))) {
    reject(p, ch, why);
    return;
  }
  p->theta_version = m->version;
  fprintf(stderr, PROG ": theta version %lld: (%g, %g, %g, %g)\n", (long long)m->version,
          m->theta_mean[0], m->theta_mean[1], m->theta_mean[2], m->theta_mean[3]);
}

/* Bytes on a typed channel that are not one message of its type: counted and logged
 * like any refused input. */
static void undecodable(void *user, const char *ch, const char *why) {
  proc *p = user;
  p->st.received++;
  reject(p, ch, why);
}

NDP_TYPED_HANDLER(nudge_mocap_t, on_mocap_raw, on_mocap, undecodable)
NDP_TYPED_HANDLER(nudge_robot_state_t, on_robot_state_raw, on_robot_state, undecodable)
NDP_TYPED_HANDLER(nudge_ee_cmd_t, on_ee_cmd_raw, on_ee_cmd, undecodable)
NDP_TYPED_HANDLER(nudge_task_t, on_task_raw, on_task, undecodable)
NDP_TYPED_HANDLER(nudge_params_t, on_params_raw, on_params, undecodable)

/* ---------------------------------------------------------------------------------- */

/* 1 if a plan may start now: mocap and robot state fresh, and the setpoint not known to
 * be behind while the executor is live (its next message is a millisecond away).
 * Ages count from each message's sending, so input that queued up while this process
 * was busy or stopped is as old as it is: after a stall the planner waits for new state
 * instead of planning from what the socket kept (the oldest, once it overflowed). */
static int state_fresh(const proc *p, double now) {
  const double to = p->o->state_timeout;
  return input_fresh(&p->in_mocap, now, to) && input_fresh(&p->in_rs, now, to) &&
         !(p->in_cmd.behind && now - p->in_cmd.t <= to);
}

/* Plan from the newest inputs and publish. Return 0, or -1 with a message (LCM failure). */
static int plan_once(proc *p, double now, char *err, int errlen) {
  const opts *o = p->o;
  nds_state s;
  memcpy(s.obj_pos, p->mocap.obj_pos, sizeof(s.obj_pos));
  memcpy(s.obj_quat, p->mocap.obj_quat, sizeof(s.obj_quat));
  obj_velocity(p, s.obj_vel);
  /* The end-effector from the robot's own state: fresher than mocap and with velocity. */
  for (int k = 0; k < 2; k++) {
    s.ee_pos[k] = p->rs.ee_pos[k];
    s.ee_vel[k] = p->rs.ee_vel[k];
  }
  /* The executor starts the plan's first segment from its setpoint, so the rollouts must
   * too. No setpoint yet, or the executor has gone quiet: the robot holds where it is.
   * Jerk is not published; 0 is the smooth assumption. */
  double sp0[2][4];
  const int cmd_ok = input_fresh(&p->in_cmd, now, o->state_timeout);
  for (int k = 0; k < 2; k++) {
    sp0[k][0] = cmd_ok ? p->cmd.p[k] : p->rs.ee_pos[k];
    sp0[k][1] = cmd_ok ? p->cmd.v[k] : 0.0;
    sp0[k][2] = cmd_ok ? p->cmd.a[k] : 0.0;
    sp0[k][3] = 0.0;
  }
  const nd_goal goal = {.x = p->task.goal_x, .y = p->task.goal_y, .yaw = p->task.goal_yaw};

  nds_plan plan;
  char why[160];
  double t0 = ndp_mono();
  if (nds_planner_plan(p->planner, &s, (const double(*)[4])sp0, &goal, &plan, why,
                       sizeof(why))) {
    /* Inputs are validated, so this is a non-finite estimate: skip this round. */
    reject(p, "plan input", why);
    return 0;
  }
  double ms = 1e3 * (ndp_mono() - t0);

  nudge_plan_t m;
  memset(&m, 0, sizeof(m));
  m.utime = ndp_utime();
  m.plan_id = ++p->plan_id;
  m.task_id = p->task.task_id;
  m.state_utime = p->mocap.utime;
  m.M = (int8_t)plan.M;
  for (int k = 0; k < plan.M && k < NUDGE_PLAN_T_MAX_KEYPOINTS; k++)
    memcpy(m.keypoints[k], plan.keys[k], 4 * sizeof(double));
  m.T = plan.T;
  m.cost = plan.cost;
  m.task_error = plan.task_error;
  m.iterations = o->iters;
  m.evals = plan.evals;
  m.plan_ms = ms;
  m.theta_version = p->theta_version;
  if (nudge_plan_t_publish(p->lcm, NDP_CH_PLAN, &m) != 0) {
    snprintf(err, errlen, "publishing on %s failed", NDP_CH_PLAN);
    return -1;
  }
  p->st.published++;
  p->task_plans++;
  p->task_ms_sum += ms;
  if (ms > p->task_ms_max) p->task_ms_max = ms;
  return 0;
}

int main(int argc, char **argv) {
  opts o;
  int rc = parse_opts(argc, argv, &o);
  if (rc == 1) return 0;
  if (rc) return 2;

  ndp_signals();
  ndp_mujoco_handlers(PROG);
  char err[512] = "";
  int status = 1;
  nds_model pm;
  memset(&pm, 0, sizeof(pm));
  nd_pool *pool = NULL;
  lcm_subscription_t *s_mocap = NULL;
  lcm_subscription_t *s_rs = NULL;
  lcm_subscription_t *s_cmd = NULL;
  lcm_subscription_t *s_task = NULL;
  lcm_subscription_t *s_par = NULL;
  lcm_subscription_t *s_epi = NULL;
  proc p;
  memset(&p, 0, sizeof(p));
  p.o = &o;
  p.theta_version = -1;
  p.pm = &pm;
  ndp_status_init(&p.st, PROG);
  p.st.state = "idle";

  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  sc.timestep = o.plan_dt;
  memcpy(sc.theta, o.theta, sizeof(sc.theta));
  nds_planner_cfg pc;
  nds_planner_cfg_default(&pc);
  pc.pop = o.pop;
  pc.iters = o.iters;
  pc.seed = o.seed;
  memcpy(pc.ws_lo, o.ws_lo, sizeof(pc.ws_lo));
  memcpy(pc.ws_hi, o.ws_hi, sizeof(pc.ws_hi));
  if (nds_model_init(&pm, &sc, err, sizeof(err))) goto done;
  if (!(pool = nd_pool_create(o.threads, err, sizeof(err)))) goto done;
  if (!(p.planner = nds_planner_create(&pm, &pc, pool, err, sizeof(err)))) goto done;
  if (!(p.lcm = ndp_lcm_create(o.url, err, sizeof(err)))) goto done;

  /* A plan keeps this thread away from LCM for tens of ms, and LCM drops the NEWEST
   * message when a subscription's queue (default 30) is full: at 1 kHz the drain after a
   * plan would then hand over state from the plan's first 30 ms. Queues of ~0.5 s of
   * input keep the newest; a longer stall is detected (input_drained). */
  p.in_mocap.cap = 128;
  p.in_rs.cap = p.in_cmd.cap = 500;
  s_mocap = lcm_subscribe(p.lcm, NDP_CH_MOCAP, on_mocap_raw, &p);
  s_rs = lcm_subscribe(p.lcm, NDP_CH_ROBOT_STATE, on_robot_state_raw, &p);
  s_cmd = lcm_subscribe(p.lcm, NDP_CH_EE_CMD, on_ee_cmd_raw, &p);
  s_task = lcm_subscribe(p.lcm, NDP_CH_TASK, on_task_raw, &p);
  s_par = lcm_subscribe(p.lcm, NDP_CH_PARAMS, on_params_raw, &p);
  s_epi = lcm_subscribe(p.lcm, NDP_CH_EPISODE, on_episode, &p);
  if (!s_mocap || !s_rs || !s_cmd || !s_task || !s_par || !s_epi ||
      lcm_subscription_set_queue_capacity(s_mocap, p.in_mocap.cap) ||
      lcm_subscription_set_queue_capacity(s_rs, p.in_rs.cap) ||
      lcm_subscription_set_queue_capacity(s_cmd, p.in_cmd.cap)) {
    snprintf(err, sizeof(err), "subscribing to the input channels failed");
    goto done;
  }

  fprintf(stderr,
          PROG ": %s, iCEM N %d C %d, M %d, T %.2f s, plan dt %.4f s, %d worker(s), max %.1f "
          "plans/s, state timeout %.3f s, theta (%g, %g, %g, %g), seed %llu, keypoints in "
          "x [%g, %g] y [%g, %g] m\n",
          ndp_url(o.url), o.pop, o.iters, pc.M, pc.T, o.plan_dt, o.threads, o.max_rate,
          o.state_timeout, o.theta[0], o.theta[1], o.theta[2], o.theta[3],
          (unsigned long long)o.seed, pc.ws_lo[0], pc.ws_hi[0], pc.ws_lo[1], pc.ws_hi[1]);

  const double period = 1.0 / o.max_rate;
  double next_plan = 0.0, last = ndp_mono();
  while (!ndp_quit) {
    double now = ndp_mono();
    /* Wait for input, but not past the next allowed plan; 10 ms keeps the heartbeat and
     * the freshness check responsive when nothing arrives. */
    double wait = 0.01;
    if (p.active && state_fresh(&p, now)) wait = fmin(wait, fmax(0.0, next_plan - now));
    if (ndp_handle(p.lcm, wait)) {
      snprintf(err, sizeof(err), "LCM receive failed: %s", strerror(errno));
      goto done;
    }
    if (ndp_quit) break;
    p.overflows += input_drained(&p.in_mocap) + input_drained(&p.in_rs) +
                   input_drained(&p.in_cmd);
    now = ndp_mono();
    if (!p.active) {
      p.st.state = "idle";
    } else if (!state_fresh(&p, now)) {
      p.st.state = "stale";
      p.task_stale += now - last;
    } else {
      p.st.state = "planning";
      if (now >= next_plan) {
        next_plan = now + period;
        if (plan_once(&p, now, err, sizeof(err))) goto done;
      }
    }
    last = now;
    if (ndp_status_tick(p.lcm, &p.st, 0) < 0) {
      snprintf(err, sizeof(err), "publishing on %s failed", NDP_CH_STATUS);
      goto done;
    }
  }
  /* An EPISODE that came during the last plan still tells how the task ended. */
  ndp_drain(p.lcm);
  if (p.active) task_summary(&p, "interrupted");
  p.st.state = "stopped";
  ndp_status_tick(p.lcm, &p.st, 1);
  status = 0;

done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  if (p.lcm) {
    if (s_mocap) lcm_unsubscribe(p.lcm, s_mocap);
    if (s_rs) lcm_unsubscribe(p.lcm, s_rs);
    if (s_cmd) lcm_unsubscribe(p.lcm, s_cmd);
    if (s_task) lcm_unsubscribe(p.lcm, s_task);
    if (s_par) lcm_unsubscribe(p.lcm, s_par);
    if (s_epi) lcm_unsubscribe(p.lcm, s_epi);
    lcm_destroy(p.lcm);
  }
  nds_planner_free(p.planner);
  nd_pool_free(pool);
  nds_model_free(&pm);
  return status;
}
