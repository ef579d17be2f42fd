/* test_cem: nd_cem finds known minima within a stated budget, is bitwise reproducible
 * (also across worker counts), keeps samples in bounds, colours its noise, keeps its
 * elites, follows its population schedule and rejects bad configurations. */
#include "nd_test.h"

#include <stdlib.h>
#include <string.h>

#include "nd_cem.h"
#include "nd_pool.h"

#define D8 8

/* ---- objectives ---- */

static double rosenbrock(const double *x, int n) {
  double f = 0.0;
  for (int i = 0; i < n - 1; i++) {
    double a = x[i + 1] - x[i] * x[i], b = 1.0 - x[i];
    f += 100.0 * a * a + b * b;
  }
  return f;
}

static const double bowl_centre[D8] = {0.5, -1.2, 0.3, 2.0, -0.7, 1.1, 0.0, -2.4};

static double bowl(const double *x) {
  double f = 0.0;
  for (int i = 0; i < D8; i++) f += (x[i] - bowl_centre[i]) * (x[i] - bowl_centre[i]);
  return f;
}

static int bowl_cost(void *ctx, const double *x, int n, double *cost) {
  (void)ctx;
  for (int k = 0; k < n; k++) cost[k] = bowl(x + k * D8);
  return 0;
}

static int rosen_cost(void *ctx, const double *x, int n, double *cost) {
  (void)ctx;
  for (int k = 0; k < n; k++) cost[k] = rosenbrock(x + k * D8, D8);
  return 0;
}

static double max_abs_diff(const double *a, const double *b, int n) {
  double m = 0.0;
  for (int i = 0; i < n; i++) m = fmax(m, fabs(a[i] - b[i]));
  return m;
}

static void fill(double *v, int n, double value) {
  for (int i = 0; i < n; i++) v[i] = value;
}

/* The iCEM configuration used by several tests (Pinneri et al.'s defaults, elites 10%). */
static void icem_cfg(nd_cem_cfg *cfg, int horizon, int block, int pop, int iters) {
  nd_cem_cfg_default(cfg, horizon, block, pop, iters);
  cfg->elite_frac = 0.1;
  cfg->keep_frac = 0.3;
  cfg->pop_decay = 1.25;
  cfg->momentum = 0.1;
  cfg->noise_beta = 2.0;
  cfg->inject_mean = 1;
}

/* ---- optimisation ---- */

/* Plain CEM, 8-D bowl centred off the origin up to 2.4 away, within bounds [-4, 4].
 * Budget: pop 128, 30 iterations (3840 evaluations), start mean 0 std 2.
 * Measured over seeds 1..10: f <= 7e-11, |x - c|inf <= 5.3e-6. */
static void test_bowl_plain_cem(void **state) {
  (void)state;
  double lo[D8], hi[D8], m0[D8], s0[D8];
  fill(lo, D8, -4.0);
  fill(hi, D8, 4.0);
  fill(m0, D8, 0.0);
  fill(s0, D8, 2.0);
  for (uint64_t seed = 1; seed <= 3; seed++) {
    nd_cem_cfg cfg;
    nd_cem_cfg_default(&cfg, D8, 1, 128, 30);
    cfg.lower = lo;
    cfg.upper = hi;
    nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
    assert_non_null(cem);
    nd_cem_set_dist(cem, m0, s0);
    nd_rng r;
    nd_rng_seed(&r, seed, 0);
    assert_int_equal(nd_cem_run(cem, &r, bowl_cost, NULL), 0);
    assert_int_equal(nd_cem_evals(cem), 128 * 30);
    double dx = max_abs_diff(nd_cem_best(cem), bowl_centre, D8);
    double dm = max_abs_diff(nd_cem_mean(cem), bowl_centre, D8);
    printf("bowl plain CEM seed %d: f %.3g |x-c|inf %.3g |mean-c|inf %.3g\n", (int)seed,
           nd_cem_best_cost(cem), dx, dm);
    assert_true(nd_cem_best_cost(cem) < 1e-6);
    assert_near(nd_cem_best_cost(cem), bowl(nd_cem_best(cem)), 0.0);
    assert_true(dx < 1e-3);
    assert_true(dm < 1e-3);
    nd_cem_free(cem);
  }
}

/* iCEM (colored noise beta 2, keep 0.3, decay 1.25, momentum 0.1, mean injection) on
 * 8-D Rosenbrock from mean 0 std 1 in [-4, 4]. Budget: pop 128, 10 iterations a run,
 * 400 warm-started runs, each restarting std at 0.01 (~234k evaluations).
 * Measured over seeds 1..10: f <= 3.4e-6, |x - 1|inf <= 3e-3. With white noise
 * (beta 0) the same budget stalls in the valley around f ~ 1e-2. */
static void test_rosenbrock_icem(void **state) {
  (void)state;
  double lo[D8], hi[D8], m0[D8], s0[D8], sr[D8], one[D8];
  fill(lo, D8, -4.0);
  fill(hi, D8, 4.0);
  fill(m0, D8, 0.0);
  fill(s0, D8, 1.0);
  fill(sr, D8, 0.01);
  fill(one, D8, 1.0);
  for (uint64_t seed = 1; seed <= 2; seed++) {
    nd_cem_cfg cfg;
    icem_cfg(&cfg, D8, 1, 128, 10);
    cfg.lower = lo;
    cfg.upper = hi;
    nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
    assert_non_null(cem);
    nd_cem_set_dist(cem, m0, s0);
    nd_rng r;
    nd_rng_seed(&r, seed, 0);
    double prev = INFINITY;
    long evals = 0;
    int worse = 0, iter_worse = 0;
    for (int run = 0; run < 400; run++) {
      if (run > 0) nd_cem_shift(cem, 0, sr);
      assert_int_equal(nd_cem_run(cem, &r, rosen_cost, NULL), 0);
      evals += nd_cem_evals(cem);
      /* kept elites carry the best across runs and iterations: never worse */
      worse += nd_cem_best_cost(cem) > prev;
      for (int i = 1; i < cfg.iters; i++)
        iter_worse += nd_cem_iter_best(cem, i) > nd_cem_iter_best(cem, i - 1);
      prev = nd_cem_best_cost(cem);
    }
    double dx = max_abs_diff(nd_cem_best(cem), one, D8);
    printf("rosenbrock iCEM seed %d: f %.3g |x-1|inf %.3g evals %ld\n", (int)seed,
           nd_cem_best_cost(cem), dx, evals);
    assert_int_equal(worse, 0);
    assert_int_equal(iter_worse, 0);
    assert_true(nd_cem_best_cost(cem) < 1e-4);
    assert_true(dx < 1e-2);
    nd_cem_free(cem);
  }
}

/* ---- reproducibility ---- */

typedef struct {
  nd_pool *pool;
  const double *x;
  double *cost;
} par_ctx;

static void par_task(void *vctx, int task, int worker) {
  (void)worker;
  par_ctx *c = (par_ctx *)vctx;
  c->cost[task] = rosenbrock(c->x + task * D8, D8);
}

static int par_cost(void *vctx, const double *x, int n, double *cost) {
  par_ctx *c = (par_ctx *)vctx;
  c->x = x;
  c->cost = cost;
  nd_pool_run(c->pool, n, par_task, c);
  return 0;
}

typedef struct {
  double best[D8], mean[D8], std[D8], best_cost;
  long evals;
} outcome;

/* Five warm-started iCEM runs (shift 1 step between runs) from seed, costs on a pool
 * of nworkers. */
static void icem_outcome(uint64_t seed, int nworkers, outcome *out) {
  nd_cem_cfg cfg;
  icem_cfg(&cfg, D8, 1, 64, 4);
  double m0[D8], s0[D8];
  fill(m0, D8, 0.0);
  fill(s0, D8, 0.5);
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  nd_cem_set_dist(cem, m0, s0);
  par_ctx c;
  c.pool = nd_pool_create(nworkers, NULL, 0);
  assert_non_null(c.pool);
  nd_rng r;
  nd_rng_seed(&r, seed, 3);
  out->evals = 0;
  for (int run = 0; run < 5; run++) {
    if (run > 0) nd_cem_shift(cem, 1, s0);
    assert_int_equal(nd_cem_run(cem, &r, par_cost, &c), 0);
    out->evals += nd_cem_evals(cem);
  }
  memcpy(out->best, nd_cem_best(cem), sizeof out->best);
  memcpy(out->mean, nd_cem_mean(cem), sizeof out->mean);
  memcpy(out->std, nd_cem_std(cem), sizeof out->std);
  out->best_cost = nd_cem_best_cost(cem);
  nd_pool_free(c.pool);
  nd_cem_free(cem);
}

static int same_outcome(const outcome *a, const outcome *b) {
  return memcmp(a->best, b->best, sizeof a->best) == 0 &&
         memcmp(a->mean, b->mean, sizeof a->mean) == 0 &&
         memcmp(a->std, b->std, sizeof a->std) == 0 &&
         memcmp(&a->best_cost, &b->best_cost, sizeof a->best_cost) == 0 && a->evals == b->evals;
}

static void test_same_seed_bitwise(void **state) {
  (void)state;
  outcome a, b, c;
  icem_outcome(42, 1, &a);
  icem_outcome(42, 1, &b);
  icem_outcome(43, 1, &c);
  assert_true(same_outcome(&a, &b));
  assert_false(same_outcome(&a, &c));  /* the seed matters, so the check above means something */
}

static void test_workers_identical(void **state) {
  (void)state;
  outcome one, two, three;
  icem_outcome(7, 1, &one);
  icem_outcome(7, 2, &two);
  icem_outcome(7, 3, &three);
  assert_true(same_outcome(&one, &two));
  assert_true(same_outcome(&one, &three));
}

/* ---- bounds ---- */

#define BH 6
#define BB 2
#define BD (BH * BB)

typedef struct {
  const double *lo, *hi;
  long outside, on_bound, seen;
} bounds_ctx;

static int bounds_cost(void *vctx, const double *x, int n, double *cost) {
  bounds_ctx *c = (bounds_ctx *)vctx;
  for (int k = 0; k < n; k++) {
    const double *v = x + k * BD;
    double f = 0.0;
    for (int i = 0; i < BD; i++) {
      c->outside += !(v[i] >= c->lo[i] && v[i] <= c->hi[i]);
      c->on_bound += v[i] == c->lo[i] || v[i] == c->hi[i];
      c->seen++;
      f += (v[i] - 3.0) * (v[i] - 3.0);  /* pulls everything past the upper bounds */
    }
    cost[k] = f;
  }
  return 0;
}

/* An iCEM optimiser over BH x BB within [lo, hi] (NULL: unbounded). */
static nd_cem *bounded_cem(const double *lo, const double *hi) {
  nd_cem_cfg cfg;
  icem_cfg(&cfg, BH, BB, 50, 4);
  cfg.lower = lo;
  cfg.upper = hi;
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  return cem;
}

static void test_samples_within_bounds(void **state) {
  (void)state;
  double lo[BD], hi[BD], m0[BD], s0[BD];
  for (int i = 0; i < BD; i++) {
    lo[i] = -1.0 - 0.1 * i;  /* bounds differ per dim, so a shift moves values across them */
    hi[i] = 0.2 + 0.15 * i;
    m0[i] = 5.0;             /* outside: set_dist must clip it */
    s0[i] = 2.0;
  }
  nd_cem *cem = bounded_cem(lo, hi);
  nd_cem_set_dist(cem, m0, s0);
  for (int i = 0; i < BD; i++) assert_near(nd_cem_mean(cem)[i], hi[i], 0.0);
  bounds_ctx c = {lo, hi, 0, 0, 0};
  nd_rng r;
  nd_rng_seed(&r, 5, 0);
  for (int run = 0; run < 6; run++) {
    if (run > 0) nd_cem_shift(cem, 1 + run % 3, s0);
    assert_int_equal(nd_cem_run(cem, &r, bounds_cost, &c), 0);
    const double *m = nd_cem_mean(cem);
    for (int i = 0; i < BD; i++) assert_true(m[i] >= lo[i] && m[i] <= hi[i]);
  }
  assert_int_equal(c.outside, 0);
  assert_true(c.on_bound > c.seen / 10);  /* clipping really happened */
  nd_cem_free(cem);
}

/* New bounds take effect at once: the mean is clipped into them, every later sample keeps
 * to them, and bounds that cannot hold (lower above upper, NaN) are refused, the old kept. */
static void test_set_bounds(void **state) {
  (void)state;
  double lo[BD], hi[BD], lo2[BD], hi2[BD], m0[BD], s0[BD];
  for (int i = 0; i < BD; i++) {
    lo[i] = -4.0, hi[i] = 4.0;
    lo2[i] = -0.5, hi2[i] = 0.25 + 0.05 * i;
    m0[i] = 0.0, s0[i] = 2.0;
  }
  nd_cem *cem = bounded_cem(lo, hi);
  nd_cem_set_dist(cem, m0, s0);
  nd_rng r;
  nd_rng_seed(&r, 9, 0);
  bounds_ctx wide = {lo, hi, 0, 0, 0};
  assert_int_equal(nd_cem_run(cem, &r, bounds_cost, &wide), 0);
  for (int i = 0; i < BD; i++) assert_true(nd_cem_mean(cem)[i] > hi2[i]);  /* pulled toward 3 */
  char err[160] = "";
  assert_int_equal(nd_cem_set_bounds(cem, lo2, hi2, err, sizeof(err)), 0);
  for (int i = 0; i < BD; i++) assert_near(nd_cem_mean(cem)[i], hi2[i], 0.0);
  bounds_ctx tight = {lo2, hi2, 0, 0, 0};
  for (int run = 0; run < 3; run++) {
    nd_cem_shift(cem, 1, s0);
    assert_int_equal(nd_cem_run(cem, &r, bounds_cost, &tight), 0);
  }
  assert_int_equal(tight.outside, 0);
  assert_true(tight.seen > 0);
  double bad_lo[BD];
  memcpy(bad_lo, lo2, sizeof(bad_lo));
  bad_lo[3] = 1.0;  /* above hi2[3] */
  assert_int_equal(nd_cem_set_bounds(cem, bad_lo, hi2, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "dim 3"));
  bad_lo[3] = NAN;
  assert_int_equal(nd_cem_set_bounds(cem, bad_lo, hi2, err, sizeof(err)), -1);
  nd_cem_shift(cem, 1, s0);
  tight.outside = 0;
  assert_int_equal(nd_cem_run(cem, &r, bounds_cost, &tight), 0);
  assert_int_equal(tight.outside, 0);
  nd_cem_free(cem);
  /* An optimiser created unbounded has no bounds to replace. */
  cem = bounded_cem(NULL, NULL);
  assert_int_equal(nd_cem_set_bounds(cem, lo2, hi2, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "created with both"));
  nd_cem_free(cem);
}

/* ---- colored noise ---- */

#define NH 32
#define NB 2

typedef struct {
  double lag1, cross, var_min, var_max;
} noise_stats;

static int noise_cost(void *vctx, const double *x, int n, double *cost) {
  noise_stats *s = (noise_stats *)vctx;
  double lag = 0.0, cross = 0.0, var[NH * NB] = {0};
  for (int k = 0; k < n; k++) {
    const double *v = x + k * NH * NB;
    for (int t = 0; t < NH; t++) {
      for (int b = 0; b < NB; b++) {
        var[t * NB + b] += v[t * NB + b] * v[t * NB + b];
        if (t + 1 < NH) lag += v[t * NB + b] * v[(t + 1) * NB + b];
      }
      cross += v[t * NB] * v[t * NB + 1];
    }
    cost[k] = 0.0;
  }
  /* mean 0 and std 1 are known, so raw moments are the statistics */
  s->lag1 = lag / ((double)n * (NH - 1) * NB);
  s->cross = cross / ((double)n * NH);
  s->var_min = INFINITY;
  s->var_max = 0.0;
  for (int i = 0; i < NH * NB; i++) {
    s->var_min = fmin(s->var_min, var[i] / n);
    s->var_max = fmax(s->var_max, var[i] / n);
  }
  return 0;
}

static noise_stats noise_with_beta(double beta) {
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, NH, NB, 4000, 1);
  cfg.noise_beta = beta;
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  double m0[NH * NB], s0[NH * NB];
  fill(m0, NH * NB, 0.0);
  fill(s0, NH * NB, 1.0);
  nd_cem_set_dist(cem, m0, s0);
  nd_rng r;
  nd_rng_seed(&r, 11, 0);
  noise_stats s;
  assert_int_equal(nd_cem_run(cem, &r, noise_cost, &s), 0);
  nd_cem_free(cem);
  return s;
}

/* Measured (4000 samples x 2 components, horizon 32): lag-1 autocorrelation 0.00 for
 * beta 0, ~0.58 for beta 1, ~0.89 for beta 2 (0.890 is the value of the exact
 * 1/f^2 spectrum on 32 steps); per-step variance within 6% of 1 (sampling error). */
static void test_colored_noise(void **state) {
  (void)state;
  noise_stats w = noise_with_beta(0.0), p = noise_with_beta(1.0), b = noise_with_beta(2.0);
  printf("lag-1 autocorrelation: beta 0 %.4f, beta 1 %.4f, beta 2 %.4f\n", w.lag1, p.lag1,
         b.lag1);
  printf("per-step variance: beta 0 [%.3f, %.3f], beta 2 [%.3f, %.3f]\n", w.var_min,
         w.var_max, b.var_min, b.var_max);
  assert_near(w.lag1, 0.0, 0.02);
  assert_true(p.lag1 > w.lag1 + 0.3);
  assert_true(b.lag1 > p.lag1 + 0.2);
  assert_near(b.lag1, 0.890, 0.03);
  /* components of a step are independent; every step has unit variance */
  assert_near(w.cross, 0.0, 0.05);
  assert_near(b.cross, 0.0, 0.05);
  assert_near(w.var_min, 1.0, 0.08);
  assert_near(w.var_max, 1.0, 0.08);
  assert_near(b.var_min, 1.0, 0.08);
  assert_near(b.var_max, 1.0, 0.08);
}

/* ---- kept elites across runs ---- */

#define KH 6
#define KB 2
#define KD (KH * KB)

typedef struct {
  int phase;  /* target moves one step per phase, like a receding horizon */
} track_ctx;

static double track(const double *x, int phase) {
  double f = 0.0;
  for (int t = 0; t < KH; t++)
    for (int b = 0; b < KB; b++) {
      double g = sin(0.7 * (t + phase) + b);
      f += (x[t * KB + b] - g) * (x[t * KB + b] - g);
    }
  return f;
}

static int track_cost(void *vctx, const double *x, int n, double *cost) {
  const track_ctx *c = (const track_ctx *)vctx;
  for (int k = 0; k < n; k++) cost[k] = track(x + k * KD, c->phase);
  return 0;
}

/* Run 1 at phase 0; shift by one step with a wide std; run 2 at phase 1. Return run 2's
 * best cost and, in *kept_cost, the phase-1 cost of run 1's best shifted by hand. */
static double two_runs(double keep_frac, double *kept_cost) {
  nd_cem_cfg cfg;
  icem_cfg(&cfg, KH, KB, 16, 3);
  cfg.keep_frac = keep_frac;
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  double m0[KD], s0[KD], wide[KD];
  fill(m0, KD, 0.0);
  fill(s0, KD, 0.5);
  fill(wide, KD, 3.0);
  nd_cem_set_dist(cem, m0, s0);
  nd_rng r;
  nd_rng_seed(&r, 9, 0);
  track_ctx c = {0};
  for (int i = 0; i < 5; i++) {  /* a few runs at phase 0 to get a good elite */
    nd_cem_shift(cem, 0, s0);
    assert_int_equal(nd_cem_run(cem, &r, track_cost, &c), 0);
  }
  double b[KD];
  for (int t = 0; t < KH; t++)
    for (int k = 0; k < KB; k++) b[t * KB + k] = nd_cem_best(cem)[(t + 1 < KH ? t + 1 : KH - 1) * KB + k];
  *kept_cost = track(b, 1);

  nd_cem_shift(cem, 1, wide);
  c.phase = 1;
  assert_int_equal(nd_cem_run(cem, &r, track_cost, &c), 0);
  double best = nd_cem_best_cost(cem);
  nd_cem_free(cem);
  return best;
}

static void test_keep_never_worse(void **state) {
  (void)state;
  double kept, kept0;
  double with_keep = two_runs(0.3, &kept);
  double without = two_runs(0.0, &kept0);
  printf("after shift: shifted elite %.4g, best with keep %.4g, best without keep %.4g\n", kept,
         with_keep, without);
  assert_true(with_keep <= kept);
  /* the scenario is hard enough that fresh samples alone do worse, so the line above
   * really depends on the kept elite */
  assert_true(without > kept0);
}

/* ---- schedule, injection, evaluations ---- */

typedef struct {
  nd_cem *cem;
  int calls;
  int sizes[16];
  int iters;
  int mean_injected;  /* last row of the last batch equals the current mean */
} sched_ctx;

static int sched_cost(void *vctx, const double *x, int n, double *cost) {
  sched_ctx *c = (sched_ctx *)vctx;
  if (c->calls < 16) c->sizes[c->calls] = n;
  c->calls++;
  if (c->calls % c->iters == 0)
    c->mean_injected = memcmp(x + (n - 1) * 4, nd_cem_mean(c->cem), 4 * sizeof(double)) == 0;
  for (int k = 0; k < n; k++) cost[k] = x[k * 4] * x[k * 4] + x[k * 4 + 3] * x[k * 4 + 3];
  return 0;
}

static void check_schedule(double decay, const int *run1, const int *run2, int evals1) {
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 2, 2, 100, 4);
  cfg.elite_frac = 0.1;  /* 10 elites */
  cfg.keep_frac = 0.3;   /* 3 kept */
  cfg.pop_decay = decay;
  cfg.inject_mean = 1;
  sched_ctx c;
  memset(&c, 0, sizeof c);
  c.iters = 4;
  c.cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(c.cem);
  nd_rng r;
  nd_rng_seed(&r, 1, 0);
  assert_int_equal(nd_cem_run(c.cem, &r, sched_cost, &c), 0);
  assert_int_equal(nd_cem_evals(c.cem), evals1);
  assert_true(c.mean_injected);
  c.mean_injected = 0;
  assert_int_equal(nd_cem_run(c.cem, &r, sched_cost, &c), 0);
  assert_true(c.mean_injected);
  assert_int_equal(c.calls, 8);
  assert_int_equal(nd_cem_max_batch(c.cem), 104);
  for (int i = 0; i < 8; i++) assert_true(c.sizes[i] <= nd_cem_max_batch(c.cem));
  for (int i = 0; i < 4; i++) {
    assert_int_equal(c.sizes[i], run1[i]);
    assert_int_equal(c.sizes[4 + i], run2[i]);
  }
  nd_cem_free(c.cem);
}

static void test_population_schedule(void **state) {
  (void)state;
  /* 100 * 1.5^-i = 100, 66, 44, 29 fresh; +1 mean in the last iteration; kept elites are
   * re-evaluated only in the first iteration of a run (+3) */
  const int a1[4] = {100, 66, 44, 30}, a2[4] = {103, 66, 44, 30};
  check_schedule(1.5, a1, a2, 240);
  /* strong decay hits the floor of twice the elite count */
  const int b1[4] = {100, 20, 20, 21}, b2[4] = {103, 20, 20, 21};
  check_schedule(10.0, b1, b2, 161);
}

static void test_shift(void **state) {
  (void)state;
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 4, 2, 10, 1);
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  const double m[8] = {0, 1, 2, 3, 4, 5, 6, 7}, s[8] = {1, 1, 1, 1, 1, 1, 1, 1};
  const double s2[8] = {2, 2, 2, 2, 2, 2, 2, 2};
  nd_cem_set_dist(cem, m, s);
  nd_cem_shift(cem, 1, s2);
  const double e1[8] = {2, 3, 4, 5, 6, 7, 6, 7};
  assert_memory_equal(nd_cem_mean(cem), e1, sizeof e1);
  assert_memory_equal(nd_cem_std(cem), s2, sizeof s2);
  nd_cem_shift(cem, 10, NULL);  /* past the end: every step takes the last one */
  const double e2[8] = {6, 7, 6, 7, 6, 7, 6, 7};
  assert_memory_equal(nd_cem_mean(cem), e2, sizeof e2);
  assert_memory_equal(nd_cem_std(cem), s2, sizeof s2);  /* NULL keeps std */
  nd_cem_free(cem);
}

/* nd_cem_map rewrites the mean and the kept elites and clips them into the bounds. */
static void add_one(void *ctx, double *x) {
  int *calls = ctx;
  (*calls)++;
  for (int i = 0; i < 4; i++) x[i] += 1.0;
}

static int zero_cost(void *ctx, const double *x, int n, double *cost) {
  (void)ctx, (void)x;
  for (int i = 0; i < n; i++) cost[i] = 0.0;
  return 0;
}

static void test_map(void **state) {
  (void)state;
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 2, 2, 8, 1);
  cfg.keep_frac = 0.5;
  const double lo[4] = {-10, -10, -10, -10}, hi[4] = {10, 10, 10, 1.5};
  cfg.lower = lo, cfg.upper = hi;
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  const double m[4] = {0, 1, 2, 3}, s[4] = {1e-3, 1e-3, 1e-3, 1e-3};
  nd_cem_set_dist(cem, m, s);
  int calls = 0;
  nd_cem_map(cem, add_one, &calls);
  assert_int_equal(calls, 1);  /* set_dist forgot the kept elites: the mean alone */
  const double e1[4] = {1, 2, 3, 1.5};
  assert_memory_equal(nd_cem_mean(cem), e1, sizeof e1);
  nd_rng r;
  nd_rng_seed(&r, 1, 1);
  assert_int_equal(nd_cem_run(cem, &r, zero_cost, NULL), 0);
  const double *mean = nd_cem_mean(cem);
  double before[4];
  memcpy(before, mean, sizeof before);
  calls = 0;
  nd_cem_map(cem, add_one, &calls);
  assert_true(calls > 1);  /* the mean and every kept elite */
  for (int i = 0; i < 4; i++) assert_near(nd_cem_mean(cem)[i], fmin(before[i] + 1.0, hi[i]), 1e-15);
  nd_cem_free(cem);
}

/* ---- elite selection: ties, non-finite costs, agreement with a full sort ---- */

#define SP 500

typedef struct {
  double x[SP + 8][3];
  double cost[SP + 8];
  int n;
} sel_ctx;

static int sel_cost(void *vctx, const double *x, int n, double *cost) {
  sel_ctx *c = (sel_ctx *)vctx;
  c->n = n;
  for (int k = 0; k < n; k++) {
    const double *v = x + k * 3;
    double f = floor(3.0 * fabs(v[0]));  /* coarse: many ties */
    if (v[1] > 1.5) f = NAN;
    else if (v[1] < -1.5) f = -INFINITY;  /* non-finite counts as +inf, even -inf */
    cost[k] = f;
    memcpy(c->x[k], v, sizeof c->x[k]);
    c->cost[k] = isfinite(f) ? f : INFINITY;
  }
  return 0;
}

static const double *sel_costs;

static int by_cost_then_index(const void *a, const void *b) {
  int i = *(const int *)a, j = *(const int *)b;
  if (sel_costs[i] < sel_costs[j]) return -1;
  if (sel_costs[i] > sel_costs[j]) return 1;
  return (i > j) - (i < j);
}

static void test_elite_selection(void **state) {
  (void)state;
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 1, 3, SP, 1);  /* 100 elites, no momentum */
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  static sel_ctx c;
  nd_rng r;
  nd_rng_seed(&r, 2, 0);
  assert_int_equal(nd_cem_run(cem, &r, sel_cost, &c), 0);
  assert_int_equal(c.n, SP);

  int order[SP];
  for (int i = 0; i < SP; i++) order[i] = i;
  sel_costs = c.cost;
  qsort(order, SP, sizeof(int), by_cost_then_index);
  const int K = 100;
  double m[3] = {0, 0, 0};
  for (int e = 0; e < K; e++)
    for (int d = 0; d < 3; d++) m[d] += c.x[order[e]][d];
  for (int d = 0; d < 3; d++) assert_near(nd_cem_mean(cem)[d], m[d] / K, 1e-12);
  assert_memory_equal(nd_cem_best(cem), c.x[order[0]], sizeof c.x[0]);
  assert_near(nd_cem_best_cost(cem), c.cost[order[0]], 0.0);
  assert_true(isfinite(nd_cem_best_cost(cem)));
  nd_cem_free(cem);
}

/* ---- update rule: momentum and std floor ---- */

typedef struct {
  double x[50][2];
  int n;
} upd_ctx;

static int upd_cost(void *vctx, const double *x, int n, double *cost) {
  upd_ctx *c = (upd_ctx *)vctx;
  c->n = n;
  for (int k = 0; k < n; k++) {
    c->x[k][0] = x[2 * k];
    c->x[k][1] = x[2 * k + 1];
    cost[k] = x[2 * k];
  }
  return 0;
}

/* step_std: along a slope the std follows the mean's steps and grows, where plain CEM's
 * shrinks; once the elites straddle the optimum it collapses like plain CEM's. A 1-D bowl
 * (x - 10)^2 from x = 0, std 1, Q 32, rho 0.2, as the theta fit runs it. */
static int bowl1_cost(void *ctx, const double *x, int n, double *cost) {
  const double t = *(const double *)ctx;
  for (int k = 0; k < n; k++) cost[k] = (x[k] - t) * (x[k] - t);
  return 0;
}

static void run_bowl1(int step_std, int iters, double *mean, double *std) {
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 1, 1, 32, iters);
  cfg.elite_frac = 0.2;
  cfg.step_std = step_std;
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  const double m0 = 0, s0 = 1;
  nd_cem_set_dist(cem, &m0, &s0);
  nd_rng r;
  nd_rng_seed(&r, 3, 0);
  static const double target = 10;
  assert_int_equal(nd_cem_run(cem, &r, bowl1_cost, (void *)&target), 0);
  *mean = nd_cem_mean(cem)[0];
  *std = nd_cem_std(cem)[0];
  nd_cem_free(cem);
}

static void test_step_std(void **state) {
  (void)state;
  double m_plain, s_plain, m_step, s_step;
  run_bowl1(0, 4, &m_plain, &s_plain);
  run_bowl1(1, 4, &m_step, &s_step);
  printf("after 4 iterations: plain mean %.3f std %.3f, step_std mean %.3f std %.3f\n",
         m_plain, s_plain, m_step, s_step);
  assert_true(m_plain < 3 && s_plain < 0.2);  /* frozen on the slope */
  assert_true(m_step > 2 * m_plain && s_step > 1);  /* still travelling, faster */
  run_bowl1(1, 16, &m_step, &s_step);
  printf("after 16 iterations: step_std mean %.6f std %.2e\n", m_step, s_step);
  assert_near(m_step, 10, 1e-2);
  assert_true(s_step < 1e-2);
}

/* step_gate: an optimum found inside wide samples is a short step in units of the sampling
 * std, so the std collapses to the elites' spread instead of following the step; along a
 * slope (steps of ~1.4 std) the gate changes nothing. One iteration on the bowl. */
static void one_step(double gate, double m0, double s0, double target, double *mean,
                     double *std) {
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 1, 1, 32, 1);
  cfg.elite_frac = 0.2;
  cfg.step_std = 2;
  cfg.step_gate = gate;
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  nd_cem_set_dist(cem, &m0, &s0);
  nd_rng r;
  nd_rng_seed(&r, 5, 0);
  assert_int_equal(nd_cem_run(cem, &r, bowl1_cost, (void *)&target), 0);
  *mean = nd_cem_mean(cem)[0];
  *std = nd_cem_std(cem)[0];
  nd_cem_free(cem);
}

static void test_step_gate(void **state) {
  (void)state;
  double m0, s0, m1, s1;
  /* Optimum 0.4 std away, inside the samples: same mean, the gated std is the elites'. */
  one_step(0, 0, 10, 4, &m0, &s0);
  one_step(1, 0, 10, 4, &m1, &s1);
  printf("inside: mean %.3f, std ungated %.3f, gated %.3f\n", m0, s0, s1);
  assert_true(m0 == m1);
  assert_near(m0, 4, 1.5);
  assert_true(s0 >= 2 * fabs(m0) * (1 - 1e-12));
  assert_true(s1 < 0.5 * s0 && s1 < 2);
  /* On a slope (optimum 10 std away) the step passes the gate: the std follows it. */
  one_step(0, 0, 1, 10, &m0, &s0);
  one_step(1, 0, 1, 10, &m1, &s1);
  printf("slope: mean %.3f, std ungated %.3f, gated %.3f\n", m0, s0, s1);
  assert_true(m0 > 1 && m0 == m1 && s0 == s1);
  assert_near(s1, 2 * m1, 1e-12);
  /* A gate below zero is refused. */
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 1, 1, 32, 1);
  cfg.step_gate = -1;
  char err[128] = "";
  assert_null(nd_cem_create(&cfg, err, sizeof(err)));
  assert_non_null(strstr(err, "step_gate"));
}

static void test_update_rule(void **state) {
  (void)state;
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 1, 2, 50, 1);
  cfg.elite_frac = 1.0;  /* every sample is an elite: the elite stats are the sample stats */
  cfg.momentum = 0.25;
  cfg.std_min = 0.6;
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  const double m0[2] = {1.0, -2.0}, s0[2] = {1.0, 0.1};
  nd_cem_set_dist(cem, m0, s0);
  static upd_ctx c;
  nd_rng r;
  nd_rng_seed(&r, 4, 0);
  assert_int_equal(nd_cem_run(cem, &r, upd_cost, &c), 0);
  assert_int_equal(c.n, 50);
  for (int d = 0; d < 2; d++) {
    double m = 0.0, v = 0.0;
    for (int k = 0; k < 50; k++) m += c.x[k][d];
    m /= 50;
    for (int k = 0; k < 50; k++) v += (c.x[k][d] - m) * (c.x[k][d] - m);
    double s = sqrt(v / 50);
    assert_near(nd_cem_mean(cem)[d], 0.25 * m0[d] + 0.75 * m, 1e-12);
    double expect = fmax(0.25 * s0[d] + 0.75 * s, 0.6);
    assert_near(nd_cem_std(cem)[d], expect, 1e-12);
  }
  assert_true(nd_cem_std(cem)[0] > 0.6);   /* dim 0 is above the floor ... */
  assert_near(nd_cem_std(cem)[1], 0.6, 0.0);  /* ... dim 1 is lifted to it */
  nd_cem_free(cem);
}

/* ---- errors ---- */

typedef struct {
  int calls, fail_at;
} err_ctx;

static int err_cost(void *vctx, const double *x, int n, double *cost) {
  (void)x;
  err_ctx *c = (err_ctx *)vctx;
  if (++c->calls == c->fail_at) return 7;
  for (int k = 0; k < n; k++) cost[k] = k;
  return 0;
}

static void test_callback_error(void **state) {
  (void)state;
  nd_cem_cfg cfg;
  nd_cem_cfg_default(&cfg, 2, 1, 20, 5);
  nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
  assert_non_null(cem);
  nd_rng r;
  nd_rng_seed(&r, 1, 0);
  err_ctx c = {0, 2};
  assert_int_equal(nd_cem_run(cem, &r, err_cost, &c), 7);
  assert_int_equal(c.calls, 2);  /* aborted: no third batch */
  c.fail_at = -1;
  assert_int_equal(nd_cem_run(cem, &r, err_cost, &c), 0);
  assert_int_equal(c.calls, 7);
  nd_cem_free(cem);
}

static void expect_invalid(const nd_cem_cfg *cfg, const char *word) {
  char err[160] = "";
  nd_cem *cem = nd_cem_create(cfg, err, sizeof err);
  if (cem) {
    nd_cem_free(cem);
    fail_msg("cfg accepted, expected an error about '%s'", word);
  }
  if (!strstr(err, word)) fail_msg("message '%s' does not mention '%s'", err, word);
}

/* ---- redraws ---- */

typedef struct {
  int calls, seen, accepted, rounds;
} redraw_ctx;

/* calls counts the candidates asked about, rounds the callbacks. */
static void redraw_accept(void *ctx, const double *x, int n, int *ok) {
  redraw_ctx *c = ctx;
  c->rounds++;
  for (int i = 0; i < n; i++) {
    c->calls++;
    ok[i] = x[(size_t)i * D8] >= 0.7;
  }
}

static int redraw_cost(void *ctx, const double *x, int n, double *cost) {
  redraw_ctx *c = ctx;
  for (int k = 0; k < n; k++) {
    c->seen++;
    c->accepted += x[k * D8] >= 0.7;
    cost[k] = bowl(x + k * D8);
  }
  return 0;
}

/* Sampling truncated to what accept allows: from mean 0, std 1 a draw passes x0 >= 0.7 with
 * p ~ 0.24, so without redraws about a quarter of the evaluated candidates pass, with 20
 * nearly all (a candidate fails only if 21 draws in a row do, p ~ 0.003); the redrawn
 * count is the refused draws; without redraws accept is never asked. */
static void test_redraw(void **state) {
  (void)state;
  double m0[D8], s0[D8];
  fill(m0, D8, 0.0);
  fill(s0, D8, 1.0);
  int accepted[2], seen[2], redrawn[2], calls[2], rounds[2];
  for (int v = 0; v < 2; v++) {
    nd_cem_cfg cfg;
    nd_cem_cfg_default(&cfg, 1, D8, 400, 1);
    cfg.redraws = v ? 20 : 0;
    nd_cem *cem = nd_cem_create(&cfg, NULL, 0);
    assert_non_null(cem);
    redraw_ctx c = {0, 0, 0, 0};
    nd_cem_set_accept(cem, redraw_accept, &c);
    nd_cem_set_dist(cem, m0, s0);
    nd_rng r;
    nd_rng_seed(&r, 11, 0);
    assert_int_equal(nd_cem_run(cem, &r, redraw_cost, &c), 0);
    accepted[v] = c.accepted, seen[v] = c.seen, redrawn[v] = nd_cem_redrawn(cem), calls[v] = c.calls;
    rounds[v] = c.rounds;
    nd_cem_free(cem);
  }
  assert_int_equal(seen[0], 400);
  assert_int_equal(seen[1], 400);
  assert_in_range(accepted[0], 60, 135);
  assert_true(accepted[1] >= 395);
  assert_int_equal(redrawn[0], 0);
  assert_int_equal(calls[0], 0);
  /* every refused draw is drawn again; the draw that passes is asked too, the last of 20
   * refusals' successor is not */
  assert_in_range(calls[1] - redrawn[1], 395, 400);
  assert_true(redrawn[1] > 2 * 300);  /* ~3 refusals per accepted candidate */
  /* one callback per round over all candidates still refused, at most one per redraw */
  assert_int_equal(rounds[0], 0);
  assert_in_range(rounds[1], 10, 20);
}

static void test_invalid_cfg(void **state) {
  (void)state;
  nd_cem_cfg ok, cfg;
  nd_cem_cfg_default(&ok, 3, 2, 32, 2);
  char err[160] = "";
  nd_cem *cem = nd_cem_create(&ok, err, sizeof err);
  assert_non_null(cem);
  nd_cem_free(cem);
  assert_null(nd_cem_create(NULL, err, sizeof err));

#define BAD(field, value, word) \
  cfg = ok;                     \
  cfg.field = value;            \
  expect_invalid(&cfg, word)
  BAD(horizon, 0, "horizon");
  BAD(block, -1, "block");
  BAD(pop, 1, "pop");
  BAD(iters, 0, "iters");
  BAD(elite_frac, 0.0, "elite_frac");
  BAD(elite_frac, 1.5, "elite_frac");
  BAD(elite_frac, NAN, "elite_frac");
  BAD(keep_frac, -0.1, "keep_frac");
  BAD(pop_decay, 0.5, "pop_decay");
  BAD(pop_decay, INFINITY, "pop_decay");
  BAD(momentum, 1.0, "momentum");
  BAD(noise_beta, -1.0, "noise_beta");
  BAD(std_min, NAN, "std_min");
  BAD(redraws, -1, "redraws");
#undef BAD
  double lo[6] = {0, 0, 0, 0, 0, 0}, hi[6] = {1, 1, 1, -1, 1, 1};
  cfg = ok;
  cfg.lower = lo;
  cfg.upper = hi;
  expect_invalid(&cfg, "dim 3");
  /* one-sided bounds are fine (parameters that must stay positive) */
  cfg.upper = NULL;
  cem = nd_cem_create(&cfg, err, sizeof err);
  assert_non_null(cem);
  nd_cem_free(cem);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_bowl_plain_cem),
      cmocka_unit_test(test_rosenbrock_icem),
      cmocka_unit_test(test_same_seed_bitwise),
      cmocka_unit_test(test_workers_identical),
      cmocka_unit_test(test_samples_within_bounds),
      cmocka_unit_test(test_set_bounds),
      cmocka_unit_test(test_colored_noise),
      cmocka_unit_test(test_keep_never_worse),
      cmocka_unit_test(test_population_schedule),
      cmocka_unit_test(test_shift),
      cmocka_unit_test(test_map),
      cmocka_unit_test(test_elite_selection),
      cmocka_unit_test(test_update_rule),
      cmocka_unit_test(test_step_std),
      cmocka_unit_test(test_step_gate),
      cmocka_unit_test(test_redraw),
      cmocka_unit_test(test_callback_error),
      cmocka_unit_test(test_invalid_cfg),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
