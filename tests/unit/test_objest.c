/* test_objest: the object's velocity from motion-capture frames (core/nd_objest.c), on
 * clean and noisy frames, and its clamps, gaps and restarts. */
#include <string.h>

#include "nd_test.h"
#include "nd_math.h"
#include "nd_objest.h"
#include "nd_rng.h"

#define U0 1795496793000000LL
#define FRAME_US 4167  /* 240 Hz */

static nd_objest e;

static void init(void) {
  nd_objest_cfg c;
  nd_objest_cfg_default(&c, 1.7, 1.7 / 0.03);
  nd_objest_init(&e, &c);
}

/* A frame of the object sliding at (vx, vy) and turning at wz, plus noise of std sp (m). */
static void add(int k, double vx, double vy, double wz, double sp, nd_rng *r) {
  const double t = 1e-6 * (double)(FRAME_US * k);
  const double pos[3] = {0.1 + vx * t + (sp > 0 ? sp * nd_rng_normal(r) : 0),
                         -0.05 + vy * t + (sp > 0 ? sp * nd_rng_normal(r) : 0), 0.025};
  double q[4];
  nd_yaw_quat(0.2 + wz * t, q);
  nd_objest_add(&e, U0 + FRAME_US * k, pos, q);
}

static void test_clean_motion(void **state) {
  (void)state;
  init();
  double v[6];
  nd_objest_velocity(&e, v);
  for (int i = 0; i < 6; i++) assert_near(v[i], 0, 0);  /* no frame */
  add(0, 0.12, -0.05, 0.8, 0, NULL);
  nd_objest_velocity(&e, v);
  assert_near(v[0], 0, 0);  /* one frame */
  for (int k = 1; k < 40; k++) add(k, 0.12, -0.05, 0.8, 0, NULL);
  nd_objest_velocity(&e, v);
  assert_near(v[0], 0.12, 1e-9);
  assert_near(v[1], -0.05, 1e-9);
  assert_near(v[2], 0, 0);
  /* A box flat on the table: the body frame's z is the world's, so all of the yaw rate
   * is about body z. */
  assert_near(v[3], 0, 1e-12);
  assert_near(v[4], 0, 1e-12);
  assert_near(v[5], 0.8, 1e-9);
}

/* 0.2 mm of marker noise per axis, the figure the estimator was sized for: a difference
 * over 25 ms keeps the velocity noise near 0.2 mm x sqrt(2) / 25 ms = 0.011 m/s. */
static void test_noisy_motion(void **state) {
  (void)state;
  nd_rng r;
  nd_rng_seed(&r, 7, 1);
  init();
  double sum = 0, sq = 0;
  int n = 0;
  for (int k = 0; k < 2000; k++) {
    add(k, 0.1, 0.0, 0.0, 2e-4, &r);
    if (k < 10) continue;
    double v[6];
    nd_objest_velocity(&e, v);
    sum += v[0] - 0.1;
    sq += (v[0] - 0.1) * (v[0] - 0.1);
    n++;
  }
  const double bias = sum / n, sd = sqrt(sq / n - bias * bias);
  printf("objest_noise_velocity_std %.4f m/s (bias %.5f m/s)\n", sd, bias);
  assert_true(sd > 0.005 && sd < 0.016);
  assert_true(fabs(bias) < 0.002);
}

static void test_clamps_gaps_restarts(void **state) {
  (void)state;
  init();
  double v[6];
  for (int k = 0; k < 10; k++) add(k, 0.0, 0.0, 0.0, 0, NULL);
  /* A marker swap: the object "jumps" 0.5 m in a frame. */
  const double far[3] = {0.6, -0.05, 0.025}, q[4] = {1, 0, 0, 0};
  nd_objest_add(&e, U0 + FRAME_US * 10, far, q);
  nd_objest_velocity(&e, v);
  assert_near(hypot(v[0], v[1]), 1.7, 1e-9);
  /* Frames 0.2 s apart say nothing about the present motion. */
  init();
  add(0, 0.1, 0, 0, 0, NULL);
  add(48, 0.1, 0, 0, 0, NULL);
  nd_objest_velocity(&e, v);
  assert_near(v[0], 0, 0);
  /* Time going back (a restarted publisher) starts over: one frame, no velocity. */
  init();
  for (int k = 10; k < 20; k++) add(k, 0.1, 0, 0, 0, NULL);
  add(3, 0.1, 0, 0, 0, NULL);
  assert_int_equal(e.n, 1);
  nd_objest_velocity(&e, v);
  assert_near(v[0], 0, 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_clean_motion),
      cmocka_unit_test(test_noisy_motion),
      cmocka_unit_test(test_clamps_gaps_restarts),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
