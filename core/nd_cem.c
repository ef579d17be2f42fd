/* nd_cem: cross-entropy method with the iCEM refinements (Pinneri et al. 2020).
 *
 * One iteration lays its candidates out as rows of one buffer:
 *   [kept elites | fresh samples | mean (last iteration, if injected)]
 * Kept elites come first, so a cost tie between a kept elite and a fresh sample goes to
 * the kept one (ties break by row), and the best of a run can never be lost between
 * iterations. Within a run the cost of a kept elite is reused (the objective does not
 * change during a run); in the first iteration of a run every row is evaluated, because
 * the objective may have changed since the last run (new state, shifted horizon). */
#include "nd_cem.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ND_CEM_MAX_DIM (1 << 20)
#define ND_CEM_MAX_POP (1 << 22)
#define ND_CEM_MAX_CELLS ((size_t)1 << 28)  /* candidate buffer, doubles */

struct nd_cem {
  nd_cem_cfg cfg;     /* lower/upper point at the copies below */
  int dim;
  int nelite;         /* elites per iteration, fixed over the run (iCEM) */
  int nkeep;          /* elites carried to the next iteration / run */
  int cap;            /* rows of the candidate buffer: pop + nkeep + 1 */

  double *lower, *upper;  /* own copies, or NULL */
  double *basis;      /* horizon x horizon map white -> colored, NULL for white noise */
  double *z;          /* horizon: white draws */

  double *x;          /* cap x dim candidates */
  double *cost;       /* cap */
  int *order;         /* cap: row indices, elites first after selection */
  int *ok;            /* cap: the accept callback's answers */

  double *keep;       /* nkeep x dim kept elites */
  double *keep_cost;  /* nkeep */
  int nkept;          /* valid rows of keep */

  double *mean, *std;
  double *best;
  double best_cost;
  double *iter_best;  /* iters */
  int evals;
  int redrawn;        /* refused draws in the last run */
  nd_cem_accept_fn accept;
  void *accept_ctx;
};

static void nd_cem_err(char *err, int errlen, const char *fmt, const char *what) {
  if (err && errlen > 0) snprintf(err, (size_t)errlen, fmt, what);
}

void nd_cem_cfg_default(nd_cem_cfg *cfg, int horizon, int block, int pop, int iters) {
  memset(cfg, 0, sizeof *cfg);
  cfg->horizon = horizon;
  cfg->block = block;
  cfg->pop = pop;
  cfg->iters = iters;
  cfg->elite_frac = 0.2;
  cfg->keep_frac = 0.0;
  cfg->pop_decay = 1.0;
  cfg->momentum = 0.0;
  cfg->noise_beta = 0.0;
  cfg->std_min = 0.0;
  cfg->lower = NULL;
  cfg->upper = NULL;
  cfg->inject_mean = 0;
}

/* Each bound a number, lower <= upper (NULL: unbounded on that side). */
static int nd_cem_bounds_check(int dim, const double *lower, const double *upper, char *err,
                               int errlen) {
  for (int i = 0; i < dim; i++) {
    double lo = lower ? lower[i] : -INFINITY;
    double hi = upper ? upper[i] : INFINITY;
    if (isnan(lo) || isnan(hi) || !(lo <= hi)) {
      if (err && errlen > 0)
        snprintf(err, (size_t)errlen, "nd_cem: bounds of dim %d are invalid (lower %g, upper %g)",
                 i, lo, hi);
      return -1;
    }
  }
  return 0;
}

/* Check cfg; 0 or -1 with a message naming the offending field. */
static int nd_cem_validate(const nd_cem_cfg *cfg, char *err, int errlen) {
  const char *bad = NULL;
  if (cfg->horizon < 1) bad = "horizon must be >= 1";
  else if (cfg->block < 1) bad = "block must be >= 1";
  else if ((long long)cfg->horizon * cfg->block > ND_CEM_MAX_DIM) bad = "horizon * block too large";
  else if (cfg->pop < 2 || cfg->pop > ND_CEM_MAX_POP) bad = "pop must be in [2, 4194304]";
  else if (cfg->iters < 1) bad = "iters must be >= 1";
  else if (!(cfg->elite_frac > 0.0 && cfg->elite_frac <= 1.0)) bad = "elite_frac must be in (0, 1]";
  else if (!(cfg->keep_frac >= 0.0 && cfg->keep_frac <= 1.0)) bad = "keep_frac must be in [0, 1]";
  else if (!(cfg->pop_decay >= 1.0 && isfinite(cfg->pop_decay))) bad = "pop_decay must be finite and >= 1";
  else if (!(cfg->momentum >= 0.0 && cfg->momentum < 1.0)) bad = "momentum must be in [0, 1)";
  else if (cfg->redraws < 0) bad = "redraws must be >= 0";
  else if (!(cfg->noise_beta >= 0.0 && isfinite(cfg->noise_beta))) bad = "noise_beta must be finite and >= 0";
  else if (!(cfg->std_min >= 0.0 && isfinite(cfg->std_min))) bad = "std_min must be finite and >= 0";
  else if (!(cfg->step_std >= 0.0 && isfinite(cfg->step_std))) bad = "step_std must be finite and >= 0";
  else if (!(cfg->step_gate >= 0.0 && isfinite(cfg->step_gate))) bad = "step_gate must be finite and >= 0";
  if (bad) {
    nd_cem_err(err, errlen, "nd_cem: %s", bad);
    return -1;
  }
  int dim = cfg->horizon * cfg->block;
  if (nd_cem_bounds_check(dim, cfg->lower, cfg->upper, err, errlen)) return -1;
  if ((size_t)(2 * cfg->pop + 1) * (size_t)dim > ND_CEM_MAX_CELLS) {
    nd_cem_err(err, errlen, "nd_cem: %s", "pop * horizon * block too large");
    return -1;
  }
  return 0;
}

/* Power-law (1/f^beta) noise along the horizon as a fixed linear map of white draws:
 * a real orthonormal Fourier basis (DC, cos/sin pairs, Nyquist) with each frequency
 * scaled by f^(-beta/2), the DC term taking the lowest frequency 1/H as iCEM's
 * reference generator does. The process is stationary (circular), so every row has the
 * same norm; each row is still normalised on its own so every step has unit variance.
 * beta = 0 gives an orthogonal map, i.e. white noise. */
static void nd_cem_make_basis(double *A, int H, double beta) {
  const double two_pi = 6.283185307179586;
  for (int t = 0; t < H; t++) A[t * H + 0] = pow(1.0 / H, -0.5 * beta) / sqrt((double)H);
  int j = 1;
  for (int k = 1; 2 * k < H; k++) {
    double s = pow((double)k / H, -0.5 * beta) * sqrt(2.0 / H);
    for (int t = 0; t < H; t++) {
      A[t * H + j] = s * cos(two_pi * k * t / H);
      A[t * H + j + 1] = s * sin(two_pi * k * t / H);
    }
    j += 2;
  }
  if (H % 2 == 0) {
    double s = pow(0.5, -0.5 * beta) / sqrt((double)H);
    for (int t = 0; t < H; t++) A[t * H + j] = (t % 2 ? -s : s);
    j++;
  }
  for (int t = 0; t < H; t++) {
    double ss = 0.0;
    for (int c = 0; c < H; c++) ss += A[t * H + c] * A[t * H + c];
    double inv = 1.0 / sqrt(ss);
    for (int c = 0; c < H; c++) A[t * H + c] *= inv;
  }
}

static double nd_cem_clip(double v, const double *lo, const double *hi, int i) {
  if (lo && v < lo[i]) v = lo[i];
  if (hi && v > hi[i]) v = hi[i];
  return v;
}

static void nd_cem_clip_vec(const nd_cem *cem, double *v) {
  if (!cem->lower && !cem->upper) return;
  for (int i = 0; i < cem->dim; i++) v[i] = nd_cem_clip(v[i], cem->lower, cem->upper, i);
}

nd_cem *nd_cem_create(const nd_cem_cfg *cfg, char *err, int errlen) {
  if (!cfg) {
    nd_cem_err(err, errlen, "nd_cem: %s", "cfg is NULL");
    return NULL;
  }
  if (nd_cem_validate(cfg, err, errlen)) return NULL;

  nd_cem *cem = (nd_cem *)calloc(1, sizeof(nd_cem));
  if (!cem) {
    nd_cem_err(err, errlen, "nd_cem: %s", "out of memory");
    return NULL;
  }
  int H = cfg->horizon, dim = cfg->horizon * cfg->block;
  cem->cfg = *cfg;
  cem->dim = dim;
  cem->nelite = (int)(cfg->elite_frac * cfg->pop + 0.5);
  if (cem->nelite < 1) cem->nelite = 1;
  if (cem->nelite > cfg->pop) cem->nelite = cfg->pop;
  cem->nkeep = 0;
  if (cfg->keep_frac > 0.0) {
    cem->nkeep = (int)(cfg->keep_frac * cem->nelite + 0.5);
    if (cem->nkeep < 1) cem->nkeep = 1;
    if (cem->nkeep > cem->nelite) cem->nkeep = cem->nelite;
  }
  cem->cap = cfg->pop + cem->nkeep + 1;

  size_t D = (size_t)dim;
  int ok = 1;
#define ND_CEM_ALLOC(p, n, T) ok = ok && ((p) = (T *)calloc((n), sizeof(T))) != NULL
  if (cfg->lower) ND_CEM_ALLOC(cem->lower, D, double);
  if (cfg->upper) ND_CEM_ALLOC(cem->upper, D, double);
  if (cfg->noise_beta != 0.0 && H > 1) ND_CEM_ALLOC(cem->basis, (size_t)H * H, double);
  ND_CEM_ALLOC(cem->z, (size_t)H, double);
  ND_CEM_ALLOC(cem->x, (size_t)cem->cap * D, double);
  ND_CEM_ALLOC(cem->cost, (size_t)cem->cap, double);
  ND_CEM_ALLOC(cem->order, (size_t)cem->cap, int);
  ND_CEM_ALLOC(cem->ok, (size_t)cem->cap, int);
  ND_CEM_ALLOC(cem->keep, (size_t)(cem->nkeep > 0 ? cem->nkeep : 1) * D, double);
  ND_CEM_ALLOC(cem->keep_cost, (size_t)(cem->nkeep > 0 ? cem->nkeep : 1), double);
  ND_CEM_ALLOC(cem->mean, D, double);
  ND_CEM_ALLOC(cem->std, D, double);
  ND_CEM_ALLOC(cem->best, D, double);
  ND_CEM_ALLOC(cem->iter_best, (size_t)cfg->iters, double);
#undef ND_CEM_ALLOC
  if (!ok) {
    nd_cem_free(cem);
    nd_cem_err(err, errlen, "nd_cem: %s", "out of memory");
    return NULL;
  }
  if (cfg->lower) memcpy(cem->lower, cfg->lower, D * sizeof(double));
  if (cfg->upper) memcpy(cem->upper, cfg->upper, D * sizeof(double));
  cem->cfg.lower = cem->lower;
  cem->cfg.upper = cem->upper;
  if (cem->basis) nd_cem_make_basis(cem->basis, H, cfg->noise_beta);

  /* until nd_cem_set_dist: mean 0 (clipped into the bounds), std 1 */
  for (int i = 0; i < dim; i++) cem->std[i] = 1.0;
  nd_cem_clip_vec(cem, cem->mean);
  memcpy(cem->best, cem->mean, D * sizeof(double));
  cem->best_cost = INFINITY;
  for (int i = 0; i < cfg->iters; i++) cem->iter_best[i] = INFINITY;
  return cem;
}

void nd_cem_free(nd_cem *cem) {
  if (!cem) return;
  free(cem->lower);
  free(cem->upper);
  free(cem->basis);
  free(cem->z);
  free(cem->x);
  free(cem->cost);
  free(cem->order);
  free(cem->ok);
  free(cem->keep);
  free(cem->keep_cost);
  free(cem->mean);
  free(cem->std);
  free(cem->best);
  free(cem->iter_best);
  free(cem);
}

void nd_cem_set_dist(nd_cem *cem, const double *mean, const double *std) {
  size_t bytes = (size_t)cem->dim * sizeof(double);
  memcpy(cem->mean, mean, bytes);
  memcpy(cem->std, std, bytes);
  nd_cem_clip_vec(cem, cem->mean);
  cem->nkept = 0;
}

int nd_cem_set_bounds(nd_cem *cem, const double *lower, const double *upper, char *err,
                      int errlen) {
  if (!cem->lower || !cem->upper) {
    nd_cem_err(err, errlen, "nd_cem: %s", "bounds can change only on an optimiser created with both");
    return -1;
  }
  if (nd_cem_bounds_check(cem->dim, lower, upper, err, errlen)) return -1;
  size_t bytes = (size_t)cem->dim * sizeof(double);
  memcpy(cem->lower, lower, bytes);
  memcpy(cem->upper, upper, bytes);
  nd_cem_clip_vec(cem, cem->mean);
  cem->nkept = 0;
  return 0;
}

/* v[t] = v[min(t + steps, H - 1)] per step of `block` values; ascending t only reads
 * steps not yet overwritten. */
static void nd_cem_shift_vec(double *v, int H, int B, int steps) {
  for (int t = 0; t < H; t++) {
    int src = t + steps < H ? t + steps : H - 1;
    if (src != t) memmove(v + (size_t)t * B, v + (size_t)src * B, (size_t)B * sizeof(double));
  }
}

void nd_cem_shift(nd_cem *cem, int steps, const double *std_init) {
  int H = cem->cfg.horizon, B = cem->cfg.block;
  if (steps > 0) {
    nd_cem_shift_vec(cem->mean, H, B, steps);
    nd_cem_clip_vec(cem, cem->mean);  /* bounds may differ from step to step */
    for (int k = 0; k < cem->nkept; k++) {
      double *e = cem->keep + (size_t)k * cem->dim;
      nd_cem_shift_vec(e, H, B, steps);
      nd_cem_clip_vec(cem, e);
    }
  }
  if (std_init) memcpy(cem->std, std_init, (size_t)cem->dim * sizeof(double));
}

void nd_cem_map(nd_cem *cem, nd_cem_map_fn fn, void *ctx) {
  fn(ctx, cem->mean);
  nd_cem_clip_vec(cem, cem->mean);
  for (int k = 0; k < cem->nkept; k++) {
    double *e = cem->keep + (size_t)k * cem->dim;
    fn(ctx, e);
    nd_cem_clip_vec(cem, e);
  }
}

/* Population of fresh samples in iteration it: pop * gamma^-it, floored at twice the
 * elite count (but never above pop) so late iterations still have a choice. */
static int nd_cem_pop_at(const nd_cem *cem, int it) {
  const nd_cem_cfg *cfg = &cem->cfg;
  int floor_pop = 2 * cem->nelite < cfg->pop ? 2 * cem->nelite : cfg->pop;
  double n = cfg->pop * pow(cfg->pop_decay, -(double)it);
  int ni = (int)n;
  if (ni > cfg->pop) ni = cfg->pop;
  return ni > floor_pop ? ni : floor_pop;
}

/* Draw one candidate around mean/std into x (dim values), clipped to the bounds. */
static void nd_cem_sample(nd_cem *cem, nd_rng *r, double *x) {
  int H = cem->cfg.horizon, B = cem->cfg.block;
  const double *A = cem->basis;
  double *z = cem->z;
  for (int b = 0; b < B; b++) {
    for (int j = 0; j < H; j++) z[j] = nd_rng_normal(r);
    for (int t = 0; t < H; t++) {
      double e = z[t];
      if (A) {
        e = 0.0;
        for (int j = 0; j < H; j++) e += A[t * H + j] * z[j];
      }
      int i = t * B + b;
      x[i] = nd_cem_clip(cem->mean[i] + cem->std[i] * e, cem->lower, cem->upper, i);
    }
  }
}

/* Strict total order on rows: cost, then row index (costs are never NaN here). */
static int nd_cem_less(const double *c, int a, int b) {
  return c[a] < c[b] || (c[a] == c[b] && a < b);
}

/* Reorder idx[0, n) so that idx[0, k) holds the k smallest rows in ascending order. */
static void nd_cem_select(const double *c, int *idx, int n, int k) {
  int lo = 0, hi = n - 1;
  while (k < n && lo < hi) {
    int mid = lo + (hi - lo) / 2, tmp;
    /* median of three into idx[hi] as the pivot */
    if (nd_cem_less(c, idx[mid], idx[lo])) { tmp = idx[mid]; idx[mid] = idx[lo]; idx[lo] = tmp; }
    if (nd_cem_less(c, idx[hi], idx[lo])) { tmp = idx[hi]; idx[hi] = idx[lo]; idx[lo] = tmp; }
    if (nd_cem_less(c, idx[mid], idx[hi])) { tmp = idx[mid]; idx[mid] = idx[hi]; idx[hi] = tmp; }
    int pivot = idx[hi], store = lo;
    for (int i = lo; i < hi; i++) {
      if (nd_cem_less(c, idx[i], pivot)) {
        tmp = idx[i]; idx[i] = idx[store]; idx[store] = tmp;
        store++;
      }
    }
    tmp = idx[store]; idx[store] = idx[hi]; idx[hi] = tmp;
    if (store == k - 1) break;
    if (store < k - 1) lo = store + 1;
    else hi = store - 1;
  }
  for (int i = 1; i < k; i++) {
    int v = idx[i], j = i - 1;
    while (j >= 0 && nd_cem_less(c, v, idx[j])) {
      idx[j + 1] = idx[j];
      j--;
    }
    idx[j + 1] = v;
  }
}

/* Refit mean/std to the elites idx[0, nelite), with momentum, std floor and mean clip. */
static void nd_cem_update(nd_cem *cem) {
  const nd_cem_cfg *cfg = &cem->cfg;
  int K = cem->nelite, D = cem->dim;
  double a = cfg->momentum;
  for (int i = 0; i < D; i++) {
    double m = 0.0, v = 0.0;
    for (int e = 0; e < K; e++) m += cem->x[(size_t)cem->order[e] * D + i];
    m /= K;
    for (int e = 0; e < K; e++) {
      double d = cem->x[(size_t)cem->order[e] * D + i] - m;
      v += d * d;
    }
    double s = sqrt(v / K);
    double nm = a * cem->mean[i] + (1.0 - a) * m;
    double ns = a * cem->std[i] + (1.0 - a) * s;
    nm = nd_cem_clip(nm, cem->lower, cem->upper, i);
    double step = fabs(nm - cem->mean[i]);
    if (step >= cfg->step_gate * cem->std[i] && cfg->step_std * step > ns) ns = cfg->step_std * step;
    cem->mean[i] = nm;
    cem->std[i] = ns > cfg->std_min ? ns : cfg->std_min;
  }
}

/* Draw the n fresh candidates x the accept callback refuses again, up to cfg.redraws
 * times. Refused rows are moved to the tail, so each round asks about one contiguous
 * block; the fresh draws are exchangeable, so their order carries nothing. */
static void nd_cem_redraw(nd_cem *cem, nd_rng *r, double *x, int n) {
  const int D = cem->dim;
  int *ok = cem->ok;
  for (int k = 0; k < cem->cfg.redraws && n > 0; k++) {
    cem->accept(cem->accept_ctx, x, n, ok);
    int lo = 0, hi = n - 1;  /* after the loop: [0, lo) accepted, [lo, n) refused */
    while (lo <= hi) {
      if (ok[lo]) {
        lo++;
      } else if (!ok[hi]) {
        hi--;
      } else {
        for (int j = 0; j < D; j++) {
          const double t = x[(size_t)lo * D + j];
          x[(size_t)lo * D + j] = x[(size_t)hi * D + j];
          x[(size_t)hi * D + j] = t;
        }
        lo++, hi--;
      }
    }
    x += (size_t)lo * D;
    n -= lo;
    for (int i = 0; i < n; i++) nd_cem_sample(cem, r, x + (size_t)i * D);
    cem->redrawn += n;
  }
}

int nd_cem_run(nd_cem *cem, nd_rng *r, nd_cem_cost_fn fn, void *ctx) {
  const nd_cem_cfg *cfg = &cem->cfg;
  size_t D = (size_t)cem->dim;
  cem->evals = 0;
  cem->redrawn = 0;
  cem->best_cost = INFINITY;
  for (int i = 0; i < cfg->iters; i++) cem->iter_best[i] = INFINITY;

  for (int it = 0; it < cfg->iters; it++) {
    int nk = cem->nkept;
    int nfresh = nd_cem_pop_at(cem, it);
    int inject = cfg->inject_mean && it == cfg->iters - 1;
    int n = nk + nfresh + inject;

    if (nk > 0) memcpy(cem->x, cem->keep, (size_t)nk * D * sizeof(double));
    for (int i = 0; i < nfresh; i++) nd_cem_sample(cem, r, cem->x + (size_t)(nk + i) * D);
    if (cem->accept) nd_cem_redraw(cem, r, cem->x + (size_t)nk * D, nfresh);
    if (inject) memcpy(cem->x + (size_t)(n - 1) * D, cem->mean, D * sizeof(double));

    int first = 0;
    if (it > 0) {
      memcpy(cem->cost, cem->keep_cost, (size_t)nk * sizeof(double));
      first = nk;
    }
    int rc = fn(ctx, cem->x + (size_t)first * D, n - first, cem->cost + first);
    cem->evals += n - first;
    if (rc != 0) return rc;
    for (int i = first; i < n; i++)
      if (!isfinite(cem->cost[i])) cem->cost[i] = INFINITY;

    for (int i = 0; i < n; i++) cem->order[i] = i;
    nd_cem_select(cem->cost, cem->order, n, cem->nelite);

    int top = cem->order[0];
    cem->iter_best[it] = cem->cost[top];
    if (it == 0 || cem->cost[top] < cem->best_cost) {
      cem->best_cost = cem->cost[top];
      memcpy(cem->best, cem->x + (size_t)top * D, D * sizeof(double));
    }

    nd_cem_update(cem);

    for (int k = 0; k < cem->nkeep; k++) {
      memcpy(cem->keep + (size_t)k * D, cem->x + (size_t)cem->order[k] * D, D * sizeof(double));
      cem->keep_cost[k] = cem->cost[cem->order[k]];
    }
    cem->nkept = cem->nkeep;
  }
  return 0;
}

int nd_cem_dim(const nd_cem *cem) {
  return cem->dim;
}

const double *nd_cem_mean(const nd_cem *cem) {
  return cem->mean;
}

const double *nd_cem_std(const nd_cem *cem) {
  return cem->std;
}

const double *nd_cem_best(const nd_cem *cem) {
  return cem->best;
}

double nd_cem_best_cost(const nd_cem *cem) {
  return cem->best_cost;
}

double nd_cem_iter_best(const nd_cem *cem, int i) {
  if (i < 0 || i >= cem->cfg.iters) return INFINITY;
  return cem->iter_best[i];
}

void nd_cem_set_accept(nd_cem *cem, nd_cem_accept_fn fn, void *ctx) {
  cem->accept = fn;
  cem->accept_ctx = ctx;
}

int nd_cem_redrawn(const nd_cem *cem) {
  return cem->redrawn;
}

int nd_cem_evals(const nd_cem *cem) {
  return cem->evals;
}

int nd_cem_max_batch(const nd_cem *cem) {
  return cem->cfg.pop + cem->nkeep + (cem->cfg.inject_mean ? 1 : 0);
}
