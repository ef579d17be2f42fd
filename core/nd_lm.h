/* nd_lm: box-constrained Levenberg-Marquardt on a residual vector, with finite-difference
 * Jacobians evaluated in batches and a covariance of the estimate.
 *
 * Each iteration evaluates one batch of n + 1 points: the trial point and its forward
 * differences along every parameter, so a caller can run them all at once (in parallel):
 * a step that lowers the cost is taken together with its Jacobian; one that does not
 * raises the damping and retries from the old Jacobian at the cost of one evaluation. The
 * parameters are scaled by `scale` (the step and the damping are in units of it), and
 * every point stays inside [lower, upper].
 *
 * The covariance is sigma^2 (J'J)^-1 with sigma^2 = |r|^2 / (m - n). Residuals of a replay
 * are correlated along time, which makes that estimate too confident by about the variance
 * inflation factor (1 + rho) / (1 - rho) of an AR(1) process with the residuals' lag
 * correlation rho (at lag `stride`, the residuals one time step apart); with `stride` > 0
 * the covariance is inflated by it. */
#ifndef ND_LM_H
#define ND_LM_H

/* Evaluate the residuals of k points x[k][n] into r[k][m]. Return 0, or -1 to abort. */
typedef int (*nd_lm_fn)(void *ctx, const double *x, int k, double *r);

typedef struct {
  int n, m;            /* parameters (1..16), residuals (>= n + 1) */
  int iters;           /* most iterations (batches of n + 1 points); 0: the covariance at
                          the start point only */
  const double *lower, *upper;  /* bounds, n each */
  const double *scale; /* n: a parameter's natural size (> 0) */
  double fd_step;      /* forward-difference step, in units of scale */
  double lambda0;      /* initial damping, relative to diag(J'J) */
  double tol;          /* stop when a step changes the cost by less than tol relative */
  int stride;          /* residuals per time step, for the correlation correction; 0: none */
} nd_lm_cfg;

/* iters 5, fd_step 1e-3, lambda0 1e-3, tol 1e-6, stride 0; n, m, bounds, scale unset. */
void nd_lm_cfg_default(nd_lm_cfg *cfg);

typedef struct {
  double cost0, cost;  /* |r|^2 at the start and at the result */
  int iters, evals;    /* iterations and points evaluated */
  int accepted;        /* steps taken */
  double sigma2;       /* |r|^2 / (m - k) at the result, k the parameters r depends on */
  double rho;          /* lag correlation of the residuals (0 without stride) */
  double inflation;    /* (1 + rho) / (1 - rho), capped at 100; 1 without stride */
  double cov[256];     /* n x n covariance of the result (row-major), inflated; a
                          parameter the residuals do not depend on (a zero column of J)
                          has an infinite variance and zero covariance with the others */
  double std[16];      /* its square-root diagonal: standard errors */
  int rank_ok;         /* J'J over the other parameters was invertible (else cov and std
                          are NaN) */
} nd_lm_out;

typedef struct nd_lm nd_lm;

/* Workspace for cfg's sizes, allocated once. NULL and a message on a bad cfg or no memory. */
nd_lm *nd_lm_create(const nd_lm_cfg *cfg, char *err, int errlen);
void nd_lm_free(nd_lm *lm);

/* Minimise |r(x)|^2 from x (n values, clipped into the bounds), in place. Return 0 with
 * out filled, or -1 with a message (the callback aborted: x then holds the best point
 * found). */
int nd_lm_run(nd_lm *lm, nd_lm_fn fn, void *ctx, double *x, nd_lm_out *out, char *err,
              int errlen);

#endif
