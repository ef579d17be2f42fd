/* nd_cem: the one cross-entropy optimiser of the project.
 *
 * Configured as iCEM (Pinneri et al. 2020) it plans keypoint sequences; configured as
 * plain CEM it fits model parameters. The decision vector has dim = horizon * block
 * entries laid out horizon-major (block values of step 0, then step 1, ...); colored
 * noise is correlated along the horizon. Costs come from a batch callback so the
 * caller can spread the evaluations over a pool. All memory is allocated by
 * nd_cem_create; nd_cem_run allocates nothing. */
#ifndef ND_CEM_H
#define ND_CEM_H

#include "nd_rng.h"

/* Evaluate n candidates x[i * dim .. i * dim + dim) into cost[i]. Return 0, or
 * non-zero to abort the run. Non-finite costs (-inf and NaN too) are treated as +inf.
 * The cost must be a function of x alone during one run: kept elites are not
 * re-evaluated within a run, only in the first iteration of the next one. */
typedef int (*nd_cem_cost_fn)(void *ctx, const double *x, int n, double *cost);

typedef struct {
  int horizon;        /* steps along which noise may be colored (>= 1) */
  int block;          /* values per step (>= 1); dim = horizon * block */
  int pop;            /* population of the first iteration (N, Q), >= 2 */
  int iters;          /* iterations per run (C) */
  double elite_frac;  /* elite fraction rho in (0, 1]: round(rho * pop) >= 1 elites, fixed */
  double keep_frac;   /* fraction of elites carried into the next iteration and run (iCEM),
                         at least one when > 0; 0 = none */
  double pop_decay;   /* iCEM gamma >= 1: iteration i samples floor(pop * gamma^-i) fresh
                         candidates, but at least min(pop, 2 * elites) */
  double momentum;    /* alpha in [0, 1): new = alpha * old + (1 - alpha) * elite stats */
  double noise_beta;  /* colored-noise exponent >= 0 (0 white, 2 ~ iCEM's default); the
                         noise is periodic over the horizon like iCEM's reference generator,
                         and has no effect for horizon <= 2 (one frequency only) */
  double std_min;     /* floor of every std after an update */
  double step_std;    /* >= 0: a std is at least step_std times its mean's step in the
                         update, so (for step_std >= 1) it grows while the elites lie on
                         one side (a slope) and shrinks once they straddle the optimum;
                         0: plain CEM (doc/decisions.md#step-std) */
  double step_gate;   /* >= 0: the step_std rule applies only to a step of at least step_gate
                         sampling stds (on a slope the elite mean moves ~1.4 std; a shorter
                         step means the elites found the optimum inside the samples); 0: any
                         step (doc/decisions.md#step-gate) */
  const double *lower; /* per-dim bounds (dim values) or NULL for none (each side on its
                          own); samples, mean and shifted elites are clipped */
  const double *upper;
  int inject_mean;    /* evaluate the mean as a candidate in the last iteration */
  int redraws;        /* >= 0: a fresh sample the accept callback refuses is drawn again up
                         to redraws times, the last draw kept (sampling truncated to what is
                         accepted; doc/decisions.md#redraw); 0: every draw kept */
} nd_cem_cfg;

/* Fill cfg with plain-CEM defaults for the given shape (white noise, no keep, no decay). */
void nd_cem_cfg_default(nd_cem_cfg *cfg, int horizon, int block, int pop, int iters);

typedef struct nd_cem nd_cem;

/* Allocate an optimiser for cfg (bounds are copied). NULL and a message if cfg is invalid.
 * The distribution starts at mean 0 (clipped into the bounds), std 1. */
nd_cem *nd_cem_create(const nd_cem_cfg *cfg, char *err, int errlen);
void nd_cem_free(nd_cem *cem);

/* Set the sampling distribution (dim values each; mean clipped) and forget kept elites. */
void nd_cem_set_dist(nd_cem *cem, const double *mean, const double *std);

/* Replace the bounds (dim values each; both were given at creation), clip the mean into
 * them and forget kept elites. Return 0, or -1 with a message when a bound is invalid. */
int nd_cem_set_bounds(nd_cem *cem, const double *lower, const double *upper, char *err,
                      int errlen);

/* Warm start for the next run: shift mean and kept elites `steps` >= 0 steps earlier
 * along the horizon, fill the freed tail with its last step, and reset std to std_init
 * (NULL keeps std). */
void nd_cem_shift(nd_cem *cem, int steps, const double *std_init);

/* Warm start in a new frame: fn(ctx, x) rewrites the mean and each kept elite x (dim
 * values) in place; the results are clipped into the bounds. */
typedef void (*nd_cem_map_fn)(void *ctx, double *x);
void nd_cem_map(nd_cem *cem, nd_cem_map_fn fn, void *ctx);

/* Set ok[i] to whether candidate x[i * dim ..) of n is worth evaluating. Called with an
 * iteration's fresh draws, then with those refused and drawn again, so the caller may
 * check them in parallel. Only consulted when cfg.redraws > 0. */
typedef void (*nd_cem_accept_fn)(void *ctx, const double *x, int n, int *ok);
void nd_cem_set_accept(nd_cem *cem, nd_cem_accept_fn fn, void *ctx);
/* Draws the accept callback refused and that were drawn again, in the last run. */
int nd_cem_redrawn(const nd_cem *cem);

/* Run cfg.iters iterations from the current distribution with generator r (all sampling
 * happens on the calling thread, so results do not depend on how costs are spread).
 * One callback per iteration. Return 0, or the callback's non-zero code at once (the
 * distribution then holds the last completed iteration's update). */
int nd_cem_run(nd_cem *cem, nd_rng *r, nd_cem_cost_fn fn, void *ctx);

int nd_cem_dim(const nd_cem *cem);
const double *nd_cem_mean(const nd_cem *cem);       /* current mean (dim) */
const double *nd_cem_std(const nd_cem *cem);        /* current std (dim) */
const double *nd_cem_best(const nd_cem *cem);       /* best candidate of the last run (dim) */
double nd_cem_best_cost(const nd_cem *cem);         /* its cost */
/* Best cost seen in iteration i of the last run, i < cfg.iters. */
double nd_cem_iter_best(const nd_cem *cem, int i);
/* Number of cost evaluations in the last run. */
int nd_cem_evals(const nd_cem *cem);
/* Largest n the cost callback can be given: pop + kept elites + injected mean. */
int nd_cem_max_batch(const nd_cem *cem);

#endif
