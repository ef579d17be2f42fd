/* test_release: the sphere's rest point after a task (core/nd_release.c): out along the
 * contact normal of a turned box to the clearance, unmoved when clear, out of the box by
 * its nearest side, and kept in the keypoint box. */
#include "nd_test.h"
#include "nd_release.h"

static const double lo[2] = {-0.5, -0.5}, hi[2] = {0.5, 0.5};
#define R 0.025
#define CLEAR 0.01

/* The sphere's surface distance from the box's sides: the point's in the box frame. */
static double gap(const nd_release_box *b, const double p[2]) {
  const double c = cos(b->yaw), s = sin(b->yaw), wx = p[0] - b->x, wy = p[1] - b->y;
  const double dx = fmax(0.0, fabs(c * wx + s * wy) - b->half[0]);
  const double dy = fmax(0.0, fabs(-s * wx + c * wy) - b->half[1]);
  return hypot(dx, dy) - R;
}

static void test_contact_on_a_side(void **state) {
  (void)state;
  /* Box turned 90 degrees: its long side (half 0.05) runs along y, so the +x side is the
   * short half 0.03 away. The sphere touches it 1 mm deep, off centre along the side. */
  const nd_release_box b = {.x = 0.1, .y = -0.05, .yaw = M_PI / 2, .half = {0.05, 0.03}};
  const double ee[2] = {0.1 + 0.03 + R - 0.001, -0.05 + 0.02};
  double out[2];
  const double moved = nd_release_target(&b, R, CLEAR, ee, lo, hi, out);
  assert_near(moved, CLEAR + 0.001, 1e-12);
  assert_near(out[0], ee[0] + CLEAR + 0.001, 1e-12);  /* straight out along +x */
  assert_near(out[1], ee[1], 1e-12);
  assert_near(gap(&b, out), CLEAR, 1e-12);
  double n[2];
  assert_near(nd_release_gap(&b, R, ee, n), -0.001, 1e-12);
  assert_near(n[0], 1, 1e-12);
  assert_near(n[1], 0, 1e-12);
}

static void test_contact_at_a_corner(void **state) {
  (void)state;
  const nd_release_box b = {.x = 0, .y = 0, .yaw = 0.3, .half = {0.05, 0.03}};
  /* The corner (+0.05, +0.03) in the world, and a sphere 5 mm from it along the
   * diagonal out of it: closer than R + CLEAR, so it moves out along that diagonal. */
  const double c = cos(0.3), s = sin(0.3), u[2] = {c * 0.6 - s * 0.8, s * 0.6 + c * 0.8};
  const double corner[2] = {c * 0.05 - s * 0.03, s * 0.05 + c * 0.03};
  const double ee[2] = {corner[0] + 0.005 * u[0], corner[1] + 0.005 * u[1]};
  double out[2];
  const double moved = nd_release_target(&b, R, CLEAR, ee, lo, hi, out);
  assert_near(moved, R + CLEAR - 0.005, 1e-12);
  assert_near(out[0], corner[0] + (R + CLEAR) * u[0], 1e-12);
  assert_near(out[1], corner[1] + (R + CLEAR) * u[1], 1e-12);
  assert_near(gap(&b, out), CLEAR, 1e-12);
  double n[2];
  assert_near(nd_release_gap(&b, R, ee, n), 0.005 - R, 1e-12);
  assert_near(n[0], u[0], 1e-12);
  assert_near(n[1], u[1], 1e-12);
}

static void test_clear_stays(void **state) {
  (void)state;
  const nd_release_box b = {.x = 0.2, .y = 0.1, .yaw = -1.0, .half = {0.05, 0.03}};
  const double ee[2] = {0.2 - 0.2, 0.1 + 0.05};
  double out[2];
  assert_near(nd_release_target(&b, R, CLEAR, ee, lo, hi, out), 0, 0);
  assert_near(out[0], ee[0], 0);
  assert_near(out[1], ee[1], 0);
  /* Clearance 0: a sphere just touching is left where it is. */
  const nd_release_box a = {.x = 0, .y = 0, .yaw = 0, .half = {0.05, 0.03}};
  const double touch[2] = {-0.05 - R, 0.01};
  assert_near(nd_release_target(&a, R, 0.0, touch, lo, hi, out), 0, 0);
}

static void test_inside_and_clamped(void **state) {
  (void)state;
  /* A centre inside the box (a glitch, or a world the model does not match) leaves by
   * the nearest side: here -y, 0.01 m away. */
  const nd_release_box b = {.x = 0, .y = 0, .yaw = 0, .half = {0.05, 0.03}};
  const double ee[2] = {0.01, -0.02};
  double out[2];
  const double moved = nd_release_target(&b, R, CLEAR, ee, lo, hi, out);
  assert_near(out[0], 0.01, 1e-12);
  assert_near(out[1], -0.03 - R - CLEAR, 1e-12);
  assert_near(moved, 0.01 + R + CLEAR, 1e-12);
  double n[2];
  assert_near(nd_release_gap(&b, R, ee, n), -0.01 - R, 1e-12);
  assert_near(n[1], -1, 0);
  /* At the keypoint box's edge the rest point is kept inside it. */
  const nd_release_box e = {.x = 0.45, .y = 0, .yaw = 0, .half = {0.05, 0.03}};
  const double ee2[2] = {0.45 + 0.05 + R - 0.002, 0.0};
  nd_release_target(&e, R, CLEAR, ee2, lo, hi, out);
  assert_near(out[0], 0.5, 0);
  assert_near(out[1], 0.0, 1e-12);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_contact_on_a_side),
      cmocka_unit_test(test_contact_at_a_corner),
      cmocka_unit_test(test_clear_stays),
      cmocka_unit_test(test_inside_and_clamped),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
