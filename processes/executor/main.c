/* nudge-executor: the 1 kHz trajectory executor.
 *
 * Follows the newest PLAN's first keypoint with a minimum-snap segment (core/nd_exec.h)
 * and publishes the setpoint (p, v, a) on EE_CMD every cycle. When the plan or the
 * robot state goes stale it brakes to rest and holds; a fresh plan resumes. Every
 * setpoint names the plan it follows (plan_id, plan_utime), so a log shows that no
 * setpoint moved on a plan older than the timeout.
 *
 * Two threads. The main thread owns LCM: it validates inputs and posts the newest of
 * each kind into a mailbox, publishes what the loop left in the ring, logs, and sends the
 * heartbeat. The real-time thread sleeps to absolute deadlines, reads the mailboxes
 * without waiting, steps the executor and encodes EE_CMD into the ring: it never
 * allocates, locks, prints or waits on I/O, so a slow network or terminal cannot delay a
 * setpoint. Its one system call besides the clock is a non-blocking eventfd write that
 * wakes the main thread to publish at once: polling the ring instead would add up to a
 * period of latency to every setpoint. Everything the loop reports (mode, stale spells,
 * refused plans, jitter) goes back through a third mailbox. The cycle itself (inputs,
 * nd_exec, the ring) is exec_loop.c, so tests can run it on synthetic time; this file
 * adds its clock, the I/O thread and the command line. */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

#include "nd_exec.h"
#include "nd_jitter.h"
#include "nd_parse.h"
#include "nd_rtio.h"
#include "ndp.h"
#include "exec_loop.h"
#include "ndp_validate.h"

#define PROG "nudge-executor"
#define RT_PRIORITY 80      /* the loop */
#define IO_PRIORITY 70      /* the main thread: publishing must not starve behind batch work */
#define RT_STACK (256 * 1024)

_Static_assert(ND_MAX_KEYS == NUDGE_PLAN_T_MAX_KEYPOINTS,
               "the loop's plan carries every keypoint a PLAN can have");

/* ---- the loop ---------------------------------------------------------------------- */

/* The hand-over objects, shared by both threads. */
typedef struct {
  exec_loop_io x;   /* mailboxes and the setpoint ring (exec_loop.h) */
  int bell;            /* eventfd: the loop rings it after committing to the ring */
  atomic_int stop;
} exec_io;

/* Settings; constant once the loop runs. */
typedef struct {
  double rate;         /* Hz */
  double timeout;      /* s: inputs older than this are stale */
  nd_exec_cfg cfg;
  int rt;              /* try SCHED_FIFO and mlockall */
  const char *url;
} exec_opts;

/* The real-time thread: the loop body (exec_loop.h) plus its clock. */
typedef struct {
  exec_loop loop;
  exec_io *io;
  double rate;
} exec_thread;

static int64_t ts_ns(const struct timespec *ts) {
  return (int64_t)ts->tv_sec * 1000000000 + ts->tv_nsec;
}

static struct timespec ns_ts(int64_t ns) {
  struct timespec ts = {(time_t)(ns / 1000000000), (long)(ns % 1000000000)};
  return ts;
}

/* Wait for the deadline *next_ns, record the wake-up error and run one cycle; then
 * advance *next_ns by a period, past every deadline already missed (a late loop skips
 * cycles rather than bursting to catch up: each setpoint is computed for the time it is
 * sent anyway). */
static void exec_tick(exec_thread *t, int64_t *next_ns, int64_t period_ns) {
  exec_loop *s = &t->loop;
  struct timespec dl = ns_ts(*next_ns), now_ts;
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &dl, NULL) == EINTR) {
  }
  clock_gettime(CLOCK_MONOTONIC, &now_ts);
  /* Stamp the setpoint with the instant it is computed for, not when computing ends:
   * a plan search takes up to ~0.1 ms, and a late stamp would skew dt downstream. */
  const int64_t utime = ndp_utime();
  const int64_t woke = ts_ns(&now_ts);
  nd_jitter_add(&s->jit, 1e-3 * (double)(woke - *next_ns), 1e-3 * (double)period_ns);
  if (exec_loop_cycle(s, 1e-9 * (double)woke, utime) > 0) {
    /* Non-blocking: a full counter (never, in practice) just means it is rung already. */
    const uint64_t one = 1;
    if (write(t->io->bell, &one, sizeof one) < 0) {
    }
  }
  *next_ns += period_ns;
  clock_gettime(CLOCK_MONOTONIC, &now_ts);
  const int64_t done = ts_ns(&now_ts);
  if (done > *next_ns) {
    const int64_t skip = (done - *next_ns) / period_ns + 1;
    *next_ns += skip * period_ns;
    s->rep.missed += skip;
    s->rep.loop.overruns++;
  }
}

static void *rt_main(void *arg) {
  exec_thread *t = arg;
  const int64_t period_ns = (int64_t)llround(1e9 / t->rate);
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  int64_t next = ts_ns(&ts) + period_ns;
  while (!atomic_load_explicit(&t->io->stop, memory_order_relaxed))
    exec_tick(t, &next, period_ns);
  exec_loop_report_post(&t->loop, 1e-9 * (double)next, 1);
  return NULL;
}

/* ---- the I/O thread ------------------------------------------------------------------ */

typedef struct {
  exec_io *io;
  double timeout;
  ndp_status st;
  int backlog_max;     /* most setpoints found waiting in the ring at once */
  ndp_ratelog log_state, log_plan, log_exec;  /* refused inputs; plans nd_exec refused */
  ndp_ratelog log_box;                        /* of those: for the workspace */
  ndp_ratelog log_old;                        /* plans made from a state too old */
} io_ctx;

static void on_state(const lcm_recv_buf_t *rbuf, const char *ch,
                     const nudge_robot_state_t *msg, void *user) {
  (void)rbuf;
  (void)ch;
  io_ctx *c = user;
  char why[160];
  c->st.received++;
  if (ndp_check_robot_state(msg, why, sizeof why)) {
    c->st.rejected++;
    ndp_refused(&c->log_state, PROG, "ROBOT_STATE", why);
    return;
  }
  exec_loop_state_in in;
  in.t_arrive = ndp_sent_mono(msg->utime);
  memcpy(in.ee_pos, msg->ee_pos, sizeof in.ee_pos);
  nd_mailbox_post(&c->io->x.state, &in, (int)sizeof(in));
}

static void on_plan(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_plan_t *msg,
                    void *user) {
  (void)rbuf;
  (void)ch;
  io_ctx *c = user;
  char why[160];
  c->st.received++;
  if (ndp_check_plan(msg, why, sizeof why)) {
    c->st.rejected++;
    ndp_refused(&c->log_plan, PROG, "PLAN", why);
    return;
  }
  exec_loop_plan_in in;
  in.t_arrive = ndp_sent_mono(msg->utime);
  in.plan_id = msg->plan_id;
  in.utime = msg->utime;
  in.M = msg->M;  /* 1..MAX_KEYPOINTS: ndp_check_plan */
  memcpy(in.keys, msg->keypoints, sizeof in.keys);
  /* The planner's rollouts reach keypoint 0 at state_utime + T. The plan arrives a planning
   * time later, so the segment is shortened by that age to keep the keypoint where the
   * planner put it in time; otherwise every plan would push the target further out and a
   * robot re-planned at 10-20 Hz would creep. Wall clocks of two hosts need to be synced
   * for this (same host here); the clamp to T/2 bounds the harm of a skewed clock. */
  double age = 1e-6 * (double)(ndp_utime() - msg->state_utime);
  if (!(age > 0.0)) age = 0.0;
  /* A plan whose first keypoint was due before it arrived was made from a state the robot
   * has left (a planner stalled mid-plan, or one that planned on input it handled late):
   * even shortened, following it would move on stale information. */
  if (age > msg->T) {
    snprintf(why, sizeof why,
             "plan %lld started from a state %.0f ms old, older than its segment (%.0f ms)",
             (long long)msg->plan_id, 1e3 * age, 1e3 * msg->T);
    ndp_refused(&c->log_old, PROG, "PLAN", why);
    return;
  }
  if (age > 0.5 * msg->T) age = 0.5 * msg->T;
  in.T = msg->T - age;
  nd_mailbox_post(&c->io->x.plan, &in, (int)sizeof(in));
}

/* Bytes on ROBOT_STATE or PLAN that are not one message of the channel's type. */
static void undecodable(void *user, const char *ch, const char *why) {
  io_ctx *c = user;
  c->st.received++;
  c->st.rejected++;
  ndp_refused(strcmp(ch, NDP_CH_PLAN) ? &c->log_state : &c->log_plan, PROG, ch, why);
}

NDP_TYPED_HANDLER(nudge_robot_state_t, on_state_raw, on_state, undecodable)
NDP_TYPED_HANDLER(nudge_plan_t, on_plan_raw, on_plan, undecodable)

static void say_stale(int bits, double timeout) {
  if (bits & EXEC_STALE_STATE)
    fprintf(stderr, PROG ": stale: no ROBOT_STATE for %g s: braking to rest and holding\n",
            timeout);
  else if (bits & EXEC_STALE_NO_PLAN)
    fprintf(stderr, PROG ": robot state received: holding there until a PLAN arrives\n");
  else
    fprintf(stderr, PROG ": stale: no PLAN for %g s: braking to rest and holding\n", timeout);
}

/* Publish what the loop committed, oldest first. Return the number popped, -1 on a
 * publish error. */
static int publish_ring(lcm_t *lcm, io_ctx *c) {
  unsigned char buf[ND_RTIO_MAX];
  int tag, len, n = 0, bad = 0;
  while ((len = nd_ring_pop(&c->io->x.ring, &tag, buf, sizeof buf)) >= 0) {
    n++;
    if (tag != EXEC_LOOP_TAG_EE_CMD) continue;
    if (lcm_publish(lcm, NDP_CH_EE_CMD, buf, len) != 0) {
      bad = 1;
      continue;
    }
    c->st.published++;
  }
  /* More than one waiting means this thread fell behind the loop by that many periods. */
  if (n > c->backlog_max) c->backlog_max = n;
  return bad ? -1 : n;
}

/* ---- command line ------------------------------------------------------------------- */

static void usage(FILE *f) {
  const nd_exec_cfg d = nd_exec_cfg_default();
  fprintf(f,
          "usage: " PROG " [options]\n"
          "Follow the newest PLAN's first keypoint with a minimum-snap segment and publish\n"
          "the end-effector setpoint (p, v, a) on EE_CMD at a fixed rate. Publishes nothing\n"
          "until the first ROBOT_STATE; brakes to rest and holds while PLAN or ROBOT_STATE\n"
          "is stale; a fresh plan resumes.\n\n"
          "  --rate HZ       loop rate (default 1000)\n"
          "  --timeout S     inputs older than this are stale (default 0.1); age counts\n"
          "                  from the message's utime, so hosts need synced clocks\n"
          "  --v-max M/S     speed limit (default %g)\n"
          "  --a-max M/S2    acceleration limit (default %g)\n"
          "  --j-max M/S3    jerk limit (default %g)\n"
          "  --workspace XLO,YLO,XHI,YHI\n"
          "                  box in metres every keypoint of a PLAN must lie in; a plan\n"
          "                  with one outside, or whose segment or brake to rest would\n"
          "                  leave the box by more than %g m, is refused and counted\n"
          "                  (default %g,%g,%g,%g: nudge-planner's keypoint box,\n"
          "                  its --workspace; keep the two, and nudge-bridge's, the same:\n"
          "                  nudge-up --workspace gives all three one box)\n"
          "  --lcm-url URL   LCM URL (default: $LCM_DEFAULT_URL, else " NDP_DEFAULT_URL ")\n"
          "  --no-rt         do not ask for SCHED_FIFO and mlockall\n"
          "  -h, --help      this text\n\n"
          "Subscribes PLAN, ROBOT_STATE; publishes EE_CMD, STATUS (1 Hz).\n",
          d.v_max, d.a_max, d.j_max, d.ws_margin, d.ws_lo[0], d.ws_lo[1], d.ws_hi[0],
          d.ws_hi[1]);
}

static int bad_arg(const char *msg) {
  fprintf(stderr, PROG ": %s\n", msg);
  usage(stderr);
  return 2;
}

/* Parse argv into o. Returns -1 to go on, else the exit code. */
static int parse_args(int argc, char **argv, exec_opts *o) {
  char err[256];
  o->rate = 1000.0;
  o->timeout = 0.1;
  o->cfg = nd_exec_cfg_default();
  o->rt = 1;
  o->url = NULL;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    }
    if (!strcmp(a, "--no-rt")) {
      o->rt = 0;
      continue;
    }
    double *dst = NULL, lo = 0.0, hi = 0.0;
    if (!strcmp(a, "--rate")) dst = &o->rate, lo = 1.0, hi = 10000.0;
    else if (!strcmp(a, "--timeout")) dst = &o->timeout, lo = 1e-3, hi = 60.0;
    else if (!strcmp(a, "--v-max")) dst = &o->cfg.v_max, lo = 1e-3, hi = 10.0;
    else if (!strcmp(a, "--a-max")) dst = &o->cfg.a_max, lo = 1e-3, hi = 1000.0;
    else if (!strcmp(a, "--j-max")) dst = &o->cfg.j_max, lo = 1e-3, hi = 1e6;
    else if (strcmp(a, "--lcm-url") && strcmp(a, "--workspace")) {
      snprintf(err, sizeof err, "unknown argument '%s'", a);
      return bad_arg(err);
    }
    if (i + 1 >= argc) {
      snprintf(err, sizeof err, "%s needs a value", a);
      return bad_arg(err);
    }
    const char *v = argv[++i];
    if (!strcmp(a, "--workspace")) {
      if (ndp_parse_workspace(v, a, o->cfg.ws_lo, o->cfg.ws_hi, err, sizeof err))
        return bad_arg(err);
    } else if (!dst) {
      o->url = v;
    } else if (nd_parse_double(v, a, lo, hi, dst, err, sizeof err)) {
      return bad_arg(err);
    }
  }
  if (nd_exec_cfg_check(&o->cfg, err, sizeof err)) return bad_arg(err);
  return -1;
}

/* ---- main --------------------------------------------------------------------------- */

/* Lock memory before the loop thread exists: mlockall populates every mapping, and a
 * loop running meanwhile would stall on page faults. Say once if not locked. */
static void lock_memory(void) {
  char err[160];
  const int rc = ndp_lock_memory(err, sizeof err);
  if (rc < 0)
    fprintf(stderr, PROG ": %s; going on with pageable memory\n", err);
  else if (rc > 0)
    fprintf(stderr, PROG ": memory not locked (AddressSanitizer build)\n");
}

/* Put the loop thread t and (lower) this thread on SCHED_FIFO; say once if refused. */
static void go_realtime(pthread_t t) {
  struct sched_param sp = {.sched_priority = RT_PRIORITY};
  int rc = pthread_setschedparam(t, SCHED_FIFO, &sp);
  if (rc == 0) {
    sp.sched_priority = IO_PRIORITY;
    rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  }
  if (rc != 0)
    fprintf(stderr, PROG ": SCHED_FIFO refused (%s); running at normal priority\n",
            strerror(rc));
}

/* Print the loop's stale transitions and refused plans that are new since *last. */
static void note_report(io_ctx *c, const exec_loop_report *r, exec_loop_report *last) {
  if (r->n_stale != last->n_stale || r->n_resume != last->n_resume) {
    const int64_t flips = (r->n_stale - last->n_stale) + (r->n_resume - last->n_resume);
    if (r->stale)
      say_stale(r->stale, c->timeout);
    else
      fprintf(stderr, PROG ": fresh plan %lld: tracking again\n", (long long)r->plan_id);
    if (flips > 1)
      fprintf(stderr, PROG ": (%lld stale/fresh changes since the last report)\n",
              (long long)flips);
  }
  if (r->refused != last->refused) {
    char why[200];
    snprintf(why, sizeof why, "plan %lld: %s", (long long)r->refused_id, r->refused_why);
    /* Apart from the limits' refusals, so a planner often refused for those cannot
     * silence the first reports of plans outside the workspace. */
    ndp_refused(r->refused_rc == ND_EXEC_EBOX ? &c->log_box : &c->log_exec, PROG, "plan", why);
  }
  *last = *r;
}

int main(int argc, char **argv) {
  static exec_opts opt;
  static exec_io io;
  static exec_thread rt;
  static io_ctx c;
  char err[512];

  const int prc = parse_args(argc, argv, &opt);
  if (prc >= 0) return prc;

  ndp_signals();
  lcm_t *lcm = ndp_lcm_create(opt.url, err, sizeof err);
  if (!lcm) {
    fprintf(stderr, PROG ": %s\n", err);
    return 1;
  }

  exec_loop_io_init(&io.x);
  io.bell = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (io.bell < 0) {
    fprintf(stderr, PROG ": eventfd: %s\n", strerror(errno));
    lcm_destroy(lcm);
    return 1;
  }
  atomic_store(&io.stop, 0);
  exec_loop_init(&rt.loop, &opt.cfg, opt.timeout, &io.x);
  rt.io = &io;
  rt.rate = opt.rate;

  c.io = &io;
  c.timeout = opt.timeout;
  ndp_status_init(&c.st, PROG);
  c.st.state = "waiting";
  lcm_subscription_t *sub_state =
      lcm_subscribe(lcm, NDP_CH_ROBOT_STATE, on_state_raw, &c);
  lcm_subscription_t *sub_plan = lcm_subscribe(lcm, NDP_CH_PLAN, on_plan_raw, &c);
  if (!sub_state || !sub_plan) {
    fprintf(stderr, PROG ": cannot subscribe to " NDP_CH_ROBOT_STATE " and " NDP_CH_PLAN "\n");
    lcm_destroy(lcm);
    return 1;
  }

  fprintf(stderr,
          PROG ": rate %g Hz, timeout %g s, v_max %g m/s, a_max %g m/s^2, j_max %g m/s^3, "
               "workspace x [%g, %g] y [%g, %g] m (+%g m for segments), lcm %s, real-time %s\n",
          opt.rate, opt.timeout, opt.cfg.v_max, opt.cfg.a_max, opt.cfg.j_max,
          opt.cfg.ws_lo[0], opt.cfg.ws_hi[0], opt.cfg.ws_lo[1], opt.cfg.ws_hi[1],
          opt.cfg.ws_margin,
          ndp_url(opt.url), opt.rt ? "requested" : "off (--no-rt)");

  if (opt.rt) lock_memory();
  /* Signals go to this thread only: the loop's sleeps stay uninterrupted. */
  sigset_t block, old;
  sigemptyset(&block);
  sigaddset(&block, SIGINT);
  sigaddset(&block, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &block, &old);
  pthread_attr_t attr;
  pthread_attr_init(&attr);
  pthread_attr_setstacksize(&attr, RT_STACK);
  pthread_t tid;
  const int crc = pthread_create(&tid, &attr, rt_main, &rt);
  pthread_attr_destroy(&attr);
  pthread_sigmask(SIG_SETMASK, &old, NULL);
  if (crc != 0) {
    fprintf(stderr, PROG ": cannot start the loop thread: %s\n", strerror(crc));
    lcm_destroy(lcm);
    return 1;
  }
  if (opt.rt) go_realtime(tid);

  exec_loop_report rep, last;
  memset(&last, 0, sizeof last);
  last.mode = -1;
  ndp_loop_stats loop = {0, 0, 0, 0};
  c.st.loop = &loop;
  uint64_t v_rep = 0;
  uint64_t drops_seen = 0;
  int pub_failing = 0, code = 0;
  struct pollfd fds[2] = {{.fd = lcm_get_fileno(lcm), .events = POLLIN},
                          {.fd = io.bell, .events = POLLIN}};
  while (!ndp_quit) {
    /* Wakes for input, for each committed setpoint, and at least every 0.1 s for the
     * heartbeat and the loop's reports. */
    const int n = poll(fds, 2, 100);
    if (n < 0 && errno != EINTR) {
      fprintf(stderr, PROG ": poll: %s\n", strerror(errno));
      code = 1;
      break;
    }
    if (n > 0 && (fds[0].revents & POLLIN) && ndp_handle(lcm, 0.0) != 0) {
      fprintf(stderr, PROG ": LCM receive failed: %s\n", strerror(errno));
      code = 1;
      break;
    }
    if (n > 0 && (fds[1].revents & POLLIN)) {
      uint64_t rings;
      if (read(io.bell, &rings, sizeof rings) < 0) {
      }
    }
    const int np = publish_ring(lcm, &c);
    if (np < 0 && !pub_failing) fprintf(stderr, PROG ": lcm_publish of EE_CMD failed\n");
    pub_failing = np < 0;
    if (nd_mailbox_take(&io.x.report, &v_rep, &rep, (int)sizeof rep) == (int)sizeof rep) {
      note_report(&c, &rep, &last);
      loop = rep.loop;
      c.st.state = rep.mode < 0 ? "waiting" : nd_exec_mode_name(rep.mode);
      c.st.rejected = c.log_state.count + c.log_plan.count + c.log_old.count + rep.refused;
    }
    const uint64_t drops = atomic_load(&io.x.ring.dropped);
    if (drops != drops_seen) {
      fprintf(stderr, PROG ": %llu setpoints dropped: publishing fell behind the loop\n",
              (unsigned long long)(drops - drops_seen));
      drops_seen = drops;
    }
    if (ndp_status_tick(lcm, &c.st, 0) < 0)
      fprintf(stderr, PROG ": lcm_publish of STATUS failed\n");
  }

  atomic_store(&io.stop, 1);
  pthread_join(tid, NULL);
  publish_ring(lcm, &c);
  if (nd_mailbox_take(&io.x.report, &v_rep, &rep, (int)sizeof rep) == (int)sizeof rep) {
    loop = rep.loop;
    c.st.state = rep.mode < 0 ? "waiting" : nd_exec_mode_name(rep.mode);
    c.st.rejected = c.log_state.count + c.log_plan.count + c.log_old.count + rep.refused;
    last = rep;
  }
  ndp_status_tick(lcm, &c.st, 1);
  fprintf(stderr,
          PROG ": stopped after %lld cycles, %lld setpoints; period error p50 %d us, p99 %d "
               "us, max %d us; %lld overruns (%lld deadlines skipped); %llu ring drops; "
               "max publish backlog %d; plans %lld taken (%lld re-sent the keypoint being "
               "tracked), %lld refused (%lld for the workspace), %lld stale on arrival, %lld "
               "from an outdated state\n",
          (long long)last.cycles, (long long)last.sent, loop.p50_us, loop.p99_us,
          loop.max_us, (long long)loop.overruns, (long long)last.missed,
          (unsigned long long)drops_seen, c.backlog_max, (long long)last.accepted,
          (long long)last.kept, (long long)last.refused, (long long)last.refused_box,
          (long long)last.late,
          (long long)c.log_old.count);
  close(io.bell);
  lcm_unsubscribe(lcm, sub_state);
  lcm_unsubscribe(lcm, sub_plan);
  lcm_destroy(lcm);
  return code;
}
