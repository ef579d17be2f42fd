/* nudge-status: print the heartbeats on STATUS, one line each, or wait for one process's
 * first heartbeat (the supervisor's readiness check). A tool, not a member of the system:
 * it publishes nothing, so it never shows up in its own listing. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_opt.h"
#include "ndp.h"
#include "ndp_validate.h"

#define PROG "nudge-status"
#define MAX_TEXT 64 /* status_t: name and state are short */

typedef struct {
  const char *wait_name; /* NULL: print every heartbeat */
  int pid;               /* 0: any */
  double timeout;        /* s; < 0: no limit */
  int count;             /* print mode: stop after this many lines; 0: no limit */
  const char *url;
} status_cfg;

typedef struct {
  const status_cfg *c;
  int matched; /* wait mode: the awaited heartbeat arrived */
  int printed;
  int64_t refused;
} status_io;

/* Heartbeats are not checked by ndp_validate (nobody acts on them); refuse only what would
 * print badly. */
static int status_ok(const nudge_status_t *m) {
  if (m->utime <= 0 || !m->name || !m->state) return 0;
  if (strnlen(m->name, MAX_TEXT) >= MAX_TEXT || strnlen(m->state, MAX_TEXT) >= MAX_TEXT)
    return 0;
  for (const char *s = m->name; *s; s++)
    if ((unsigned char)*s < 0x20) return 0;
  for (const char *s = m->state; *s; s++)
    if ((unsigned char)*s < 0x20) return 0;
  return 1;
}

static void show_status(status_io *io, const nudge_status_t *m) {
  if (!status_ok(m)) {
    if (io->refused++ < 3) fprintf(stderr, PROG ": ignored a malformed heartbeat\n");
    return;
  }
  if (io->c->wait_name) {
    if (!strcmp(m->name, io->c->wait_name) && (!io->c->pid || m->pid == io->c->pid))
      io->matched = 1;
    return;
  }
  printf("%-16s pid %-7d %-10s recv %lld pub %lld rej %lld", m->name, m->pid, m->state,
         (long long)m->received, (long long)m->published, (long long)m->rejected);
  if (m->period_p50_us || m->period_p99_us || m->period_max_us || m->overruns)
    printf("  period err p50 %d us p99 %d us max %d us overruns %lld", m->period_p50_us,
           m->period_p99_us, m->period_max_us, (long long)m->overruns);
  printf("  up %.1f s\n", m->uptime);
  fflush(stdout);
  io->printed++;
}

/* Raw subscription: lcm-gen's stub would decode a lying string length and crash
 * (ndp_decode_status). */
static void on_status(const lcm_recv_buf_t *rbuf, const char *ch, void *user) {
  (void)ch;
  status_io *io = user;
  nudge_status_t msg;
  char why[160];
  if (ndp_decode_status(rbuf->data, (int)rbuf->data_size, &msg, why, sizeof(why))) {
    if (io->refused++ < 3) fprintf(stderr, PROG ": ignored a malformed heartbeat: %s\n", why);
    return;
  }
  show_status(io, &msg);
  nudge_status_t_decode_cleanup(&msg);
}

int main(int argc, char **argv) {
  char err[512];
  status_cfg c = {NULL, 0, -1.0, 0, NULL};
  nd_opt opts[] = {
      {"wait", ND_OPT_STRING, &c.wait_name, .arg = "NAME",
       .help = "print nothing; exit 0 as soon as a heartbeat of NAME arrives, 1 if none "
               "within --timeout"},
      {"pid", ND_OPT_INT, &c.pid, 1, 0x7fffffff, .arg = "PID", .def = "",
       .help = "with --wait: the heartbeat must come from this pid"},
      {"timeout", ND_OPT_DOUBLE, &c.timeout, 0.0, 1e6, .arg = "S",
       .def = "10 with --wait, else until SIGINT", .help = "stop after S s (print mode: exit 0)"},
      {"count", ND_OPT_INT, &c.count, 1, 0x7fffffff, .def = "",
       .help = "print mode: exit after N heartbeats"},
      {"lcm-url", ND_OPT_STRING, &c.url, .arg = "URL", .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL,
       .help = "LCM URL"},
  };
  nd_opt_spec spec = {PROG, "[options]",
                      "Print every heartbeat on STATUS as one line: name pid state counters "
                      "period stats.",
                      NULL, opts, sizeof(opts) / sizeof(opts[0])};
  const int rc = nd_opt_parse(&spec, argc, argv);
  if (rc != ND_OPT_RUN) return rc;
  if (c.pid && !c.wait_name) return nd_opt_fail(&spec, "--pid needs --wait NAME");
  if (c.wait_name && c.timeout < 0.0) c.timeout = 10.0;

  ndp_signals();
  lcm_t *lcm = ndp_lcm_create(c.url, err, sizeof(err));
  if (!lcm) {
    fprintf(stderr, PROG ": %s\n", err);
    return 1;
  }
  status_io io = {&c, 0, 0, 0};
  lcm_subscription_t *sub = lcm_subscribe(lcm, NDP_CH_STATUS, on_status, &io);
  const double t_end = c.timeout >= 0.0 ? ndp_mono() + c.timeout : 0.0;
  int status = 0;
  while (!ndp_quit && !io.matched && !(c.count && io.printed >= c.count)) {
    double dt = 0.1;
    if (c.timeout >= 0.0) {
      const double left = t_end - ndp_mono();
      if (left <= 0.0) break;
      if (left < dt) dt = left;
    }
    if (ndp_handle(lcm, dt)) {
      fprintf(stderr, PROG ": LCM failed while receiving\n");
      status = 1;
      break;
    }
  }
  if (c.wait_name && !io.matched && status == 0) {
    if (ndp_quit) {
      status = 1;
    } else if (c.pid) {
      fprintf(stderr, PROG ": no heartbeat from %s (pid %d) within %g s\n", c.wait_name, c.pid,
              c.timeout);
      status = 1;
    } else {
      fprintf(stderr, PROG ": no heartbeat from %s within %g s\n", c.wait_name, c.timeout);
      status = 1;
    }
  }
  lcm_unsubscribe(lcm, sub);
  lcm_destroy(lcm);
  return status;
}
