/* nds_fit_int: what the files of the fit share (nds_fit.c: CEM; nds_fit_lm.c: the
 * Levenberg-Marquardt refinement). Not for other modules. */
#ifndef NDS_FIT_INT_H
#define NDS_FIT_INT_H

#include <pthread.h>

#include "nd_cem.h"
#include "nds_fit.h"

struct nds_fit {
  nds_fit_cfg cfg;
  nd_pool *pool;
  int nworkers;
  nds_model proto;      /* the model as given, for checking records against it */
  nds_model *models;    /* one per worker */
  mjData **data;
  double *cur;          /* nworkers x ND_NTHETA: theta each worker's model holds, NaN none */
  nd_cem *cem;
  nd_rng rng;
  int nfit, idx[ND_NTHETA];  /* fitted parameters, in theta order */
  double scale[ND_NTHETA];   /* CEM space: theta / scale, or ln theta / scale with logfit */
  double hold[ND_NTHETA];    /* the full theta; fitted entries are overwritten per candidate */

  int cand_cap;         /* rows of theta: nd_cem_max_batch */
  double *theta;        /* cand_cap x ND_NTHETA candidates of the current batch */
  size_t terms_cap;
  nds_replay_terms *terms;  /* cand x rollout, candidate-major */

  /* The current batch, read by the tasks. */
  const nd_rollout *rs;
  int nr;               /* replays per candidate: rollouts x cfg.phases; replay i is
                         * rollout i / phases at phase i % phases */
  int task_err;         /* a task could not replay (only on a record changed under us) */

  /* Pruning (cfg.prune): a candidate is dropped once the L of its finished and running
   * replays already exceeds the nelite-th best complete total of the batch. */
  int nelite;           /* as nd_cem counts them */
  int bounded;          /* this batch may prune (CEM iterations, not single evaluations) */
  double robust;        /* this batch's robust scale (0: it scores L) */
  pthread_mutex_t lock; /* guards the fields below during a batch */
  double *done;         /* cand_cap: L of each candidate's finished replays (any order) */
  int *left;            /* cand_cap: replays not yet finished */
  unsigned char *cut;   /* cand_cap: candidate dropped */
  double *top;          /* nelite smallest complete totals, ascending */
  int *order;           /* cand_cap: candidates in the order their replays are handed out */
  int ntop;
  int nrun;             /* replays run in the batch */
  int r0, nrp;          /* this pass replays rollouts [r0, r0 + nrp) of each candidate */
  int lock_init;

  double cost_lo, cost_hi; /* finite candidate costs of the current run */
  int cost_cut;            /* a candidate of the current run was pruned */
};

/* Make worker's model hold theta th (skipped when it does already). 0, or -1 when th is
 * not a valid theta (the worker then holds none). */
int nds_fit_hold(nds_fit *f, int worker, const double th[ND_NTHETA]);

/* Fitted parameter j between theta and the fit's space: its value (kept at lower), and
 * its std at value th. */
double nds_fit_x(const nds_fit *f, int j, double th);
double nds_fit_th(const nds_fit *f, int j, double x);
double nds_fit_xstd(const nds_fit *f, int j, double th, double std);
double nds_fit_thstd(const nds_fit *f, int j, double th, double xstd);

/* Theta of point x in the fit's space: held entries, fitted ones by nds_fit_th. */
void nds_fit_to_theta(const nds_fit *f, const double *x, double *th);

/* Refine the fitted entries of theta (in/out) by cfg.lm_iters Levenberg-Marquardt
 * iterations on the replay residuals of rs[0, n), into out's lm_ fields. 0, or -1 with a
 * message (a replay failed; theta unchanged). */
int nds_fit_refine(nds_fit *f, const nd_rollout *rs, int n, double theta[ND_NTHETA],
                   nds_fit_out *out, char *err, int errlen);

#endif
