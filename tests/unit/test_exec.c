/* Tests of nd_exec: continuity of the commanded trajectory across plan switches, limits
 * at every emitted setpoint, braking to rest when inputs go stale, plan rejection.
 *
 * Bounds used for consecutive setpoints dt apart: if |v| <= v_max, |a| <= a_max and
 * |j| <= j_max hold at every instant (what nd_exec guarantees), then |dp| <= v_max dt,
 * |dv| <= a_max dt and |da| <= j_max dt (= 6.5 m/s^2 per ms), across switches too,
 * because a switch continues p, v, a and j. Jerk itself is continuous at switches
 * (checked directly: the state just before and just after a new plan is equal).
 *
 * The tests of the limits run in a 200 m workspace (wide()), so that only the limits
 * decide; the workspace has tests of its own, with the default box. */
#include <string.h>

#include "nd_test.h"
#include "nd_exec.h"
#include "nd_math.h"
#include "nd_rng.h"

#define REL 1e-9

static double norm2(double x, double y) { return sqrt(x * x + y * y); }
static double comp(const double s[2][4], int k) { return norm2(s[0][k], s[1][k]); }

/* Figures gathered while running a sequence of setpoints. */
typedef struct {
  double peak[3];      /* max |v|, |a|, |j| seen */
  double step[3];      /* max |dp| / (v_max dt), |dv| / (a_max dt), |da| / (j_max dt) */
  long samples;
} run_stats;

/* Assert the limits at sample cur and the continuity bounds against prev, dt apart. */
static void check_sample(const nd_exec_cfg *cfg, const double prev[2][4],
                         const double cur[2][4], double dt, run_stats *st) {
  const double lim[3] = {cfg->v_max, cfg->a_max, cfg->j_max};
  for (int k = 0; k < 3; k++) {
    const double m = comp(cur, k + 1);
    if (!(m <= lim[k] * (1.0 + REL)))
      fail_msg("derivative %d norm %.17g exceeds limit %g", k + 1, m, lim[k]);
    if (m > st->peak[k]) st->peak[k] = m;
    if (dt > 0.0) {
      const double d = norm2(cur[0][k] - prev[0][k], cur[1][k] - prev[1][k]);
      const double r = d / (lim[k] * dt);
      /* 1e-6: sample times near 1e5 s are rounded to ~1e-11 s, dt is the nominal step. */
      if (!(r <= 1.0 + 1e-6))
        fail_msg("step of derivative %d: %.17g over dt %.6g is %.6f x the bound", k, d, dt,
                 r);
      if (r > st->step[k]) st->step[k] = r;
    }
  }
  st->samples++;
}

/* The default limits in a workspace no test of the limits reaches. */
static nd_exec_cfg wide(void) {
  nd_exec_cfg c = nd_exec_cfg_default();
  c.ws_lo[0] = c.ws_lo[1] = -100.0;
  c.ws_hi[0] = c.ws_hi[1] = 100.0;
  return c;
}

static void assert_state_equal(const double a[2][4], const double b[2][4]) {
  for (int ax = 0; ax < 2; ax++)
    for (int k = 0; k < 4; k++)
      assert_near(a[ax][k], b[ax][k], 1e-9 * (1.0 + fabs(a[ax][k])));
}

/* A random keypoint in a square of side span m about 0 with speed up to v_max. */
static void random_key(nd_rng *r, const nd_exec_cfg *cfg, double span, double key[4]) {
  const double speed = cfg->v_max * nd_rng_uniform(r);
  const double dir = 2.0 * ND_PI * nd_rng_uniform(r);
  key[0] = span * (nd_rng_uniform(r) - 0.5);
  key[1] = span * (nd_rng_uniform(r) - 0.5);
  key[2] = speed * cos(dir);
  key[3] = speed * sin(dir);
}

/* Next measured step length: 1 ms +- 0.2 ms, with a 5 ms overrun now and then. */
static double next_dt(nd_rng *r) {
  if (nd_rng_uniform(r) < 0.01) return 0.005;
  return 0.001 + 0.0004 * (nd_rng_uniform(r) - 0.5);
}

static void test_cfg(void **state) {
  (void)state;
  nd_exec_cfg cfg = nd_exec_cfg_default();
  char err[128] = "";
  assert_near(cfg.v_max, 1.7, 0.0);
  assert_near(cfg.a_max, 13.0, 0.0);
  assert_near(cfg.j_max, 6500.0, 0.0);
  assert_int_equal(nd_exec_cfg_check(&cfg, err, sizeof err), ND_EXEC_OK);
  cfg.stretch = 1.0;
  assert_int_equal(nd_exec_cfg_check(&cfg, err, sizeof err), ND_EXEC_EINVAL);
  assert_non_null(strstr(err, "stretch"));
  cfg = nd_exec_cfg_default();
  cfg.a_max = NAN;
  assert_int_equal(nd_exec_cfg_check(&cfg, err, sizeof err), ND_EXEC_EINVAL);
  assert_non_null(strstr(err, "a_max"));
  cfg = nd_exec_cfg_default();
  cfg.t_max = cfg.t_min;
  assert_int_equal(nd_exec_cfg_check(&cfg, err, sizeof err), ND_EXEC_EINVAL);
  /* The workspace: the planner's box by default; finite, lo < hi, margin >= 0. */
  cfg = nd_exec_cfg_default();
  assert_true(cfg.ws_lo[0] == -0.5 && cfg.ws_lo[1] == -0.5 && cfg.ws_hi[0] == 0.5 &&
              cfg.ws_hi[1] == 0.5 && cfg.ws_margin == 0.04);
  const double bad_lo[4] = {NAN, 0.5, -INFINITY, 0.6};
  for (int i = 0; i < 4; i++) {
    cfg = nd_exec_cfg_default();
    cfg.ws_lo[i & 1] = bad_lo[i];
    assert_int_equal(nd_exec_cfg_check(&cfg, err, sizeof err), ND_EXEC_EINVAL);
    assert_non_null(strstr(err, "workspace"));
  }
  cfg = nd_exec_cfg_default();
  cfg.ws_margin = -0.01;
  assert_int_equal(nd_exec_cfg_check(&cfg, err, sizeof err), ND_EXEC_EINVAL);
  assert_non_null(strstr(err, "margin"));
  /* Brakes at a_max unless brake_a_max says less; it cannot be negative or NaN. */
  cfg = nd_exec_cfg_default();
  assert_true(cfg.brake_a_max == 0.0);
  assert_near(nd_exec_stale_brake_a(&cfg), cfg.a_max, 0.0);
  cfg.brake_a_max = 2.0;
  assert_near(nd_exec_stale_brake_a(&cfg), 2.0, 0.0);
  cfg.brake_a_max = 2.0 * cfg.a_max;
  assert_near(nd_exec_stale_brake_a(&cfg), cfg.a_max, 0.0);
  const double bad_brake[2] = {-1.0, NAN};
  for (int i = 0; i < 2; i++) {
    cfg.brake_a_max = bad_brake[i];
    assert_int_equal(nd_exec_cfg_check(&cfg, err, sizeof err), ND_EXEC_EINVAL);
    assert_non_null(strstr(err, "brake_a_max"));
  }
  assert_string_equal(nd_exec_mode_name(ND_EXEC_HOLD), "holding");
}

/* The continuous-time bounds must lie above a dense sampling and not far above it. */
static void test_bounds(void **state) {
  (void)state;
  nd_rng r;
  nd_rng_seed(&r, 7, 0);
  double worst_slack[3] = {0, 0, 0};
  for (int trial = 0; trial < 200; trial++) {
    double s0[2][4], p1[2], v1[2];
    for (int ax = 0; ax < 2; ax++) {
      s0[ax][ND_P] = nd_rng_uniform(&r) - 0.5;
      s0[ax][ND_V] = 2.0 * (nd_rng_uniform(&r) - 0.5);
      s0[ax][ND_A] = 20.0 * (nd_rng_uniform(&r) - 0.5);
      s0[ax][ND_J] = 5000.0 * (nd_rng_uniform(&r) - 0.5);
      p1[ax] = nd_rng_uniform(&r) - 0.5;
      v1[ax] = 2.0 * (nd_rng_uniform(&r) - 0.5);
    }
    nd_snap_seg seg;
    nd_snap_seg_make(&seg, s0, p1, v1, 0.05 + nd_rng_uniform(&r));
    double b[3], dense[3] = {0, 0, 0};
    nd_exec_seg_bounds(&seg, 64, b);
    const int n = 20000;
    for (int i = 0; i <= n; i++) {
      double s[2][4];
      nd_snap_seg_eval(&seg, seg.T * i / n, s);
      for (int k = 0; k < 3; k++) dense[k] = fmax(dense[k], comp(s, k + 1));
    }
    for (int k = 0; k < 3; k++) {
      if (!(b[k] >= dense[k])) fail_msg("bound %d: %.17g below sampled %.17g", k, b[k], dense[k]);
      worst_slack[k] = fmax(worst_slack[k], b[k] / dense[k] - 1.0);
    }
  }
  printf("exec_bound_slack_v %.4f %%\nexec_bound_slack_a %.4f %%\nexec_bound_slack_j %.4f %%\n",
         100 * worst_slack[0], 100 * worst_slack[1], 100 * worst_slack[2]);
  for (int k = 0; k < 3; k++) assert_true(worst_slack[k] < 0.05);
}

/* brake_a_max bounds the brake begun when the inputs go stale, while the tracking segment
 * and the brake planned after it keep a_max: the stale brake departs where the segment's
 * own acceleration is within the cap. */
static void test_brake_cap(void **state) {
  (void)state;
  nd_exec_cfg cfg = wide();
  cfg.a_max = 6.0, cfg.brake_a_max = 2.0;
  nd_exec ex;
  const double p[2] = {0.0, 0.0}, key[4] = {0.4, 0.0, 1.0, 0.0};
  char err[128];
  nd_exec_init(&ex, p, 0.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, key, 0.3, err, sizeof err), ND_EXEC_OK);
  /* The planned brake from (1 m/s, 0, 0): the min-snap stop's 15/8 v / a at a_max. */
  assert_near(ex.brake.T, 1.875 * 1.0 / 6.0, 0.01 * 1.875 / 6.0);
  const double t_rest_planned = ex.t_brake + ex.brake.T;
  double out[2][4], seg_a = 0.0, brake_a = 0.0, t_stale = 0.0;
  for (double t = 0.0; t < ex.t_brake; t += 1e-3) {
    nd_exec_eval(&ex, t, out);
    if (comp(out, ND_A) > seg_a) seg_a = comp(out, ND_A), t_stale = t;
  }
  assert_true(seg_a > 3.0 && seg_a <= 6.0);
  /* Stale where the segment accelerates hardest, beyond the cap: no brake departs there. */
  double t = 0.0;
  int mode = ND_EXEC_TRACK;
  for (; mode != ND_EXEC_HOLD; t += 1e-3) {
    mode = nd_exec_step(&ex, &cfg, t, t >= t_stale, out);
    if (t >= ex.t_brake) brake_a = fmax(brake_a, comp(out, ND_A));
  }
  printf("exec_brake_cap: segment up to %.2f m/s^2, stale at %.3f s, brake from %.3f s up to "
         "%.3f m/s^2 (cap 2), rest at %.3f s (planned %.3f s)\n", seg_a, t_stale, ex.t_brake,
         brake_a, t, t_rest_planned);
  assert_true(brake_a > 1.5 && brake_a <= 2.0);
  assert_true(ex.t_brake > t_stale && t < t_rest_planned + 1.875 * 1.0 / 2.0);
  /* Without the cap the same stale brake decelerates harder. */
  cfg.brake_a_max = 0.0;
  nd_exec_init(&ex, p, 0.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, key, 0.3, err, sizeof err), ND_EXEC_OK);
  double free_a = 0.0;
  mode = ND_EXEC_TRACK;
  for (t = 0.0; mode != ND_EXEC_HOLD; t += 1e-3) {
    mode = nd_exec_step(&ex, &cfg, t, t >= t_stale, out);
    if (t >= ex.t_brake) free_a = fmax(free_a, comp(out, ND_A));
  }
  assert_true(free_a > 2.5);
}

static void test_init_holds(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  nd_exec ex;
  const double p[2] = {0.3, -0.2};
  nd_exec_init(&ex, p, 50.0);
  double out[2][4];
  for (int i = 0; i < 10; i++) {
    assert_int_equal(nd_exec_step(&ex, &cfg, 50.0 + 0.001 * i, i & 1, out), ND_EXEC_HOLD);
    assert_true(out[0][ND_P] == 0.3 && out[1][ND_P] == -0.2);
    for (int k = 1; k < 4; k++) assert_true(out[0][k] == 0.0 && out[1][k] == 0.0);
  }
}

/* A modest plan is followed as asked: no stretch, keypoint reached at T exactly. */
static void test_reaches_key(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  nd_exec ex;
  const double p[2] = {0.0, 0.0}, key[4] = {0.05, 0.02, 0.1, 0.0};
  char err[128];
  nd_exec_init(&ex, p, 10.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 10.0, key, 0.3, err, sizeof err), ND_EXEC_OK);
  assert_int_equal(ex.mode, ND_EXEC_TRACK);
  assert_near(ex.seg.T, 0.3, 0.0);
  double out[2][4];
  assert_int_equal(nd_exec_step(&ex, &cfg, 10.3 - 1e-9, 0, out), ND_EXEC_TRACK);
  assert_near(out[0][ND_P], 0.05, 1e-9);
  assert_near(out[1][ND_P], 0.02, 1e-9);
  assert_near(out[0][ND_V], 0.1, 1e-6);
  assert_near(out[1][ND_V], 0.0, 1e-6);
}

/* A far keypoint is stretched just enough: within limits, close to the binding one. */
static void test_stretches(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  nd_exec ex;
  const double p[2] = {0.0, 0.0}, key[4] = {0.8, 0.0, 0.0, 0.0};
  char err[128];
  nd_exec_init(&ex, p, 0.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, key, 0.3, err, sizeof err), ND_EXEC_OK);
  double b[3];
  nd_exec_seg_bounds(&ex.seg, 64, b);
  const double load = fmax(b[0] / cfg.v_max, fmax(b[1] / cfg.a_max, b[2] / cfg.j_max));
  printf("exec_stretch_T %.4f s (asked 0.3)\nexec_stretch_load %.4f\n", ex.seg.T, load);
  assert_true(ex.seg.T > 0.3);
  assert_true(load <= 1.0 && load > 0.95);
  double out[2][4], prev[2][4];
  run_stats st = {{0}, {0}, 0};
  nd_exec_eval(&ex, 0.0, prev);
  for (int i = 1; i <= 2000; i++) {
    nd_exec_step(&ex, &cfg, 0.001 * i, 0, out);
    check_sample(&cfg, prev, out, 0.001, &st);
    memcpy(prev, out, sizeof prev);
  }
  assert_int_equal(ex.mode, ND_EXEC_HOLD);
  assert_near(out[0][ND_P], 0.8, 1e-9);

  /* A 0.2 mm hop asked in 10 ms: here jerk is the binding limit. */
  const double hop[4] = {0.8002, 0.0, 0.0, 0.0};
  assert_int_equal(nd_exec_plan(&ex, &cfg, 2.0, hop, 0.01, err, sizeof err), ND_EXEC_OK);
  nd_exec_seg_bounds(&ex.seg, 64, b);
  printf("exec_hop_T %.4f s (asked 0.01)\nexec_hop_jerk_load %.4f\n", ex.seg.T,
         b[2] / cfg.j_max);
  assert_true(ex.seg.T > 0.01);
  assert_true(b[2] <= cfg.j_max && b[2] > 0.95 * cfg.j_max && b[1] < cfg.a_max);
}

/* Near full speed (1.69 m/s: exactly v_max cannot be certified, see nd_exec.h) at the
 * end of a segment, then nothing new: the planned brake stops in 15/8 v / a_max =
 * 0.2438 s (the min-snap stop; a bang-bang stop would take v / a_max = 0.130 s, with
 * unbounded jerk), speed never rising, then holds exactly still. */
static void test_brake_from_full_speed(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  nd_exec ex;
  const double p[2] = {0.0, 0.0}, key[4] = {0.6, 0.0, 1.69, 0.0};
  char err[128];
  nd_exec_init(&ex, p, 0.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, key, 0.5, err, sizeof err), ND_EXEC_OK);
  const double t_end = ex.t_seg + ex.seg.T, tb_min = 1.875 * 1.69 / 13.0;
  double out[2][4], prev[2][4];
  run_stats st = {{0}, {0}, 0};
  double t = 0.0, t_rest = -1.0, v_prev = 1e9;
  nd_exec_eval(&ex, 0.0, prev);
  while (t < t_end + 1.0) {
    t += 0.001;
    const int mode = nd_exec_step(&ex, &cfg, t, 0, out);
    check_sample(&cfg, prev, out, 0.001, &st);
    if (t > t_end) {
      const double v = comp(out, ND_V);
      assert_true(v <= v_prev + 1e-12);
      v_prev = v;
    }
    if (mode == ND_EXEC_HOLD && t_rest < 0.0) t_rest = t;
    if (mode == ND_EXEC_HOLD) assert_true(memcmp(out[0], prev[0], sizeof out[0]) == 0 ||
                                          t == t_rest);
    memcpy(prev, out, sizeof prev);
  }
  const double tb = t_rest - t_end;
  printf("exec_brake_full_speed %.4f s (min-snap bound %.4f)\n", tb, tb_min);
  assert_true(tb >= tb_min - 0.001 && tb <= tb_min * 1.01 + 0.001);
  assert_near(ex.brake.T, tb_min, 0.01 * tb_min);
  for (int k = 1; k < 4; k++) assert_true(out[0][k] == 0.0 && out[1][k] == 0.0);
  /* The rest position is where the stop's average speed (v / 2) carries it. */
  assert_near(out[0][ND_P], 0.6 + 0.5 * 1.69 * ex.brake.T, 1e-9);
}

/* Plans every 50 ms at a jittery 1 kHz, with stale spells and resumption. near > 0:
 * keypoints within near metres of the setpoint at up to 0.3 m/s (the pushing regime);
 * near == 0: anywhere in a square of side span at up to v_max (adversarial). Refusals
 * must be for the limits (not reachable) or the workspace (counted by kind), and every
 * setpoint must lie within the workspace plus its margin. */
typedef struct {
  int plans, accepted, stretched, stops, resumed_from_hold;
  int box_key, box_seg, box_brake;   /* refused for the workspace: keypoint, segment, brake */
  double worst_rest, worst_plan_stretch;
  double worst_out;                  /* farthest setpoint beyond the box, m */
  long outside;                      /* setpoints beyond the box plus margin */
  run_stats st;
} switch_stats;

static void run_switching(const nd_exec_cfg *cfgp, uint64_t seed, double near, double span,
                          int steps, switch_stats *out_stats) {
  const nd_exec_cfg cfg = *cfgp;
  nd_rng r;
  nd_rng_seed(&r, seed, 1);
  nd_exec ex;
  const double p0[2] = {0.0, 0.0};
  const double t0 = 1e5; /* a monotonic clock some days after boot */
  char err[160];
  nd_exec_init(&ex, p0, t0);

  switch_stats S;
  memset(&S, 0, sizeof S);
  double prev[2][4], out[2][4];
  nd_exec_eval(&ex, t0, prev);
  double t = t0, next_plan = t0, stale_until = -1.0, promise = -1.0, t_stale = 0.0;
  int at_rest = 0;
  for (int i = 0; i < steps; i++) {
    const double dt = next_dt(&r);
    t += dt;
    const int stale = t < stale_until;
    if (!stale && t >= next_plan) {
      double key[4], before[2][4], after[2][4];
      const int was_hold = ex.mode == ND_EXEC_HOLD;
      random_key(&r, &cfg, span, key);
      if (near > 0.0) {
        key[0] = prev[0][ND_P] + 2.0 * near * (key[0]);
        key[1] = prev[1][ND_P] + 2.0 * near * (key[1]);
        key[2] *= 0.3 / cfg.v_max;
        key[3] *= 0.3 / cfg.v_max;
      }
      const double T = near > 0.0 || nd_rng_uniform(&r) < 0.5 ? 0.3 : 0.1;
      nd_exec_eval(&ex, t, before);
      const nd_exec snapshot = ex;
      const int rc = nd_exec_plan(&ex, &cfg, t, key, T, err, sizeof err);
      S.plans++;
      if (rc == ND_EXEC_OK) {
        S.accepted++;
        S.stretched += ex.seg.T > T;
        S.worst_plan_stretch = fmax(S.worst_plan_stretch, ex.seg.T / T);
        S.resumed_from_hold += was_hold;
        nd_exec_eval(&ex, t, after);
        assert_state_equal(before, after); /* continuous in p, v, a and j */
        assert_int_equal(ex.mode, ND_EXEC_TRACK);
      } else if (rc == ND_EXEC_EBOX) {
        if (strstr(err, "outside the workspace")) S.box_key++;
        else if (strstr(err, "the segment to keypoint")) S.box_seg++;
        else if (strstr(err, "the brake after the segment")) S.box_brake++;
        else fail_msg("workspace refusal without a known reason: %s", err);
        assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);
      } else {
        assert_int_equal(rc, ND_EXEC_ELIMIT);
        assert_non_null(strstr(err, "not reachable"));
        assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);
      }
      next_plan = t + 0.05;
      if (nd_rng_uniform(&r) < 0.05) stale_until = t + 0.4 + 0.4 * nd_rng_uniform(&r);
    }
    if (stale && promise < 0.0 && ex.mode == ND_EXEC_TRACK) {
      /* Going stale now; rest is due no later than the brake planned at the end. */
      promise = ex.t_brake + ex.brake.T;
      t_stale = t;
      at_rest = 0;
      S.stops++;
    }
    const int mode = nd_exec_step(&ex, &cfg, t, stale, out);
    check_sample(&cfg, prev, out, dt, &S.st);
    for (int ax = 0; ax < 2; ax++) {
      const double beyond = fmax(cfg.ws_lo[ax] - out[ax][ND_P], out[ax][ND_P] - cfg.ws_hi[ax]);
      S.worst_out = fmax(S.worst_out, beyond);
      if (beyond > cfg.ws_margin + 1e-12) S.outside++;
    }
    if (stale && mode == ND_EXEC_HOLD) {
      for (int k = 1; k < 4; k++) assert_true(out[0][k] == 0.0 && out[1][k] == 0.0);
      if (at_rest) assert_true(memcmp(out, prev, sizeof out) == 0); /* exactly still */
      if (!at_rest && promise > 0.0) {
        assert_true(t < promise + dt); /* the first sample at rest is on time */
        S.worst_rest = fmax(S.worst_rest, t - t_stale);
      }
      at_rest = 1;
    }
    /* A stale spell can begin after the segment ended (braking already): at_rest must not
     * carry over from the last spell then. */
    if (!stale) promise = -1.0, at_rest = 0;
    memcpy(prev, out, sizeof prev);
  }
  *out_stats = S;
}

static void print_switch_stats(const char *name, const switch_stats *S) {
  printf("exec_%s_plans %d\nexec_%s_accepted %d\nexec_%s_stretched %d\n"
         "exec_%s_max_stretch %.3f x\nexec_%s_stale_stops %d\nexec_%s_resumed_from_hold %d\n"
         "exec_%s_worst_time_to_rest %.4f s\n",
         name, S->plans, name, S->accepted, name, S->stretched, name, S->worst_plan_stretch,
         name, S->stops, name, S->resumed_from_hold, name, S->worst_rest);
  printf("exec_%s_peak_speed %.6f m/s\nexec_%s_peak_accel %.6f m/s^2\n"
         "exec_%s_peak_jerk %.1f m/s^3\n", name, S->st.peak[0], name, S->st.peak[1], name,
         S->st.peak[2]);
  printf("exec_%s_step_ratio_p %.4f\nexec_%s_step_ratio_v %.4f\nexec_%s_step_ratio_a %.4f\n",
         name, S->st.step[0], name, S->st.step[1], name, S->st.step[2]);
}

static void test_random_switching(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  switch_stats S;
  run_switching(&cfg, 12345, 0.0, 1.0, 10000, &S);
  print_switch_stats("random", &S);
  /* The limits must have been binding, or this test proved nothing about them. */
  assert_true(S.st.peak[0] > 0.95 * cfg.v_max);
  assert_true(S.st.peak[1] > 0.95 * cfg.a_max);
  assert_true(S.stretched > S.accepted / 2);
  /* Unrelated keypoints at full speed every 50 ms: one min-snap segment from a state at
   * the limits often cannot reach them at any duration; most must still be taken. */
  assert_true(S.accepted > S.plans / 2);
  assert_true(S.stops >= 5 && S.resumed_from_hold >= 3);
  /* Every stop began from at most v_max: the end brake takes ~0.245 s at most, and a
   * stop never waits for more than the rest of a segment stretched to t_max. */
  assert_true(S.worst_rest <= cfg.t_max + 0.25);
}

static void test_pushing_switching(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  switch_stats S;
  run_switching(&cfg, 777, 0.1, 1.0, 10000, &S);
  print_switch_stats("pushing", &S);
  assert_int_equal(S.accepted, S.plans); /* the working regime: nothing refused */
  assert_true(S.stops >= 3);
  assert_true(S.worst_rest < 0.3);
}

/* The default workspace against adversarial plans: keypoints in a 1.2 m square (so some
 * lie outside the 1 m box) at up to v_max, stale spells included. Keypoints outside and
 * segments overshooting are refused (a brake leaving the margin is rarer here than a plan
 * the limits refuse first: test_workspace has one), many plans are still taken, and no
 * setpoint (segments, planned brakes, brakes begun on going stale) gets beyond the box by
 * more than the margin. */
static void test_workspace_switching(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  switch_stats S;
  run_switching(&cfg, 4242, 0.0, 1.2, 60000, &S);
  print_switch_stats("workspace", &S);
  printf("exec_workspace_refused_keypoint %d\nexec_workspace_refused_segment %d\n"
         "exec_workspace_refused_brake %d\nexec_workspace_worst_beyond_box %.4f m (margin %g)\n",
         S.box_key, S.box_seg, S.box_brake, S.worst_out, cfg.ws_margin);
  assert_int_equal(S.outside, 0);
  assert_true(S.worst_out <= cfg.ws_margin);
  assert_true(S.worst_out > 0.0);  /* the margin was used: the check was not vacuous */
  assert_true(S.box_key > 0 && S.box_seg > 0);
  assert_true(S.accepted > S.plans / 3);
  assert_true(S.stops >= 5);
}

/* A keypoint outside the box is refused, names itself and the box, and changes nothing:
 * the setpoint goes on where it was going and never toward the refused keypoint. One
 * inside is followed. A keypoint on the edge is taken while its brake stays within the
 * margin, and refused once the brake would carry the robot beyond it. */
static void test_workspace(void **state) {
  (void)state;
  const nd_exec_cfg cfg = nd_exec_cfg_default();
  nd_exec ex, snapshot;
  const double p[2] = {0.1, 0.0};
  char err[200];
  double out[2][4];
  nd_exec_init(&ex, p, 0.0);
  snapshot = ex;
  const double out_key[4] = {0.8, 0.0, 0.0, 0.0};
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, out_key, 0.3, err, sizeof err), ND_EXEC_EBOX);
  assert_non_null(strstr(err, "keypoint 0 (0.800, 0.000)"));
  assert_non_null(strstr(err, "x [-0.500, 0.500], y [-0.500, 0.500]"));
  assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);
  for (int i = 1; i <= 500; i++) {
    assert_int_equal(nd_exec_step(&ex, &cfg, 0.001 * i, 0, out), ND_EXEC_HOLD);
    assert_true(out[0][ND_P] == 0.1 && out[1][ND_P] == 0.0);
  }

  /* In the box: followed to the keypoint. */
  const double in_key[4] = {0.3, 0.1, 0.0, 0.0};
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.5, in_key, 0.3, err, sizeof err), ND_EXEC_OK);
  /* Refused mid-segment: the segment toward in_key goes on unchanged. */
  nd_exec_step(&ex, &cfg, 0.6, 0, out);
  snapshot = ex;
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.6, out_key, 0.3, err, sizeof err), ND_EXEC_EBOX);
  assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);
  for (int i = 1; i <= 400; i++) nd_exec_step(&ex, &cfg, 0.6 + 0.001 * i, 0, out);
  assert_int_equal(ex.mode, ND_EXEC_HOLD);
  assert_near(out[0][ND_P], 0.3, 1e-9);
  assert_near(out[1][ND_P], 0.1, 1e-9);

  /* Later keypoints count too. */
  const double keys[3][4] = {{0.3, 0.1, 0, 0}, {0.4, 0.2, 0, 0}, {0.45, -0.51, 0, 0}};
  assert_int_equal(nd_exec_keys_check(&cfg, keys, 2, err, sizeof err), ND_EXEC_OK);
  assert_int_equal(nd_exec_keys_check(&cfg, keys, 3, err, sizeof err), ND_EXEC_EBOX);
  assert_non_null(strstr(err, "keypoint 2 (0.450, -0.510)"));
  const double nan_keys[1][4] = {{NAN, 0.0, 0.0, 0.0}};
  assert_int_equal(nd_exec_keys_check(&cfg, nan_keys, 1, err, sizeof err), ND_EXEC_EBOX);

  /* On the edge moving outward: the brake travels 15/16 v^2 / a_max beyond it, 1.8 cm at
   * 0.5 m/s (taken), 7.2 cm at 1 m/s (beyond the 4 cm margin: refused). */
  const double edge_slow[4] = {0.5, 0.1, 0.5, 0.0}, edge_fast[4] = {0.5, 0.1, 1.0, 0.0};
  snapshot = ex;
  assert_int_equal(nd_exec_plan(&ex, &cfg, 1.0, edge_fast, 0.3, err, sizeof err),
                   ND_EXEC_EBOX);
  assert_non_null(strstr(err, "the brake after the segment to keypoint (0.500, 0.100)"));
  assert_non_null(strstr(err, "0.040 m margin"));
  assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 1.0, edge_slow, 0.3, err, sizeof err), ND_EXEC_OK);
  assert_true(ex.hold[0] > 0.5 && ex.hold[0] <= 0.5 + cfg.ws_margin);

  /* Going stale on a segment that runs along the edge at speed: braking at once would
   * stop 5.4 cm beyond x = -0.5, so the brake departs later (a candidate that stays
   * within the margin), and every setpoint to rest stays inside it. */
  const double corner[2] = {-0.5, -0.5};
  const double k1[4] = {-0.25, -0.4, 0.5, -0.1}, k2[4] = {-0.5, -0.05, 0.5, 0.8};
  nd_exec_init(&ex, corner, 0.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, k1, 0.5, err, sizeof err), ND_EXEC_OK);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.3, k2, 0.335, err, sizeof err), ND_EXEC_OK);
  double t = 0.595, x_min = 0.0;
  assert_int_equal(nd_exec_step(&ex, &cfg, t, 1, out), ND_EXEC_STOPPING);
  assert_true(ex.t_brake > t);
  while (ex.mode != ND_EXEC_HOLD && t < 2.0) {
    t += 0.001;
    nd_exec_step(&ex, &cfg, t, 1, out);
    x_min = fmin(x_min, out[0][ND_P]);
  }
  printf("exec_workspace_stale_brake_x_min %.4f m\n", x_min);
  assert_int_equal(ex.mode, ND_EXEC_HOLD);
  assert_true(x_min >= -0.5 - cfg.ws_margin);

  /* Started outside the box (the first measured position): nothing moves it further, and
   * no plan is taken, since the segment would begin beyond the margin. */
  const double far_p[2] = {0.7, 0.0};
  nd_exec_init(&ex, far_p, 2.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 2.0, in_key, 0.3, err, sizeof err), ND_EXEC_EBOX);
  assert_non_null(strstr(err, "the segment to keypoint (0.300, 0.100) reaches x = 0.700"));
}

/* A fresh plan while braking, or from rest, starts continuously and tracks again. */
static void test_resume(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  nd_exec ex;
  const double p[2] = {0.0, 0.0}, key[4] = {0.3, 0.1, 0.5, 0.2};
  const double key2[4] = {-0.2, 0.2, 0.0, -0.4};
  char err[128];
  double out[2][4], prev[2][4], before[2][4], after[2][4];
  run_stats st = {{0}, {0}, 0};
  nd_exec_init(&ex, p, 0.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, key, 0.3, err, sizeof err), ND_EXEC_OK);
  nd_exec_eval(&ex, 0.0, prev);
  double t = 0.0;
  for (; t < 0.15; t += 0.001) {
    nd_exec_step(&ex, &cfg, t, 0, out);
    check_sample(&cfg, prev, out, t > 0 ? 0.001 : 0, &st);
    memcpy(prev, out, sizeof prev);
  }
  /* Stale mid-segment: stopping; a plan in the middle of the brake resumes. */
  for (int i = 0; i < 40; i++, t += 0.001) {
    assert_int_equal(nd_exec_step(&ex, &cfg, t, 1, out), ND_EXEC_STOPPING);
    check_sample(&cfg, prev, out, 0.001, &st);
    memcpy(prev, out, sizeof prev);
  }
  assert_true(comp(out, ND_V) > 0.01); /* still moving: this is a switch mid-brake */
  nd_exec_eval(&ex, t, before);
  assert_int_equal(nd_exec_plan(&ex, &cfg, t, key2, 0.3, err, sizeof err), ND_EXEC_OK);
  nd_exec_eval(&ex, t, after);
  assert_state_equal(before, after);
  assert_int_equal(nd_exec_step(&ex, &cfg, t, 0, out), ND_EXEC_TRACK);
  check_sample(&cfg, prev, out, 0.001, &st);
  memcpy(prev, out, sizeof prev);
  /* Stale again until at rest, then hold still, then resume from rest. */
  int mode = ND_EXEC_TRACK;
  for (int i = 0; i < 3000 && mode != ND_EXEC_HOLD; i++) {
    t += 0.001;
    mode = nd_exec_step(&ex, &cfg, t, 1, out);
    check_sample(&cfg, prev, out, 0.001, &st);
    memcpy(prev, out, sizeof prev);
  }
  assert_int_equal(mode, ND_EXEC_HOLD);
  for (int i = 0; i < 100; i++) {
    t += 0.001;
    nd_exec_step(&ex, &cfg, t, 1, out);
    assert_true(memcmp(out, prev, sizeof out) == 0);
  }
  nd_exec_eval(&ex, t, before);
  assert_int_equal(nd_exec_plan(&ex, &cfg, t, key, 0.3, err, sizeof err), ND_EXEC_OK);
  nd_exec_eval(&ex, t, after);
  assert_state_equal(before, after);
  const double t_end = ex.t_seg + ex.seg.T;
  while (t + 0.001 < t_end) {
    t += 0.001;
    assert_int_equal(nd_exec_step(&ex, &cfg, t, 0, out), ND_EXEC_TRACK);
    check_sample(&cfg, prev, out, 0.001, &st);
    memcpy(prev, out, sizeof prev);
  }
  nd_exec_eval(&ex, t_end - 1e-9, out);
  assert_near(out[0][ND_P], key[0], 1e-6);
  assert_near(out[1][ND_V], key[3], 1e-5);
}

/* nd_exec_heading_to: true only while a tracking segment runs toward that very keypoint,
 * also after the limits stretched it; not for another keypoint, after the segment's end,
 * while braking or holding. */
static void test_heading_to(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  nd_exec ex;
  const double p[2] = {0.06, -0.042}, key[4] = {0.085, -0.038, 0.25, 0.04};
  const double far[4] = {0.45, 0.3, 0.2, 0.0};
  char err[128];
  double out[2][4];
  nd_exec_init(&ex, p, 1.0);
  assert_false(nd_exec_heading_to(&ex, 1.0, key, 1e-6));  /* holding */
  assert_int_equal(nd_exec_plan(&ex, &cfg, 1.0, key, 0.25, err, sizeof err), ND_EXEC_OK);
  assert_true(nd_exec_heading_to(&ex, 1.0, key, 1e-6));
  assert_true(nd_exec_heading_to(&ex, 1.2, key, 1e-6));
  for (int k = 0; k < 4; k++) {
    double other[4];
    memcpy(other, key, sizeof other);
    other[k] += 1e-4;
    assert_false(nd_exec_heading_to(&ex, 1.1, other, 1e-6));
    assert_true(nd_exec_heading_to(&ex, 1.1, other, 2e-4));
  }
  assert_false(nd_exec_heading_to(&ex, 1.25, key, 1e-6));  /* the segment has ended */
  /* Stretched by the limits: still heading there, until the stretched end. */
  assert_int_equal(nd_exec_plan(&ex, &cfg, 1.0, far, 0.05, err, sizeof err), ND_EXEC_OK);
  assert_true(ex.seg.T > 0.2);
  assert_true(nd_exec_heading_to(&ex, 1.0 + 0.9 * ex.seg.T, far, 1e-6));
  /* Going stale: braking, so a plan to the same keypoint must start a segment again. */
  assert_int_equal(nd_exec_step(&ex, &cfg, 1.05, 1, out), ND_EXEC_STOPPING);
  assert_false(nd_exec_heading_to(&ex, 1.05, far, 1e-6));
}

/* What a receiver rebuilds from one setpoint and the future (nd_exec_future_eval) is
 * what the executor then commands: along the segment, through an early or planned brake
 * and into the hold, from any point on the way. */
static void check_future(const nd_exec *ex, double t) {
  nd_exec_future f;
  nd_exec_future_get(ex, &f);
  double sp[2][4], want[2][4], got[2][4];
  nd_exec_eval(ex, t, sp);
  for (double t1 = t; t1 < f.t_rest + 0.1; t1 += 0.0137) {
    nd_exec_eval(ex, t1, want);
    nd_exec_future_eval((const double(*)[4])sp, t, &f, t1, got);
    for (int ax = 0; ax < 2; ax++)
      for (int k = 0; k < 4; k++)
        if (!(fabs(got[ax][k] - want[ax][k]) <= 1e-7 * (1.0 + fabs(want[ax][k]))))
          fail_msg("rebuilt from t %.4f (mode %d, seg end %.4f, brake %.4f, rest %.4f): at t "
                   "%.4f axis %d derivative %d is %.12g, the executor commands %.12g", t,
                   ex->mode, f.t_seg_end, f.t_brake, f.t_rest, t1, ax, k, got[ax][k],
                   want[ax][k]);
  }
}

static void test_future(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  nd_rng r;
  nd_rng_seed(&r, 17, 3);
  nd_exec ex;
  const double p[2] = {0.0, 0.0};
  char err[128];
  double out[2][4];
  nd_exec_init(&ex, p, 0.0);
  check_future(&ex, 0.0);                       /* holding */
  double now = 0.0;
  for (int i = 0; i < 200; i++) {
    double key[4];
    random_key(&r, &cfg, 0.4, key);
    if (nd_exec_plan(&ex, &cfg, now, key, 0.1 + 0.3 * nd_rng_uniform(&r), err, sizeof err))
      continue;
    /* A point on the segment, maybe after an early brake (stale inputs) or past the
     * segment's end, where the planned brake runs. */
    const double u = nd_rng_uniform(&r);
    const double t = now + (ex.seg.T + 0.2) * nd_rng_uniform(&r);
    if (u < 0.3) nd_exec_step(&ex, &cfg, now + (t - now) * u, 1, out);
    nd_exec_step(&ex, &cfg, t, 0, out);
    check_future(&ex, t);
    now = t + 0.01;
    nd_exec_step(&ex, &cfg, now, 0, out);
  }
  /* A piece with under ND_EXEC_REBUILD_MIN left is taken as ended: still within a few
   * micrometres of the executor. */
  const double key[4] = {0.1, 0.05, 0.2, 0.0};
  nd_exec_init(&ex, p, now);
  assert_int_equal(nd_exec_plan(&ex, &cfg, now, key, 0.2, err, sizeof err), ND_EXEC_OK);
  nd_exec_future f;
  nd_exec_future_get(&ex, &f);
  const double t = f.t_seg_end - 0.5 * ND_EXEC_REBUILD_MIN;
  double sp[2][4], want[2][4], got[2][4];
  nd_exec_eval(&ex, t, sp);
  nd_exec_eval(&ex, f.t_seg_end + 0.01, want);
  nd_exec_future_eval((const double(*)[4])sp, t, &f, f.t_seg_end + 0.01, got);
  assert_near(got[0][ND_P], want[0][ND_P], 1e-5);
  assert_near(got[1][ND_P], want[1][ND_P], 1e-5);
}

/* Bad plans are refused with a message and change nothing. */
static void test_rejects(void **state) {
  (void)state;
  const nd_exec_cfg cfg = wide();
  nd_exec ex, snapshot;
  const double p[2] = {0.1, 0.1}, ok[4] = {0.2, 0.1, 0.3, 0.0};
  char err[160];
  double out[2][4];
  nd_exec_init(&ex, p, 0.0);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.0, ok, 0.3, err, sizeof err), ND_EXEC_OK);
  nd_exec_step(&ex, &cfg, 0.1, 0, out);
  snapshot = ex;

  const double nan_key[4] = {0.2, NAN, 0.0, 0.0};
  err[0] = 0;
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, nan_key, 0.3, err, sizeof err),
                   ND_EXEC_EINVAL);
  assert_non_null(strstr(err, "non-finite"));
  assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);

  const double inf_key[4] = {0.2, 0.1, INFINITY, 0.0};
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, inf_key, 0.3, err, sizeof err),
                   ND_EXEC_EINVAL);
  assert_int_equal(nd_exec_plan(&ex, &cfg, NAN, ok, 0.3, err, sizeof err), ND_EXEC_EINVAL);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, ok, NAN, err, sizeof err), ND_EXEC_EINVAL);
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, ok, 0.0, err, sizeof err), ND_EXEC_EINVAL);
  assert_non_null(strstr(err, "not positive"));
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, ok, -0.3, err, sizeof err), ND_EXEC_EINVAL);
  assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);

  const double fast[4] = {0.2, 0.1, 1.5, 1.5};
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, fast, 0.3, err, sizeof err),
                   ND_EXEC_ELIMIT);
  assert_non_null(strstr(err, "v_max"));
  const double at_limit[4] = {0.2, 0.1, 1.7, 0.0};
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, at_limit, 0.3, err, sizeof err),
                   ND_EXEC_ELIMIT);
  assert_non_null(strstr(err, "too close to v_max"));
  const double far[4] = {100.0, 0.0, 0.0, 0.0};
  assert_int_equal(nd_exec_plan(&ex, &cfg, 0.101, far, 0.3, err, sizeof err),
                   ND_EXEC_ELIMIT);
  assert_non_null(strstr(err, "not reachable"));
  assert_true(memcmp(&snapshot, &ex, sizeof ex) == 0);

  /* Time that goes back or is not a number repeats the last setpoint. */
  double again[2][4];
  nd_exec_step(&ex, &cfg, 0.05, 0, again);
  assert_true(memcmp(again, out, sizeof out) == 0);
  nd_exec_step(&ex, &cfg, NAN, 0, again);
  assert_true(memcmp(again, out, sizeof out) == 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_cfg),
      cmocka_unit_test(test_bounds),
      cmocka_unit_test(test_init_holds),
      cmocka_unit_test(test_reaches_key),
      cmocka_unit_test(test_stretches),
      cmocka_unit_test(test_brake_from_full_speed),
      cmocka_unit_test(test_brake_cap),
      cmocka_unit_test(test_random_switching),
      cmocka_unit_test(test_pushing_switching),
      cmocka_unit_test(test_resume),
      cmocka_unit_test(test_heading_to),
      cmocka_unit_test(test_future),
      cmocka_unit_test(test_workspace),
      cmocka_unit_test(test_workspace_switching),
      cmocka_unit_test(test_rejects),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
