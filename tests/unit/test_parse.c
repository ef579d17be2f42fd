/* nd_parse: strict numbers and lists; every refusal names the option. */
#include "nd_test.h"

#include <float.h>
#include <stdio.h>
#include <string.h>

#include "nd_parse.h"
#include "nd_theta.h"

static void test_numbers(void **state) {
  (void)state;
  char err[256];
  double d;
  int i;
  uint64_t u;
  assert_int_equal(nd_parse_double("0.25", "--x", 0, 1, &d, err, sizeof(err)), 0);
  assert_near(d, 0.25, 0);
  const char *bad[] = {"", "0.25s", "nan", "inf", "1e999", " 0.5x", "2"};
  for (int k = 0; k < 7; k++) {
    assert_int_equal(nd_parse_double(bad[k], "--x", 0, 1, &d, err, sizeof(err)), -1);
    assert_non_null(strstr(err, "--x"));
  }
  /* Underflow is a number, rounded: a subnormal, written in hex or as %.17g prints it,
   * and a decimal below the least subnormal (zero). Overflow is not. */
  assert_int_equal(nd_parse_double("0x1p-1038", "--x", -1, 1, &d, err, sizeof(err)), 0);
  assert_true(d == 0x1p-1038);
  char printed[64];
  snprintf(printed, sizeof(printed), "%.17g", d);
  assert_int_equal(nd_parse_double(printed, "--x", -1, 1, &d, err, sizeof(err)), 0);
  assert_true(d == 0x1p-1038);
  assert_int_equal(nd_parse_double("-1e-400", "--x", -1, 1, &d, err, sizeof(err)), 0);
  assert_true(d == 0.0);
  assert_int_equal(nd_parse_double("-1e999", "--x", -DBL_MAX, 1, &d, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "not a finite number"));
  assert_int_equal(nd_parse_int("12", "--n", 1, 20, &i, err, sizeof(err)), 0);
  assert_int_equal(i, 12);
  assert_int_equal(nd_parse_int("21", "--n", 1, 20, &i, err, sizeof(err)), -1);
  assert_int_equal(nd_parse_int("3.5", "--n", 1, 20, &i, err, sizeof(err)), -1);
  assert_int_equal(nd_parse_u64("-1", "--seed", &u, err, sizeof(err)), -1);
  assert_int_equal(nd_parse_u64("18446744073709551615", "--seed", &u, err, sizeof(err)), 0);
  assert_true(u == UINT64_MAX);
}

static void test_list(void **state) {
  (void)state;
  char err[256];
  double v[4];
  assert_int_equal(nd_parse_list("1,0.005,1e-4,2", "--theta", 4, 0, 10, v, err, sizeof(err)), 0);
  assert_near(v[0], 1, 0);
  assert_near(v[2], 1e-4, 0);
  assert_near(v[3], 2, 0);
  const char *bad[] = {"1,2,3", "1,2,3,4,5", "1,,3,4", "1,2,3,", ",1,2,3", "1,2,3,11", "1,2,x,4", ""};
  for (int k = 0; k < 8; k++) {
    assert_int_equal(nd_parse_list(bad[k], "--theta", 4, 0, 10, v, err, sizeof(err)), -1);
    assert_non_null(strstr(err, "--theta"));
  }
}

/* Theta has one validity rule: every entry finite; frictions in [0, 1e4]; masses and the
 * box's scale in (0, 1e4]; the centre-of-mass shifts within +-5 cm. */
static void test_theta(void **state) {
  (void)state;
  char err[256];
  double th[ND_NTHETA] = {0};
  assert_int_equal(nd_theta_parse("0.3,0,1e-4,50", "--theta", th, err, sizeof(err)), 0);
  assert_near(th[ND_TH_MASS], 50, 0);
  const double good[ND_NTHETA] = {1, 0.005, 1e-4, 1, 1, 0, 0};
  assert_int_equal(nd_theta_check(good, err, sizeof(err)), 0);
  const double bad[7][ND_NTHETA] = {
      {-1e-9, 0.005, 1e-4, 1, 1, 0, 0}, {1, NAN, 1e-4, 1, 1, 0, 0},
      {1, 0.005, 2e4, 1, 1, 0, 0},      {1, 0.005, 1e-4, 1, 0, 0, 0},
      {1, 0.005, 1e-4, 1, 1, 0.051, 0}, {1, 0.005, 1e-4, 1, 1, 0, -INFINITY},
      {1, 0.005, 1e-4, 0, 1, 0, 0}};
  for (int k = 0; k < 7; k++) assert_int_equal(nd_theta_check(bad[k], err, sizeof(err)), -1);
  assert_non_null(strstr(err, "theta[3] (sphere mass) = 0"));
  assert_int_equal(nd_theta_check(bad[4], err, sizeof(err)), -1);
  assert_non_null(strstr(err, "theta[5] (box COM shift x) = 0.051"));
  /* A shift may be negative; four values leave the box as built. */
  double th7[ND_NTHETA];
  assert_int_equal(nd_theta_parse("1,0.005,1e-4,1,1.1,0.008,-0.004", "--theta", th7, err,
                                  sizeof(err)), 0);
  assert_near(th7[ND_TH_BOX_SCALE], 1.1, 0);
  assert_near(th7[ND_TH_COM_Y], -0.004, 0);
  assert_int_equal(nd_theta_parse("1,0.005,1e-4,2", "--theta", th7, err, sizeof(err)), 0);
  assert_near(th7[ND_TH_MASS], 2, 0);
  assert_near(th7[ND_TH_BOX_SCALE], 1, 0);
  assert_near(th7[ND_TH_COM_X], 0, 0);
  assert_near(th7[ND_TH_COM_Y], 0, 0);
  assert_int_equal(nd_theta_parse("1,0.005,1e-4,2,1", "--theta", th7, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "--theta: '1,0.005,1e-4,2,1': expected 4 values"));
  assert_int_equal(nd_theta_parse("-1,0.005,1e-4,2", "--theta", th7, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "--theta: theta[0] (sliding friction) = -1"));
  char str[200];
  nd_theta_str(nd_theta_true, ",", str, sizeof(str));
  assert_string_equal(str, "1,0.005,0.0001,1,1,0,0");
  assert_int_equal(nd_theta_parse("1,0.005,1e-4,0", "--theta", th, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "--theta: theta[3]"));
  assert_near(th[ND_TH_MASS], 50, 0);  /* a refused value leaves theta as it was */
  unsigned m = 0;
  char names[64];
  assert_int_equal(nd_theta_parse_mask("mass,slide", "--fit", &m, err, sizeof(err)), 0);
  assert_int_equal(m, 1u << ND_TH_MASS | 1u << ND_TH_SLIDE);
  nd_theta_mask_str(m, names, sizeof(names));
  assert_string_equal(names, "slide,mass");
  const char *badm[] = {"slide,slide", "friction", "", ",", "slide,", "slide,,mass"};
  for (int k = 0; k < 6; k++) {
    assert_int_equal(nd_theta_parse_mask(badm[k], "--fit", &m, err, sizeof(err)), -1);
    assert_non_null(strstr(err, "--fit"));
  }
}

static void test_box(void **state) {
  (void)state;
  char err[256];
  nd_box b;
  assert_int_equal(nd_parse_box("-0.4,-0.3,0.4,0.3", "--workspace", 10, &b, err, sizeof(err)), 0);
  assert_near(b.lo[1], -0.3, 0);
  assert_near(b.hi[0], 0.4, 0);
  const char *bad[] = {"0.4,-0.3,-0.4,0.3", "0,0,0,0", "-20,0,1,1", "1,2,3"};
  for (int k = 0; k < 4; k++)
    assert_int_equal(nd_parse_box(bad[k], "--workspace", 10, &b, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "--workspace"));
}

int main(void) {
  const struct CMUnitTest tests[] = {cmocka_unit_test(test_numbers), cmocka_unit_test(test_list),
                                     cmocka_unit_test(test_theta), cmocka_unit_test(test_box)};
  return cmocka_run_group_tests(tests, NULL, NULL);
}
