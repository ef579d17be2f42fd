/* test_rng: xoshiro256** reference values, reproducible streams, distributions. */
#include "nd_test.h"

#include "nd_rng.h"

static void test_xoshiro_reference(void **state) {
  (void)state;
  /* From state {1, 2, 3, 4} xoshiro256** yields these first words (checked against an
   * independent implementation of the published algorithm). */
  nd_rng r = {.s = {1, 2, 3, 4}};
  const uint64_t want[6] = {0x2d00ULL, 0x0ULL, 0x5a007080ULL, 0x10e0000000009d80ULL,
                            0x10e0b61ce1009d80ULL, 0x870021ce143ad00ULL};
  for (int i = 0; i < 6; i++) assert_int_equal(nd_rng_u64(&r), want[i]);
}

static void test_same_seed_same_sequence(void **state) {
  (void)state;
  nd_rng a, b;
  nd_rng_seed(&a, 123, 7);
  nd_rng_seed(&b, 123, 7);
  for (int i = 0; i < 1000; i++) assert_int_equal(nd_rng_u64(&a), nd_rng_u64(&b));
  for (int i = 0; i < 1001; i++) assert_true(nd_rng_normal(&a) == nd_rng_normal(&b));
  /* Reseeding restarts the sequence and drops a cached normal. */
  nd_rng_seed(&a, 123, 7);
  nd_rng_seed(&b, 123, 7);
  const double first = nd_rng_normal(&a);
  (void)nd_rng_normal(&b); /* b now holds a spare */
  nd_rng_seed(&b, 123, 7);
  assert_true(nd_rng_normal(&b) == first);
  assert_int_equal(b.has_spare, 1);
}

static void test_streams_differ(void **state) {
  (void)state;
  /* Neighbouring streams and seeds share no word in their first 1000 outputs. */
  enum { NS = 8, NW = 1000 };
  static uint64_t words[2 * NS][NW];
  for (int k = 0; k < 2 * NS; k++) {
    nd_rng r;
    if (k < NS)
      nd_rng_seed(&r, 5, (uint64_t)k);
    else
      nd_rng_seed(&r, (uint64_t)(k - NS + 6), 0);
    for (int i = 0; i < NW; i++) words[k][i] = nd_rng_u64(&r);
  }
  int equal = 0;
  for (int k = 0; k < 2 * NS; k++)
    for (int l = k + 1; l < 2 * NS; l++)
      for (int i = 0; i < NW; i++)
        for (int j = 0; j < NW; j++) equal += words[k][i] == words[l][j];
  assert_int_equal(equal, 0);
  /* (seed, stream) is not symmetric: (5, 6) and (6, 5) differ. */
  nd_rng a, b;
  nd_rng_seed(&a, 5, 6);
  nd_rng_seed(&b, 6, 5);
  assert_true(nd_rng_u64(&a) != nd_rng_u64(&b));
}

static void test_uniform_range_and_moments(void **state) {
  (void)state;
  enum { N = 1000000 };
  nd_rng r;
  nd_rng_seed(&r, 99, 0);
  double sum = 0.0, sum2 = 0.0, lo = 1.0, hi = 0.0;
  int bins[10] = {0};
  for (int i = 0; i < N; i++) {
    const double u = nd_rng_uniform(&r);
    assert_true(u >= 0.0 && u < 1.0);
    /* 53-bit grid: u * 2^53 is an integer. */
    assert_true(u * 0x1.0p53 == floor(u * 0x1.0p53));
    sum += u;
    sum2 += u * u;
    lo = fmin(lo, u);
    hi = fmax(hi, u);
    bins[(int)(u * 10.0)]++;
  }
  const double mean = sum / N, var = sum2 / N - mean * mean;
  /* 5 standard errors: mean sqrt(1/12 / N), variance sqrt((1/80 - 1/144) / N). */
  assert_near(mean, 0.5, 5.0 * sqrt(1.0 / 12.0 / N));
  assert_near(var, 1.0 / 12.0, 5.0 * sqrt(1.0 / 180.0 / N));
  assert_true(lo < 1e-5 && hi > 1.0 - 1e-5);
  /* Each decile holds 1e5 +- 5 sigma (sigma = 300). */
  for (int b = 0; b < 10; b++) assert_near(bins[b], N / 10, 1500);
  print_message("uniform: mean %.6f var %.6f (1/12 = %.6f)\n", mean, var, 1.0 / 12.0);
}

static void test_normal_moments(void **state) {
  (void)state;
  enum { N = 1000000 };
  nd_rng r;
  nd_rng_seed(&r, 2024, 3);
  double s1 = 0.0, s2 = 0.0, s3 = 0.0, s4 = 0.0;
  int tail = 0;
  for (int i = 0; i < N; i++) {
    const double x = nd_rng_normal(&r);
    assert_true(isfinite(x));
    s1 += x;
    s2 += x * x;
    s3 += x * x * x;
    s4 += x * x * x * x;
    tail += fabs(x) > 1.959963984540054;
  }
  const double mean = s1 / N, var = s2 / N - mean * mean, skew = s3 / N, kurt = s4 / N;
  /* 5 standard errors: mean 1/sqrt(N), variance sqrt(2/N), third moment sqrt(15/N),
   * fourth moment sqrt(96/N); the two-sided 5% tail count sqrt(N 0.05 0.95). */
  assert_near(mean, 0.0, 5.0 * sqrt(1.0 / N));
  assert_near(var, 1.0, 5.0 * sqrt(2.0 / N));
  assert_near(skew, 0.0, 5.0 * sqrt(15.0 / N));
  assert_near(kurt, 3.0, 5.0 * sqrt(96.0 / N));
  assert_near((double)tail / N, 0.05, 5.0 * sqrt(0.05 * 0.95 / N));
  print_message("normal: mean %.5f var %.5f m3 %.5f m4 %.5f P(|x|>1.96) %.5f\n", mean, var,
                skew, kurt, (double)tail / N);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_xoshiro_reference),
      cmocka_unit_test(test_same_seed_same_sequence),
      cmocka_unit_test(test_streams_differ),
      cmocka_unit_test(test_uniform_range_and_moments),
      cmocka_unit_test(test_normal_moments),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
