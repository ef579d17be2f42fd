/* nd_jitter: quantiles to bin resolution, overruns and max. */
#include "nd_test.h"

#include "nd_jitter.h"

static void test_quantiles(void **state) {
  (void)state;
  nd_jitter j;
  nd_jitter_reset(&j);
  assert_near(nd_jitter_quantile(&j, 0.5), 0.0, 0.0);
  /* 1000 samples 0..999 us, plus 10 at 5 ms (beyond one 1 ms period: overruns). */
  for (int i = 0; i < 1000; i++) nd_jitter_add(&j, i + 0.5, 1000.0);
  for (int i = 0; i < 10; i++) nd_jitter_add(&j, 5000.0 + i, 1000.0);
  assert_int_equal(j.count, 1010);
  assert_int_equal(j.overruns, 10);
  assert_near(j.max_us, 5009.0, 0.0);
  assert_near(nd_jitter_quantile(&j, 0.5), 504.0, 1.0);
  assert_near(nd_jitter_quantile(&j, 0.99), 999.0, 2.0);
  assert_near(nd_jitter_quantile(&j, 0.995), 5000.0, 100.0);
  assert_near(nd_jitter_quantile(&j, 1.0), 5000.0, 100.0);
  nd_jitter_add(&j, 1e7, 1000.0);   /* overflow bin reports the max */
  assert_near(nd_jitter_quantile(&j, 1.0), 1e7, 0.0);
  nd_jitter_add(&j, -3.0, 1000.0);  /* early wake-ups count as zero error */
  nd_jitter_add(&j, NAN, 1000.0);
  assert_int_equal(j.bins[0], 3);  /* 0.5 us, -3 us and NaN */
}

int main(void) {
  const struct CMUnitTest tests[] = {cmocka_unit_test(test_quantiles)};
  return cmocka_run_group_tests(tests, NULL, NULL);
}
