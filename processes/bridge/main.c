/* nudge-bridge: the mocap/robot bridge. In emulation mode (the only one built here) it is
 * the "real world": a MuJoCo pushing scene with the ground-truth theta, stepped at 1 kHz of
 * real time. The robot's low-level tracking controller drives the sphere toward the newest
 * EE_CMD setpoint and holds where it is when commands go stale. It publishes ROBOT_STATE
 * every step and MOCAP at the motion-capture rate, exactly what a hardware bridge would
 * publish from the robot and the mocap system.
 *
 * Two threads: the I/O thread (main) owns lcm_t, validates EE_CMD and posts it into a
 * mailbox with its local arrival time; the real-time thread steps the world on absolute
 * deadlines, encodes what it publishes into a ring and hands its loop statistics back
 * through a second mailbox. The real-time thread never allocates, locks or does I/O. */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "nd_exec.h"
#include "nd_jitter.h"
#include "nd_parse.h"
#include "nd_rtio.h"
#include "nd_snap.h"
#include "nds_ctrl.h"
#include "nds_model.h"
#include "nds_state.h"
#include "ndp.h"
#include "ndp_validate.h"

#define PROG "nudge-bridge"

/* How far beyond its workspace box an EE_CMD position may lie. The executor keeps its
 * trajectories within ND_EXEC_WS_MARGIN of the same box (segment overshoot, brake travel);
 * one more centimetre, so that a setpoint it certified is never refused here, also when
 * the two were given the box in different digits. */
#define BRIDGE_WS_MARGIN 0.05
_Static_assert(BRIDGE_WS_MARGIN >= ND_EXEC_WS_MARGIN,
               "the bridge must accept every setpoint the executor may send");

/* Beyond this many missed deadlines in one wake-up the world stops catching up and lets
 * real time slip: stepping 20 ms of backlog costs well under a period, a longer stall
 * (debugger, suspended VM) would otherwise replay seconds of physics in a burst. */
#define CATCHUP_MAX 20

/* The RT thread hands its statistics over this often (in steps), and at every hold change. */
#define STATS_EVERY 100

enum { TAG_ROBOT_STATE = 0, TAG_MOCAP = 1 };

/* ---- configuration (constant once parsed) ---- */

typedef struct {
  const char *url;
  const char *model_path;  /* NULL: the generated scene */
  double rate;             /* steps per second of real time; timestep = 1 / rate */
  int rate_given;
  double mocap_hz;
  double cmd_timeout;      /* s */
  double seconds;          /* run time, 0: until signalled */
  double theta[ND_NTHETA];
  double obj[3];           /* x, y, yaw */
  double ee[2];
  double ws_lo[2], ws_hi[2]; /* workspace box, m: EE_CMD beyond it + BRIDGE_WS_MARGIN refused */
  int no_rt;
} bridge_cfg;

/* ---- what crosses between the threads ---- */

/* A validated EE_CMD as the RT thread needs it, stamped with its local arrival time. */
typedef struct {
  double p[2], v[2], a[2];
  double arrival;  /* ndp_mono() s */
  int64_t seq;
} cmd_post;

/* The RT thread's account of itself, summarised in its own thread. */
typedef struct {
  int64_t steps, slipped, resets, hold_events;
  int64_t robot_states, mocaps;
  ndp_loop_stats loop;
  double hold_pos[2];  /* setpoint while holding */
  int32_t holding, have_cmd;
} rt_stats;

typedef struct {
  const bridge_cfg *cfg;
  nds_model nm;
  mjData *d;
  nds_ctrl_cfg ctrl;
  nds_state init;       /* initial (and reset) state */
  nd_mailbox cmd;       /* I/O -> RT */
  nd_mailbox stats;     /* RT -> I/O */
  nd_ring out;          /* RT -> I/O: encoded ROBOT_STATE / MOCAP */
  atomic_int stop;
  nd_jitter jit;        /* RT thread only */
  unsigned char io_buf[ND_RTIO_MAX];  /* I/O thread only: one message on its way to LCM */
} bridge;

/* ---- the world ---- */

/* Put the world into its initial state: object and sphere at rest where the options say,
 * every input and warm start cleared, the controller's memory zeroed. Allocation-free, so
 * a divergence (and later a reset request) can call it from the RT loop. */
static int world_reset(bridge *b, nds_ctrl *pid, char *err, int errlen) {
  if (nds_state_set(&b->nm, b->d, &b->init, err, errlen)) return -1;
  mj_forward(b->nm.m, b->d);
  nds_ctrl_reset(pid);
  return 0;
}

/* MuJoCo resets mjData to qpos0 by itself on a bad qacc and only counts a warning: look at
 * both the counters (cleared before each step) and the configuration. */
static int world_diverged(const mjModel *m, const mjData *d) {
  if (d->warning[mjWARN_BADQPOS].number || d->warning[mjWARN_BADQVEL].number ||
      d->warning[mjWARN_BADQACC].number)
    return 1;
  for (int i = 0; i < m->nq; i++)
    if (!isfinite(d->qpos[i])) return 1;
  for (int i = 0; i < m->nv; i++)
    if (!isfinite(d->qvel[i])) return 1;
  return 0;
}

/* ---- the real-time thread ---- */

typedef struct {
  nds_ctrl pid;
  cmd_post cmd;
  uint64_t cmd_version;
  int have_cmd, holding;
  double hold[2];
  double next_mocap;   /* step index of the next MOCAP frame */
  double steps_per_frame;
  int64_t rs_seq, mc_seq;
  rt_stats st;
} rt_state;

static int64_t ts_ns(const struct timespec *t) { return (int64_t)t->tv_sec * 1000000000 + t->tv_nsec; }

static void ns_ts(int64_t ns, struct timespec *t) {
  t->tv_sec = ns / 1000000000;
  t->tv_nsec = ns % 1000000000;
}

static void post_stats(bridge *b, rt_state *r) {
  r->st.loop.p50_us = (int32_t)nd_jitter_quantile(&b->jit, 0.5);
  r->st.loop.p99_us = (int32_t)nd_jitter_quantile(&b->jit, 0.99);
  r->st.loop.max_us = (int32_t)b->jit.max_us;
  r->st.loop.overruns = b->jit.overruns;
  r->st.holding = r->holding;
  r->st.have_cmd = r->have_cmd;
  r->st.hold_pos[0] = r->hold[0];
  r->st.hold_pos[1] = r->hold[1];
  nd_mailbox_post(&b->stats, &r->st, sizeof(r->st));
}

/* Choose the setpoint: the newest command while fresh, else hold where the sphere was when
 * commands went stale (or never came). Return 1 if the hold state changed. */
static int setpoint(bridge *b, rt_state *r, double now, const double pos[2], double sp[2][4]) {
  cmd_post c;
  if (nd_mailbox_take(&b->cmd, &r->cmd_version, &c, sizeof(c)) == (int)sizeof(c)) {
    r->cmd = c;
    r->have_cmd = 1;
  }
  int fresh = r->have_cmd && now - r->cmd.arrival <= b->cfg->cmd_timeout;
  int changed = 0;
  if (fresh && r->holding) {
    r->holding = 0;
    changed = 1;
  } else if (!fresh && !r->holding) {
    r->holding = 1;
    r->hold[0] = pos[0];
    r->hold[1] = pos[1];
    r->st.hold_events++;
    changed = 1;
  }
  for (int k = 0; k < 2; k++) {
    sp[k][ND_P] = r->holding ? r->hold[k] : r->cmd.p[k];
    sp[k][ND_V] = r->holding ? 0.0 : r->cmd.v[k];
    sp[k][ND_A] = r->holding ? 0.0 : r->cmd.a[k];
    sp[k][ND_J] = 0.0;
  }
  return changed;
}

/* One world step under the tracking controller, then encode what it publishes. utime is
 * the wall-clock time the step's state is for. */
static void rt_step(bridge *b, rt_state *r, double now, int64_t utime) {
  const mjModel *m = b->nm.m;
  mjData *d = b->d;
  nds_state s;
  nds_state_get(&b->nm, d, &s);
  double sp[2][4], f[2];
  if (setpoint(b, r, now, s.ee_pos, sp)) post_stats(b, r);
  nds_ctrl_pid(&b->ctrl, &r->pid, sp, s.ee_pos, s.ee_vel, m->opt.timestep, f);
  d->qfrc_applied[b->nm.ee_dof[0]] = f[0];
  d->qfrc_applied[b->nm.ee_dof[1]] = f[1];
  for (int w = mjWARN_BADQPOS; w <= mjWARN_BADQACC; w++) d->warning[w].number = 0;
  mj_step(m, d);
  if (world_diverged(m, d)) {
    char err[128];
    world_reset(b, &r->pid, err, sizeof(err));  /* the initial state was checked at start */
    r->st.resets++;
    f[0] = f[1] = 0.0;
    if (r->holding) {
      r->hold[0] = b->init.ee_pos[0];
      r->hold[1] = b->init.ee_pos[1];
    }
  }
  nds_state_get(&b->nm, d, &s);

  unsigned char *slot = nd_ring_reserve(&b->out);
  if (slot) {
    nudge_robot_state_t rs = {0};
    rs.utime = utime;
    rs.seq = r->rs_seq;
    rs.ee_pos[0] = s.ee_pos[0];
    rs.ee_pos[1] = s.ee_pos[1];
    rs.ee_pos[2] = b->nm.ee_height;
    rs.ee_vel[0] = s.ee_vel[0];
    rs.ee_vel[1] = s.ee_vel[1];
    rs.ee_force[0] = f[0];
    rs.ee_force[1] = f[1];
    int n = nudge_robot_state_t_encode(slot, 0, ND_RTIO_MAX, &rs);
    if (n > 0) nd_ring_commit(&b->out, TAG_ROBOT_STATE, n);
    r->st.robot_states++;
  }
  r->rs_seq++;  /* also on a full ring, so receivers see the gap */

  if ((double)r->st.steps >= r->next_mocap) {
    r->next_mocap += r->steps_per_frame;
    slot = nd_ring_reserve(&b->out);
    if (slot) {
      nudge_mocap_t mc = {0};
      mc.utime = utime;
      mc.seq = r->mc_seq;
      memcpy(mc.obj_pos, s.obj_pos, sizeof(mc.obj_pos));
      memcpy(mc.obj_quat, s.obj_quat, sizeof(mc.obj_quat));
      mc.ee_pos[0] = s.ee_pos[0];
      mc.ee_pos[1] = s.ee_pos[1];
      mc.ee_pos[2] = b->nm.ee_height;
      int n = nudge_mocap_t_encode(slot, 0, ND_RTIO_MAX, &mc);
      if (n > 0) nd_ring_commit(&b->out, TAG_MOCAP, n);
      r->st.mocaps++;
    }
    r->mc_seq++;
  }
  r->st.steps++;
}

static void *rt_main(void *arg) {
  bridge *b = arg;
  rt_state r;
  memset(&r, 0, sizeof(r));
  nds_ctrl_reset(&r.pid);
  r.holding = 1;  /* no command yet: hold the initial position */
  r.hold[0] = b->init.ee_pos[0];
  r.hold[1] = b->init.ee_pos[1];
  r.steps_per_frame = b->cfg->rate / b->cfg->mocap_hz;
  nd_jitter_reset(&b->jit);
  post_stats(b, &r);

  const int64_t period = (int64_t)llround(1e9 / b->cfg->rate);
  const double period_us = period * 1e-3;
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  int64_t next = ts_ns(&ts) + period;
  while (!atomic_load_explicit(&b->stop, memory_order_relaxed)) {
    ns_ts(next, &ts);
    int rc;
    do rc = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
    while (rc == EINTR && !atomic_load_explicit(&b->stop, memory_order_relaxed));
    clock_gettime(CLOCK_MONOTONIC, &ts);
    int64_t now = ts_ns(&ts), utime_now = ndp_utime();
    int64_t late = now - next;
    nd_jitter_add(&b->jit, late * 1e-3, period_us);

    /* Every deadline that has passed gets its step, so simulated time keeps up with real
     * time; a backlog beyond CATCHUP_MAX is dropped and the schedule re-anchored. */
    int64_t due = late > 0 ? 1 + late / period : 1;
    if (due > CATCHUP_MAX) {
      r.st.slipped += due - CATCHUP_MAX;
      next += (due - CATCHUP_MAX) * period;
      due = CATCHUP_MAX;
    }
    for (int64_t k = 0; k < due; k++) {
      int64_t deadline = next + k * period;
      rt_step(b, &r, deadline * 1e-9, utime_now - (now - deadline) / 1000);
    }
    next += due * period;
    if (r.st.steps % STATS_EVERY < due) post_stats(b, &r);
  }
  post_stats(b, &r);
  return NULL;
}

/* ---- the I/O thread ---- */

typedef struct {
  bridge *b;
  ndp_status *status;
  ndp_ratelog refused;
  ndp_ratelog refused_ws;  /* valid, but outside the workspace */
} io_ctx;

static void on_ee_cmd(const lcm_recv_buf_t *rbuf, const char *channel,
                      const nudge_ee_cmd_t *msg, void *user) {
  (void)rbuf;
  (void)channel;
  io_ctx *io = user;
  io->status->received++;
  char why[256];
  if (ndp_check_ee_cmd(msg, why, sizeof(why))) {
    io->status->rejected++;
    ndp_refused(&io->refused, PROG, "EE_CMD", why);
    return;
  }
  /* Tracking a command that the executor would never send moves the robot where nothing
   * checked it may go: refused like an invalid one, so the newest valid command goes on
   * being tracked until it is stale, and then the robot holds. */
  const bridge_cfg *cfg = io->b->cfg;
  for (int k = 0; k < 2; k++) {
    if (msg->p[k] >= cfg->ws_lo[k] - BRIDGE_WS_MARGIN &&
        msg->p[k] <= cfg->ws_hi[k] + BRIDGE_WS_MARGIN)
      continue;
    snprintf(why, sizeof(why), "p (%.3f, %.3f) is outside the workspace x [%.3f, %.3f], "
             "y [%.3f, %.3f] m plus its %.2f m margin", msg->p[0], msg->p[1], cfg->ws_lo[0],
             cfg->ws_hi[0], cfg->ws_lo[1], cfg->ws_hi[1], BRIDGE_WS_MARGIN);
    io->status->rejected++;
    ndp_refused(&io->refused_ws, PROG, "EE_CMD", why);
    return;
  }
  cmd_post c;
  for (int k = 0; k < 2; k++) {
    c.p[k] = msg->p[k];
    c.v[k] = msg->v[k];
    c.a[k] = msg->a[k];
  }
  c.arrival = ndp_mono();
  c.seq = msg->seq;
  nd_mailbox_post(&io->b->cmd, &c, sizeof(c));
}

/* Bytes on EE_CMD that are not one nudge_ee_cmd_t. */
static void undecodable(void *user, const char *ch, const char *why) {
  io_ctx *io = user;
  io->status->received++;
  io->status->rejected++;
  ndp_refused(&io->refused, PROG, ch, why);
}

NDP_TYPED_HANDLER(nudge_ee_cmd_t, on_ee_cmd_raw, on_ee_cmd, undecodable)

/* Publish what the RT thread has encoded. Return the number of failed publishes. */
static int publish_ring(lcm_t *lcm, bridge *b, ndp_status *st) {
  int tag, n, failed = 0;
  while ((n = nd_ring_pop(&b->out, &tag, b->io_buf, sizeof(b->io_buf))) >= 0) {
    const char *ch = tag == TAG_MOCAP ? NDP_CH_MOCAP : NDP_CH_ROBOT_STATE;
    if (lcm_publish(lcm, ch, b->io_buf, (unsigned)n) == 0) st->published++;
    else failed++;
  }
  return failed;
}

/* ---- command line ---- */

static void usage(FILE *f) {
  fprintf(f,
          "usage: " PROG " [options]\n"
          "Mocap/robot bridge. Emulation mode: a MuJoCo pushing scene with the true theta,\n"
          "stepped in real time; the robot's tracking controller follows EE_CMD and holds\n"
          "when commands go stale. Publishes ROBOT_STATE every step and MOCAP (object pose,\n"
          "end-effector position) at the mocap rate; heartbeat on STATUS.\n\n"
          "  --mode MODE        emulation (default, the only mode of this build)\n"
          "  --rate HZ          world steps per second of real time; timestep 1/HZ\n"
          "                     (default 1000, or the --model file's own timestep)\n"
          "  --mocap-hz HZ      MOCAP rate (default 240)\n"
          "  --cmd-timeout S    hold when the newest EE_CMD is older than S (default 0.1)\n"
          "  --theta S,T,R,M    sliding, torsional, rolling friction, sphere mass [kg]\n"
          "                     (default: ground truth 1,0.005,0.0001,1)\n"
          "  --object X,Y,YAW   initial object pose, m, m, rad (default 0,0,0)\n"
          "  --ee X,Y           initial sphere position, m (default -0.10,0), inside the\n"
          "                     workspace\n"
          "  --workspace XLO,YLO,XHI,YHI\n"
          "                     box in metres: an EE_CMD whose position lies beyond it\n"
          "                     by more than %g m is refused and counted; the robot goes\n"
          "                     on with the last valid command, then holds. Default\n"
          "                     %g,%g,%g,%g, nudge-planner's keypoint box; give\n"
          "                     nudge-executor and nudge-planner the same --workspace\n"
          "                     (nudge-up --workspace does)\n"
          "  --model FILE       MJCF with bodies \"object\" (free joint) and \"ee\" (slide\n"
          "                     joints \"ee_x\", \"ee_y\") instead of the built-in scene\n"
          "  --seconds S        run S seconds, then exit 0 (default: until SIGINT/SIGTERM)\n"
          "  --lcm-url URL      LCM URL (default: $LCM_DEFAULT_URL, else %s)\n"
          "  --no-rt            do not ask for SCHED_FIFO and mlockall\n"
          "  -h, --help         this text\n\n"
          "Exit status: 0 after SIGINT/SIGTERM or --seconds, 1 on a runtime failure (LCM),\n"
          "2 on bad arguments, a --model file among them (missing, malformed, unusable).\n",
          BRIDGE_WS_MARGIN, ND_EXEC_WS_LO, ND_EXEC_WS_LO, ND_EXEC_WS_HI, ND_EXEC_WS_HI,
          NDP_DEFAULT_URL);
}

/* Return 0, 1 for --help, or -1 with a message for a bad argument. */
static int parse_args(int argc, char **argv, bridge_cfg *c, char *err, int errlen) {
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) return 1;
    if (!strcmp(a, "--no-rt")) {
      c->no_rt = 1;
      continue;
    }
    int known = !strcmp(a, "--mode") || !strcmp(a, "--rate") || !strcmp(a, "--mocap-hz") ||
                !strcmp(a, "--cmd-timeout") || !strcmp(a, "--theta") ||
                !strcmp(a, "--object") || !strcmp(a, "--ee") || !strcmp(a, "--model") ||
                !strcmp(a, "--seconds") || !strcmp(a, "--lcm-url") ||
                !strcmp(a, "--workspace");
    if (!known) {
      snprintf(err, errlen, "unknown option: %s", a);
      return -1;
    }
    if (i + 1 >= argc) {
      snprintf(err, errlen, "%s needs a value", a);
      return -1;
    }
    const char *v = argv[++i];
    int rc = 0;
    if (!strcmp(a, "--mode")) {
      if (strcmp(v, "emulation")) {
        snprintf(err, errlen,
                 "--mode %s is not available: this build has only the emulation mode. A real "
                 "hardware bridge publishes the same channels (%s, %s) from the motion capture "
                 "and the robot, and follows %s the same way",
                 v, NDP_CH_MOCAP, NDP_CH_ROBOT_STATE, NDP_CH_EE_CMD);
        return -1;
      }
    } else if (!strcmp(a, "--rate")) {
      rc = nd_parse_double(v, "--rate", 20.0, 10000.0, &c->rate, err, errlen);
      c->rate_given = 1;
    } else if (!strcmp(a, "--mocap-hz"))
      rc = nd_parse_double(v, "--mocap-hz", 1.0, 10000.0, &c->mocap_hz, err, errlen);
    else if (!strcmp(a, "--cmd-timeout"))
      rc = nd_parse_double(v, "--cmd-timeout", 1e-3, 60.0, &c->cmd_timeout, err, errlen);
    else if (!strcmp(a, "--theta"))
      rc = nd_theta_parse(v, a, c->theta, err, errlen);
    else if (!strcmp(a, "--object"))
      rc = nd_parse_list(v, "--object", 3, -NDP_MAX_POS, NDP_MAX_POS, c->obj, err, errlen);
    else if (!strcmp(a, "--ee"))
      rc = nd_parse_list(v, "--ee", 2, -NDP_MAX_POS, NDP_MAX_POS, c->ee, err, errlen);
    else if (!strcmp(a, "--workspace"))
      rc = ndp_parse_workspace(v, "--workspace", c->ws_lo, c->ws_hi, err, errlen);
    else if (!strcmp(a, "--model"))
      c->model_path = v;
    else if (!strcmp(a, "--seconds"))
      rc = nd_parse_double(v, "--seconds", 1e-3, 1e9, &c->seconds, err, errlen);
    else
      c->url = v;
    if (rc) return -1;
  }
  return 0;
}

/* The sphere must start clear of the box, or the first contact throws the object. */
static int check_start(const nds_model *nm, const bridge_cfg *c, char *err, int errlen) {
  double dx = c->ee[0] - c->obj[0], dy = c->ee[1] - c->obj[1];
  double cy = cos(c->obj[2]), sy = sin(c->obj[2]);
  double lx = cy * dx + sy * dy, ly = -sy * dx + cy * dy;  /* in the box frame */
  double ex = fabs(lx) - nm->cfg.obj_half[0], ey = fabs(ly) - nm->cfg.obj_half[1];
  double gap = hypot(ex > 0 ? ex : 0, ey > 0 ? ey : 0);
  if (ex <= 0 && ey <= 0) gap = ex > ey ? ex : ey;
  if (gap < nm->cfg.ee_radius) {
    snprintf(err, errlen,
             "the sphere at --ee %g,%g (radius %g m) overlaps the object at --object %g,%g,%g "
             "(half sizes %g x %g m)",
             c->ee[0], c->ee[1], nm->cfg.ee_radius, c->obj[0], c->obj[1], c->obj[2],
             nm->cfg.obj_half[0], nm->cfg.obj_half[1]);
    return -1;
  }
  return 0;
}

/* SCHED_FIFO for the RT thread if allowed, else a normal thread. Sets *how to a word for
 * the banner. */
static int start_rt(pthread_t *th, bridge *b, int no_rt, const char **how) {
  if (!no_rt) {
    pthread_attr_t at;
    struct sched_param sp = {.sched_priority = 80};
    pthread_attr_init(&at);
    pthread_attr_setinheritsched(&at, PTHREAD_EXPLICIT_SCHED);
    pthread_attr_setschedpolicy(&at, SCHED_FIFO);
    pthread_attr_setschedparam(&at, &sp);
    int rc = pthread_create(th, &at, rt_main, b);
    pthread_attr_destroy(&at);
    if (rc == 0) {
      *how = "SCHED_FIFO 80";
      return 0;
    }
    fprintf(stderr, "%s: SCHED_FIFO refused (%s): the world loop runs at normal priority\n",
            PROG, strerror(rc));
  }
  *how = no_rt ? "normal priority (--no-rt)" : "normal priority";
  return pthread_create(th, NULL, rt_main, b);
}

int main(int argc, char **argv) {
  char err[512];
  bridge_cfg cfg = {0};
  cfg.rate = 1000.0;
  cfg.mocap_hz = 240.0;
  cfg.cmd_timeout = 0.1;
  memcpy(cfg.theta, nd_theta_true, sizeof(cfg.theta));
  cfg.ee[0] = -0.10;
  cfg.ws_lo[0] = cfg.ws_lo[1] = ND_EXEC_WS_LO;
  cfg.ws_hi[0] = cfg.ws_hi[1] = ND_EXEC_WS_HI;

  int pa = parse_args(argc, argv, &cfg, err, sizeof(err));
  if (pa == 1) {
    usage(stdout);
    return 0;
  }
  if (pa < 0) {
    fprintf(stderr, "%s: %s\n", PROG, err);
    usage(stderr);
    return 2;
  }

  ndp_signals();
  ndp_mujoco_handlers(PROG);

  bridge *b = calloc(1, sizeof(*b));  /* the ring is 256 KB: not on the stack */
  lcm_t *lcm = NULL;
  lcm_subscription_t *sub = NULL;
  int status = 1, started = 0;
  pthread_t rt;
  if (!b) {
    fprintf(stderr, "%s: out of memory\n", PROG);
    return 1;
  }
  b->cfg = &cfg;
  nd_mailbox_init(&b->cmd);
  nd_mailbox_init(&b->stats);
  nd_ring_init(&b->out);
  atomic_init(&b->stop, 0);
  nds_ctrl_cfg_default(&b->ctrl);

  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  memcpy(sc.theta, cfg.theta, sizeof(sc.theta));
  sc.timestep = 1.0 / cfg.rate;
  if (cfg.model_path) {
    /* A file that is missing or not a usable scene is a bad argument (status 2): the
     * supervisor must not restart the bridge on it. MuJoCo's parser reports a missing file
     * as an XML error: say it plainly. */
    FILE *probe = fopen(cfg.model_path, "r");
    if (!probe) {
      fprintf(stderr, "%s: cannot open --model %s: %s\n", PROG, cfg.model_path, strerror(errno));
      status = 2;
      goto done;
    }
    fclose(probe);
    if (nds_model_load_file(&b->nm, cfg.model_path, &sc, err, sizeof(err))) {
      fprintf(stderr, "%s: cannot use --model %s: %s\n", PROG, cfg.model_path, err);
      status = 2;
      goto done;
    }
    /* Simulated time must be real time: the file's timestep sets the rate unless --rate
     * overrides it. */
    double dt = b->nm.m->opt.timestep;
    if (!cfg.rate_given) {
      cfg.rate = 1.0 / dt;
      if (cfg.rate < 20.0 || cfg.rate > 10000.0) {
        fprintf(stderr, "%s: --model %s: timestep %g s is outside [0.1, 50] ms for a real-time "
                        "world; give --rate\n", PROG, cfg.model_path, dt);
        status = 2;
        goto done;
      }
    } else if (fabs(dt * cfg.rate - 1.0) > 1e-9) {
      fprintf(stderr, "%s: --model %s: timestep %g s replaced by 1/--rate = %g s\n", PROG,
              cfg.model_path, dt, 1.0 / cfg.rate);
      b->nm.m->opt.timestep = 1.0 / cfg.rate;
    }
  } else if (nds_model_init(&b->nm, &sc, err, sizeof(err))) {
    fprintf(stderr, "%s: cannot build the scene: %s\n", PROG, err);
    goto done;
  }
  if (cfg.mocap_hz > cfg.rate) {
    fprintf(stderr, "%s: --mocap-hz %g exceeds the world's step rate %g Hz\n", PROG,
            cfg.mocap_hz, cfg.rate);
    usage(stderr);
    status = 2;
    goto done;
  }
  if (cfg.ee[0] < cfg.ws_lo[0] || cfg.ee[0] > cfg.ws_hi[0] || cfg.ee[1] < cfg.ws_lo[1] ||
      cfg.ee[1] > cfg.ws_hi[1]) {
    /* The executor would refuse every plan from there, and this bridge its commands. */
    fprintf(stderr, "%s: the sphere at --ee %g,%g starts outside the workspace x [%g, %g], "
            "y [%g, %g] m (--workspace)\n", PROG, cfg.ee[0], cfg.ee[1], cfg.ws_lo[0],
            cfg.ws_hi[0], cfg.ws_lo[1], cfg.ws_hi[1]);
    usage(stderr);
    status = 2;
    goto done;
  }
  if (check_start(&b->nm, &cfg, err, sizeof(err))) {
    fprintf(stderr, "%s: %s\n", PROG, err);
    usage(stderr);
    status = 2;
    goto done;
  }
  if (!(b->d = mj_makeData(b->nm.m))) {
    fprintf(stderr, "%s: out of memory for the world's mjData\n", PROG);
    goto done;
  }
  nds_state_rest(&b->nm, cfg.obj[0], cfg.obj[1], cfg.obj[2], cfg.ee, &b->init);
  {
    nds_ctrl scratch;
    if (world_reset(b, &scratch, err, sizeof(err))) {
      fprintf(stderr, "%s: initial state: %s\n", PROG, err);
      goto done;
    }
  }

  if (!(lcm = ndp_lcm_create(cfg.url, err, sizeof(err)))) {
    fprintf(stderr, "%s: %s\n", PROG, err);
    goto done;
  }
  ndp_status st;
  ndp_status_init(&st, PROG);
  rt_stats rs = {0};
  st.loop = &rs.loop;
  io_ctx io = {.b = b, .status = &st};
  if (!(sub = lcm_subscribe(lcm, NDP_CH_EE_CMD, on_ee_cmd_raw, &io))) {
    fprintf(stderr, "%s: cannot subscribe to %s\n", PROG, NDP_CH_EE_CMD);
    goto done;
  }

  const char *lock = "not requested";
  if (!cfg.no_rt) {
    char why[160];
    const int lk = ndp_lock_memory(why, sizeof why);
    if (lk == 0) {
      lock = "locked";
    } else if (lk > 0) {
      lock = "not locked: AddressSanitizer build";
    } else {
      fprintf(stderr, "%s: %s: page faults may delay the world loop\n", PROG, why);
      lock = "not locked";
    }
  }
  const char *how;
  int rc = start_rt(&rt, b, cfg.no_rt, &how);
  if (rc) {
    fprintf(stderr, "%s: cannot start the world thread: %s\n", PROG, strerror(rc));
    goto done;
  }
  started = 1;
  fprintf(stderr,
          "%s: emulation, world dt %.3g ms at %g Hz real time (%s, memory %s), MOCAP %g Hz, "
          "EE_CMD timeout %g s, theta (%g, %g, %g, %g), object (%g, %g, %g), ee (%g, %g), "
          "workspace x [%g, %g] y [%g, %g] m (+%g m), model %s, LCM %s\n",
          PROG, 1e3 / cfg.rate, cfg.rate, how, lock, cfg.mocap_hz, cfg.cmd_timeout,
          cfg.theta[0], cfg.theta[1], cfg.theta[2], cfg.theta[3], cfg.obj[0], cfg.obj[1],
          cfg.obj[2], cfg.ee[0], cfg.ee[1], cfg.ws_lo[0], cfg.ws_hi[0], cfg.ws_lo[1],
          cfg.ws_hi[1], BRIDGE_WS_MARGIN, cfg.model_path ? cfg.model_path : "built-in scene",
          ndp_url(cfg.url));

  const double t0 = ndp_mono();
  uint64_t stats_version = 0;
  int holding = -1, have_cmd = 0, pub_fail_said = 0;
  int64_t resets_said = 0, slipped_said = 0;
  double reset_said_at = -1e9, slip_said_at = -1e9;  /* at most one line per 5 s each */
  st.state = "holding";
  status = 0;
  while (!ndp_quit) {
    if (cfg.seconds > 0 && ndp_mono() - t0 >= cfg.seconds) break;
    if (ndp_handle(lcm, 0.001)) {
      fprintf(stderr, "%s: LCM receive failed: %s\n", PROG, strerror(errno));
      status = 1;
      break;
    }
    if (publish_ring(lcm, b, &st) && !pub_fail_said) {
      fprintf(stderr, "%s: LCM publish failed (said once)\n", PROG);
      pub_fail_said = 1;
    }
    if (nd_mailbox_take(&b->stats, &stats_version, &rs, sizeof(rs)) == (int)sizeof(rs)) {
      if (rs.holding != holding) {
        if (rs.holding)
          fprintf(stderr, "%s: %s: the robot holds at (%.4f, %.4f)\n", PROG,
                  rs.have_cmd ? "EE_CMD went stale" : "no EE_CMD yet", rs.hold_pos[0],
                  rs.hold_pos[1]);
        else
          fprintf(stderr, "%s: EE_CMD %s: tracking\n", PROG, have_cmd ? "back" : "arrived");
        holding = rs.holding;
        have_cmd |= rs.have_cmd;
      }
      if (rs.resets > resets_said && ndp_mono() - reset_said_at >= 5.0) {
        fprintf(stderr, "%s: the world diverged (non-finite state): reset to the initial "
                        "state (%lld resets)\n", PROG, (long long)rs.resets);
        resets_said = rs.resets;
        reset_said_at = ndp_mono();
      }
      if (rs.slipped > slipped_said && ndp_mono() - slip_said_at >= 5.0) {
        fprintf(stderr, "%s: the world loop stalled: %lld steps dropped so far\n", PROG,
                (long long)rs.slipped);
        slipped_said = rs.slipped;
        slip_said_at = ndp_mono();
      }
      st.state = rs.holding ? "holding" : "emulating";
    }
    if (ndp_status_tick(lcm, &st, 0) < 0 && !pub_fail_said) {
      fprintf(stderr, "%s: STATUS publish failed (said once)\n", PROG);
      pub_fail_said = 1;
    }
  }

  atomic_store(&b->stop, 1);
  pthread_join(rt, NULL);
  started = 0;
  publish_ring(lcm, b, &st);
  nd_mailbox_take(&b->stats, &stats_version, &rs, sizeof(rs));
  st.state = "stopped";
  ndp_status_tick(lcm, &st, 1);
  double up = ndp_mono() - t0;
  fprintf(stderr,
          "%s: stopped after %.2f s: %lld steps (%.1f /s), %lld ROBOT_STATE, %lld MOCAP, "
          "EE_CMD %lld received %lld refused (%lld outside the workspace), period error p50 "
          "%d p99 %d max %d us, "
          "overruns %lld, dropped steps %lld, resets %lld, ring drops %llu\n",
          PROG, up, (long long)rs.steps, rs.steps / up, (long long)rs.robot_states,
          (long long)rs.mocaps, (long long)st.received, (long long)st.rejected,
          (long long)io.refused_ws.count, (int)rs.loop.p50_us,
          (int)rs.loop.p99_us, (int)rs.loop.max_us, (long long)rs.loop.overruns, (long long)rs.slipped,
          (long long)rs.resets, (unsigned long long)atomic_load(&b->out.dropped));

done:
  if (started) {
    atomic_store(&b->stop, 1);
    pthread_join(rt, NULL);
  }
  if (sub) lcm_unsubscribe(lcm, sub);
  if (lcm) lcm_destroy(lcm);
  if (b->d) mj_deleteData(b->d);
  nds_model_free(&b->nm);
  free(b);
  return status;
}
