/* nd_parse: strict numbers and lists; every refusal names the option. */
#include "nd_test.h"

#include <string.h>

#include "nd_parse.h"

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

int main(void) {
  const struct CMUnitTest tests[] = {cmocka_unit_test(test_numbers), cmocka_unit_test(test_list)};
  return cmocka_run_group_tests(tests, NULL, NULL);
}
