/* nds_fit_lm: the fit's Levenberg-Marquardt refinement (nds_fit_int.h).
 *
 * After CEM has found the basin, the replays' residuals are nearly linear in theta over a
 * few of its stds, and a Gauss-Newton step on them costs one batch of n + 1 replays of the
 * buffer (the trial point and a forward difference per fitted parameter, run together on
 * the pool) where CEM's iteration costs Q. Its J'J also gives the estimate's covariance.
 *
 * Residuals, per compared step of each rollout (as nds_replay compares them): the
 * object's x and y, the sphere's x and y weighted by sqrt(k1), and the object's yaw
 * difference weighted by sqrt(k2 / rad), all over sqrt(T) of their rollout, so |r|^2
 * is L with the yaw term squared rather than absolute (a least-squares problem needs a
 * smooth residual; near the fit the squared yaw flattens, so it informs less than in L). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_lm.h"
#include "nd_math.h"
#include "nds_fit_int.h"

#define COLS NDS_REPLAY_PRED_COLS

/* A residual for a replay that diverged: a metre, far above any real error. */
#define DIVERGED_RESIDUAL 1.0

typedef struct {
  nds_fit *f;
  const nd_rollout *rs;
  int n;
  int *rows;            /* n: compared steps of each rollout */
  size_t *off;          /* n: its first row in a point's prediction */
  size_t nrows;         /* all rollouts' rows */
  int m;                /* residuals: nrows x COLS */
  int npts;             /* points of the batch being replayed */
  double *theta;        /* npts x ND_NTHETA */
  double *pred;         /* npts x nrows x COLS */
  int failed, replays;
} refine_ctx;

static void pred_task(void *ctx, int task, int worker) {
  refine_ctx *c = ctx;
  nds_fit *f = c->f;
  const int p = task / c->n, r = task % c->n;
  double *pred = c->pred + ((size_t)p * c->nrows + c->off[r]) * COLS;
  nds_replay_terms t;
  char err[160];
  if (nds_fit_hold(f, worker, c->theta + (size_t)p * ND_NTHETA)) {
    for (size_t i = 0; i < (size_t)c->rows[r] * COLS; i++) pred[i] = NAN;
    return;
  }
  if (nds_replay(&f->models[worker], f->data[worker], &f->cfg.replay, &c->rs[r], &t, pred,
                 err, sizeof(err)))
    __atomic_store_n(&c->failed, 1, __ATOMIC_RELAXED);
}

static int residuals(void *ctx, const double *x, int k, double *res) {
  refine_ctx *c = ctx;
  nds_fit *f = c->f;
  c->npts = k;
  for (int p = 0; p < k; p++)
    nds_fit_to_theta(f, x + (size_t)p * f->nfit, c->theta + (size_t)p * ND_NTHETA);
  nd_pool_run(f->pool, k * c->n, pred_task, c);
  c->replays += k * c->n;
  if (c->failed) return -1;
  const double w[COLS] = {1.0, 1.0, sqrt(f->cfg.k2), sqrt(f->cfg.k1), sqrt(f->cfg.k1)};
  for (int p = 0; p < k; p++) {
    double *rp = res + (size_t)p * c->m;
    for (int r = 0; r < c->n; r++) {
      const nd_rollout *ro = &c->rs[r];
      const int kk = ro->n / c->rows[r];
      const double norm = 1.0 / sqrt((double)c->rows[r]);
      const double *pr = c->pred + ((size_t)p * c->nrows + c->off[r]) * COLS;
      double *rr = rp + c->off[r] * COLS;
      for (int j = 0; j < c->rows[r]; j++) {
        const double *oo = ro->obj + ND_ROLLOUT_OBJ * ((size_t)j * kk + kk - 1);
        const double *oe = ro->ee + 2 * ((size_t)j * kk + kk - 1);
        const double *q = pr + (size_t)j * COLS;
        double e[COLS] = {q[0] - oo[0], q[1] - oo[1], nd_wrap_angle(q[2] - nd_quat_yaw(oo + 3)),
                          q[3] - oe[0], q[4] - oe[1]};
        for (int i = 0; i < COLS; i++)
          rr[(size_t)j * COLS + i] =
              isfinite(e[i]) ? w[i] * e[i] * norm : DIVERGED_RESIDUAL * norm;
      }
    }
  }
  return 0;
}

/* iters Levenberg-Marquardt iterations from theta (in/out) into out's lm_ fields; 0: the
 * covariance at theta only. */
static int lm_solve(nds_fit *f, const nd_rollout *rs, int n, int iters,
                    double theta[ND_NTHETA], nds_fit_out *out, char *err, int errlen) {
  refine_ctx c = {.f = f, .rs = rs, .n = n};
  nd_lm *lm = NULL;
  int rc = -1;
  c.rows = malloc(sizeof(int) * n);
  c.off = malloc(sizeof(size_t) * n);
  if (!c.rows || !c.off) goto oom;
  for (int r = 0; r < n; r++) {
    const int k = nds_replay_ratio(&f->proto, &rs[r], err, errlen);
    if (k < 1) goto done;
    c.rows[r] = rs[r].n / k;
    c.off[r] = c.nrows;
    c.nrows += (size_t)c.rows[r];
  }
  if (c.nrows * COLS > 50000000) {
    snprintf(err, errlen, "fit: %zu replay steps are too many for the refinement", c.nrows);
    goto done;
  }
  c.m = (int)(c.nrows * COLS);
  const int npts = f->nfit + 1;
  c.theta = malloc(sizeof(double) * ND_NTHETA * npts);
  c.pred = malloc(sizeof(double) * c.nrows * COLS * npts);
  if (!c.theta || !c.pred) goto oom;

  double x[ND_NTHETA], lo[ND_NTHETA], hi[ND_NTHETA], sc[ND_NTHETA];
  for (int j = 0; j < f->nfit; j++) {
    x[j] = nds_fit_x(f, j, theta[f->idx[j]]);
    lo[j] = nds_fit_x(f, j, nds_fit_floor(&f->cfg, f->idx[j]));
    hi[j] = isfinite(f->cfg.upper[f->idx[j]]) ? nds_fit_x(f, j, f->cfg.upper[f->idx[j]]) : 1e6;
    sc[j] = 1.0;
  }
  nd_lm_cfg lc;
  nd_lm_cfg_default(&lc);
  lc.n = f->nfit;
  lc.m = c.m;
  lc.iters = iters;
  lc.lower = lo;
  lc.upper = hi;
  lc.scale = sc;
  lc.fd_step = f->cfg.lm_fd;
  lc.stride = COLS;
  if (!(lm = nd_lm_create(&lc, err, errlen))) goto done;
  nd_lm_out lo_out;
  if (nd_lm_run(lm, residuals, &c, x, &lo_out, err, errlen)) {
    if (c.failed) snprintf(err, errlen, "fit: a record could not be replayed");
    goto done;
  }
  out->lm_run = 1;
  out->lm_iters = lo_out.iters;
  out->lm_replays = c.replays;
  out->lm_cost0 = lo_out.cost0;
  out->lm_cost = lo_out.cost;
  out->lm_inflation = lo_out.inflation;
  for (int i = 0; i < ND_NTHETA; i++) out->lm_std[i] = 0.0;
  for (int j = 0; j < f->nfit; j++) {
    theta[f->idx[j]] = nds_fit_th(f, j, x[j]);
    out->lm_std[f->idx[j]] =
        lo_out.rank_ok ? nds_fit_thstd(f, j, theta[f->idx[j]], lo_out.std[j]) : NAN;
  }
  rc = 0;
  goto done;
oom:
  snprintf(err, errlen, "fit: out of memory for the refinement");
done:
  nd_lm_free(lm);
  free(c.rows);
  free(c.off);
  free(c.theta);
  free(c.pred);
  return rc;
}

int nds_fit_refine(nds_fit *f, const nd_rollout *rs, int n, double theta[ND_NTHETA],
                   nds_fit_out *out, char *err, int errlen) {
  return lm_solve(f, rs, n, f->cfg.lm_iters, theta, out, err, errlen);
}

int nds_fit_cov(nds_fit *f, const double theta[ND_NTHETA], const nd_rollout *rs, int n,
                double std[ND_NTHETA], char *err, int errlen) {
  nds_fit_out out;
  double th[ND_NTHETA];
  memcpy(th, theta, sizeof(th));
  memset(&out, 0, sizeof(out));
  if (lm_solve(f, rs, n, 0, th, &out, err, errlen)) return -1;
  memcpy(std, out.lm_std, sizeof(out.lm_std));
  return 0;
}
