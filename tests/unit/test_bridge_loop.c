/* test_bridge_loop: the bridge's 1 kHz step (processes/bridge/bridge_loop.c), run through
 * nd_rtloop's schedule on synthetic time, allocates nothing and makes no blocking call
 * (counted by rt_count.h's wrappers), and does what the bridge promises: hold until the
 * first command, track fresh commands, follow the last one when they stop and hold once it
 * is stale, one ROBOT_STATE per step with consecutive seq, MOCAP at 240 Hz stamped with its
 * capture time, and every deadline of a catch-up wake-up stepped. With the lab world's arm
 * and an executor's commands: jittered ones are applied at the step's time and stop no
 * reflex, a jump does; through a silent commander or a stall of the whole machine the
 * robot's setpoint stays on the executor's trajectory and no reflex stops it, and a command
 * that arrives late after a plan switch is joined, not stepped to. A PLACE waits for the
 * sphere to clear its pose, then puts the object there at rest, or is dropped. */
#define _GNU_SOURCE
#include "nd_test.h"
#include "rt_count.h"

#include "bridge_loop.h"
#include "nd_math.h"
#include "nd_release.h"
#include "nd_rtloop.h"
#include "nudge/nudge_mocap_t.h"
#include "nudge/nudge_robot_state_t.h"

#define T0 1000.0              /* s, the synthetic monotonic clock's start */
#define U0 1795496793000000LL  /* us, its wall-clock time */

static bridge_loop g_b;
static nd_rtloop g_l;

typedef struct {
  long states, frames, arm_states, seq_gaps, late_frames;
  int64_t last_seq, last_frame_us, last_state_us;
  double ee[2];
  double obj[3];  /* the newest frame's object x, y, yaw */
  int mode;
} drained;

/* Pop everything the loop encoded, checking what can be checked per message. */
static void drain(drained *d) {
  unsigned char buf[ND_RTIO_MAX];
  int tag, n;
  while ((n = nd_ring_pop(&g_b.out, &tag, buf, sizeof buf)) >= 0) {
    if (tag == BRIDGE_TAG_ROBOT_STATE) {
      nudge_robot_state_t m;
      assert_int_equal(nudge_robot_state_t_decode(buf, 0, n, &m), n);
      if (d->states && m.seq != d->last_seq + 1) d->seq_gaps++;
      d->last_seq = m.seq;
      d->last_state_us = m.utime;
      d->ee[0] = m.ee_pos[0], d->ee[1] = m.ee_pos[1];
      d->mode = m.mode;
      d->states++;
    } else if (tag == BRIDGE_TAG_MOCAP) {
      nudge_mocap_t m;
      assert_int_equal(nudge_mocap_t_decode(buf, 0, n, &m), n);
      /* The ideal world's capture has no latency: a frame is stamped with its step's time. */
      d->late_frames += m.utime != d->last_state_us;
      d->last_frame_us = m.utime;
      d->obj[0] = m.obj_pos[0], d->obj[1] = m.obj_pos[1], d->obj[2] = nd_quat_yaw(m.obj_quat);
      d->frames++;
    } else {
      assert_int_equal(tag, BRIDGE_TAG_ARM_STATE);
      d->arm_states++;
    }
  }
}

/* A command to rest at (x, y): its future holds there. */
static void post_cmd(double now, double x, double y) {
  bridge_cmd c = {.sp = {{x}, {y}}, .utime = U0 + (int64_t)llround((now - T0) * 1e6),
                  .arrival = now};
  c.f.key[0] = c.f.hold[0] = x;
  c.f.key[1] = c.f.hold[1] = y;
  nd_mailbox_post(&g_b.cmd, &c, sizeof c);
}

/* The executor feeding the lab bridge (lab_bridge starts it at rest at the sphere). */
static nd_exec_cfg g_ec;
static nd_exec g_ex;

/* The lab world's bridge and its executor, fed from a fresh start. */
static nds_world *lab_bridge(void) {
  char err[256];
  nds_world_cfg wc;
  nds_world_cfg_lab(&wc);
  nds_world *w = nds_world_create(&wc, err, sizeof err);
  if (!w) fail_msg("%s", err);
  bridge_loop_init(&g_b, w, 0.1);
  g_ec = nd_exec_cfg_default();
  nd_exec_init(&g_ex, (const double[2]){-0.10, 0.0}, 0.0);
  return w;
}

/* g_ex's next plan: toward key with duration T, from synthetic time t. */
static void exec_plan(double t, const double key[4], double T) {
  char err[256];
  if (nd_exec_plan(&g_ex, &g_ec, t, key, T, err, sizeof err)) fail_msg("%s", err);
}

/* The command g_ex sends at synthetic time t, as exec_loop.c puts it in an EE_CMD and
 * bridge_io.c takes it (the future on the command's own clock, microsecond stamps),
 * arriving at t. */
static bridge_cmd exec_send(double t) {
  bridge_cmd c = {.utime = U0 + (int64_t)llround(t * 1e6), .arrival = T0 + t};
  nd_exec_step(&g_ex, &g_ec, t, 0, c.sp);
  nd_exec_future f;
  nd_exec_future_get(&g_ex, &f);
  c.f = f;
  c.f.t_seg_end = 1e-6 * (double)llround(1e6 * (f.t_seg_end - t));
  c.f.t_brake = 1e-6 * (double)llround(1e6 * (f.t_brake - t));
  c.f.t_rest = 1e-6 * (double)llround(1e6 * (f.t_rest - t));
  return c;
}

/* How far the bridge's last setpoint is from executor ex's trajectory at t (m). */
static double setpoint_off(const nd_exec *ex, double t) {
  double want[2][4];
  nd_exec_eval(ex, t, want);
  return hypot(g_b.sp_last[0] - want[0][ND_P], g_b.sp_last[1] - want[1][ND_P]);
}

/* The lab world's arm fed an executor's path (x moves 10 cm and back, two rest-to-rest
 * segments of 1.4 s, at most 0.16 m/s) whose commands arrive with a network's jitter: the
 * command for step k comes at step k or k + 1 (seeded), so some steps see two new commands
 * and some none. Applied at the step's time, the setpoint stays smooth: no reflex stops the
 * arm and it tracks. Then one command 0.5 mm off the path (500 m/s^2 in one step): the arm
 * stops on the Cartesian acceleration reflex, ROBOT_STATE says so, and a new task resumes
 * it. */
static void test_lab_jittered_commands(void **state) {
  (void)state;
  nds_world *w = lab_bridge();
  enum { STEPS = 3000, BACK = 1400, JUMP = 2500 };
  uint64_t rng = 12345;
  bridge_cmd late = {0};
  int have_late = 0;
  double err_max = 0;
  drained d = {0};
  for (int k = 0; k < STEPS; k++) {
    const double t = 1e-3 * k, now = T0 + t;
    if (k == 0 || k == BACK) exec_plan(t, (const double[4]){k ? -0.10 : 0.0, 0.0, 0.0, 0.0}, 1.4);
    bridge_cmd c = exec_send(t);
    const double x = c.sp[0][ND_P];
    if (k == JUMP) c.sp[0][ND_P] += 5e-4;
    if (have_late) nd_mailbox_post(&g_b.cmd, &late, sizeof late), have_late = 0;
    rng = rng * 6364136223846793005ULL + 1442695040888963407ULL;
    if ((rng >> 33) & 1) nd_mailbox_post(&g_b.cmd, &c, sizeof c);
    else late = c, have_late = 1;
    bridge_loop_step(&g_b, now, c.utime);
    drain(&d);
    if (k > 200 && k < JUMP) err_max = fmax(err_max, fabs(d.ee[0] - x));
    if (k == JUMP - 1) {
      printf("lab_jitter_stops %lld count\nlab_jitter_track_err_max %.4f m\n",
             (long long)g_b.rep.stops, err_max);
      assert_int_equal(g_b.rep.stops, 0);
      assert_int_equal(d.mode, NUDGE_ROBOT_STATE_T_MODE_TRACKING);
      assert_true(err_max < 5e-3);
    }
  }
  printf("lab_jump_stops %lld count, reflex %d\n", (long long)g_b.rep.stops, g_b.rep.reflex.kind);
  assert_int_equal(g_b.rep.stops, 1);
  assert_int_equal(g_b.rep.reflex.kind, NDS_PANDA_REFLEX_CART_ACCELERATION);
  assert_int_equal(d.mode, NUDGE_ROBOT_STATE_T_MODE_STOPPED);
  atomic_fetch_add(&g_b.resume_req, 1);
  bridge_loop_step(&g_b, T0 + 1e-3 * STEPS, U0 + (int64_t)STEPS * 1000);
  drain(&d);
  assert_int_not_equal(d.mode, NUDGE_ROBOT_STATE_T_MODE_STOPPED);
  nds_world_free(w);
}

/* A live-like executor: every 30 ms a new plan toward where a target speeding up to 0.2 m/s
 * along x and swaying 6 cm in y will be in 0.15 s, each a fresh 0.15 s segment (the high
 * snap of a live segment's start; up to 1.9 m/s^2, within the arm's 2); g_ex's command
 * at step k. */
static bridge_cmd live_send(int k) {
  const double t = 1e-3 * k, tk = t + 0.15, w = 2 * M_PI / 1.2;
  if (k % 30 == 0)
    exec_plan(t, (const double[4]){-0.10 + 0.2 * tk * tk / (tk + 0.3), 0.03 * (1 - cos(w * tk)),
                                   0.2 * tk * (tk + 0.6) / ((tk + 0.3) * (tk + 0.3)),
                                   0.03 * w * sin(w * tk)}, 0.15);
  return exec_send(t);
}

/* The commander falls silent, as the executor does when the machine stalls: for 13 ms and
 * for 45 ms of a live-like path, no command, no plan, and the executor's clock jumps on
 * (nd_rtloop's skip) when it resumes. The robot's setpoint follows the trajectory the last
 * command committed to, so it stays on the executor's own trajectory to 1 um throughout
 * (the Taylor terms alone drift by snap h^4/24 off it, 0.1 mm after 13 ms), the executor's
 * next command continues it, and no reflex stops the arm. The 45 ms silence is reported;
 * the robot never holds. */
static void test_lab_commander_silent(void **state) {
  (void)state;
  nds_world *w = lab_bridge();
  enum { STEPS = 1200 };
  double off_max = 0, off_silent = 0, off_taylor = 0, err_max = 0;
  bridge_cmd c = {0};
  drained d = {0};
  for (int k = 0; k < STEPS; k++) {
    const double t = 1e-3 * k;
    const int silent = (k >= 300 && k < 313) || (k >= 600 && k < 645);
    if (!silent) {
      c = live_send(k);
      nd_mailbox_post(&g_b.cmd, &c, sizeof c);
    }
    bridge_loop_step(&g_b, T0 + t, U0 + (int64_t)k * 1000);
    drain(&d);
    double want[2][4];
    nd_exec_eval(&g_ex, t, want);
    const double off = setpoint_off(&g_ex, t);
    off_max = fmax(off_max, off);
    if (silent) {
      off_silent = fmax(off_silent, off);
      /* What the last command's Taylor terms alone would have commanded. */
      const double h = t - 1e-6 * (double)(c.utime - U0);
      double tay[2];
      for (int i = 0; i < 2; i++)
        tay[i] = c.sp[i][ND_P] +
                 h * (c.sp[i][ND_V] + h * (c.sp[i][ND_A] / 2 + h * c.sp[i][ND_J] / 6)) -
                 want[i][ND_P];
      off_taylor = fmax(off_taylor, hypot(tay[0], tay[1]));
    }
    if (k > 100) err_max = fmax(err_max, hypot(d.ee[0] - want[0][ND_P], d.ee[1] - want[1][ND_P]));
  }
  printf("silent_setpoint_off_max %.2e m (silences %.2e m, Taylor terms alone %.2e m)\n"
         "silent_stops %lld count\nsilent_track_err_max %.4f m\n", off_max, off_silent,
         off_taylor, (long long)g_b.rep.stops, err_max);
  assert_true(off_silent > 0);  /* the silences were bridged, not skipped */
  assert_true(off_taylor > 1e-5);  /* and the path is one the Taylor terms cannot bridge */
  assert_true(off_max < 1e-6);
  assert_int_equal(g_b.rep.stops, 0);
  assert_int_equal(g_b.rep.silent_events, 1);
  assert_int_equal(g_b.rep.apart_events + g_b.rep.hold_events, 0);
  assert_int_equal(d.mode, NUDGE_ROBOT_STATE_T_MODE_TRACKING);
  assert_true(err_max < 5e-3);
  nds_world_free(w);
}

/* The executor runs on, but its commands reach the bridge late: those of 25 ms (and of
 * 30 ms, 40 ms) arrive together at its end, and the executor switched plans inside each delay.
 * The robot followed the future of the last command it had, which the switch left: the
 * newest command is up to ~10 um off it (6.5 um in one step is 6500 m/s^3 to the jerk
 * reflex; stepped to, the first stops the arm at 7400). The bridge joins each within
 * BRIDGE_JOIN_S: no reflex stops the arm, and the setpoint is back on the executor's
 * trajectory to 1 um once each join ends, having strayed less than 0.1 mm. */
static void test_lab_late_switch(void **state) {
  (void)state;
  nds_world *w = lab_bridge();
  enum { STEPS = 1200, NLATE = 3 };
  static const int from[NLATE] = {295, 590, 875}, to[NLATE] = {320, 620, 915};
  double off_max = 0, off_after = 0, hist[4][2] = {{0}}, jerk_join = 0, jerk_else = 0;
  int late_i = 0;
  bridge_cmd c = {0};
  drained d = {0};
  for (int k = 0; k < STEPS; k++) {
    const double t = 1e-3 * k;
    c = live_send(k);
    const int held = late_i < NLATE && k >= from[late_i] && k < to[late_i];
    if (!held) nd_mailbox_post(&g_b.cmd, &c, sizeof c);
    if (late_i < NLATE && k == to[late_i]) late_i++;
    bridge_loop_step(&g_b, T0 + t, U0 + (int64_t)k * 1000);
    drain(&d);
    const double off = setpoint_off(&g_ex, t);
    int joining = 0;
    for (int i = 0; i < NLATE; i++)
      joining |= k >= from[i] && k < to[i] + (int)ceil(BRIDGE_JOIN_S * 1e3);
    /* The commanded jerk as the robot's reflex sees it: third backward differences. */
    memmove(hist[1], hist[0], sizeof hist[0] * 3);
    memcpy(hist[0], g_b.sp_last, sizeof hist[0]);
    const double jerk = 1e9 * hypot(hist[0][0] - 3 * hist[1][0] + 3 * hist[2][0] - hist[3][0],
                                    hist[0][1] - 3 * hist[1][1] + 3 * hist[2][1] - hist[3][1]);
    if (joining) off_max = fmax(off_max, off), jerk_join = fmax(jerk_join, jerk);
    else if (k > 3) off_after = fmax(off_after, off), jerk_else = fmax(jerk_else, jerk);
  }
  printf("late_switch_off_max %.2e m (after the joins %.2e m)\nlate_switch_joins %lld count\n"
         "late_switch_jerk_max %.0f m/s^3 (elsewhere %.0f m/s^3)\nlate_switch_stops %lld count\n",
         off_max, off_after, (long long)g_b.rep.joins, jerk_join, jerk_else,
         (long long)g_b.rep.stops);
  assert_int_equal(g_b.rep.joins, NLATE);
  assert_true(off_max > 5e-6);  /* the switches left the followed futures */
  assert_true(off_max < 1e-4);
  assert_true(off_after < 1e-6);
  assert_true(jerk_join < 1000);
  assert_int_equal(g_b.rep.stops, 0);
  assert_int_equal(d.mode, NUDGE_ROBOT_STATE_T_MODE_TRACKING);
  nds_world_free(w);
}

/* The executor's trajectory as of its last step before the bridge's wake-up, and how far
 * the bridge's setpoint got from it at any deadline served (check_tick). */
static nd_exec g_ref;
static double g_off_max;
/* While the bridge catches up: the executor's next command every g_feed_every ticks
 * (0: none), the last one it sent g_fed. */
static int g_feed_every, g_feed_ticks, g_fed;

static void check_tick(void *ctx, const nd_rtloop_tick *t) {
  if (g_feed_every && ++g_feed_ticks % g_feed_every == 0) {
    const bridge_cmd c = live_send(++g_fed);
    nd_mailbox_post(&g_b.cmd, &c, sizeof c);
  }
  bridge_loop_tick(ctx, t);
  g_off_max = fmax(g_off_max, setpoint_off(&g_ref, 1e-3 * (double)llround((t->deadline - T0) * 1e3)));
}

/* The whole machine stalls, the bridge's loop and the executor alike, for 45 ms, 60 ms
 * and 42 ms; afterwards the executor sends its command for the present first, or the
 * bridge wakes first, or (the third) the executor sends first and goes on sending while
 * the bridge catches up, each command stamped ahead of the steps. Run through nd_rtloop with the bridge's catch-up, every missed deadline gets its
 * world step, each sampling the command it is after (the one before the newest, when the
 * executor woke first), so the setpoint keeps to the executor's trajectory to 1 um at every
 * deadline, none is skipped, and no reflex stops the arm (a skipped one would move the
 * setpoint by the skipped time in one step: decisions#catch-up). */
/* g_l: the bridge's 1 kHz catch-up schedule, ticking check_tick on g_b. */
static void stall_loop_init(void) {
  memset(&g_l, 0, sizeof g_l);
  nd_rtloop_cfg_default(&g_l.cfg);
  g_l.cfg.policy = ND_RT_CATCH_UP;
  g_l.cfg.catch_up_max = bridge_loop_catch_up_max(1000.0);
  g_l.fn = check_tick;
  g_l.ctx = &g_b;
  nd_mailbox_init(&g_l.stats);
  nd_jitter_reset(&g_l.jit);
  g_ref = g_ex;
  g_off_max = 0;
}

/* g_l's wake-up at step k (20 us after its deadline on the synthetic clock), then drain. */
static void stall_wake(int k, int64_t *next, drained *d) {
  const int64_t now_ns = (int64_t)(T0 * 1e9) + (int64_t)k * 1000000 + 20000;
  nd_rtloop_wake(&g_l, next, now_ns, U0 + (now_ns - (int64_t)(T0 * 1e9)) / 1000);
  drain(d);
}

static void test_lab_machine_stall(void **state) {
  (void)state;
  nds_world *w = lab_bridge();
  stall_loop_init();
  /* S3's commands during the catch-up start no new plan (none at a multiple of 30), so
   * g_ref, the trajectory before the wake, still holds for them. */
  enum { STEPS = 1200, S1 = 400, S1_END = 445, S2 = 800, S2_END = 860, S3 = 1000,
         S3_END = 1042, FEED_EVERY = 10 };
  int64_t next = (int64_t)(T0 * 1e9);
  drained d = {0};
  g_feed_every = g_feed_ticks = 0;
  for (int k = 0; k < STEPS; k++) {
    if ((k >= S1 && k < S1_END) || (k >= S2 && k < S2_END) || (k >= S3 && k < S3_END))
      continue;  /* all asleep */
    if (k > S3_END && k <= g_fed) continue;  /* sent during the catch-up */
    const int bridge_first = k == S2_END;
    if (bridge_first) stall_wake(k, &next, &d);
    const bridge_cmd c = live_send(k);
    nd_mailbox_post(&g_b.cmd, &c, sizeof c);
    if (k == S3_END) g_fed = k, g_feed_every = FEED_EVERY, g_feed_ticks = 0;
    if (!bridge_first) stall_wake(k, &next, &d);
    g_feed_every = 0;
    g_ref = g_ex;
  }
  assert_true(g_fed > S3_END + 2);  /* several commands came during the third catch-up */
  printf("machine_stall_setpoint_off_max %.2e m\nmachine_stall_skipped %lld count\n"
         "machine_stall_stops %lld count\n", g_off_max, (long long)g_l.st.skipped,
         (long long)g_b.rep.stops);
  assert_int_equal(g_l.st.skipped, 0);
  assert_int_equal(g_b.rep.steps, STEPS);
  assert_true(g_off_max < 1e-6);
  assert_int_equal(g_b.rep.stops, 0);
  assert_int_equal(g_b.rep.apart_events + g_b.rep.hold_events, 0);
  assert_int_equal(g_b.rep.silent_events, 1);  /* the bridge woke first: it saw the silence */
  nds_world_free(w);
}

/* The whole machine stalls for 0.25 s, longer than the commands' timeout and than the
 * newest 0.15 s that a replay publishes: once the bridge wakes first, once the executor
 * sends first. Every deadline still gets its world step on the executor's trajectory (to
 * 1 um), no reflex stops the arm and it never holds: the frozen commander's silence counts
 * from the wake-up (BRIDGE_STALL_S). The steps older than 0.15 s publish nothing: one gap in
 * the ROBOT_STATE seq per stall, no ring drop. */
static void test_lab_long_stall(void **state) {
  (void)state;
  nds_world *w = lab_bridge();
  /* The executor's brake past the last plan's segment, within what the arm takes radially
   * (nudge-up --world lab gives it 2.8 m/s^2, at which this brake loads joint 2 to 7.53
   * rad/s^2 against 7.499: decisions#long-stall). */
  g_ec.v_max = 0.65, g_ec.a_max = 2.0;
  stall_loop_init();
  enum { STEPS = 900, S4 = 300, S4_END = 550, S5 = 600, S5_END = 850 };
  int64_t next = (int64_t)(T0 * 1e9);
  drained d = {0};
  g_feed_every = 0;
  for (int k = 0; k < STEPS; k++) {
    if ((k >= S4 && k < S4_END) || (k >= S5 && k < S5_END)) continue;  /* all asleep */
    const int bridge_first = k == S4_END;
    if (bridge_first) stall_wake(k, &next, &d);
    const bridge_cmd c = live_send(k);
    nd_mailbox_post(&g_b.cmd, &c, sizeof c);
    if (!bridge_first) stall_wake(k, &next, &d);
    g_ref = g_ex;
  }
  const long quiet = (S4_END - S4 + S5_END - S5) - 2 * (long)llround(BRIDGE_PUBLISH_S * 1e3);
  printf("long_stall_setpoint_off_max %.2e m\nlong_stall_skipped %lld count\n"
         "long_stall_stops %lld count\nlong_stall_unpublished %lld count\n", g_off_max,
         (long long)g_l.st.skipped, (long long)g_b.rep.stops, (long long)g_b.rep.unpublished);
  assert_int_equal(g_l.st.skipped, 0);
  assert_int_equal(g_b.rep.steps, STEPS);
  assert_true(g_off_max < 1e-6);
  assert_int_equal(g_b.rep.stops, 0);
  assert_int_equal(g_b.rep.apart_events + g_b.rep.hold_events, 0);
  assert_int_equal(d.mode, NUDGE_ROBOT_STATE_T_MODE_TRACKING);
  assert_true(labs((long)g_b.rep.unpublished - quiet) <= 2);
  assert_int_equal(d.states, STEPS - g_b.rep.unpublished);
  assert_int_equal(d.seq_gaps, 2);
  assert_int_equal(atomic_load(&g_b.out.dropped), 0);

  /* Then the executor falls silent for good: its last command goes stale and the robot
   * holds where the sphere is. A stall after that revives no command: it holds on. */
  enum { GONE_END = 1500, S6 = 1200, S6_END = 1400, HELD_FROM = 1050 };
  int held = 1;
  for (int k = STEPS; k < GONE_END; k++) {
    if (k >= S6 && k < S6_END) continue;
    stall_wake(k, &next, &d);
    if (k >= HELD_FROM) held &= g_b.holding;
  }
  printf("long_stall_gone_hold_events %lld count\n", (long long)g_b.rep.hold_events);
  assert_true(held);
  assert_int_equal(g_b.rep.hold_events, 1);
  assert_int_equal(g_b.rep.stops, 0);
  assert_int_equal(d.mode, NUDGE_ROBOT_STATE_T_MODE_HOLDING);
  nds_world_free(w);
}

static void test_step_allocates_nothing(void **state) {
  (void)state;
  char err[256];
  nds_world_cfg wc;
  nds_world_cfg_default(&wc);
  nds_world *w = nds_world_create(&wc, err, sizeof err);
  if (!w) fail_msg("%s", err);
  bridge_loop_init(&g_b, w, 0.1);
  memset(&g_l, 0, sizeof g_l);
  nd_rtloop_cfg_default(&g_l.cfg);
  g_l.cfg.policy = ND_RT_CATCH_UP;
  g_l.fn = bridge_loop_tick;
  g_l.ctx = &g_b;
  nd_mailbox_init(&g_l.stats);
  nd_jitter_reset(&g_l.jit);

  enum { STEPS = 100000, TRACK = 1000, STALE = 4000, BACK = 6000, FULL = 9000 };
  drained d = {0};
  int64_t next = (int64_t)(T0 * 1e9);
  double x = -0.10, y = 0.0;
  long held_still = 0, tracked = 0;
  window_open();
  for (long k = 0; k < STEPS;) {
    const double now = T0 + 1e-3 * (double)k;
    /* Commands from TRACK to STALE and again from BACK: a slow circle of 5 cm. */
    if ((k >= TRACK && k < STALE) || k >= BACK) {
      x = -0.10 + 0.05 * sin(1e-3 * (double)k);
      y = 0.05 * (1 - cos(1e-3 * (double)k));
      post_cmd(now, x, y);
    }
    /* A PLACE clear of the sphere's circle: placed inside the counted window. */
    if (k >= 2000 && !g_b.pl_version) {
      const bridge_place pl = {1, {0.10, 0.10, 0.3}, 0.01, now};
      nd_mailbox_post(&g_b.place, &pl, sizeof pl);
    }
    /* Every 997th wake-up comes 7.5 ms late: the loop catches up step by step. */
    const double late = k % 997 == 0 ? 7.5e-3 : 2e-5;
    const int64_t now_ns = next + (int64_t)(late * 1e9);
    nd_rtloop_wake(&g_l, &next, now_ns, U0 + (now_ns - (int64_t)(T0 * 1e9)) / 1000);
    k = (long)llround(((double)next * 1e-9 - T0) * 1e3);
    if (k >= FULL && k < FULL + 400) continue;  /* the consumer stalls: the ring fills */
    drain(&d);
    /* Holding: at the last setpoint once the commands stopped, once the sphere settled. */
    if (k > STALE + 1200 && k < BACK) held_still += hypot(d.ee[0] - g_b.hold[0], d.ee[1] - g_b.hold[1]) < 1e-3;
    if (k > TRACK + 500 && k < STALE) tracked += hypot(d.ee[0] - x, d.ee[1] - y) < 0.01;
  }
  window_close();
  char seen[256];
  window_list(seen, sizeof seen, 0, N_FN);
  const long n_calls = window_sum(0, N_FN);
  printf("bridge_loop_calls %ld count (%s)\n", n_calls, seen);
  printf("bridge_loop_steps %lld count, robot states %ld, frames %ld, ring drops %llu\n",
         (long long)g_b.rep.steps, d.states, d.frames,
         (unsigned long long)atomic_load(&g_b.out.dropped));
  assert_int_equal(n_calls, 0);
  /* Every deadline stepped (the late wake-ups caught up), one state per step. */
  assert_int_equal(g_b.rep.steps, g_l.st.cycles);
  assert_true(g_b.rep.steps >= STEPS);
  assert_int_equal(g_l.st.skipped, 0);
  assert_int_equal(g_b.rs_seq, g_b.rep.steps);
  /* The stalled consumer lost messages only to the full ring (every step's state and
   * every frame is either encoded or counted as a drop), and those show as seq gaps. */
  const int64_t lost = (g_b.rs_seq - g_b.rep.robot_states) + (g_b.mc_seq - g_b.rep.frames);
  assert_true(lost > 0);
  assert_int_equal(lost, (int64_t)atomic_load(&g_b.out.dropped));
  assert_true(d.seq_gaps >= 1);
  /* MOCAP at 240 Hz of the 1 kHz steps, each stamped with its step's time. */
  assert_near((double)g_b.mc_seq / (double)g_b.rep.steps, 0.24, 1e-3);
  assert_int_equal(d.late_frames, 0);
  /* Tracking while fresh, following the last command once they stop, holding where the
   * sphere is when it went stale, tracking again. */
  assert_true(tracked > (STALE - TRACK - 500) * 0.95);
  assert_true(held_still > (BACK - STALE - 1200) * 0.95);
  assert_int_equal(g_b.rep.silent_events, 1);  /* 20 ms after the commands stopped */
  assert_int_equal(g_b.rep.hold_events, 1);    /* and the hold when they went stale */
  assert_int_equal(g_b.rep.apart_events, 0);
  assert_int_equal(g_b.holding, 0);
  assert_int_equal(g_b.rep.places, 1);
  nds_world_free(w);
}

/* PLACE on the lab world. A pose the sphere sits in waits: the object stays. The executor
 * takes the sphere 12 cm away; the object is put there only once the sphere has stopped,
 * its surface at least the PLACE's clear from the pose's sides (not as it passes that
 * clear on its way), and the motion capture shows it there, at rest, within its noise; no
 * reflex stops the arm. A PLACE whose pose the sphere keeps to is dropped after
 * NUDGE_PLACE_T_WAIT, the object left where it was. */
static void test_lab_place(void **state) {
  (void)state;
  nds_world *w = lab_bridge();
  drained d = {0};
  const bridge_place first = {7, {-0.10, 0.02, 0.3}, 0.01, T0};
  nd_mailbox_post(&g_b.place, &first, sizeof first);
  int k = 0, placed_at = -1, clear_at = -1;
  double v_at_place = INFINITY;  /* the sphere's speed the placing step went by */
  double obj0[3] = {0}, half[3], r;
  nds_world_sizes(w, half, &r);
  const nd_release_box at = {-0.10, 0.02, 0.3, {half[0], half[1]}};
  for (; k < 2500; k++) {
    const double t = 1e-3 * k;
    if (k == 500) exec_plan(t, (const double[4]){-0.10, -0.12, 0.0, 0.0}, 1.0);
    const bridge_cmd c = exec_send(t);
    nd_mailbox_post(&g_b.cmd, &c, sizeof c);
    const double v_before = g_b.ee_speed;
    bridge_loop_step(&g_b, T0 + t, U0 + (int64_t)k * 1000);
    drain(&d);
    if (k == 450) memcpy(obj0, d.obj, sizeof obj0);
    if (placed_at < 0 && g_b.rep.places) placed_at = k, v_at_place = v_before;
    double ee[2], n[2];
    nds_world_ee(w, ee);
    if (clear_at < 0 && nd_release_gap(&at, r, ee, n) >= 0.01) clear_at = k;
  }
  printf("clear_after %.3f s, place_after %.3f s at %.4f m/s (the move 0.5-1.5 s), gap %.4f m, "
         "object seen at (%.4f, %.4f, %.3f)\n", 1e-3 * clear_at, 1e-3 * placed_at, v_at_place,
         g_b.rep.place_gap, d.obj[0], d.obj[1], d.obj[2]);
  /* Waited while the sphere was in the way, and while it moved: the object at the start
   * (origin) until then. */
  assert_true(hypot(obj0[0], obj0[1]) < 1e-3);
  assert_true(clear_at > 500 && clear_at < 1400);
  assert_true(placed_at > 1400 && placed_at < 2500);
  assert_true(v_at_place < BRIDGE_PLACE_REST);
  assert_int_equal(g_b.rep.places, 1);
  assert_int_equal(g_b.rep.place_id, 7);
  assert_true(g_b.rep.place_gap > 0.05);
  assert_true(hypot(d.obj[0] + 0.10, d.obj[1] - 0.02) < 1e-3);
  assert_near(d.obj[2], 0.3, 0.01);
  assert_int_equal(g_b.rep.stops, 0);

  /* The sphere rests at (-0.10, -0.12): a pose around it is never clear. */
  const bridge_place blocked = {8, {-0.10, -0.12, 0.0}, 0.01, T0 + 1e-3 * k};
  nd_mailbox_post(&g_b.place, &blocked, sizeof blocked);
  for (int j = 0; j < 200; j++, k++) {
    const bridge_cmd c = exec_send(1e-3 * k);
    nd_mailbox_post(&g_b.cmd, &c, sizeof c);
    /* The clock jumps past the wait at the 100th step. */
    bridge_loop_step(&g_b, T0 + 1e-3 * k + (j >= 100 ? NUDGE_PLACE_T_WAIT : 0.0),
                     U0 + (int64_t)k * 1000);
    drain(&d);
    if (j == 99) assert_int_equal(g_b.rep.places_dropped, 0);
  }
  assert_int_equal(g_b.rep.places_dropped, 1);
  assert_int_equal(g_b.rep.places, 1);
  assert_int_equal(g_b.rep.place_id, 8);
  assert_true(g_b.rep.place_gap < 0.0);
  assert_true(hypot(d.obj[0] + 0.10, d.obj[1] - 0.02) < 1e-3);
  assert_int_equal(g_b.rep.stops, 0);
  nds_world_free(w);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_step_allocates_nothing),
      cmocka_unit_test(test_lab_jittered_commands),
      cmocka_unit_test(test_lab_commander_silent),
      cmocka_unit_test(test_lab_machine_stall),
      cmocka_unit_test(test_lab_long_stall),
      cmocka_unit_test(test_lab_late_switch),
      cmocka_unit_test(test_lab_place),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
