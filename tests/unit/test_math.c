/* test_math: angle wrapping, quaternion yaw, small vector helpers. */
#include "nd_test.h"

#include "nd_math.h"
#include "nd_stats.h"

/* Hamilton product, w first: r = a * b (apply b, then a). */
static void quat_mul(const double a[4], const double b[4], double r[4]) {
  r[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
  r[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
  r[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
  r[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
}

/* Angular distance on the circle, immune to the +-pi seam. */
static double ang_diff(double a, double b) { return fabs(remainder(a - b, 2.0 * ND_PI)); }

static void test_wrap_edges(void **state) {
  (void)state;
  /* The interval is half open: +pi maps to -pi, -pi stays. */
  assert_true(nd_wrap_angle(ND_PI) == -ND_PI);
  assert_true(nd_wrap_angle(-ND_PI) == -ND_PI);
  assert_true(nd_wrap_angle(0.0) == 0.0);
  double below = nextafter(ND_PI, 0.0);
  assert_true(nd_wrap_angle(below) == below);
  double under = nextafter(-ND_PI, -4.0);
  double w = nd_wrap_angle(under);
  assert_true(w >= -ND_PI && w < ND_PI);
  assert_near(ang_diff(w, under), 0.0, 1e-12);
  assert_near(nd_wrap_angle(3.0 * ND_PI), -ND_PI, 1e-12);
  assert_near(nd_wrap_angle(-3.0 * ND_PI), -ND_PI, 1e-12);
  assert_near(nd_wrap_angle(2.0 * ND_PI + 0.25), 0.25, 1e-12);
  assert_near(nd_wrap_angle(-2.0 * ND_PI - 0.25), -0.25, 1e-12);
  assert_near(nd_wrap_angle(1000.0 * 2.0 * ND_PI + 1.0), 1.0, 1e-9);
  assert_true(isnan(nd_wrap_angle(NAN)));
}

static void test_wrap_range_sweep(void **state) {
  (void)state;
  for (int i = -4000; i <= 4000; i++) {
    double a = i * 0.01 + 1e-3;
    double w = nd_wrap_angle(a);
    assert_true(w >= -ND_PI && w < ND_PI);
    assert_near(ang_diff(w, a), 0.0, 1e-12);
  }
}

static void test_yaw_quat_round_trip(void **state) {
  (void)state;
  double q[4];
  for (int i = -360; i < 360; i++) {
    double yaw = i * (ND_PI / 180.0) + 1e-4;
    nd_yaw_quat(yaw, q);
    assert_near(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0, 1e-15);
    assert_true(q[1] == 0.0 && q[2] == 0.0);
    double back = nd_quat_yaw(q);
    assert_true(back >= -ND_PI && back <= ND_PI);
    assert_near(ang_diff(back, yaw), 0.0, 1e-12);
    /* q and -q are the same rotation. */
    double nq[4] = {-q[0], -q[1], -q[2], -q[3]};
    assert_near(ang_diff(nd_quat_yaw(nq), yaw), 0.0, 1e-12);
  }
  nd_yaw_quat(ND_PI / 2.0, q);
  assert_near(q[0], sqrt(0.5), 1e-15);
  assert_near(q[3], sqrt(0.5), 1e-15);
}

static void test_yaw_of_composed(void **state) {
  (void)state;
  double qa[4], qb[4], qc[4];
  for (int i = 0; i < 50; i++) {
    double a = -3.0 + 0.13 * i, b = 2.9 - 0.11 * i;
    nd_yaw_quat(a, qa);
    nd_yaw_quat(b, qb);
    quat_mul(qa, qb, qc);
    assert_near(ang_diff(nd_quat_yaw(qc), a + b), 0.0, 1e-12);
  }
  /* A roll about the body x-axis after the yaw keeps the x-axis heading, so the yaw. */
  double roll = 0.3, qr[4] = {cos(0.5 * roll), sin(0.5 * roll), 0.0, 0.0};
  nd_yaw_quat(2.5, qa);
  quat_mul(qa, qr, qc);
  assert_near(nd_quat_yaw(qc), 2.5, 1e-12);
  /* A pitch changes the heading of nothing either: the x-axis tilts within its plane. */
  double pitch = -0.4, qp[4] = {cos(0.5 * pitch), 0.0, sin(0.5 * pitch), 0.0};
  quat_mul(qa, qp, qc);
  assert_near(nd_quat_yaw(qc), 2.5, 1e-12);
  /* Scale does not matter (the formula uses the unnormalised R00). */
  for (int k = 0; k < 4; k++) qc[k] *= 1.01;
  assert_near(nd_quat_yaw(qc), 2.5, 1e-12);
}

/* nlerp between two yaws moves along the shorter arc, also when one quaternion has the
 * other sign (the same rotation), ends exactly at its endpoints, and stays unit. */
static void test_quat_nlerp(void **state) {
  (void)state;
  double a[4], b[4], q[4];
  nd_yaw_quat(0.1, a);
  nd_yaw_quat(0.3, b);
  for (int s = 0; s < 2; s++) {
    if (s)
      for (int i = 0; i < 4; i++) b[i] = -b[i];
    nd_quat_nlerp(a, b, 0.5, q);
    assert_near(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0, 1e-15);
    assert_near(nd_quat_yaw(q), 0.2, 1e-12);
    nd_quat_nlerp(a, b, 0.25, q);
    assert_near(nd_quat_yaw(q), 0.15, 1e-4); /* nlerp is not uniform in angle, nearly so */
    nd_quat_nlerp(a, b, 0, q);
    assert_memory_equal(q, a, sizeof(q));
    nd_quat_nlerp(a, b, 1, q);
    assert_near(ang_diff(nd_quat_yaw(q), 0.3), 0, 1e-15);
  }
  /* Across +-pi: 3.1 to -3.1 goes the 0.08 rad way through pi, not back through 0. */
  nd_yaw_quat(3.1, a);
  nd_yaw_quat(-3.1, b);
  nd_quat_nlerp(a, b, 0.5, q);
  assert_near(fabs(nd_quat_yaw(q)), ND_PI, 1e-12);
}

static void test_vec_helpers(void **state) {
  (void)state;
  const double v[2] = {3.0, -4.0}, a[2] = {1.0, 1.0}, b[2] = {4.0, 5.0};
  assert_near(nd_norm2_sq(v), 25.0, 0.0);
  assert_near(nd_norm2(v), 5.0, 0.0);
  assert_near(nd_dist2(a, b), 5.0, 1e-15);
  assert_near(nd_dist2(b, a), 5.0, 1e-15);
  assert_near(nd_clamp(2.0, -1.0, 1.0), 1.0, 0.0);
  assert_near(nd_clamp(-2.0, -1.0, 1.0), -1.0, 0.0);
  assert_near(nd_clamp(0.5, -1.0, 1.0), 0.5, 0.0);
  assert_true(isnan(nd_clamp(NAN, -1.0, 1.0)));
  /* A quarter turn takes x to y; the turn back, in place, restores it. */
  double r[2];
  nd_rot2(0.0, 1.0, v, r);
  assert_near(r[0], 4.0, 0.0);
  assert_near(r[1], 3.0, 0.0);
  nd_rot2(0.0, -1.0, r, r);
  assert_near(r[0], 3.0, 0.0);
  assert_near(r[1], -4.0, 0.0);
  const double ok[3] = {0.0, -1e308, 5.0};
  double bad[3] = {0.0, 1.0, 2.0};
  assert_int_equal(nd_all_finite(ok, 3), 1);
  assert_int_equal(nd_all_finite(bad, 0), 1);
  bad[2] = INFINITY;
  assert_int_equal(nd_all_finite(bad, 3), 0);
  assert_int_equal(nd_all_finite(bad, 2), 1);
  bad[0] = NAN;
  assert_int_equal(nd_all_finite(bad, 1), 0);
}

/* Summary statistics ignore what is not finite; quantiles are nearest-rank. */
static void test_stats(void **state) {
  (void)state;
  double v[] = {4, NAN, 1, 3, INFINITY, 2};
  const nd_stats s = nd_stats_of(v, 6);
  assert_int_equal(s.n, 4);
  assert_near(s.mean, 2.5, 1e-15);
  assert_near(s.median, 2.5, 1e-15);
  assert_near(s.min, 1, 0);
  assert_near(s.max, 4, 0);
  assert_near(s.std, sqrt(5.0 / 3.0), 1e-15);
  double none[] = {NAN};
  assert_true(isnan(nd_stats_of(none, 1).mean));
  double q[] = {5, 1, 4, 2, 3};
  assert_near(nd_quantile(q, 5, 0.5), 3, 0);
  assert_near(nd_quantile(q, 5, 0.99), 5, 0);
  assert_near(nd_quantile(q, 5, 0.0), 1, 0);
  assert_true(isnan(nd_quantile(q, 0, 0.5)));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_stats),
      cmocka_unit_test(test_wrap_edges),      cmocka_unit_test(test_wrap_range_sweep),
      cmocka_unit_test(test_yaw_quat_round_trip), cmocka_unit_test(test_yaw_of_composed),
      cmocka_unit_test(test_quat_nlerp),      cmocka_unit_test(test_vec_helpers),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
