/* ndp: shared process plumbing. */
#include "ndp.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/select.h>
#include <time.h>
#include <unistd.h>

#include <mujoco/mujoco.h>

#include "ndp_validate.h"
#include "nudge/nudge_status_t.h"

volatile sig_atomic_t ndp_quit = 0;

static void on_quit(int sig) {
  ndp_quit = sig;
}

void ndp_signals(void) {
  struct sigaction sa;
  memset(&sa, 0, sizeof(sa));
  sa.sa_handler = on_quit;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  signal(SIGPIPE, SIG_IGN);
}

const char *ndp_url(const char *url) {
  if (url && *url) return url;
  const char *env = getenv("LCM_DEFAULT_URL");
  return env && *env ? env : NDP_DEFAULT_URL;
}

lcm_t *ndp_lcm_create(const char *url, char *err, int errlen) {
  url = ndp_url(url);
  lcm_t *l = lcm_create(url);
  if (!l)
    snprintf(err, errlen,
             "cannot open LCM on '%s'. For udpm URLs this usually means there is no "
             "multicast route: run 'ip route add 224.0.0.0/4 dev lo' (as root), or set "
             "--lcm-url / LCM_DEFAULT_URL", url);
  return l;
}

int64_t ndp_utime(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

double ndp_mono(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

double ndp_sent_mono(int64_t utime) {
  const double now = ndp_mono();
  const double delay = 1e-6 * (double)(ndp_utime() - utime);
  return delay > 0.0 ? now - delay : now;
}

static const char *mj_prog = "nudge";

static void on_mj_error(const char *msg) {
  fprintf(stderr, "%s: MuJoCo error: %s\n", mj_prog, msg);
  exit(1);
}

static void on_mj_warning(const char *msg) { (void)msg; }

void ndp_mujoco_handlers(const char *prog) {
  mj_prog = prog;
  mju_user_error = on_mj_error;
  mju_user_warning = on_mj_warning;
}

void ndp_status_init(ndp_status *st, const char *name) {
  memset(st, 0, sizeof(*st));
  st->name = name;
  st->state = "starting";
  st->t0 = ndp_mono();
  st->next = st->t0;
}

int ndp_status_tick(lcm_t *lcm, ndp_status *st, int force) {
  double now = ndp_mono();
  if (!force && now < st->next) return 0;
  st->next = now + 1.0;
  nudge_status_t m;
  memset(&m, 0, sizeof(m));
  m.utime = ndp_utime();
  m.name = (char *)st->name;
  m.pid = (int32_t)getpid();
  m.state = (char *)(st->state ? st->state : "");
  m.received = st->received;
  m.published = st->published + 1;  /* counts this heartbeat */
  m.rejected = st->rejected;
  if (st->loop) {
    m.period_p50_us = st->loop->p50_us;
    m.period_p99_us = st->loop->p99_us;
    m.period_max_us = st->loop->max_us;
    m.overruns = st->loop->overruns;
  }
  m.uptime = now - st->t0;
  if (nudge_status_t_publish(lcm, NDP_CH_STATUS, &m) != 0) return -1;
  st->published++;
  return 1;
}

/* Count one event; 1 if its line is due. */
static int ratelog_due(ndp_ratelog *rl) {
  const double now = ndp_mono();
  rl->count++;
  if (rl->count > NDP_RATELOG_FIRST && now < rl->next) return 0;
  if (rl->count >= NDP_RATELOG_FIRST) rl->next = now + NDP_RATELOG_EVERY;
  return 1;
}

void ndp_refused(ndp_ratelog *rl, const char *prog, const char *what, const char *why) {
  if (ratelog_due(rl))
    fprintf(stderr, "%s: refused %s: %s (%lld so far)\n", prog, what, why, (long long)rl->count);
}

void ndp_lost(ndp_ratelog *rl, const char *prog, const char *what) {
  if (ratelog_due(rl))
    fprintf(stderr, "%s: lost %s (%lld so far)\n", prog, what, (long long)rl->count);
}

int ndp_decode_why(int status, int size, const char *type, char *why, int len) {
  if (status >= 0 && status == size) return 0;
  if (status < 0)
    snprintf(why, (size_t)len, "%d bytes do not decode as %s", size, type);
  else
    snprintf(why, (size_t)len, "%d bytes after a %s", size - status, type);
  return -1;
}

int ndp_default_threads(void) {
  long n = sysconf(_SC_NPROCESSORS_ONLN);
  return n < 1 ? 1 : (int)n;
}

void ndp_drain(lcm_t *lcm) {
  while (lcm_handle_timeout(lcm, 0) > 0) {
  }
}

int ndp_handle(lcm_t *lcm, double timeout_s) {
  int ms = (int)(timeout_s * 1e3);
  if (ms < 0) ms = 0;
  int rc = lcm_handle_timeout(lcm, ms);
  if (rc < 0 && errno != EINTR) return -1;
  if (rc > 0) ndp_drain(lcm);
  return 0;
}


void ndp_input_got(ndp_input *in, int64_t utime) {
  in->have = 1;
  in->t = ndp_sent_mono(utime);
  in->batch++;
  in->behind = 0;
}

int ndp_input_drained(ndp_input *in) {
  const int full = in->batch >= in->cap;
  if (full) in->behind = 1;
  in->batch = 0;
  return full;
}

int ndp_input_fresh(const ndp_input *in, double now, double timeout) {
  return in->have && !in->behind && now - in->t <= timeout;
}

int ndp_nice(const char *prog, int n) {
  if (setpriority(PRIO_PROCESS, 0, n)) {
    fprintf(stderr, "%s: cannot set niceness %d: %s\n", prog, n, strerror(errno));
    return -1;
  }
  FILE *f = getsid(0) == getpid() ? fopen("/proc/self/autogroup", "w") : NULL;
  if (f) {
    const int w = fprintf(f, "%d", n) < 0;
    if (fclose(f) || w) {
      fprintf(stderr, "%s: cannot set the autogroup's niceness %d: %s\n", prog, n, strerror(errno));
      return -1;
    }
  }
  return 0;
}
