/* ndp: what every nudge process shares: channel names, LCM set-up, clocks, signals,
 * MuJoCo error handlers and the 1 Hz status heartbeat. */
#ifndef NDP_H
#define NDP_H

#include <lcm/lcm.h>
#include <signal.h>
#include <stdint.h>
#include <string.h>

#include "nd_rtloop.h"

/* Channels (doc/design.md lists who publishes and who subscribes). */
#define NDP_CH_MOCAP "MOCAP"
#define NDP_CH_ROBOT_STATE "ROBOT_STATE"
#define NDP_CH_EE_CMD "EE_CMD"
#define NDP_CH_PLAN "PLAN"
#define NDP_CH_TASK "TASK"
#define NDP_CH_PARAMS "PARAMS"
#define NDP_CH_EPISODE "EPISODE"
#define NDP_CH_STATUS "STATUS"
#define NDP_CH_ARM_STATE "ARM_STATE"
#define NDP_CH_PLACE "PLACE"

/* Where nothing leaves the host: ttl=0 multicast on the default LCM group. */
#define NDP_DEFAULT_URL "udpm://239.255.76.67:7667?ttl=0"

/* 0, or the number of the SIGINT/SIGTERM that arrived once ndp_signals() is installed
 * (so an exit status can report it as 128 + n). */
extern volatile sig_atomic_t ndp_quit;

/* Install SIGINT/SIGTERM handlers (set ndp_quit, no SA_RESTART so waits return EINTR) and
 * ignore SIGPIPE. */
void ndp_signals(void);

/* The URL to use: url if non-NULL, else $LCM_DEFAULT_URL, else NDP_DEFAULT_URL. */
const char *ndp_url(const char *url);

/* Create an LCM instance on url. NULL with a message that says how to fix the common
 * cause (no multicast route) on failure. */
lcm_t *ndp_lcm_create(const char *url, char *err, int errlen);

/* Wall-clock time in microseconds (message utime). */
int64_t ndp_utime(void);

/* Monotonic time in seconds (loops, timeouts). */
double ndp_mono(void);

/* The ndp_mono() time at which a message stamped utime (its sender's wall clock) was sent:
 * now less its time on the way. Input freshness counts from here, not from handling: a
 * process resuming from a stall (SIGSTOP, a debugger, starvation) handles what queued up
 * meanwhile, and by handling time a state or plan a second old would look new. Needs the
 * hosts' wall clocks in sync; a sender's clock ahead of ours counts as no delay. */
double ndp_sent_mono(int64_t utime);

/* Route MuJoCo errors to stderr with the program name and exit(1) (MuJoCo's handler
 * must not return), and keep MuJoCo warnings off stdout and out of MUJOCO_LOG.TXT:
 * callers detect instabilities through mjData's warning counters. */
void ndp_mujoco_handlers(const char *prog);

/* Lower the whole process to niceness n (before its threads start: they inherit it), and
 * its autogroup when it leads its session: under autogroup scheduling (Linux's default)
 * niceness orders threads only within a session's group, and the groups share the CPU as
 * equals; nudge-up starts every process in a session of its own. Run from a shell it
 * leaves the shell's group alone. 0, or -1 with a message naming prog on stderr. */
int ndp_nice(const char *prog, int n);

/* The heartbeat every process publishes on STATUS. Counters are plain fields owned by
 * the process's main thread; a real-time process points loop at the newest statistics
 * its loop posted (nd_rtloop_stats_take). */
typedef struct {
  const char *name;
  int64_t received, published, rejected;
  const char *state;   /* short word: "running", "holding", ... */
  const nd_rtloop_stats *loop;  /* NULL: not a real-time process */
  double t0;           /* ndp_mono() at start */
  double next;         /* next publication time */
} ndp_status;

/* Start the heartbeat clock for process name. */
void ndp_status_init(ndp_status *st, const char *name);

/* Publish STATUS now if a second has passed since the last one (or force). Return 1 if
 * published, 0 if not due, -1 on a publish error. */
int ndp_status_tick(lcm_t *lcm, ndp_status *st, int force);

/* Rate-limited lines about input, refused or lost: the first NDP_RATELOG_FIRST of one kind,
 * then at most one every NDP_RATELOG_EVERY s, each with the running count, so a flood of bad
 * input cannot flood stderr. Zero-initialise one per kind; count is every event seen. */
#define NDP_RATELOG_FIRST 5
#define NDP_RATELOG_EVERY 10.0
typedef struct {
  int64_t count;
  double next;   /* ndp_mono() before which a line past the first few is suppressed */
} ndp_ratelog;

/* Count one refusal and print "<prog>: refused <what>: <why> (<count> so far)" if due. */
void ndp_refused(ndp_ratelog *rl, const char *prog, const char *what, const char *why);

/* Count one loss of input and print "<prog>: lost <what> (<count> so far)" if due. */
void ndp_lost(ndp_ratelog *rl, const char *prog, const char *what);

/* Typed input without lcm-gen's subscribe wrapper, which prints a line to stderr for each
 * message that does not decode and drops it uncounted (a flood of garbage then grows the
 * logs without bound). NDP_TYPED_HANDLER(T, name, handler, bad) defines
 * `static void name(const lcm_recv_buf_t *, const char *, void *)` for lcm_subscribe: it
 * decodes a T and calls handler(rb, channel, &msg, user) as lcm-gen's wrapper would, or,
 * when the bytes are not exactly one T, bad(user, channel, why) for the caller to count
 * and log (ndp_refused). */
#define NDP_TYPED_HANDLER(T, name, handler, bad)                                       \
  static void name(const lcm_recv_buf_t *rb_, const char *ch_, void *user_) {          \
    T m_;                                                                              \
    char why_[128];                                                                    \
    memset(&m_, 0, sizeof(m_));                                                        \
    const int st_ = T##_decode(rb_->data, 0, (int)rb_->data_size, &m_);                \
    if (ndp_decode_why(st_, (int)rb_->data_size, #T, why_, (int)sizeof(why_))) {       \
      if (st_ >= 0) T##_decode_cleanup(&m_);                                           \
      bad(user_, ch_, why_);                                                           \
      return;                                                                          \
    }                                                                                  \
    handler(rb_, ch_, &m_, user_);                                                     \
    T##_decode_cleanup(&m_);                                                           \
  }

/* NDP_INPUT(T, check, name, use, refuse) defines the lcm_subscribe callback `name` of an
 * input channel of type T: the bytes are decoded as exactly one T (NDP_TYPED_HANDLER) and
 * validated with check (ndp_validate.h's ndp_check_*); then use(user, &msg) does what the
 * process does with a valid message, or refuse(user, channel, why) counts and logs a
 * refused one. Every input message of every process passes here. */
#define NDP_INPUT(T, check, name, use, refuse)                                         \
  static void name##_valid_(const lcm_recv_buf_t *rb_, const char *ch_, const T *m_,   \
                            void *user_) {                                             \
    (void)rb_;                                                                         \
    char why_[200];                                                                    \
    if (check(m_, why_, (int)sizeof(why_)))                                            \
      refuse(user_, ch_, why_);                                                        \
    else                                                                               \
      use(user_, m_);                                                                  \
  }                                                                                    \
  NDP_TYPED_HANDLER(T, name, name##_valid_, refuse)

/* For NDP_TYPED_HANDLER: 0 when a decoder's result status consumed all size bytes, else
 * -1 with why saying so ("N bytes do not decode as T", "N bytes after a T"). */
int ndp_decode_why(int status, int size, const char *type, char *why, int len);

/* Rollout workers: one per online core. They run at normal priority; the 1 kHz loops, their
 * I/O threads and LCM's receive threads run SCHED_FIFO above them
 * (doc/decisions.md#command-sampling). */
int ndp_default_threads(void);

/* Freshness of one periodic input stream. LCM drops the newest message when a
 * subscription's queue is full, so a drain that emptied a full queue ended on an old
 * message, however fresh its handling: the stream is behind until its next message. */
typedef struct {
  int have;       /* a valid message has arrived */
  double t;       /* ndp_mono() when the newest was sent (ndp_sent_mono) */
  int cap;        /* queue capacity of its subscription */
  int batch;      /* messages handled in the current drain */
  int behind;     /* the last drain filled the queue: newer messages may have been dropped */
} ndp_input;

/* A valid message stamped utime arrived on the stream. */
void ndp_input_got(ndp_input *in, int64_t utime);

/* After a drain: return 1 if it filled the queue (the stream is then behind). */
int ndp_input_drained(ndp_input *in);

/* Heard from within timeout of now (ndp_mono), and not behind. */
int ndp_input_fresh(const ndp_input *in, double now, double timeout);

/* Drain every queued message without blocking (LCM's queues drop the newest when full). */
void ndp_drain(lcm_t *lcm);

/* Wait up to timeout_s for messages and handle what arrives, then drain. Return 0, or -1 on
 * an LCM error that is not an interrupted wait. */
int ndp_handle(lcm_t *lcm, double timeout_s);

#endif
