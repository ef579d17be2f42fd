/* nd_rtloop: the deadline loop, its overrun policies and its real-time set-up. */
#define _GNU_SOURCE
#include "nd_rtloop.h"

#include <errno.h>
#include <math.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

#define STATS_PERIOD_NS 100000000  /* the loop posts its statistics every 0.1 s */
#define STACK (256 * 1024)

/* GCC says __SANITIZE_ADDRESS__, clang __has_feature(address_sanitizer). */
#if defined(__SANITIZE_ADDRESS__)
#define ND_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define ND_ASAN 1
#endif
#endif

int nd_rtloop_asan(void) {
#ifdef ND_ASAN
  return 1;
#else
  return 0;
#endif
}

void nd_rtloop_cfg_default(nd_rtloop_cfg *cfg) {
  cfg->rate = 1000.0;
  cfg->policy = ND_RT_SKIP;
  cfg->catch_up_max = 20;
  cfg->priority = 80;
  cfg->io_priority = 70;
  cfg->lock_memory = 1;
}

static int64_t ts_ns(const struct timespec *t) {
  return (int64_t)t->tv_sec * 1000000000 + t->tv_nsec;
}

static int64_t mono_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return ts_ns(&t);
}

/* Wall clock less monotonic clock, ns: of a few paired reads the tightest, so a preemption
 * between two reads does not enter it. */
static int64_t wall_offset_ns(void) {
  int64_t best_gap = INT64_MAX, off = 0;
  for (int i = 0; i < 5; i++) {
    struct timespec w;
    const int64_t m0 = mono_ns();
    clock_gettime(CLOCK_REALTIME, &w);
    const int64_t m1 = mono_ns();
    if (m1 - m0 < best_gap) best_gap = m1 - m0, off = ts_ns(&w) - (m0 + (m1 - m0) / 2);
  }
  return off;
}

int64_t nd_rtloop_slew(int64_t off, int64_t target, int64_t period_ns) {
  const int64_t d = target - off, slew_ns = period_ns * ND_RTLOOP_SLEW_PPM / 1000000;
  if (d >= ND_RTLOOP_STEP_NS || d <= -ND_RTLOOP_STEP_NS) return target;
  if (d > slew_ns) return off + slew_ns;
  if (d < -slew_ns) return off - slew_ns;
  return target;
}

static void post(nd_rtloop *l) {
  l->st.p50_us = (int32_t)nd_jitter_quantile(&l->jit, 0.5);
  l->st.p99_us = (int32_t)nd_jitter_quantile(&l->jit, 0.99);
  l->st.max_us = (int32_t)l->jit.max_us;
  l->st.overruns = l->jit.overruns;
  nd_mailbox_post(&l->stats, &l->st, sizeof(l->st));
}

void nd_rtloop_wake(nd_rtloop *l, int64_t *next_ns, int64_t now_ns, int64_t utime_now) {
  const int64_t period = (int64_t)llround(1e9 / l->cfg.rate);
  const int64_t late = now_ns - *next_ns;
  nd_jitter_add(&l->jit, 1e-3 * (double)late, 1e-3 * (double)period);
  int64_t due = late > 0 ? 1 + late / period : 1;
  int64_t run = 1;
  if (l->cfg.policy == ND_RT_CATCH_UP) run = due < l->cfg.catch_up_max ? due : l->cfg.catch_up_max;
  /* The cycles served are the newest run of the due deadlines: skipped ones are the oldest. */
  const int64_t first = *next_ns + (due - run) * period;
  l->st.skipped += due - run;
  nd_rtloop_tick tk;
  tk.wake_utime = utime_now;
  for (int64_t k = 0; k < run; k++) {
    const int64_t dl = first + k * period;
    tk.deadline = 1e-9 * (double)dl;
    tk.utime = utime_now - (now_ns - dl) / 1000;
    tk.catching_up = k + 1 < run;
    const int64_t t_ns = k ? mono_ns() : now_ns;
    tk.now = 1e-9 * (double)t_ns;
    tk.utime_now = k ? utime_now + (t_ns - now_ns) / 1000 : utime_now;
    l->fn(l->ctx, &tk);
    l->st.cycles++;
  }
  const int64_t prev = *next_ns;
  *next_ns += due * period;
  if (prev / STATS_PERIOD_NS != *next_ns / STATS_PERIOD_NS) post(l);
}

static void *loop_main(void *arg) {
  nd_rtloop *l = arg;
  const int64_t period = (int64_t)llround(1e9 / l->cfg.rate);
  int64_t next = mono_ns() + period, target = wall_offset_ns();
  int64_t resync = next + 1000000000;
  l->wall_off_ns = target;
  while (!atomic_load_explicit(&l->stop, memory_order_relaxed)) {
    /* The clocks' offset, again once a second: the wall clock may be slewed or stepped. */
    if (next >= resync) target = wall_offset_ns(), resync = next + 1000000000;
    l->wall_off_ns = nd_rtloop_slew(l->wall_off_ns, target, period);
    const struct timespec dl = {(time_t)(next / 1000000000), (long)(next % 1000000000)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &dl, NULL) == EINTR) {
    }
    /* Stamp the cycle with the instant it starts, not when computing ends. */
    const int64_t now = mono_ns();
    nd_rtloop_wake(l, &next, now, (now + l->wall_off_ns) / 1000);
  }
  post(l);
  return NULL;
}

int nd_rtloop_start(nd_rtloop *l, const nd_rtloop_cfg *cfg, nd_rtloop_fn fn, void *ctx,
                    char *how, int howlen, char *err, int errlen) {
  if (!(cfg->rate >= 1.0 && cfg->rate <= 10000.0) || cfg->catch_up_max < 1 ||
      cfg->priority < 0 || cfg->priority > 99 || cfg->io_priority < 0 ||
      cfg->io_priority > 99) {
    snprintf(err, errlen, "real-time loop: rate %g Hz, catch-up %d, priorities %d/%d out of "
             "range", cfg->rate, cfg->catch_up_max, cfg->priority, cfg->io_priority);
    return -1;
  }
  memset(l, 0, sizeof(*l));
  l->cfg = *cfg;
  l->fn = fn;
  l->ctx = ctx;
  atomic_init(&l->stop, 0);
  nd_mailbox_init(&l->stats);
  nd_jitter_reset(&l->jit);

  /* Before the thread exists: mlockall populates every mapping, and a loop running
   * meanwhile would stall on page faults. */
  const char *mem = "memory not locked";
  char why[160] = "";
  if (cfg->lock_memory) {
    if (nd_rtloop_asan()) mem = "memory not locked (AddressSanitizer build)";
    else if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) mem = "memory locked";
    else snprintf(why, sizeof why, "; mlockall refused (%s)", strerror(errno));
  }

  sigset_t block, old;
  sigemptyset(&block);
  sigaddset(&block, SIGINT);
  sigaddset(&block, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &block, &old);
  pthread_attr_t at;
  pthread_attr_init(&at);
  pthread_attr_setstacksize(&at, STACK);
  int rc = EPERM;
  if (cfg->priority > 0) {
    struct sched_param sp = {.sched_priority = cfg->priority};
    pthread_attr_setinheritsched(&at, PTHREAD_EXPLICIT_SCHED);
    pthread_attr_setschedpolicy(&at, SCHED_FIFO);
    pthread_attr_setschedparam(&at, &sp);
    rc = pthread_create(&l->thread, &at, loop_main, l);
  }
  const int fifo = rc == 0;
  if (!fifo) {
    if (cfg->priority > 0) snprintf(why + strlen(why), sizeof why - strlen(why),
                                    "; SCHED_FIFO refused (%s)", strerror(rc));
    pthread_attr_setinheritsched(&at, PTHREAD_INHERIT_SCHED);
    rc = pthread_create(&l->thread, &at, loop_main, l);
  }
  pthread_attr_destroy(&at);
  pthread_sigmask(SIG_SETMASK, &old, NULL);
  if (rc != 0) {
    snprintf(err, errlen, "cannot start the real-time thread: %s", strerror(rc));
    return -1;
  }
  l->running = 1;
  if (fifo && cfg->io_priority > 0) {
    struct sched_param sp = {.sched_priority = cfg->io_priority};
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  }
  if (fifo) snprintf(how, howlen, "SCHED_FIFO %d, %s%s", cfg->priority, mem, why);
  else snprintf(how, howlen, "normal priority, %s%s", mem, why);
  return 0;
}

void nd_rtloop_stop(nd_rtloop *l) {
  if (!l->running) return;
  atomic_store(&l->stop, 1);
  pthread_join(l->thread, NULL);
  l->running = 0;
}

int nd_rtloop_stats_take(nd_rtloop *l, uint64_t *version, nd_rtloop_stats *out) {
  return nd_mailbox_take(&l->stats, version, out, sizeof(*out)) == (int)sizeof(*out);
}
