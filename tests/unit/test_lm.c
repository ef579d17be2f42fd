/* test_lm: Levenberg-Marquardt with batched forward differences (core/nd_lm.c): it
 * converges on a curve fit from a far start within its iterations, keeps to its bounds, and
 * its 95 % intervals hold the truth about 95 % of the time, for white residuals and, with
 * the correlation correction, for correlated ones. With no iterations it evaluates one batch
 * and gives the covariance at the start point, which it leaves unchanged. A parameter the
 * residuals ignore gets an infinite std and leaves the others' alone. */
#include <string.h>

#include "nd_test.h"
#include "nd_lm.h"
#include "nd_rng.h"

#define M 400

typedef struct {
  double y[M];
  int calls, points;
} fit;

/* y = a exp(-b t) + c on t in [0, 4). */
static double model(const double *x, int j) {
  const double t = 0.01 * j;
  return x[0] * exp(-x[1] * t) + x[2];
}

static int residuals(void *ctx, const double *x, int k, double *r) {
  fit *f = ctx;
  f->calls++;
  f->points += k;
  for (int p = 0; p < k; p++)
    for (int j = 0; j < M; j++) r[p * M + j] = model(x + 3 * p, j) - f->y[j];
  return 0;
}

static const double truth[3] = {2.0, 1.5, 0.3}, lo[3] = {0, 0.01, -1}, hi[3] = {10, 10, 1};
static const double scale[3] = {1.0, 1.0, 0.1};

/* Data with noise of std sd; rho > 0: AR(1) correlated along t. */
static void data(fit *f, nd_rng *r, double sd, double rho) {
  double e = 0;
  for (int j = 0; j < M; j++) {
    e = rho * e + sqrt(1 - rho * rho) * sd * nd_rng_normal(r);
    f->y[j] = model(truth, j) + e;
  }
}

static nd_lm *make_n(int n, const double *lower, const double *upper, const double *sc,
                     int stride, int iters) {
  nd_lm_cfg c;
  nd_lm_cfg_default(&c);
  c.n = n, c.m = M, c.lower = lower, c.upper = upper, c.scale = sc, c.stride = stride;
  c.iters = iters;
  char err[128];
  nd_lm *lm = nd_lm_create(&c, err, sizeof err);
  if (!lm) fail_msg("%s", err);
  return lm;
}

static nd_lm *make(int stride, int iters) { return make_n(3, lo, hi, scale, stride, iters); }

static void test_converges(void **state) {
  (void)state;
  static fit f;
  nd_rng r;
  nd_rng_seed(&r, 3, 0);
  data(&f, &r, 0.0, 0.0);
  nd_lm *lm = make(0, 20);
  double x[3] = {0.5, 4.0, -0.5};
  nd_lm_out o;
  char err[128];
  assert_int_equal(nd_lm_run(lm, residuals, &f, x, &o, err, sizeof err), 0);
  printf("lm_iters %d, evals %d, cost %.3g -> %.3g, x (%.6f, %.6f, %.6f)\n", o.iters, o.evals,
         o.cost0, o.cost, x[0], x[1], x[2]);
  for (int i = 0; i < 3; i++) assert_near(x[i], truth[i], 1e-6);
  assert_int_equal(o.evals, 4 * (o.iters + 1));  /* n + 1 points per batch */
  assert_int_equal(f.points, o.evals);
  /* Bounds hold: a start outside is clipped, and a truth beyond a bound stops there. */
  double y[3] = {50, -3, 0};
  assert_int_equal(nd_lm_run(lm, residuals, &f, y, &o, err, sizeof err), 0);
  assert_true(y[0] <= 10 && y[1] >= 0.01);
  nd_lm_free(lm);
}

/* Share of 200 fits whose 95 % interval for b holds the truth. */
static double coverage(double rho, int stride, double *mean_std) {
  static fit f;
  nd_rng r;
  nd_rng_seed(&r, 11, (uint64_t)(rho * 100));
  nd_lm *lm = make(stride, 8);
  int hit = 0;
  *mean_std = 0;
  for (int k = 0; k < 200; k++) {
    data(&f, &r, 0.02, rho);
    double x[3] = {1.8, 1.3, 0.35};
    nd_lm_out o;
    char err[128];
    assert_int_equal(nd_lm_run(lm, residuals, &f, x, &o, err, sizeof err), 0);
    assert_true(o.rank_ok);
    hit += fabs(x[1] - truth[1]) <= 1.96 * o.std[1];
    *mean_std += o.std[1] / 200;
  }
  nd_lm_free(lm);
  return hit / 200.0;
}

static void test_intervals(void **state) {
  (void)state;
  double s_white, s_raw, s_fixed;
  const double white = coverage(0.0, 0, &s_white);
  const double raw = coverage(0.9, 0, &s_raw);
  const double fixed = coverage(0.9, 1, &s_fixed);
  printf("lm_ci95_coverage white %.3f (std %.4f), AR(1) 0.9 uncorrected %.3f (std %.4f), "
         "corrected %.3f (std %.4f)\n", white, s_white, raw, s_raw, fixed, s_fixed);
  assert_true(white >= 0.90 && white <= 0.99);
  assert_true(raw < 0.75);      /* correlated residuals: the plain estimate is overconfident */
  assert_true(fixed >= 0.88);   /* the correction restores it */
}

/* iters 0: one batch of n + 1 points, x untouched, the covariance at x: at the truth the
 * same standard errors as a converged fit's. */
static void test_cov_only(void **state) {
  (void)state;
  static fit f;
  nd_rng r;
  nd_rng_seed(&r, 5, 0);
  data(&f, &r, 0.02, 0.0);
  nd_lm *fitter = make(0, 8), *cov = make(0, 0);
  double xf[3] = {1.8, 1.3, 0.35}, x[3];
  nd_lm_out of, oc;
  char err[128];
  assert_int_equal(nd_lm_run(fitter, residuals, &f, xf, &of, err, sizeof err), 0);
  memcpy(x, xf, sizeof x);
  f.points = 0;
  assert_int_equal(nd_lm_run(cov, residuals, &f, x, &oc, err, sizeof err), 0);
  assert_int_equal(f.points, 4);
  assert_int_equal(oc.iters, 0);
  assert_memory_equal(x, xf, sizeof x);
  assert_true(oc.rank_ok);
  for (int i = 0; i < 3; i++) assert_true(fabs(oc.std[i] / of.std[i] - 1) < 0.02);
  nd_lm_free(fitter);
  nd_lm_free(cov);
}

/* The curve with a fourth parameter it does not depend on. */
static int residuals4(void *ctx, const double *x, int k, double *r) {
  fit *f = ctx;
  for (int p = 0; p < k; p++)
    for (int j = 0; j < M; j++) r[p * M + j] = model(x + 4 * p, j) - f->y[j];
  return 0;
}

/* A parameter the residuals ignore has an infinite std; the others' intervals are those of
 * the fit without it. */
static void test_uninformed(void **state) {
  (void)state;
  static fit f;
  nd_rng r;
  nd_rng_seed(&r, 7, 0);
  data(&f, &r, 0.02, 0.0);
  const double lo4[4] = {0, 0.01, -1, -1}, hi4[4] = {10, 10, 1, 1}, sc4[4] = {1, 1, 0.1, 1};
  nd_lm *lm4 = make_n(4, lo4, hi4, sc4, 0, 8), *lm3 = make(0, 8);
  char err[128];
  double x4[4] = {1.8, 1.3, 0.35, 0.5}, x3[3] = {1.8, 1.3, 0.35};
  nd_lm_out o4, o3;
  assert_int_equal(nd_lm_run(lm4, residuals4, &f, x4, &o4, err, sizeof err), 0);
  assert_int_equal(nd_lm_run(lm3, residuals, &f, x3, &o3, err, sizeof err), 0);
  assert_true(o4.rank_ok);
  assert_true(isinf(o4.std[3]));
  assert_near(x4[3], 0.5, 0);
  for (int i = 0; i < 3; i++) {
    assert_near(x4[i], x3[i], 1e-6);
    assert_true(isfinite(o4.std[i]) && fabs(o4.std[i] / o3.std[i] - 1) < 1e-3);
    assert_near(o4.cov[i * 4 + 3], 0, 0);
  }
  nd_lm_free(lm4);
  nd_lm_free(lm3);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_converges),
      cmocka_unit_test(test_intervals),
      cmocka_unit_test(test_cov_only),
      cmocka_unit_test(test_uninformed),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
