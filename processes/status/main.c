/* nudge-status: print the heartbeats on STATUS, one line each, or wait for one process's
 * first heartbeat (the supervisor's readiness check). A tool, not a member of the system:
 * it publishes nothing, so it never shows up in its own listing. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_parse.h"
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

static void usage(FILE *f) {
  fprintf(f,
          "usage: " PROG " [options]\n"
          "Print every heartbeat on STATUS as one line: name pid state counters period stats.\n\n"
          "  --wait NAME      print nothing; exit 0 as soon as a heartbeat of NAME arrives,\n"
          "                   1 if none within --timeout (default 10 s)\n"
          "  --pid PID        with --wait: the heartbeat must come from this pid\n"
          "  --timeout S      stop after S s (print mode: exit 0; default: until SIGINT)\n"
          "  --count N        print mode: exit after N heartbeats\n"
          "  --lcm-url URL    default $LCM_DEFAULT_URL, else " NDP_DEFAULT_URL "\n"
          "  -h, --help       this text\n");
}

int main(int argc, char **argv) {
  char err[512];
  status_cfg c = {NULL, 0, -1.0, 0, NULL};
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    }
    int rc = 0;
    if (strcmp(a, "--wait") && strcmp(a, "--pid") && strcmp(a, "--timeout") &&
        strcmp(a, "--count") && strcmp(a, "--lcm-url")) {
      snprintf(err, sizeof(err), "unknown argument: %s", a);
      rc = -1;
    } else if (i + 1 >= argc) {
      snprintf(err, sizeof(err), "%s needs a value", a);
      rc = -1;
    } else {
      const char *v = argv[++i];
      if (!strcmp(a, "--wait")) {
        c.wait_name = v;
        if (!*v) {
          snprintf(err, sizeof(err), "--wait: empty name");
          rc = -1;
        }
      } else if (!strcmp(a, "--pid")) {
        rc = nd_parse_int(v, "--pid", 1, 0x7fffffff, &c.pid, err, sizeof(err));
      } else if (!strcmp(a, "--timeout")) {
        rc = nd_parse_double(v, "--timeout", 0.0, 1e6, &c.timeout, err, sizeof(err));
      } else if (!strcmp(a, "--count")) {
        rc = nd_parse_int(v, "--count", 1, 0x7fffffff, &c.count, err, sizeof(err));
      } else {
        c.url = v;
      }
    }
    if (rc) {
      fprintf(stderr, PROG ": %s\n", err);
      usage(stderr);
      return 2;
    }
  }
  if (c.pid && !c.wait_name) {
    fprintf(stderr, PROG ": --pid needs --wait NAME\n");
    usage(stderr);
    return 2;
  }
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
