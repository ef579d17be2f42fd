/* nd_rng: xoshiro256** (Blackman and Vigna) seeded through splitmix64. */
#include "nd_rng.h"

#include <math.h>

#include "nd_math.h"

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

/* The splitmix64 output function: a bijection on 64-bit words with full avalanche. */
static uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

static uint64_t splitmix64_next(uint64_t *x) {
  *x += 0x9e3779b97f4a7c15ULL;
  return mix64(*x);
}

void nd_rng_seed(nd_rng *r, uint64_t seed, uint64_t stream) {
  /* Hashing the stream id (a bijection) before combining keeps the splitmix64 start
   * points of neighbouring streams far apart, so their state sequences do not overlap.
   * splitmix64 never yields four zero words in a row, so the state is never all zero. */
  uint64_t x = seed ^ mix64(stream + 0x632be59bd9b4e019ULL);
  for (int i = 0; i < 4; i++) r->s[i] = splitmix64_next(&x);
  r->spare = 0.0;
  r->has_spare = 0;
}

uint64_t nd_rng_u64(nd_rng *r) {
  uint64_t *s = r->s;
  const uint64_t out = rotl(s[1] * 5, 7) * 9;
  const uint64_t t = s[1] << 17;
  s[2] ^= s[0];
  s[3] ^= s[1];
  s[1] ^= s[2];
  s[0] ^= s[3];
  s[2] ^= t;
  s[3] = rotl(s[3], 45);
  return out;
}

double nd_rng_uniform(nd_rng *r) {
  /* The top 53 bits fill a double's mantissa exactly: values k / 2^53. */
  return (double)(nd_rng_u64(r) >> 11) * 0x1.0p-53;
}

double nd_rng_normal(nd_rng *r) {
  if (r->has_spare) {
    r->has_spare = 0;
    return r->spare;
  }
  /* 1 - u lies in (0, 1], so the logarithm stays finite. */
  const double u1 = 1.0 - nd_rng_uniform(r);
  const double u2 = nd_rng_uniform(r);
  const double rad = sqrt(-2.0 * log(u1));
  const double th = 2.0 * ND_PI * u2;
  r->spare = rad * sin(th);
  r->has_spare = 1;
  return rad * cos(th);
}
