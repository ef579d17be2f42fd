/* nd_rtloop: a periodic real-time thread on absolute deadlines (clock_nanosleep,
 * TIMER_ABSTIME), the one loop of the 1 kHz processes (executor, bridge).
 *
 * The thread calls the caller's cycle function once per deadline. After an overrun (a
 * wake-up a period or more late) it either skips the missed deadlines (ND_RT_SKIP: a
 * setpoint is computed for the instant it is sent anyway) or runs one cycle for each, up
 * to catch_up_max, and lets real time slip beyond (ND_RT_CATCH_UP: a simulated world keeps
 * its time equal to real time; a longer stall would replay seconds in a burst). The
 * thread owns its jitter histogram and hands statistics to other threads through a
 * mailbox; the loop itself never allocates, locks or does I/O. */
#ifndef ND_RTLOOP_H
#define ND_RTLOOP_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>

#include "nd_jitter.h"
#include "nd_rtio.h"

enum { ND_RT_SKIP = 0, ND_RT_CATCH_UP = 1 };

typedef struct {
  double rate;          /* Hz, in [1, 10000] */
  int policy;           /* ND_RT_SKIP or ND_RT_CATCH_UP */
  int catch_up_max;     /* CATCH_UP: most cycles run in one wake-up */
  int priority;         /* SCHED_FIFO priority of the loop thread, 1..99; 0: normal */
  int io_priority;      /* SCHED_FIFO priority of the calling thread (publishing must not
                           starve behind batch work), below priority; 0: leave it */
  int lock_memory;      /* mlockall before the thread starts (no page faults in the loop) */
} nd_rtloop_cfg;

/* 1 kHz, skip, SCHED_FIFO 80 for the loop and 70 for the caller, memory locked. */
void nd_rtloop_cfg_default(nd_rtloop_cfg *cfg);

/* What one cycle is for. */
typedef struct {
  double deadline;      /* monotonic s: the deadline this cycle serves */
  double now;           /* monotonic s: when the cycle started */
  int64_t utime;        /* wall-clock us of deadline */
  int64_t utime_now;    /* wall-clock us of now: the same instant as now, through an offset
                         * between the clocks measured outside the cycles, so a preemption
                         * between two clock reads cannot stamp a setpoint with another
                         * time than it is for (doc/decisions.md#command-sampling) */
  int64_t wake_utime;   /* wall-clock us of the wake-up: utime_now of its first cycle */
  int catching_up;      /* 1 for the extra cycles of a CATCH_UP wake-up */
} nd_rtloop_tick;

typedef void (*nd_rtloop_fn)(void *ctx, const nd_rtloop_tick *tick);

/* The loop's statistics, as the thread posts them (every 0.1 s and at its end). */
typedef struct {
  int64_t cycles;       /* cycle calls */
  int64_t overruns;     /* wake-ups a period or more late */
  int64_t skipped;      /* deadlines that got no cycle (SKIP: missed; CATCH_UP: beyond max) */
  int32_t p50_us, p99_us, max_us;  /* wake-up error */
} nd_rtloop_stats;

typedef struct {
  nd_rtloop_cfg cfg;
  nd_rtloop_fn fn;
  void *ctx;
  pthread_t thread;
  int running;
  atomic_int stop;
  nd_mailbox stats;     /* loop thread -> anyone */
  nd_jitter jit;        /* loop thread only */
  nd_rtloop_stats st;   /* loop thread only; posted copies in stats */
  int64_t wall_off_ns;  /* loop thread only: wall clock less monotonic clock, as stamped
                           (nd_rtloop_slew) */
} nd_rtloop;

/* Lock memory (if asked), start the loop thread on cfg (SCHED_FIFO if allowed, else normal
 * priority, said in how: "SCHED_FIFO 80, memory locked"), with SIGINT/SIGTERM blocked in
 * it so its sleeps run to their deadlines. Return 0, or -1 with a message (no thread). */
int nd_rtloop_start(nd_rtloop *l, const nd_rtloop_cfg *cfg, nd_rtloop_fn fn, void *ctx,
                    char *how, int howlen, char *err, int errlen);

/* Stop the loop after its current cycle and join it (a no-op if not running). */
void nd_rtloop_stop(nd_rtloop *l);

/* The newest statistics posted, if newer than *version. Return 1 if taken, else 0. */
int nd_rtloop_stats_take(nd_rtloop *l, uint64_t *version, nd_rtloop_stats *out);

/* Run the schedule for one wake-up at monotonic time now_ns with *next_ns the earliest
 * deadline not yet served: the cycles due, then *next_ns past them. The thread's body,
 * exposed so a test can drive the policies on synthetic time. */
void nd_rtloop_wake(nd_rtloop *l, int64_t *next_ns, int64_t now_ns, int64_t utime_now);

/* How the stamps follow the wall clock. Each loop measures the wall clock's offset from
 * the monotonic clock once a second, each at its own instant. A change of the offset
 * (an NTP step, a virtual machine's clock corrected after a pause) below
 * ND_RTLOOP_STEP_NS is slewed in at ND_RTLOOP_SLEW_PPM, so two loops never disagree by a
 * step: the robot samples the executor's commands at its stamp less theirs, and a step
 * of d between them moves its setpoint by v d in one cycle (doc/decisions.md#clock-slew).
 * A larger change is taken at once (a commander that far off is held as late). */
#define ND_RTLOOP_SLEW_PPM 500
#define ND_RTLOOP_STEP_NS 20000000

/* The offset one wake-up of period_ns on: off moved toward target by at most
 * ND_RTLOOP_SLEW_PPM of period_ns, or target if they differ by ND_RTLOOP_STEP_NS or more. */
int64_t nd_rtloop_slew(int64_t off, int64_t target, int64_t period_ns);

/* 1 when this is an AddressSanitizer build: its runtime ignores mlockall (and locking its
 * shadow memory could not work), so callers say memory is not locked. */
int nd_rtloop_asan(void);

#endif
