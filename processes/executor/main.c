/* nudge-executor: the 1 kHz trajectory executor.
 *
 * Follows the newest PLAN's first keypoint with a minimum-snap segment (core/nd_exec.h)
 * and publishes the setpoint (p, v, a) on EE_CMD every cycle; brakes to rest and holds when
 * the plan or the robot state goes stale. Two threads: the real-time loop (nd_rtloop, its
 * cycle in exec_loop.c) never allocates, locks, prints or waits on I/O; this thread owns
 * LCM (exec_io.c). The loop's one system call besides the clock is a non-blocking eventfd
 * write that wakes this thread to publish at once: polling the ring instead would add up
 * to a period of latency to every setpoint. */
#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include "exec_io.h"
#include "nd_opt.h"

#define PROG "nudge-executor"

typedef struct {
  exec_loop loop;
  int bell;            /* eventfd rung after each committed setpoint */
} exec_rt;

static void tick(void *ctx, const nd_rtloop_tick *t) {
  exec_rt *rt = ctx;
  /* The setpoint is for the instant the cycle starts (trajectory time is measured, not
   * counted in cycles). */
  if (exec_loop_cycle(&rt->loop, t->now, t->utime_now) > 0) {
    const uint64_t one = 1;  /* a full counter just means it is rung already */
    if (write(rt->bell, &one, sizeof one) < 0) {
    }
  }
}

int main(int argc, char **argv) {
  static exec_loop_io x;
  static exec_rt rt;
  static exec_io io;
  static nd_rtloop loop;
  exec_opts o = {0};
  const int st = exec_options(argc, argv, &o);
  if (st != ND_OPT_RUN) return st;
  const nd_exec_cfg cfg = o.cfg;
  const nd_rtloop_cfg rc = o.rt;
  const double timeout = o.timeout;
  const char *url = o.url;
  char err[512];
  ndp_signals();
  exec_loop_io_init(&x);
  exec_loop_init(&rt.loop, &cfg, timeout, o.plan_timeout, &x);
  io.x = &x;
  io.timeout = timeout;
  io.plan_timeout = o.plan_timeout;
  io.last.mode = -1;
  ndp_status_init(&io.st, PROG);
  io.st.state = "waiting";
  nd_rtloop_stats ls = {0};
  io.st.loop = &ls;
  char how[200];
  lcm_t *lcm = NULL;
  /* The loop first: it raises this thread to the I/O priority, and LCM's receive thread,
   * created with the LCM instance, inherits it (doc/decisions.md#command-sampling). */
  if ((rt.bell = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) < 0 ||
      nd_rtloop_start(&loop, &rc, tick, &rt, how, sizeof how, err, sizeof err) ||
      !(lcm = ndp_lcm_create(url, err, sizeof err)) ||
      exec_io_subscribe(&io, lcm, err, sizeof err)) {
    if (rt.bell < 0) snprintf(err, sizeof err, "eventfd: %s", strerror(errno));
    fprintf(stderr, PROG ": %s\n", err);
    nd_rtloop_stop(&loop);
    if (lcm) lcm_destroy(lcm);
    return 1;
  }
  fprintf(stderr,
          PROG ": rate %g Hz, timeout %g s, plan timeout %g s, v_max %g m/s, a_max %g m/s^2 "
               "(stale brake %g), j_max %g m/s^3, "
               "workspace x [%g, %g] y [%g, %g] m (+%g m for segments), lcm %s, %s\n",
          rc.rate, timeout, o.plan_timeout, cfg.v_max, cfg.a_max,
          nd_exec_stale_brake_a(&cfg), cfg.j_max,
          cfg.ws_lo[0], cfg.ws_hi[0],
          cfg.ws_lo[1], cfg.ws_hi[1], cfg.ws_margin, ndp_url(url), how);

  uint64_t v_rep = 0, v_loop = 0, drops_seen = 0;
  int pub_failing = 0, code = 0;
  struct pollfd fds[2] = {{.fd = lcm_get_fileno(lcm), .events = POLLIN},
                          {.fd = rt.bell, .events = POLLIN}};
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
    uint64_t rings;
    if (n > 0 && (fds[1].revents & POLLIN) && read(rt.bell, &rings, sizeof rings) < 0) {
    }
    const int np = exec_io_publish(&io, lcm);
    if (np < 0 && !pub_failing) fprintf(stderr, PROG ": lcm_publish of EE_CMD failed\n");
    pub_failing = np < 0;
    exec_io_report(&io, &v_rep);
    nd_rtloop_stats_take(&loop, &v_loop, &ls);
    const uint64_t drops = atomic_load(&x.ring.dropped);
    if (drops != drops_seen) {
      fprintf(stderr, PROG ": %llu setpoints dropped: publishing fell behind the loop\n",
              (unsigned long long)(drops - drops_seen));
      drops_seen = drops;
    }
    if (ndp_status_tick(lcm, &io.st, 0) < 0)
      fprintf(stderr, PROG ": lcm_publish of STATUS failed\n");
  }

  nd_rtloop_stop(&loop);
  exec_loop_report_post(&rt.loop, 0.0, 1);
  exec_io_publish(&io, lcm);
  exec_io_report(&io, &v_rep);
  nd_rtloop_stats_take(&loop, &v_loop, &ls);
  ndp_status_tick(lcm, &io.st, 1);
  const exec_loop_report *r = &io.last;
  fprintf(stderr,
          PROG ": stopped after %lld cycles, %lld setpoints; period error p50 %d us, p99 %d "
               "us, max %d us; %lld overruns (%lld deadlines skipped); %llu ring drops; "
               "max publish backlog %d; plans %lld taken (%lld re-sent the keypoint being "
               "tracked), %lld refused (%lld for the workspace), %lld stale on arrival, %lld "
               "from an outdated state; setpoint off the plan's start by %.1f mm mean, %.1f mm "
               "max\n",
          (long long)r->cycles, (long long)r->sent, ls.p50_us, ls.p99_us, ls.max_us,
          (long long)ls.overruns, (long long)ls.skipped, (unsigned long long)drops_seen,
          io.backlog_max, (long long)r->accepted, (long long)r->kept, (long long)r->refused,
          (long long)r->refused_box, (long long)r->late, (long long)io.log_old.count,
          r->accepted ? 1e3 * r->start_err_sum / r->accepted : 0.0, 1e3 * r->start_err_max);
  close(rt.bell);
  lcm_destroy(lcm);
  return code;
}
