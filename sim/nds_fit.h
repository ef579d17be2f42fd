/* nds_fit: fitting theta to recorded rollouts with CEM (paper sec. III-C;
 * doc/design.md#refit).
 *
 * Each candidate theta is scored by replaying every rollout of the buffer (nds_replay)
 * and summing the rollouts' L = L_pos,o + k1 L_pos,ee + k2 L_rot,o. The optimiser is the
 * project's nd_cem in its plain configuration: white Gaussian noise per parameter, no
 * elites kept, no population decay, no momentum, no injected mean; only a floor on the std
 * (std_floor, rel_floor, shift_floor) and a std that follows the mean's long steps (step_std,
 * step_gate; nds_fit.c says why). Kept elites would carry costs measured on an older
 * buffer into the next refit, and with C = 2 the extra evaluations buy little.
 *
 * The distribution persists between runs: create sets it to the prior (mu0, sigma0),
 * each nds_fit_run goes on from where the last ended (the incremental loop's warm start
 * across episodes), nds_fit_set_dist replaces it. The (candidate, rollout) replays of an
 * iteration are spread over the pool, each worker with its own model copy and mjData;
 * results do not depend on the pool's size. Parameters not fitted are held fixed. */
#ifndef NDS_FIT_H
#define NDS_FIT_H

#include <stdint.h>

#include "nd_pool.h"
#include "nd_rng.h"
#include "nds_replay.h"

#define NDS_FIT_MAX_ITERS 16
#define NDS_FIT_MAX_PHASES 16
#define NDS_FIT_MAX_SCAN 16

/* Re-anchoring window, s, for records whose object pose was interpolated between
 * motion-capture frames (nudge-tasks: MOCAP at 240 Hz, steps at 1 kHz) rather than
 * observed at every step: a window of a frame or two re-anchors on the interpolation,
 * whose rates are a frame's mean, and biases the fit. The adapter's default (its records
 * come from nudge-tasks); nds_fit_cfg_default keeps 5 ms for records observed at every
 * step (nds_record, the study). doc/decisions.md#mocap-window */
#define NDS_FIT_WINDOW_MOCAP 0.1

/* A velocity replay's windows whose recorded sphere keeps this far (m) from the box are
 * scored without stepping the model (nds_replay_cfg.skip_clear): they cannot tell theta. */
#define NDS_FIT_SKIP_CLEAR 0.01

/* The robust score's scale that ranked best when it was measured, m^2; the default ranks
 * by L instead (nds_fit_cfg.robust; doc/decisions.md#robust-score). */
#define NDS_FIT_ROBUST_SCALE 1e-9

typedef struct {
  int pop, iters;              /* Q >= 2 candidates, C in [1, NDS_FIT_MAX_ITERS] iterations */
  double elite_frac;           /* rho in (0, 1] */
  int fit[ND_NTHETA];         /* 1: fitted, 0: held at mu0 (at least one fitted) */
  double mu0[ND_NTHETA];      /* prior mean; a held parameter's value */
  double sigma0[ND_NTHETA];   /* prior std, > 0 where fitted */
  int logfit[ND_NTHETA];      /* 1: searched as ln theta with std sigma0 / mu0 (a parameter
                                  whose prior spans decades); its std in and out is then
                                  theta times the std of ln theta. 0: as theta */
  double lower;                /* every fitted parameter that cannot be negative stays >=
                                  lower > 0 (samples clipped); a signed one (nd_theta_signed)
                                  >= -upper[i] (nds_fit_floor) */
  double upper[ND_NTHETA];     /* and <= upper[i] > its floor (INFINITY: unbounded, the
                                  default; for a signed one finite, at most ND_THETA_COM_MAX,
                                  the default) */
  double std_floor;            /* std never falls below std_floor * sigma0 (0: the paper's
                                  plain CEM, which freezes after a run or two) */
  double step_std;             /* nd_cem's step_std (the std follows the mean's steps; 0 off) */
  double step_gate;            /* nd_cem's step_gate (step_std only for steps >= this many
                                  stds; 0: every step) */
  double rel_floor;            /* each run starts with std >= rel_floor |mean| (0: off) */
  double shift_floor;          /* and a signed parameter's (the box's shift, whose mean may
                                  be 0) with std >= shift_floor * sigma0 (0: off) */
  double k1, k2;               /* weights of L_pos,ee (1) and L_rot,o (m^2/rad) */
  double robust;               /* m^2; > 0: CEM ranks candidates by the windows' robust
                                  score of this scale (nds_replay_bounded); 0: by L, the
                                  paper's. Reported losses are L either way */
  int prune;                   /* 1: stop replaying a candidate once it cannot be an elite
                                  (same results, less work: see nds_fit.c); 0: replay all */
  nds_replay_cfg replay;       /* how rollouts are replayed (mode, robot controller); its
                                  phase is the fit's to set (below) */
  int phases;                  /* >= 1: each rollout is replayed this many times, its
                                  anchors shifted by window / phases each time, and scored
                                  by the mean: the contact chaos each set of anchors starts
                                  averages out of L (doc/decisions.md#replay-phases). 1, the
                                  default: once, unshifted. More than 1 needs a window, L's
                                  ranking (robust 0) and no refinement (lm_iters 0) */
  int lm_iters;                /* > 0: after CEM, at most this many Levenberg-Marquardt
                                  iterations on the replays' residuals from CEM's mean, which
                                  also give a covariance (nds_fit_out.lm_*); 0: off */
  double lm_fd;                /* its forward-difference step in units of sigma0: 0.5 by
                                  default, through the roughness contact events give the
                                  replays; records the model replays exactly take 0.02 */
  int scan[ND_NTHETA];         /* 0, or >= 2 (at most NDS_FIT_MAX_SCAN) points spread
                                  evenly over [scan_lo, scan_hi] (geometrically for a
                                  logfit parameter) at which each run first scores the
                                  mean with this parameter changed, one batch each; the
                                  best moves the mean there when it beats it. CEM is local,
                                  and a loss flat away from the truth holds it wherever it
                                  starts (doc/decisions.md#scan). Fitted parameters only */
  double scan_lo[ND_NTHETA], scan_hi[ND_NTHETA];  /* lower <= lo < hi where scan > 0 */
  uint64_t seed;
} nds_fit_cfg;

/* The centre-of-mass shift that sizes its prior as the paper's formula sizes the others
 * with nominal r: the range +-D NDS_FIT_COM_SPAN, m. The paper's formula scales with r,
 * and the nominal shift is 0; 2 cm is 40 % of the model box's half length. */
#define NDS_FIT_COM_SPAN 0.02

/* Paper settings: Q 32, C 2, rho 0.2, fitting the three frictions with the mass held;
 * prior at nd_theta_true with the paper's D = 0.2 std; lower 1e-7; k1 = 1,
 * k2 = 1e-3 m^2/rad; prune; seed 1. Beyond the paper (nds_fit.c; doc/decisions.md):
 * step_std 2 gated at 0.75 std, std_floor 0.25, rel_floor 0.05, FORCE replay re-anchored
 * on the observed full pose every 5 ms with the default controller, candidates ranked by
 * L (robust 0), no Levenberg-Marquardt refinement (lm_iters 0; lm_fd 0.5). */
void nds_fit_cfg_default(nds_fit_cfg *cfg);

/* Check cfg. Return 0, or -1 naming the bad field. */
int nds_fit_cfg_check(const nds_fit_cfg *cfg, char *err, int errlen);

/* The prior's range of entry i for nominal value r and uncertainty D: the paper's
 * [max(lower, r - D r), r + D r], or r -+ D NDS_FIT_COM_SPAN for a signed entry. */
void nds_fit_prior_range(double r, double D, double lower, int i, double *lo, double *hi);

/* Prior std of entry i: a sixteenth of that range, the paper's sigma_0. */
double nds_fit_prior_std(double r, double D, double lower, int i);

/* The least value entry i may take in a fit: cfg->lower, or -cfg->upper[i] for a signed
 * entry. */
double nds_fit_floor(const nds_fit_cfg *cfg, int i);

/* The paper's prior around theta for uncertainty D > 0: mu0 ~ U(theta - D theta,
 * theta + D theta) (clipped at lower), sigma0 = nds_fit_prior_std, for the paper's four
 * entries (four draws from r, in order); the box's entries keep theta as their mean. */
void nds_fit_paper_prior(const double theta[ND_NTHETA], double D, double lower, nd_rng *r,
                         double mu0[ND_NTHETA], double sigma0[ND_NTHETA]);

typedef struct {
  double mean[ND_NTHETA];     /* distribution after the run; held parameters: their value */
  double std[ND_NTHETA];      /* held parameters: 0 */
  double best[ND_NTHETA];     /* lowest-loss candidate of the run */
  double best_loss;            /* its score (L, or the robust score with cfg.robust) */
  double loss_mean;            /* L(mean) on the buffer, evaluated after the last update */
  int diverged_mean;           /* replays of the mean that diverged */
  int iters;
  double iter_best[NDS_FIT_MAX_ITERS]; /* lowest score of each iteration */
  int replays;                 /* rollout replays started (pruned ones too), the mean's
                                  included; depends on timing when pruning */
  int flat;                    /* 1: every candidate scored the same L (the rollouts say
                                  nothing about the fitted parameters, e.g. the sphere
                                  never touched the box): the distribution is left as it
                                  was; best and iter_best still report the draws */
  /* With cfg.lm_iters (and not flat): the refinement from CEM's mean. Its result is the
   * distribution's mean from then on (the std stays CEM's, to search with); lm_std is the
   * standard error of the estimate, sqrt of the diagonal of sigma^2 (J'J)^-1 inflated for
   * residuals correlated in time (nd_lm), 0 for held entries, NaN where J'J is singular. */
  int lm_run;                  /* 1: the refinement ran */
  int lm_iters, lm_replays;    /* its iterations, and rollout replays */
  double lm_cost0, lm_cost;    /* |r|^2 at CEM's mean and at the result */
  double lm_std[ND_NTHETA];
  double lm_inflation;         /* the correlation correction applied to the covariance */
  int scan_moved;              /* parameters the scan moved the mean of (cfg.scan) */
} nds_fit_out;

typedef struct nds_fit nds_fit;

/* A fit of theta in copies of model proto (its timestep is the replay's) on pool, which
 * the fit uses only inside its calls. NULL and a message on a bad cfg or no memory. */
nds_fit *nds_fit_create(const nds_model *proto, const nds_fit_cfg *cfg, nd_pool *pool,
                        char *err, int errlen);
void nds_fit_free(nds_fit *f);

/* Replace the distribution: full theta vectors; fitted entries need finite mean (clipped
 * at lower) and finite std >= 0, held entries a valid theta value (std ignored), which
 * they are held at from now on. Return 0, or -1 with a message (nothing changed). */
int nds_fit_set_dist(nds_fit *f, const double mean[ND_NTHETA], const double std[ND_NTHETA],
                     char *err, int errlen);

/* The current distribution (held entries: value, std 0). */
void nds_fit_dist(const nds_fit *f, double mean[ND_NTHETA], double std[ND_NTHETA]);

/* C iterations of CEM on the buffer rs[0, n), then L of the resulting mean (out->flat:
 * the loss did not tell candidates apart and the distribution is unchanged). Every record
 * is checked first (nds_replay_check). Allocates only when n exceeds every earlier
 * buffer. Return 0, or -1 with a message (distribution unchanged, out untouched). */
int nds_fit_run(nds_fit *f, const nd_rollout *rs, int n, nds_fit_out *out, char *err,
                int errlen);

/* L(theta) on rs[0, n) in parallel (a validation loss). per, if not NULL, receives each
 * rollout's terms. Return 0, or -1 with a message. */
int nds_fit_loss(nds_fit *f, const double theta[ND_NTHETA], const nd_rollout *rs, int n,
                 double *loss, nds_replay_terms *per, char *err, int errlen);

/* The standard errors of the fitted entries of theta on rs[0, n) (held ones 0; NaN if
 * the replays do not determine them), from the replay residuals' Jacobian at theta, one
 * batch of nfit + 1 replays of the buffer (the refinement's covariance, no step). Return
 * 0, or -1 with a message. */
int nds_fit_cov(nds_fit *f, const double theta[ND_NTHETA], const nd_rollout *rs, int n,
                double std[ND_NTHETA], char *err, int errlen);

/* nds_fit_loss, scored as CEM ranks a candidate: the robust score with cfg.robust > 0
 * (per[i].robust each rollout's), else L. */
int nds_fit_score(nds_fit *f, const double theta[ND_NTHETA], const nd_rollout *rs, int n,
                  double *score, nds_replay_terms *per, char *err, int errlen);

#endif
