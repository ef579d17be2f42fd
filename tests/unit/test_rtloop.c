/* test_rtloop: the executor's 1 kHz cycle (processes/executor/exec_loop.c) allocates
 * nothing and makes no blocking call, through every path it has (counted by rt_count.h's
 * wrappers), and the real-time loop's overrun policies (core/nd_rtloop.c) on synthetic
 * time.
 *
 * One window spans 100k+ cycles on synthetic time, through the first robot state, plan
 * switches at 20 Hz, plans stretched by the limits and plans refused by them, a stale plan
 * (brake, hold), a stale robot state (brake, hold, plans kept waiting), plans refused for
 * a keypoint outside the workspace, and a consumer that stops draining the ring until it
 * is full. The count over the window must be exactly 0. That the count can fail is checked
 * first: mallocs, a free and a write made inside a window, from this file and from inside
 * nd_core, are all seen. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "nd_test.h"
#include "rt_count.h"
#include "nd_exec.h"
#include "nd_math.h"
#include "nd_rng.h"
#include "nd_rollout.h"
#include "exec_loop.h"
#include "nd_rtloop.h"
#include "nudge/nudge_ee_cmd_t.h"

/* ---- the counter sees what it should ---------------------------------------------------- */

static void *volatile g_sink;  /* keeps the compiler from dropping a malloc/free pair */

static void test_counter_sees_calls(void **state) {
  (void)state;
  window_open();
  g_sink = malloc(40);
  free(g_sink);
  const long here = g_count[C_MALLOC];
  /* From inside a static library: nd_core's own allocations are rewritten too. */
  const long before_lib = window_sum(0, N_ALLOC_FN);
  nd_rollout r;
  assert_int_equal(nd_rollout_alloc(&r, 16), 0);
  const long lib = window_sum(0, N_ALLOC_FN) - before_lib;
  nd_rollout_free(&r);
  const int fd = open("/dev/null", O_WRONLY | O_CLOEXEC);
  const ssize_t w = write(fd, "x", 1);
  window_close();
  close(fd);
  char seen[256];
  window_list(seen, sizeof seen, 0, N_FN);
  printf("rtloop_selfcheck_seen: %s\n", seen);
  assert_int_equal(w, 1);
  assert_int_equal(here, 1);
  assert_true(lib >= 1);
  assert_true(g_count[C_FREE] >= 2);
  assert_int_equal(g_count[C_WRITE], 1);
  /* Outside a window nothing is counted. */
  const long before = window_sum(0, N_FN);
  g_sink = malloc(8);
  free(g_sink);
  assert_int_equal(window_sum(0, N_FN), before);
}

/* ---- the loop on synthetic time --------------------------------------------------------- */

#define DT 1e-3
#define T0 1000.0               /* s, the synthetic monotonic clock's start */
#define U0 1700000000000000LL   /* us, wall clock at T0 */
#define EPISODE 4000            /* cycles of one round of the scenario below */
#define EPISODES 26             /* 104k cycles */
#define PRE 50                  /* cycles before the first robot state */

/* One round, in cycles from its start: plans at 20 Hz with robot state at 1 kHz; then no
 * plan (stale plan: brake, hold); plans again; then no robot state (stale state: brake,
 * hold, the plans that keep coming wait); then the consumer stops draining (ring full). */
enum { PH_PLAN_STALE = 1500, PH_PLAN_BACK = 2200, PH_STATE_STALE = 2700,
       PH_STATE_BACK = 3400, PH_NO_DRAIN = 3500, PH_DRAIN = 3900 };

/* What the window saw; asserted after it closes (no cmocka call inside). */
typedef struct {
  long cycles, ret_none, ret_sent, ret_full;
  long popped, decode_bad, seq_gaps;
  long plans_posted, plans_far, plans_bad, plans_out, stretched;
  long plans_late;                       /* sent LATE_S ago, taken while the state is live */
  long track_no_plan, track_old_plan;    /* tracking setpoints naming no plan / a stale one */
  double plan_age_max;                   /* s, oldest plan a tracking setpoint named */
  long over_v, over_a, step_p, step_v;   /* limit or continuity violations */
  long hold_moved;                       /* a HOLD setpoint that moved or was not still */
  long hold_at_plan_stale, hold_at_state_stale, checks_plan_stale, checks_state_stale;
  long resumed;                          /* tracking again after a stale spell */
  double peak_v, peak_a;                 /* max |v| / v_max, |a| / a_max */
  double t_cycle_max;                    /* s, one cycle's longest run (figure only) */
  double t_cycles;                       /* s, all cycles */
  exec_loop_report rep;               /* the newest report taken */
  int stale_bits_seen;                   /* union of the reports' stale bits */
} run_stats;

static double mono(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#define TIMEOUT 0.1             /* s, the executor's default input timeout */
#define LATE_S 0.5              /* s, how long ago a late plan was sent */

/* Every 13th plan was sent LATE_S ago: what an executor resuming from a stall finds
 * queued. The loop must drop it (counted as late), never follow it. */
static int plan_is_late(long k) { return k % 13 == 0; }

/* A plan toward a keypoint near p: mostly reachable ones (T 0.3 s, as the planner's),
 * every 7th far and fast to do (the limits stretch it), every 11th faster than v_max at
 * the keypoint (refused), every 17th with its second keypoint outside the workspace
 * (refused); late ones are reachable. */
static void make_plan(nd_rng *r, long k, const double p[2], const nd_exec_cfg *cfg,
                      exec_loop_plan_in *pl, run_stats *st) {
  const double dir = 2.0 * ND_PI * nd_rng_uniform(r);
  double reach = 0.1 * nd_rng_uniform(r), speed = 0.3 * cfg->v_max * nd_rng_uniform(r);
  pl->T = 0.3;
  if (plan_is_late(k)) {
  } else if (k % 11 == 0) {
    speed = 1.5 * cfg->v_max;
    st->plans_bad++;
  } else if (k % 7 == 0) {
    reach = 0.4;
    pl->T = 0.05;
    st->plans_far++;
  }
  for (int ax = 0; ax < 2; ax++) {
    const double c = ax ? sin(dir) : cos(dir);
    double x = p[ax] + reach * c;
    if (x > 0.5) x = 0.5;
    if (x < -0.5) x = -0.5;
    pl->keys[0][ax] = x;
    pl->keys[0][2 + ax] = speed * c;
  }
  pl->M = 2;
  memcpy(pl->keys[1], pl->keys[0], sizeof pl->keys[1]);
  if (!plan_is_late(k) && k % 11 && k % 7 && k % 17 == 0) {
    pl->keys[1][0] = 0.8;
    st->plans_out++;
  }
  pl->plan_id = k;
  st->plans_posted++;
}

/* Consume one setpoint from the ring as the I/O thread would, and check it against the
 * limits and against the previous one. */
static void check_setpoint(const unsigned char *buf, int len, const nd_exec_cfg *cfg,
                           nudge_ee_cmd_t *prev, int *have_prev, run_stats *st) {
  nudge_ee_cmd_t m;
  if (nudge_ee_cmd_t_decode(buf, 0, len, &m) != len) {
    st->decode_bad++;
    return;
  }
  st->popped++;
  const double v = hypot(m.v[0], m.v[1]), a = hypot(m.a[0], m.a[1]);
  if (v > cfg->v_max * (1 + 1e-9)) st->over_v++;
  if (a > cfg->a_max * (1 + 1e-9)) st->over_a++;
  if (v / cfg->v_max > st->peak_v) st->peak_v = v / cfg->v_max;
  if (a / cfg->a_max > st->peak_a) st->peak_a = a / cfg->a_max;
  if (m.mode == ND_EXEC_HOLD && (v != 0.0 || a != 0.0)) st->hold_moved++;
  if (m.mode == ND_EXEC_TRACK) {
    /* Tracking names its plan, and that plan is at most the timeout old (+ a period). */
    const double age = 1e-6 * (double)(m.utime - m.plan_utime);
    if (m.plan_utime <= 0 || m.plan_id < 0) st->track_no_plan++;
    else if (age > TIMEOUT + DT) st->track_old_plan++;
    if (m.plan_utime > 0 && age > st->plan_age_max) st->plan_age_max = age;
  }
  if (*have_prev && m.seq == prev->seq + 1) {
    const double dp = hypot(m.p[0] - prev->p[0], m.p[1] - prev->p[1]);
    const double dv = hypot(m.v[0] - prev->v[0], m.v[1] - prev->v[1]);
    if (dp > cfg->v_max * DT * (1 + 1e-6)) st->step_p++;
    if (dv > cfg->a_max * DT * (1 + 1e-6)) st->step_v++;
    if (m.mode == ND_EXEC_HOLD && prev->mode == ND_EXEC_HOLD &&
        (m.p[0] != prev->p[0] || m.p[1] != prev->p[1]))
      st->hold_moved++;
  } else if (*have_prev) {
    st->seq_gaps++;
  }
  *prev = m;
  *have_prev = 1;
}

/* Run the scenario; everything between window_open and window_close is what a 1 kHz
 * cycle and its I/O thread do, on one thread and a synthetic clock. */
static void run_scenario(exec_loop *s, exec_loop_io *io, const nd_exec_cfg *cfg,
                         run_stats *st) {
  nd_rng rng;
  nd_rng_seed(&rng, 5, 0);
  nudge_ee_cmd_t prev;
  memset(&prev, 0, sizeof prev);
  int have_prev = 0, was_stale = 0;
  uint64_t v_rep = 0;
  long plan_k = 1;
  double last_p[2] = {0.0, 0.0};
  double t_state = -1e9;        /* send time of the newest robot state posted */
  const long total = PRE + (long)EPISODES * EPISODE;

  window_open();
  for (long k = 0; k < total; k++) {
    const double now = T0 + DT * (double)k;
    const int64_t utime = U0 + 1000 * k;
    const long e = k < PRE ? -1 : (k - PRE) % EPISODE;

    /* The I/O thread's side: a robot state every ms (it arrived 0.2 ms ago), a plan
     * every 50 ms, each posted only in the phases that have them. */
    const int state_on = e >= 0 && !(e >= PH_STATE_STALE && e < PH_STATE_BACK);
    const int plan_on = e >= 0 && !(e >= PH_PLAN_STALE && e < PH_PLAN_BACK);
    if (state_on) {
      exec_loop_state_in in = {.t_arrive = now - 2e-4, .ee_pos = {last_p[0], last_p[1], 0.025}, .stopped = 0};
      if (!have_prev) in.ee_pos[0] = 0.05, in.ee_pos[1] = -0.02;
      nd_mailbox_post(&io->state, &in, (int)sizeof in);
      t_state = in.t_arrive;
    }
    if (plan_on && e % 50 == 0) {
      exec_loop_plan_in pl = {0};
      const double sent_ago = plan_is_late(plan_k) ? LATE_S : 2e-4;
      pl.t_arrive = now - sent_ago;
      pl.utime = utime - (int64_t)llround(1e6 * sent_ago);
      /* The loop takes a plan at once while the state is fresh; while it is stale the plan
       * waits and the next one replaces it. */
      if (plan_is_late(plan_k) && now - t_state <= TIMEOUT) st->plans_late++;
      make_plan(&rng, plan_k++, last_p, cfg, &pl, st);
      nd_mailbox_post(&io->plan, &pl, (int)sizeof pl);
    }

    /* The cycle. */
    const int64_t accepted0 = s->rep.accepted;
    const double t0 = mono();
    const int rc = exec_loop_cycle(s, now, utime);
    const double t1 = mono() - t0;
    st->t_cycles += t1;
    if (t1 > st->t_cycle_max) st->t_cycle_max = t1;
    st->cycles++;
    if (rc == 0) st->ret_none++;
    else if (rc > 0) st->ret_sent++;
    else st->ret_full++;
    if (s->rep.accepted != accepted0 && s->ex.seg.T > s->plan.T * (1 + 1e-9)) st->stretched++;

    /* At the end of each stale spell the robot must be at rest. */
    if (e == PH_PLAN_BACK - 1) {
      st->checks_plan_stale++;
      if (s->rep.mode == ND_EXEC_HOLD && (s->rep.stale & EXEC_STALE_PLAN))
        st->hold_at_plan_stale++;
    }
    if (e == PH_STATE_BACK - 1) {
      st->checks_state_stale++;
      if (s->rep.mode == ND_EXEC_HOLD && (s->rep.stale & EXEC_STALE_STATE))
        st->hold_at_state_stale++;
    }
    if (was_stale && !s->rep.stale && s->rep.mode == ND_EXEC_TRACK) st->resumed++;
    was_stale = s->rep.stale != 0;

    /* The consumer drains the ring, except while it is made to fall behind. */
    if (!(e >= PH_NO_DRAIN && e < PH_DRAIN)) {
      unsigned char buf[ND_RTIO_MAX];
      int tag, len;
      while ((len = nd_ring_pop(&io->ring, &tag, buf, sizeof buf)) >= 0) {
        if (tag == EXEC_LOOP_TAG_EE_CMD)
          check_setpoint(buf, len, cfg, &prev, &have_prev, st);
      }
      if (have_prev) last_p[0] = prev.p[0], last_p[1] = prev.p[1];
    }
    if (k % 10 == 0 &&
        nd_mailbox_take(&io->report, &v_rep, &st->rep, (int)sizeof st->rep) ==
            (int)sizeof st->rep)
      st->stale_bits_seen |= st->rep.stale;
  }
  window_close();
}

static exec_loop_io g_io;  /* 260 kB: static, like the executor's */
static exec_loop g_loop;

static void test_cycle_allocates_nothing(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  exec_loop_io_init(&g_io);
  exec_loop_init(&g_loop, &cfg, TIMEOUT, TIMEOUT, &g_io);
  run_stats st;
  memset(&st, 0, sizeof st);
  run_scenario(&g_loop, &g_io, &cfg, &st);
  exec_loop_report_post(&g_loop, T0 + 1e6, 1);
  uint64_t v = 0;
  assert_int_equal(nd_mailbox_take(&g_io.report, &v, &st.rep, (int)sizeof st.rep),
                   (int)sizeof st.rep);

  char allocs[512], blocking[512];
  window_list(allocs, sizeof allocs, 0, N_ALLOC_FN);
  window_list(blocking, sizeof blocking, N_ALLOC_FN, N_FN);
  const long n_alloc = window_sum(0, N_ALLOC_FN), n_block = window_sum(N_ALLOC_FN, N_FN);
  const uint64_t drops = atomic_load(&g_io.ring.dropped);
  printf("rtloop_cycles %ld count\n", st.cycles);
  printf("rtloop_alloc_calls %ld count\n", n_alloc);
  printf("rtloop_blocking_calls %ld count\n", n_block);
  printf("rtloop_plans_accepted %lld count\n", (long long)st.rep.accepted);
  printf("rtloop_plans_refused %lld count\n", (long long)st.rep.refused);
  printf("rtloop_plans_refused_workspace %lld count\n", (long long)st.rep.refused_box);
  printf("rtloop_plans_stretched %ld count\n", st.stretched);
  printf("rtloop_plans_late %lld count\n", (long long)st.rep.late);
  printf("rtloop_plan_age_max %.1f ms\n", 1e3 * st.plan_age_max);
  printf("rtloop_stale_spells %lld count\n", (long long)st.rep.n_stale);
  printf("rtloop_ring_full_cycles %ld count\n", st.ret_full);
  printf("rtloop_ring_drops %llu count\n", (unsigned long long)drops);
  printf("rtloop_peak_speed %.3f v_max\n", st.peak_v);
  printf("rtloop_peak_accel %.3f a_max\n", st.peak_a);
  printf("rtloop_cycle_mean %.2f us\n", 1e6 * st.t_cycles / (double)st.cycles);
  printf("rtloop_cycle_max %.1f us\n", 1e6 * st.t_cycle_max);

  /* The point of the test. */
  if (n_alloc) fail_msg("the cycle allocated inside the window: %s", allocs);
  if (n_block) fail_msg("the cycle made blocking calls inside the window: %s", blocking);

  /* The window went through every path it claims to. */
  assert_true(st.cycles >= 100000);
  assert_int_equal(st.ret_none, PRE);
  assert_int_equal(st.rep.cycles, st.cycles);
  assert_true(st.rep.accepted >= 20 * EPISODES);        /* plan switches */
  assert_true(st.rep.refused >= EPISODES);              /* limits: refused */
  assert_true(st.plans_out > 0);                        /* workspace: refused */
  assert_true(st.rep.refused_box >= EPISODES / 2);
  assert_true(st.stretched >= EPISODES);                /* limits: stretched */
  assert_true(st.plans_far > 0 && st.plans_bad > 0);
  assert_true(st.plans_late >= EPISODES);               /* sent long ago: dropped */
  assert_int_equal(st.rep.late, st.plans_late);
  assert_int_equal(st.stale_bits_seen & (EXEC_STALE_PLAN | EXEC_STALE_STATE),
                   EXEC_STALE_PLAN | EXEC_STALE_STATE);
  assert_true(st.rep.n_stale >= 2 * EPISODES);
  assert_true(st.resumed >= 2 * EPISODES);
  assert_int_equal(st.hold_at_plan_stale, st.checks_plan_stale);
  assert_int_equal(st.hold_at_state_stale, st.checks_state_stale);
  assert_int_equal(st.checks_plan_stale, EPISODES);
  /* Ring full: 400 undrained cycles against 256 slots, every round. */
  assert_true(st.ret_full >= (long)EPISODES * (PH_DRAIN - PH_NO_DRAIN - ND_RING_SLOTS));
  assert_int_equal((long)drops, st.ret_full);
  assert_int_equal(st.rep.sent, st.ret_sent);
  /* What the consumer saw obeys the limits and is continuous (gaps: the drops). */
  assert_int_equal(st.decode_bad, 0);
  assert_int_equal(st.popped, st.ret_sent);  /* the last round ends draining */
  assert_int_equal(st.over_v + st.over_a, 0);
  assert_int_equal(st.step_p + st.step_v, 0);
  assert_int_equal(st.hold_moved, 0);
  /* Every tracking setpoint names a plan no older than the timeout: never a late one. */
  assert_int_equal(st.track_no_plan, 0);
  assert_int_equal(st.track_old_plan, 0);
  assert_true(st.plan_age_max > 0.5 * TIMEOUT);  /* the plan-stale spells age it */
  assert_true(st.seq_gaps >= EPISODES);
  assert_true(st.peak_a > 0.5);  /* the far plans drive it near its limits */
}

/* The robot state as the loop's input: the sphere at p, received 0.2 ms before now, the
 * robot stopped by a reflex or not. */
static void post_state_as(double now, const double p[2], int stopped) {
  exec_loop_state_in in = {.t_arrive = now - 2e-4, .ee_pos = {p[0], p[1], 0.025},
                           .stopped = stopped};
  nd_mailbox_post(&g_io.state, &in, (int)sizeof in);
}

static void post_state(double now, const double p[2]) { post_state_as(now, p, 0); }

/* A plan received 0.2 ms before now, sent at utime - 200 us, starting on arrival; the
 * caller fills in what it is. */
static exec_loop_plan_in plan_now(double now, int64_t utime) {
  exec_loop_plan_in pl = {0};
  pl.t_arrive = now - 2e-4;
  pl.utime = utime - 200;
  return pl;
}

/* The next EE_CMD the loop left in the ring (other messages skipped): 1, or 0 when none. */
static int pop_ee_cmd(nudge_ee_cmd_t *m) {
  unsigned char buf[ND_RTIO_MAX];
  int tag, len;
  while ((len = nd_ring_pop(&g_io.ring, &tag, buf, sizeof buf)) >= 0)
    if (tag == EXEC_LOOP_TAG_EE_CMD && nudge_ee_cmd_t_decode(buf, 0, len, m) == len) return 1;
  return 0;
}

/* After a planner restart the robot is at rest and the new planner, finding nothing
 * better, re-sends one plan at 20 Hz: a keypoint 25 mm ahead to be passed at 0.25 m/s,
 * its segment 0.25 s (0.3 s shortened by the 50 ms its state had aged). Restarting the
 * segment on every copy kept the robot within 2 mm of where it stood for good (the first
 * 50 ms of such a segment wind up rather than advance): test_planner_kill's task then
 * timed out. The loop must keep the segment and reach the keypoint when it is due, while
 * every setpoint names the newest plan. */
static void test_resent_plan_after_restart(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  exec_loop_io_init(&g_io);
  exec_loop_init(&g_loop, &cfg, TIMEOUT, TIMEOUT, &g_io);
  const double start[2] = {0.03, -0.04};
  enum { DEAD = 600, BACK = 1000, END = 3000 };  /* ms: planner killed / restarted / end */
  double key[4] = {0};
  double p[2] = {start[0], start[1]}, hold[2] = {0.0, 0.0};
  double t_first = 0.0, t_reach = -1.0, moved = 0.0;
  long resumed_tracking = 0, named_old = 0, stale_after = 0, held_at_restart = 0;
  int64_t last_id = 0;
  window_open();
  for (long k = 0; k < END; k++) {
    const double now = T0 + DT * (double)k;
    const int64_t utime = U0 + 1000 * k;
    post_state(now, p);
    exec_loop_plan_in pl = plan_now(now, utime);
    if (k < DEAD && k % 50 == 0) {
      /* The first planner: a new keypoint every plan, the robot moving. */
      pl.plan_id = 100 + k / 50;
      pl.T = 0.3;
      const double f = 0.01 * (double)(k / 50);
      double k0[4] = {start[0] + 0.02 + f, start[1] + 0.5 * f, 0.1, 0.05};
      pl.M = 1;
      memcpy(pl.keys[0], k0, sizeof k0);
      nd_mailbox_post(&g_io.plan, &pl, (int)sizeof pl);
    } else if (k >= BACK && k % 50 == 0) {
      if (k == BACK) {
        held_at_restart = g_loop.rep.mode == ND_EXEC_HOLD;
        hold[0] = p[0], hold[1] = p[1];
        const double k0[4] = {p[0] + 0.025, p[1] + 0.004, 0.25, 0.04};
        memcpy(key, k0, sizeof key);
        t_first = now;
      }
      pl.plan_id = 1 + (k - BACK) / 50;  /* the restarted planner counts from 1 */
      pl.T = 0.25;
      pl.M = 1;
      memcpy(pl.keys[0], key, sizeof key);
      nd_mailbox_post(&g_io.plan, &pl, (int)sizeof pl);
      last_id = pl.plan_id;
    }
    exec_loop_cycle(&g_loop, now, utime);
    nudge_ee_cmd_t m;
    while (pop_ee_cmd(&m)) {
      p[0] = m.p[0], p[1] = m.p[1];
      if (k < BACK) continue;
      if (m.mode == ND_EXEC_TRACK) resumed_tracking++;
      if (m.plan_id >= 100) named_old++;
      if (k > BACK && g_loop.rep.stale) stale_after++;
      const double d = hypot(m.p[0] - hold[0], m.p[1] - hold[1]);
      if (d > moved) moved = d;
      if (t_reach < 0.0 && hypot(m.p[0] - key[0], m.p[1] - key[1]) < 1e-3) t_reach = now;
    }
  }
  window_close();
  const long n_calls = window_sum(0, N_FN);
  exec_loop_report_post(&g_loop, T0 + 1e6, 1);
  exec_loop_report rep;
  uint64_t v = 0;
  assert_int_equal(nd_mailbox_take(&g_io.report, &v, &rep, (int)sizeof rep), (int)sizeof rep);
  printf("rtloop_restart_moved %.1f mm\n", 1e3 * moved);
  printf("rtloop_restart_reached %.3f s\n", t_reach < 0.0 ? -1.0 : t_reach - t_first);
  printf("rtloop_restart_kept %lld count\n", (long long)rep.kept);
  assert_int_equal(n_calls, 0);
  assert_true(held_at_restart);  /* the dead planner's plans went stale: at rest */
  assert_true(resumed_tracking > 0);
  assert_int_equal(named_old, 0);
  assert_int_equal(stale_after, 0);
  assert_int_equal(rep.plan_id, last_id);
  /* The point: the keypoint is reached when due (0.25 s after the first copy), not never. */
  if (t_reach < 0.0)
    fail_msg("the setpoint never came within 1 mm of the re-sent keypoint: it moved at most "
             "%.1f mm of %.1f mm", 1e3 * moved, 1e3 * hypot(key[0] - hold[0], key[1] - hold[1]));
  assert_true(t_reach - t_first <= 0.25 + 2 * DT);
  assert_true(moved > 0.02);
  /* Every copy after the first renewed the segment instead of restarting it. */
  assert_true(rep.kept >= 4);
}

/* A reflex stops the robot mid-push: its brake carries the sphere 4 mm on and back to
 * where the reflex read the joints, which is the first stopped state's sphere. The loop
 * holds the setpoint there, still, until the robot resumes, whatever the readings do
 * meanwhile and whatever plans arrive: the robot resumes on the command it holds, and a
 * step in it just after (the loop cannot know the robot has resumed before the state
 * says so) is a Cartesian reflex. After the resume a fresh plan is followed from there
 * within the robot's Cartesian acceleration limit, 13 m/s^2. */
static void test_stopped_hold(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  exec_loop_io_init(&g_io);
  exec_loop_init(&g_loop, &cfg, TIMEOUT, TIMEOUT, &g_io);
  enum { STOP = 400, RESUME = 1400, END = 2200 };  /* ms */
  double p[2] = {-0.05, 0.02}, stop_at[2] = {0.0, 0.0}, prev[2][2];
  long held = 0, moved_stopped = 0, n_prev = 0, tracked_after = 0;
  double a_max = 0.0, travel_after = 0.0;
  for (long k = 0; k < END; k++) {
    const double now = T0 + DT * (double)k;
    const int64_t utime = U0 + 1000 * k;
    const int stopped = k >= STOP && k < RESUME;
    if (k == STOP) stop_at[0] = p[0], stop_at[1] = p[1];
    if (stopped) {
      /* The brake's overshoot and return, 4 mm at most along x. */
      const double t = DT * (double)(k - STOP), ex = 4e-3 * (t / 0.05) * exp(1.0 - t / 0.05);
      const double r[2] = {stop_at[0] + ex, stop_at[1]};
      post_state_as(now, r, 1);
    } else {
      post_state(now, k >= RESUME ? stop_at : p);
    }
    /* The planner sends a plan every 50 ms throughout: a keypoint ahead of the sphere. */
    if (k % 50 == 0) {
      exec_loop_plan_in pl = plan_now(now, utime);
      pl.plan_id = 1 + k / 50;
      pl.T = 0.3;
      pl.M = 1;
      const double key[4] = {p[0] + 0.03, p[1] + 0.01, 0.2, 0.05};
      memcpy(pl.keys[0], key, sizeof key);
      nd_mailbox_post(&g_io.plan, &pl, (int)sizeof pl);
    }
    exec_loop_cycle(&g_loop, now, utime);
    nudge_ee_cmd_t m;
    while (pop_ee_cmd(&m)) {
      /* The first stopped cycle puts the setpoint on the robot: from the next one on, the
       * command must be continuous as the robot sees it. */
      if (k > STOP) {
        if (n_prev >= 2) {
          const double ax = (m.p[0] - 2 * prev[0][0] + prev[1][0]) / (DT * DT);
          const double ay = (m.p[1] - 2 * prev[0][1] + prev[1][1]) / (DT * DT);
          if (hypot(ax, ay) > a_max) a_max = hypot(ax, ay);
        }
        prev[1][0] = prev[0][0], prev[1][1] = prev[0][1];
        prev[0][0] = m.p[0], prev[0][1] = m.p[1];
        n_prev++;
      }
      if (stopped && k > STOP) {
        held += m.mode == ND_EXEC_HOLD && m.v[0] == 0.0 && m.v[1] == 0.0;
        moved_stopped += m.p[0] != stop_at[0] || m.p[1] != stop_at[1];
      }
      if (k >= RESUME) {
        tracked_after += m.mode == ND_EXEC_TRACK;
        const double d = hypot(m.p[0] - stop_at[0], m.p[1] - stop_at[1]);
        if (d > travel_after) travel_after = d;
      }
      if (!stopped) p[0] = m.p[0], p[1] = m.p[1];
    }
  }
  printf("rtloop_stopped_a_max %.2f m/s^2\n", a_max);
  printf("rtloop_resumed_travel %.1f mm\n", 1e3 * travel_after);
  assert_true(hypot(stop_at[0] + 0.05, stop_at[1] - 0.02) > 0.01);  /* it was pushing */
  assert_int_equal(moved_stopped, 0);
  assert_int_equal(held, RESUME - STOP - 1);
  assert_true(a_max <= 13.0);
  assert_true(tracked_after > 0);
  assert_true(travel_after > 0.01);
}

/* Latency compensation end to end: a planner that predicts the setpoint at a later start
 * from one EE_CMD's setpoint and future (nd_exec_future_eval), as nudge-planner does,
 * sends a plan that starts there; the loop keeps its segment until then, starts the new
 * one on time, and finds its setpoint where the plan said it would be. */
static void test_plan_start(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  exec_loop_io_init(&g_io);
  exec_loop_init(&g_loop, &cfg, TIMEOUT, 0.3, &g_io);
  enum { SEND = 150, LEAD = 60, END = 400 };  /* ms */
  double p[2] = {0.0, 0.0};
  const double a[4] = {0.08, 0.02, 0.3, 0.0}, b[4] = {0.12, -0.04, 0.0, -0.2};
  nudge_ee_cmd_t at_send = {0};
  long on_a_before = 0, on_b_before = 0, on_b_after = 0, n_after = 0;
  double predicted[2][4] = {{0}}, jump = 0.0, prev_p[2] = {0.0, 0.0};
  for (long k = 0; k < END; k++) {
    const double now = T0 + DT * (double)k;
    const int64_t utime = U0 + 1000 * k;
    post_state(now, p);
    exec_loop_plan_in pl = plan_now(now, utime);
    pl.M = 1;
    if (k == 1) {
      pl.plan_id = 1, pl.T = 0.3, pl.t_start = pl.t_arrive;
      memcpy(pl.keys[0], a, sizeof a);
      pl.start_p[0] = p[0], pl.start_p[1] = p[1];
      nd_mailbox_post(&g_io.plan, &pl, (int)sizeof pl);
    } else if (k == SEND) {
      /* From the newest EE_CMD (1 ms old): where its trajectory will be LEAD ms ahead. */
      double sp[2][4];
      for (int ax = 0; ax < 2; ax++)
        sp[ax][ND_P] = at_send.p[ax], sp[ax][ND_V] = at_send.v[ax],
        sp[ax][ND_A] = at_send.a[ax], sp[ax][ND_J] = at_send.j[ax];
      nd_exec_future f = {.t_seg_end = 1e-6 * (double)at_send.seg_end_utime,
                          .t_brake = 1e-6 * (double)at_send.brake_utime,
                          .t_rest = 1e-6 * (double)at_send.rest_utime,
                          .hold = {at_send.hold[0], at_send.hold[1]}};
      memcpy(f.key, at_send.seg_key, sizeof f.key);
      nd_exec_future_eval((const double(*)[4])sp, 1e-6 * (double)at_send.utime, &f,
                          1e-6 * (double)(utime + 1000 * LEAD), predicted);
      pl.plan_id = 2, pl.T = 0.3, pl.t_start = now + 1e-3 * LEAD;
      memcpy(pl.keys[0], b, sizeof b);
      pl.start_p[0] = predicted[0][ND_P], pl.start_p[1] = predicted[1][ND_P];
      nd_mailbox_post(&g_io.plan, &pl, (int)sizeof pl);
    }
    exec_loop_cycle(&g_loop, now, utime);
    nudge_ee_cmd_t m;
    while (pop_ee_cmd(&m)) {
      if (k > 1) jump = fmax(jump, hypot(m.p[0] - prev_p[0], m.p[1] - prev_p[1]));
      prev_p[0] = m.p[0], prev_p[1] = m.p[1];
      p[0] = m.p[0], p[1] = m.p[1];
      at_send = m;
      const int on_a = hypot(m.seg_key[0] - a[0], m.seg_key[1] - a[1]) < 1e-9;
      const int on_b = hypot(m.seg_key[0] - b[0], m.seg_key[1] - b[1]) < 1e-9;
      if (k >= SEND && k < SEND + LEAD) on_a_before += on_a, on_b_before += on_b;
      if (k >= SEND + LEAD) on_b_after += on_b, n_after++;
      if (k == SEND + LEAD) {
        printf("rtloop_start_predicted_error %.2e m\n",
               hypot(m.p[0] - predicted[0][ND_P], m.p[1] - predicted[1][ND_P]));
        assert_near(m.p[0], predicted[0][ND_P], 1e-6);
        assert_near(m.p[1], predicted[1][ND_P], 1e-6);
      }
    }
  }
  exec_loop_report_post(&g_loop, T0 + 1e6, 1);
  exec_loop_report rep;
  uint64_t v = 0;
  assert_int_equal(nd_mailbox_take(&g_io.report, &v, &rep, (int)sizeof rep), (int)sizeof rep);
  assert_int_equal(on_a_before, LEAD);   /* the old segment ran until the start */
  assert_int_equal(on_b_before, 0);
  assert_int_equal(on_b_after, n_after); /* then the new one, from its first cycle */
  assert_int_equal(rep.accepted, 2);
  assert_int_equal(rep.plan_id, 2);
  printf("rtloop_start_err_max %.2e m\n", rep.start_err_max);
  assert_true(rep.start_err_max < 1e-6);
  assert_true(jump < cfg.v_max * DT * 1.001);  /* continuous across the switch */
}

/* The workspace at the loop: a plan whose keypoint lies at (0.8, 0), outside the default
 * box, is refused and counted, and the robot stays exactly where it is (no plan was ever
 * taken: it holds). A plan inside the box is then followed to its keypoint. Plans whose
 * first keypoint is inside but whose second is at (0.8, 0) are refused too, and the robot
 * stays at rest where the good plan left it. */
static void test_workspace_plans(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  exec_loop_io_init(&g_io);
  exec_loop_init(&g_loop, &cfg, TIMEOUT, TIMEOUT, &g_io);
  enum { IN = 500, BAD2 = 1000, END = 1500 };  /* ms: phase starts */
  const double start[2] = {0.1, 0.0}, out_key[4] = {0.8, 0.0, 0.0, 0.0};
  const double in_key[4] = {0.3, 0.1, 0.0, 0.0}, in_next[4] = {0.35, 0.1, 0.0, 0.0};
  double p[2] = {start[0], start[1]};
  double x_max_out = -1.0, x_max_bad2 = -1.0, p_in[2] = {0.0, 0.0};
  long posted_out = 0, posted_bad2 = 0, moved_out = 0, moved_bad2 = 0;
  int64_t refused_at_in = 0, box_at_in = 0, refused_at_bad2 = 0;
  char why_out[160] = "", why_bad2[160] = "";
  window_open();
  for (long k = 0; k < END; k++) {
    const double now = T0 + DT * (double)k;
    const int64_t utime = U0 + 1000 * k;
    post_state(now, p);
    if (k % 50 == 0) {
      exec_loop_plan_in pl;
      memset(&pl, 0, sizeof pl);
      pl.t_arrive = now - 2e-4;
      pl.utime = utime - 200;
      pl.plan_id = 1 + k / 50;
      pl.T = 0.3;
      pl.M = 2;
      if (k < IN) {
        memcpy(pl.keys[0], out_key, sizeof out_key);
        memcpy(pl.keys[1], out_key, sizeof out_key);
        posted_out++;
      } else if (k < BAD2) {
        memcpy(pl.keys[0], in_key, sizeof in_key);
        memcpy(pl.keys[1], in_next, sizeof in_next);
      } else {
        memcpy(pl.keys[0], in_next, sizeof in_next);
        memcpy(pl.keys[1], out_key, sizeof out_key);
        posted_bad2++;
      }
      nd_mailbox_post(&g_io.plan, &pl, (int)sizeof pl);
    }
    if (k == IN) {
      refused_at_in = g_loop.rep.refused;
      box_at_in = g_loop.rep.refused_box;
      memcpy(why_out, g_loop.rep.refused_why, sizeof why_out);
    }
    if (k == BAD2) {
      refused_at_bad2 = g_loop.rep.refused;
      p_in[0] = p[0], p_in[1] = p[1];
    }
    exec_loop_cycle(&g_loop, now, utime);
    nudge_ee_cmd_t m;
    while (pop_ee_cmd(&m)) {
      p[0] = m.p[0], p[1] = m.p[1];
      if (k < IN) {
        x_max_out = fmax(x_max_out, m.p[0]);
        moved_out += m.p[0] != start[0] || m.p[1] != start[1] || m.mode != ND_EXEC_HOLD;
      } else if (k >= BAD2) {
        x_max_bad2 = fmax(x_max_bad2, m.p[0]);
        /* At rest on its keypoint, re-planned there: rounding moves it by ~1e-17 m. */
        moved_bad2 += hypot(m.p[0] - p_in[0], m.p[1] - p_in[1]) > 1e-9;
      }
    }
  }
  window_close();
  memcpy(why_bad2, g_loop.rep.refused_why, sizeof why_bad2);
  const long n_calls = window_sum(0, N_FN);
  printf("rtloop_workspace_refused %lld count (of %ld + %ld posted outside)\n",
         (long long)g_loop.rep.refused, posted_out, posted_bad2);
  printf("rtloop_workspace_x_max_while_refusing %.6f m\n", x_max_out);
  printf("rtloop_workspace_reached (%.4f, %.4f) m\n", p_in[0], p_in[1]);
  printf("rtloop_workspace_why_first: %s\nrtloop_workspace_why_second: %s\n", why_out,
         why_bad2);
  assert_int_equal(n_calls, 0);
  /* Refused and counted, each one; the robot never moved toward (0.8, 0). */
  assert_int_equal(refused_at_in, posted_out);
  assert_int_equal(box_at_in, posted_out);
  assert_non_null(strstr(why_out, "keypoint 0 (0.800, 0.000) is outside the workspace"));
  assert_non_null(strstr(why_out, "x [-0.500, 0.500], y [-0.500, 0.500]"));
  assert_int_equal(moved_out, 0);
  assert_true(x_max_out == start[0]);
  /* The plan in the box is followed to its keypoint. */
  assert_near(p_in[0], in_key[0], 1e-6);
  assert_near(p_in[1], in_key[1], 1e-6);
  /* A later keypoint outside refuses the plan too: no step toward (0.35, 0.1) or beyond. */
  assert_int_equal(g_loop.rep.refused - refused_at_bad2, posted_bad2);
  assert_int_equal(g_loop.rep.refused_box, posted_out + posted_bad2);
  assert_non_null(strstr(why_bad2, "keypoint 1 (0.800, 0.000)"));
  assert_int_equal(moved_bad2, 0);
  assert_true(x_max_bad2 <= p_in[0] + 1e-9);
  assert_int_equal(g_loop.rep.mode, ND_EXEC_HOLD);
}

/* ---- nd_rtloop's schedule on synthetic time ---------------------------------------------- */

typedef struct {
  int calls, extra;          /* cycles, of which catching up */
  double first_deadline, last_deadline;
  int64_t last_utime;
} tick_log;

static void log_tick(void *ctx, const nd_rtloop_tick *t) {
  tick_log *g = ctx;
  if (!g->calls) g->first_deadline = t->deadline;
  g->calls++;
  g->extra += t->catching_up;
  g->last_deadline = t->deadline;
  g->last_utime = t->utime;
}

/* One wake-up of a 1 kHz loop, late_ms after its deadline; returns the log of the cycles. */
static tick_log wake(nd_rtloop *l, int64_t *next, double late_ms) {
  tick_log g = {0};
  l->ctx = &g;
  const int64_t now = *next + (int64_t)(late_ms * 1e6);
  nd_rtloop_wake(l, next, now, 5000000000LL + now / 1000);
  return g;
}

/* SKIP runs one cycle per wake-up, for the newest deadline due, and counts the rest as
 * skipped; CATCH_UP runs one per deadline up to its maximum, oldest first, and counts what
 * is beyond. Both advance the schedule past every deadline served, allocating nothing. */
static void test_loop_policies(void **state) {
  (void)state;
  static nd_rtloop l;
  for (int policy = ND_RT_SKIP; policy <= ND_RT_CATCH_UP; policy++) {
    memset(&l, 0, sizeof l);
    nd_rtloop_cfg_default(&l.cfg);
    l.cfg.policy = policy;
    l.cfg.catch_up_max = 20;
    l.fn = log_tick;
    nd_mailbox_init(&l.stats);
    nd_jitter_reset(&l.jit);
    int64_t next = 1000000000LL;  /* 1 s */
    window_open();
    tick_log on_time = wake(&l, &next, 0.05);
    const int64_t after_on_time = next;
    tick_log late5 = wake(&l, &next, 4.5);      /* 4 deadlines passed besides this one */
    const int64_t after_late5 = next;
    tick_log stall = wake(&l, &next, 99.5);     /* a 100 ms stall: 100 deadlines due */
    for (int k = 0; k < 1000; k++) wake(&l, &next, 0.01);
    window_close();
    assert_int_equal(window_sum(0, N_FN), 0);
    assert_int_equal(on_time.calls, 1);
    assert_int_equal(after_on_time, 1000000000LL + 1000000);
    assert_int_equal(after_late5, after_on_time + 5 * 1000000);
    if (policy == ND_RT_SKIP) {
      assert_int_equal(late5.calls, 1);
      assert_near(late5.last_deadline, 1.001 + 0.004, 1e-12);  /* the newest due */
      assert_int_equal(stall.calls, 1);
      assert_int_equal(l.st.skipped, 4 + 99);
    } else {
      assert_int_equal(late5.calls, 5);
      assert_int_equal(late5.extra, 4);
      assert_near(late5.first_deadline, 1.001, 1e-12);
      assert_near(late5.last_deadline, 1.005, 1e-12);
      assert_int_equal(stall.calls, 20);
      assert_int_equal(l.st.skipped, 80);
      /* The cycles served are the newest 20, each stamped with its own deadline's time. */
      assert_near(stall.last_deadline - stall.first_deadline, 0.019, 1e-9);
    }
    assert_int_equal(l.jit.overruns, 2);
    printf("rtloop_policy_%s cycles %lld, skipped %lld, overruns %lld\n",
           policy == ND_RT_SKIP ? "skip" : "catch_up", (long long)l.st.cycles,
           (long long)l.st.skipped, (long long)l.jit.overruns);
  }
}

/* Two loops (the executor's and the robot's) meet a 5 ms wall-clock step at resyncs 0.7 s
 * apart. Their stamps must never disagree by a step: the robot samples the commands at
 * h = its stamp less the command's, so a jump of h by d moves its setpoint by v d in one
 * cycle (5 ms at 0.5 m/s: 2.5 mm, 2500 m/s^2 against the 13 m/s^2 reflex). Slewed, the
 * disagreement grows by at most 0.5 us a cycle; a step of 20 ms or more is taken at once. */
static void test_clock_slew(void **state) {
  (void)state;
  const int64_t period = 1000000, slew = 500;  /* 1 ms cycles: 500 ppm is 0.5 us a cycle */
  int64_t a = 0, b = 0, ta = 0, tb = 0, worst = 0, worst_change = 0, prev = 0;
  for (int k = 0; k < 20000; k++) {
    if (k == 300) ta = 5000000;   /* the executor's resync after the step */
    if (k == 1000) tb = 5000000;  /* the robot's, 0.7 s later */
    a = nd_rtloop_slew(a, ta, period);
    b = nd_rtloop_slew(b, tb, period);
    const int64_t d = a > b ? a - b : b - a;
    if (d > worst) worst = d;
    if (llabs(d - prev) > worst_change) worst_change = llabs(d - prev);
    prev = d;
  }
  assert_int_equal(a, 5000000);
  assert_int_equal(b, 5000000);
  assert_int_equal(worst_change, slew);   /* h changes by 0.5 us a cycle at most */
  assert_int_equal(worst, 700 * slew);    /* 0.35 ms apart at worst, not 5 */
  /* The setpoint's second difference at 0.5 m/s from h changing by that much a cycle. */
  printf("clock_slew_h_change_max %lld ns per cycle, disagreement_max %.3f ms, setpoint_acc %.2f m/s^2\n",
         (long long)worst_change, 1e-6 * (double)worst, 0.5 * 1e-9 * (double)worst_change / 1e-6);

  assert_int_equal(nd_rtloop_slew(0, -3000000, period), -slew);
  assert_int_equal(nd_rtloop_slew(0, -3000000, 2 * period), -2 * slew);  /* per ns of period */
  assert_int_equal(nd_rtloop_slew(1000, 1200, period), 1200);       /* within a cycle's slew */
  assert_int_equal(nd_rtloop_slew(0, ND_RTLOOP_STEP_NS, period), ND_RTLOOP_STEP_NS);
  assert_int_equal(nd_rtloop_slew(0, -ND_RTLOOP_STEP_NS - 1, period), -ND_RTLOOP_STEP_NS - 1);
  assert_int_equal(nd_rtloop_slew(0, ND_RTLOOP_STEP_NS - 1, period), slew);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_clock_slew),
      cmocka_unit_test(test_loop_policies),
      cmocka_unit_test(test_counter_sees_calls),
      cmocka_unit_test(test_cycle_allocates_nothing),
      cmocka_unit_test(test_resent_plan_after_restart),
      cmocka_unit_test(test_stopped_hold),
      cmocka_unit_test(test_workspace_plans),
      cmocka_unit_test(test_plan_start),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
