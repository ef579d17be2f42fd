/* nd_rng: seeded random numbers (xoshiro256**) with independent streams.
 * A generator is plain state owned by its user; streams with the same seed and
 * different stream ids never overlap in practice (seeded through splitmix64). */
#ifndef ND_RNG_H
#define ND_RNG_H

#include <stdint.h>

typedef struct {
  uint64_t s[4];
  double spare;     /* cached second Box-Muller sample */
  int has_spare;
} nd_rng;

/* Seed generator r for (seed, stream). Same pair, same sequence. */
void nd_rng_seed(nd_rng *r, uint64_t seed, uint64_t stream);

/* Next raw 64-bit value. */
uint64_t nd_rng_u64(nd_rng *r);

/* Uniform double in [0, 1). */
double nd_rng_uniform(nd_rng *r);

/* Standard normal sample. */
double nd_rng_normal(nd_rng *r);

#endif
