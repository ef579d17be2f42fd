/* test_mocap: the emulated motion capture (core/nd_mocap.c): its noise, latency, drops and
 * order measured against what was configured. */
#include <string.h>

#include "nd_test.h"
#include "nd_math.h"
#include "nd_mocap.h"
#include "nd_stats.h"

#define DT 0.001

/* Step a still object at (0.1, 0.2, 0.025), yaw 0.3, for seconds s; collect the frames. */
static int run(nd_mocap *m, double s, nd_mocap_frame *out, int cap) {
  const double pos[3] = {0.1, 0.2, 0.025}, ee[3] = {-0.1, 0, 0.027};
  double q[4];
  nd_yaw_quat(0.3, q);
  int n = 0;
  for (int k = 0; k < (int)(s / DT + 0.5); k++) {
    const double t = k * DT;
    nd_mocap_capture(m, t, pos, q, ee);
    n += nd_mocap_release(m, t, out + n, cap - n);
  }
  return n;
}

static void test_exact(void **state) {
  (void)state;
  nd_mocap_cfg c;
  nd_mocap_cfg_exact(&c);
  char err[128];
  assert_int_equal(nd_mocap_cfg_check(&c, err, sizeof err), 0);
  static nd_mocap m;
  static nd_mocap_frame f[2000];
  nd_mocap_init(&m, &c, 0.0);
  const int n = run(&m, 2.0, f, 2000);
  assert_int_equal(n, 480);  /* 240 Hz for 2 s */
  for (int i = 0; i < n; i++) {
    assert_true(f[i].t_release == f[i].t_capture);
    assert_true(f[i].obj_pos[0] == 0.1 && f[i].ee_pos[2] == 0.027);
    assert_near(nd_quat_yaw(f[i].obj_quat), 0.3, 1e-15);
  }
}

/* The lab's figures on the wire: noise std, latency and drop rate as configured. */
static void test_lab_statistics(void **state) {
  (void)state;
  nd_mocap_cfg c;
  nd_mocap_cfg_lab(&c);
  static nd_mocap m;
  static nd_mocap_frame f[40000];
  nd_mocap_init(&m, &c, 0.0);
  const int n = run(&m, 120.0, f, 40000);
  static double dx[40000], lat[40000], yaw[40000];
  int gaps = 0, longest = 0;
  for (int i = 0; i < n; i++) {
    dx[i] = f[i].obj_pos[0] - 0.1;
    lat[i] = f[i].t_release - f[i].t_capture;
    yaw[i] = nd_wrap_angle(nd_quat_yaw(f[i].obj_quat) - 0.3);
    assert_near(hypot(hypot(f[i].obj_quat[0], f[i].obj_quat[1]), hypot(f[i].obj_quat[2], f[i].obj_quat[3])), 1.0, 1e-12);
    if (i) {
      assert_true(f[i].t_capture > f[i - 1].t_capture && f[i].t_release >= f[i - 1].t_release);
      const int missing = (int)lround((f[i].t_capture - f[i - 1].t_capture) * c.rate) - 1;
      assert_int_equal(f[i].index - f[i - 1].index - 1, missing);  /* drops leave gaps */
      gaps += missing > 0;
      if (missing > longest) longest = missing;
    }
  }
  const nd_stats sx = nd_stats_of(dx, n), sl = nd_stats_of(lat, n), sy = nd_stats_of(yaw, n);
  const double lost = (double)m.dropped / (double)(m.captured + m.dropped);
  printf("mocap_noise_pos_std %.4f mm (configured %.4f)\n", 1e3 * sx.std, 1e3 * c.sigma_pos);
  printf("mocap_noise_yaw_std %.5f rad (configured %.5f per axis)\n", sy.std, c.sigma_rot);
  printf("mocap_latency_ms mean %.3f, min %.3f, max %.3f\n", 1e3 * sl.mean, 1e3 * sl.min, 1e3 * sl.max);
  printf("mocap_dropped %.4f share, %d bursts, longest %d frames\n", lost, gaps, longest);
  assert_near(sx.std, c.sigma_pos, 0.03 * c.sigma_pos);
  assert_near(sx.mean, 0, 3 * c.sigma_pos / sqrt(n));
  assert_near(sy.std, c.sigma_rot, 0.05 * c.sigma_rot);
  assert_near(sl.mean, c.latency, 1e-4);
  assert_true(sl.min >= c.latency - c.latency_jitter - 1e-12);
  assert_true(sl.max <= c.latency + c.latency_jitter + DT);  /* released at the step after */
  assert_near(lost, 0.01, 0.003);
  assert_near((double)m.dropped / gaps, c.drop_burst, 0.5);
  assert_int_equal(m.overflow, 0);
}

/* Same seed, same frames; another seed, other noise. */
static void test_seeded(void **state) {
  (void)state;
  nd_mocap_cfg c;
  nd_mocap_cfg_lab(&c);
  static nd_mocap a, b;
  static nd_mocap_frame fa[300], fb[300];
  nd_mocap_init(&a, &c, 0.0);
  nd_mocap_init(&b, &c, 0.0);
  const int na = run(&a, 1.0, fa, 300), nb = run(&b, 1.0, fb, 300);
  assert_int_equal(na, nb);
  assert_memory_equal(fa, fb, sizeof(nd_mocap_frame) * na);
  c.seed = 2;
  nd_mocap_init(&b, &c, 0.0);
  run(&b, 1.0, fb, 300);
  assert_true(fa[0].obj_pos[0] != fb[0].obj_pos[0]);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_exact),
      cmocka_unit_test(test_lab_statistics),
      cmocka_unit_test(test_seeded),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
