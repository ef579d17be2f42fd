/* nd_lm: Levenberg-Marquardt with batched forward differences (nd_lm.h). */
#include "nd_lm.h"

#include "nd_linalg.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define N_MAX 16

struct nd_lm {
  nd_lm_cfg cfg;
  double lower[N_MAX], upper[N_MAX], scale[N_MAX];
  double *pts;   /* (n + 1) x n: the batch */
  double *res;   /* (n + 1) x m: its residuals */
  double *r0;    /* m: residuals at the current point */
  double *J;     /* m x n: Jacobian at the current point (scaled parameters) */
};

void nd_lm_cfg_default(nd_lm_cfg *cfg) {
  memset(cfg, 0, sizeof(*cfg));
  cfg->iters = 5;
  cfg->fd_step = 1e-3;
  cfg->lambda0 = 1e-3;
  cfg->tol = 1e-6;
}

nd_lm *nd_lm_create(const nd_lm_cfg *c, char *err, int errlen) {
  if (c->n < 1 || c->n > N_MAX || c->m < c->n + 1 || c->iters < 0 || !c->lower ||
      !c->upper || !c->scale || !(c->fd_step > 0) || !(c->lambda0 > 0) || !(c->tol >= 0) ||
      c->stride < 0) {
    snprintf(err, errlen, "nd_lm: bad configuration (n %d, m %d, iters %d)", c->n, c->m,
             c->iters);
    return NULL;
  }
  for (int i = 0; i < c->n; i++)
    if (!(c->scale[i] > 0) || !(c->lower[i] <= c->upper[i])) {
      snprintf(err, errlen, "nd_lm: parameter %d: scale %g, bounds [%g, %g]", i, c->scale[i],
               c->lower[i], c->upper[i]);
      return NULL;
    }
  nd_lm *lm = calloc(1, sizeof(*lm));
  const size_t n = (size_t)c->n, m = (size_t)c->m;
  if (lm) {
    lm->pts = malloc(sizeof(double) * (n + 1) * n);
    lm->res = malloc(sizeof(double) * (n + 1) * m);
    lm->r0 = malloc(sizeof(double) * m);
    lm->J = malloc(sizeof(double) * m * n);
  }
  if (!lm || !lm->pts || !lm->res || !lm->r0 || !lm->J) {
    nd_lm_free(lm);
    snprintf(err, errlen, "nd_lm: out of memory for %d residuals", c->m);
    return NULL;
  }
  lm->cfg = *c;
  memcpy(lm->lower, c->lower, sizeof(double) * n);
  memcpy(lm->upper, c->upper, sizeof(double) * n);
  memcpy(lm->scale, c->scale, sizeof(double) * n);
  lm->cfg.lower = lm->lower, lm->cfg.upper = lm->upper, lm->cfg.scale = lm->scale;
  return lm;
}

void nd_lm_free(nd_lm *lm) {
  if (!lm) return;
  free(lm->pts);
  free(lm->res);
  free(lm->r0);
  free(lm->J);
  free(lm);
}

static double sumsq(const double *r, int m) {
  double s = 0;
  for (int i = 0; i < m; i++) s += r[i] * r[i];
  return s;
}

static double clampd(double v, double lo, double hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Solve the symmetric positive definite A (n x n, destroyed) x = b in place. 0, or -1
 * when A is not positive definite. */
static int spd_solve(double *A, int n, double *b) {
  if (nd_chol(A, n)) return -1;
  nd_chol_solve(A, n, b, b);
  return 0;
}

/* The batch around point x: x itself, then x + h_i e_i (a step that would leave the box
 * goes the other way). h[i] receives each signed step. */
static void make_batch(nd_lm *lm, const double *x, double *h) {
  const int n = lm->cfg.n;
  for (int k = 0; k <= n; k++) memcpy(lm->pts + (size_t)k * n, x, sizeof(double) * n);
  for (int i = 0; i < n; i++) {
    double step = lm->cfg.fd_step * lm->scale[i];
    if (x[i] + step > lm->upper[i]) step = -step;
    h[i] = step;
    lm->pts[(size_t)(i + 1) * n + i] = x[i] + step;
  }
}

/* Jacobian in scaled parameters from the batch's residuals (res row 0 is the base). */
static void jacobian(nd_lm *lm, const double *h) {
  const int n = lm->cfg.n, m = lm->cfg.m;
  for (int i = 0; i < n; i++) {
    const double *ri = lm->res + (size_t)(i + 1) * m;
    const double f = lm->scale[i] / h[i];
    for (int j = 0; j < m; j++) lm->J[(size_t)j * n + i] = (ri[j] - lm->res[j]) * f;
  }
  memcpy(lm->r0, lm->res, sizeof(double) * m);
}

/* J'J (n x n) and J'r (n) at the current point. */
static void normal_eq(const nd_lm *lm, double *A, double *g) {
  const int n = lm->cfg.n, m = lm->cfg.m;
  memset(A, 0, sizeof(double) * n * n);
  memset(g, 0, sizeof(double) * n);
  for (int j = 0; j < m; j++) {
    const double *row = lm->J + (size_t)j * n;
    for (int a = 0; a < n; a++) {
      g[a] += row[a] * lm->r0[j];
      for (int b = 0; b <= a; b++) A[a * n + b] += row[a] * row[b];
    }
  }
  for (int a = 0; a < n; a++)
    for (int b = a + 1; b < n; b++) A[a * n + b] = A[b * n + a];
}

/* The residuals' correlation between consecutive time steps (lag stride). */
static double lag_correlation(const double *r, int m, int stride) {
  double c0 = 0, c1 = 0;
  for (int j = 0; j < m; j++) c0 += r[j] * r[j];
  for (int j = stride; j < m; j++) c1 += r[j] * r[j - stride];
  return c0 > 0 ? c1 / c0 : 0.0;
}

int nd_lm_run(nd_lm *lm, nd_lm_fn fn, void *ctx, double *x, nd_lm_out *out, char *err,
              int errlen) {
  const nd_lm_cfg *c = &lm->cfg;
  const int n = c->n, m = c->m;
  double h[N_MAX], A[N_MAX * N_MAX], g[N_MAX], dx[N_MAX], xt[N_MAX];
  memset(out, 0, sizeof(*out));
  for (int i = 0; i < n; i++) x[i] = clampd(x[i], lm->lower[i], lm->upper[i]);
  make_batch(lm, x, h);
  if (fn(ctx, lm->pts, n + 1, lm->res)) goto aborted;
  out->evals = n + 1;
  jacobian(lm, h);
  double cost = sumsq(lm->r0, m), lambda = c->lambda0;
  out->cost0 = cost;
  for (int it = 0; it < c->iters; it++) {
    out->iters = it + 1;
    normal_eq(lm, A, g);
    /* Marquardt's damping on the diagonal; the step in scaled units, projected into the
     * box. */
    double M[N_MAX * N_MAX];
    memcpy(M, A, sizeof(double) * n * n);
    for (int a = 0; a < n; a++) {
      M[a * n + a] += lambda * (A[a * n + a] > 0 ? A[a * n + a] : 1.0);
      dx[a] = -g[a];
    }
    if (spd_solve(M, n, dx)) break;
    for (int a = 0; a < n; a++) xt[a] = clampd(x[a] + dx[a] * lm->scale[a], lm->lower[a], lm->upper[a]);
    make_batch(lm, xt, h);
    if (fn(ctx, lm->pts, n + 1, lm->res)) goto aborted;
    out->evals += n + 1;
    const double ct = sumsq(lm->res, m);
    if (ct < cost) {
      const double gain = (cost - ct) / cost;
      memcpy(x, xt, sizeof(double) * n);
      jacobian(lm, h);
      cost = ct;
      lambda = fmax(lambda / 10, 1e-12);
      out->accepted++;
      if (gain < c->tol) break;
    } else {
      lambda *= 10;
      if (lambda > 1e12) break;
    }
  }
  out->cost = cost;
  out->rho = c->stride > 0 ? lag_correlation(lm->r0, m, c->stride) : 0.0;
  const double rho = clampd(out->rho, 0.0, 0.98);
  out->inflation = c->stride > 0 ? fmin((1 + rho) / (1 - rho), 100.0) : 1.0;
  /* Covariance: the inverse of J'J column by column, in physical units, over the
   * parameters the residuals depend on; one they do not (a zero column: no difference
   * at the step) has an infinite std and no covariance with the others. */
  normal_eq(lm, A, g);
  int informed[N_MAX], k = 0, at[N_MAX];
  for (int a = 0; a < n; a++) {
    informed[a] = A[a * n + a] > 0;
    if (informed[a]) at[k++] = a;
  }
  out->sigma2 = cost / (m - k);  /* an ignored parameter takes no degree of freedom */
  out->rank_ok = k > 0;
  for (int a = 0; a < n * n; a++) out->cov[a] = 0.0;
  for (int bi = 0; bi < k && out->rank_ok; bi++) {
    double R[N_MAX * N_MAX], col[N_MAX] = {0};
    for (int i = 0; i < k; i++)
      for (int j = 0; j < k; j++) R[i * k + j] = A[at[i] * n + at[j]];
    col[bi] = 1.0;
    if (spd_solve(R, k, col)) out->rank_ok = 0;
    const int b = at[bi];
    for (int ai = 0; ai < k; ai++) {
      const int a = at[ai];
      out->cov[a * n + b] = col[ai] * out->sigma2 * out->inflation * lm->scale[a] * lm->scale[b];
    }
  }
  for (int a = 0; a < n; a++) {
    if (!out->rank_ok) {
      for (int b = 0; b < n; b++) out->cov[a * n + b] = NAN;
      out->std[a] = NAN;
      continue;
    }
    if (!informed[a]) out->cov[a * n + a] = INFINITY;
    out->std[a] = sqrt(out->cov[a * n + a]);
  }
  return 0;
aborted:
  snprintf(err, errlen, "nd_lm: the residuals could not be evaluated");
  return -1;
}
