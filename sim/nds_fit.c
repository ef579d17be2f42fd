/* nds_fit: CEM over theta, scoring candidates by replaying the buffer on the pool
 * (doc/design.md#refit).
 *
 * The optimiser works on theta / sigma0 per fitted parameter. Plain CEM is indifferent to
 * a per-coordinate scale, but the parameters span four decades (sliding ~1, rolling
 * ~1e-4), and nd_cem's one std floor and one bound tolerance are then meaningful for all
 * of them alike. A parameter whose prior spans decades (torsional friction started at 1
 * against a truth near 0.005) is searched as ln theta: over a linear std of 1/16 of its
 * range, the loss is flat for all of it (doc/decisions.md#log-fit). */
#include "nds_fit.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_cem.h"
#include "nds_fit_int.h"

/* The weights of L (the paper's are not legible). k1 = 1: the sphere's path is as much an
 * observation as the object's. k2 = 1e-3 m^2/rad: L_rot,o is a mean absolute angle, so a
 * yaw error counts about as much as the corner displacement it causes for the errors a
 * poor torsional friction gives (0.1-0.3 rad), and its linear slope keeps yaw informative
 * near the fit, where the squared terms flatten (doc/decisions.md#fit-weights). */
#define NDS_FIT_K1 1.0
#define NDS_FIT_K2 1e-3

/* Beyond the paper's plain CEM on a one-shot replay (doc/design.md#refit):
 * - FORCE replay, re-anchored on the observed full pose every NDS_FIT_WINDOW: one-shot
 *   force replay is a cliff once contact differs, setpoint replay hides sliding friction,
 *   and with the full pose put back L is a bowl around the truth whose fit improves as the
 *   window shortens; 5 ms keeps a few model steps per window at a 2 ms model too
 *   (doc/decisions.md#replay-mode, #full-pose, #replay-window). Records interpolated from
 *   MOCAP frames use NDS_FIT_WINDOW_MOCAP instead (nds_fit.h).
 * - step_std: the std is at least twice the mean's last step, so the mean can travel the
 *   whole prior; plain CEM freezes after ~2.6 sigma0 (doc/decisions.md#step-std).
 * - step_gate: only steps of at least 0.75 sampling stds count, so a wide std that has
 *   sampled the optimum does not draw as widely again (doc/decisions.md#step-gate).
 * - std_floor (in units of sigma0) and rel_floor (of the mean, at the start of each refit)
 *   keep a warm-started fit able to move when a new rollout shifts the optimum
 *   (doc/decisions.md#step-std). A signed parameter's mean may sit at 0, where rel_floor
 *   gives nothing: shift_floor (in sigma0, off by default) restarts it instead
 *   (doc/decisions.md#shift-restart). */
#define NDS_FIT_STD_FLOOR 0.25
#define NDS_FIT_MODE_DEFAULT NDS_REPLAY_FORCE
#define NDS_FIT_WINDOW 0.005
#define NDS_FIT_STEP_STD 2.0
#define NDS_FIT_STEP_GATE 0.75
#define NDS_FIT_REL_FLOOR 0.05

/* Candidates are ranked by L, the paper's score. The robust score (nds_replay_bounded,
 * NDS_FIT_ROBUST_SCALE) ranked better on the earlier, rough loss, but its log keeps poor
 * candidates under the pruning bound longer and the adapter's refit then overran its 10 s
 * budget; it stays an option (doc/decisions.md#robust-score). */
#define NDS_FIT_ROBUST 0.0

/* The refinement's difference step, in sigma0 (~6 % of sliding friction at D = 1): a
 * replay's contact events make its residuals rough at finer steps, and a difference over
 * them is noise that refuses the LM steps (doc/decisions.md#lm-step). */
#define NDS_FIT_LM_FD 0.5

/* Default prior width: the paper's smaller uncertainty, D = 0.2. */
#define NDS_FIT_D_DEFAULT 0.2

/* Candidate costs that differ by no more than this (m^2) are the same: a buffer that gives
 * every candidate the same L says nothing about the fitted parameters. Rollouts in which
 * the sphere never touched the box replay to an L of ~1e-30 for any friction, while a
 * single contact makes candidates differ by > 1e-10 (doc/decisions.md#flat-loss). */
#define FLAT_COST 1e-15

void nds_fit_cfg_default(nds_fit_cfg *cfg) {
  memset(cfg, 0, sizeof(*cfg));
  cfg->pop = 32;
  cfg->iters = 2;
  cfg->elite_frac = 0.2;
  cfg->fit[ND_TH_SLIDE] = cfg->fit[ND_TH_TORSION] = cfg->fit[ND_TH_ROLL] = 1;
  cfg->fit[ND_TH_MASS] = 0;
  cfg->lower = 1e-7;
  for (int i = 0; i < ND_NTHETA; i++) {
    double th = nd_theta_true[i], D = NDS_FIT_D_DEFAULT;
    cfg->upper[i] = nd_theta_signed(i) ? ND_THETA_COM_MAX : INFINITY;
    cfg->mu0[i] = th;
    cfg->sigma0[i] = nds_fit_prior_std(th, D, cfg->lower, i);
  }
  cfg->std_floor = NDS_FIT_STD_FLOOR;
  cfg->k1 = NDS_FIT_K1;
  cfg->k2 = NDS_FIT_K2;
  cfg->robust = NDS_FIT_ROBUST;
  cfg->lm_fd = NDS_FIT_LM_FD;
  cfg->prune = 1;
  cfg->phases = 1;
  nds_replay_cfg_default(&cfg->replay, NDS_FIT_MODE_DEFAULT);
  cfg->replay.window = NDS_FIT_WINDOW;
  cfg->replay.skip_clear = NDS_FIT_SKIP_CLEAR;
  cfg->step_std = NDS_FIT_STEP_STD;
  cfg->step_gate = NDS_FIT_STEP_GATE;
  cfg->rel_floor = NDS_FIT_REL_FLOOR;
  cfg->seed = 1;
}

void nds_fit_prior_range(double r, double D, double lower, int i, double *lo, double *hi) {
  const double w = nd_theta_signed(i) ? D * NDS_FIT_COM_SPAN : D * r;
  *lo = nd_theta_signed(i) ? r - w : fmax(lower, r - w);
  *hi = r + w;
}

double nds_fit_prior_std(double r, double D, double lower, int i) {
  double lo, hi;
  nds_fit_prior_range(r, D, lower, i, &lo, &hi);
  return (hi - lo) / 16;
}

double nds_fit_floor(const nds_fit_cfg *c, int i) {
  return nd_theta_signed(i) ? -c->upper[i] : c->lower;
}

void nds_fit_paper_prior(const double theta[ND_NTHETA], double D, double lower, nd_rng *r,
                         double mu0[ND_NTHETA], double sigma0[ND_NTHETA]) {
  for (int i = 0; i < ND_NTHETA; i++) {
    double th = theta[i], lo = th - D * th, hi = th + D * th;
    mu0[i] = th;
    sigma0[i] = nds_fit_prior_std(th, D, lower, i);
    if (i >= ND_NTHETA_PAPER) continue;
    double u = nd_rng_uniform(r);
    mu0[i] = fmax(lower, lo + u * (hi - lo));
  }
}

int nds_fit_cfg_check(const nds_fit_cfg *c, char *err, int errlen) {
  const char *bad = NULL;
  char rerr[160];
  if (c->pop < 2) bad = "pop (Q) must be >= 2";
  else if (c->iters < 1 || c->iters > NDS_FIT_MAX_ITERS) bad = "iters (C) must be in [1, 16]";
  else if (!(c->elite_frac > 0 && c->elite_frac <= 1)) bad = "elite_frac must be in (0, 1]";
  else if (!(isfinite(c->lower) && c->lower > 0)) bad = "lower must be finite and > 0";
  else if (!(isfinite(c->std_floor) && c->std_floor >= 0)) bad = "std_floor must be finite and >= 0";
  else if (!(isfinite(c->k1) && c->k1 >= 0)) bad = "k1 must be finite and >= 0";
  else if (!(isfinite(c->k2) && c->k2 >= 0)) bad = "k2 must be finite and >= 0";
  else if (!(isfinite(c->robust) && c->robust >= 0)) bad = "robust must be finite and >= 0";
  else if (c->prune != 0 && c->prune != 1) bad = "prune must be 0 or 1";
  else if (!(isfinite(c->step_std) && c->step_std >= 0)) bad = "step_std must be finite and >= 0";
  else if (!(isfinite(c->step_gate) && c->step_gate >= 0)) bad = "step_gate must be finite and >= 0";
  else if (!(isfinite(c->rel_floor) && c->rel_floor >= 0 && c->rel_floor < 1))
    bad = "rel_floor must be in [0, 1)";
  else if (!(isfinite(c->shift_floor) && c->shift_floor >= 0 && c->shift_floor <= 16))
    bad = "shift_floor must be in [0, 16]";
  else if (nds_replay_cfg_check(&c->replay, rerr, sizeof(rerr)))
    bad = rerr;
  else if (c->replay.phase != 0)
    bad = "replay.phase must be 0: the fit sets it (phases)";
  else if (c->phases < 1 || c->phases > NDS_FIT_MAX_PHASES)
    bad = "phases must be in [1, 16]";
  else if (c->phases > 1 && !(c->replay.window > 0 && c->robust == 0 && c->lm_iters == 0))
    bad = "phases > 1 needs replay.window > 0, robust 0 and lm_iters 0";
  for (int i = 0; !bad && i < ND_NTHETA; i++) {
    if (c->scan[i] == 0) continue;
    if (c->scan[i] < 2 || c->scan[i] > NDS_FIT_MAX_SCAN || !c->fit[i])
      bad = "scan needs 2..16 points and a fitted parameter, or 0";
    else if (!(isfinite(c->scan_lo[i]) && isfinite(c->scan_hi[i]) &&
               c->scan_lo[i] >= nds_fit_floor(c, i) && c->scan_lo[i] < c->scan_hi[i]))
      bad = "scan needs lower <= scan_lo < scan_hi, both finite";
  }
  for (int i = 0; i < ND_NTHETA && !bad; i++) {
    if (c->fit[i] && !(c->upper[i] > nds_fit_floor(c, i)))
      bad = "upper must be > lower (INFINITY: none)";
    else if (c->logfit[i] == 1 && nd_theta_signed(i))
      bad = "logfit needs a parameter that cannot be negative";
    else if (nd_theta_signed(i) && !(c->upper[i] > 0 && c->upper[i] <= ND_THETA_COM_MAX))
      bad = "a signed parameter's upper must be in (0, ND_THETA_COM_MAX]";
  }
  if (bad) {
    snprintf(err, errlen, "fit: %s", bad);
    return -1;
  }
  int nfit = 0;
  for (int i = 0; i < ND_NTHETA; i++) {
    if (c->fit[i] != 0 && c->fit[i] != 1) {
      snprintf(err, errlen, "fit: fit[%d] (%s) = %d, must be 0 or 1", i, nd_theta_key[i],
               c->fit[i]);
      return -1;
    }
    if (c->logfit[i] != 0 && c->logfit[i] != 1) {
      snprintf(err, errlen, "fit: logfit[%d] (%s) = %d, must be 0 or 1", i, nd_theta_key[i],
               c->logfit[i]);
      return -1;
    }
    nfit += c->fit[i];
    if (c->fit[i] && !(isfinite(c->mu0[i]) && isfinite(c->sigma0[i]) && c->sigma0[i] > 0)) {
      snprintf(err, errlen, "fit: %s prior mu0 = %g, sigma0 = %g: need finite, sigma0 > 0",
               nd_theta_key[i], c->mu0[i], c->sigma0[i]);
      return -1;
    }
  }
  if (nfit == 0) {
    snprintf(err, errlen, "fit: no parameter is fitted");
    return -1;
  }
  if (c->lm_iters < 0 || c->lm_iters > 50) {
    snprintf(err, errlen, "fit: lm_iters = %d, must be in [0, 50]", c->lm_iters);
    return -1;
  }
  if (!(c->lm_fd > 0 && c->lm_fd <= 10)) {
    snprintf(err, errlen, "fit: lm_fd = %g, must be in (0, 10]", c->lm_fd);
    return -1;
  }
  /* What the first candidate sees: fitted entries at their clipped prior mean. */
  double th[ND_NTHETA];
  for (int i = 0; i < ND_NTHETA; i++)
    th[i] = c->fit[i] ? fmax(nds_fit_floor(c, i), c->mu0[i]) : c->mu0[i];
  char terr[160];
  if (nd_theta_check(th, terr, sizeof(terr))) {
    snprintf(err, errlen, "fit: prior mean: %s", terr);
    return -1;
  }
  return 0;
}

void nds_fit_free(nds_fit *f) {
  if (!f) return;
  for (int w = 0; w < f->nworkers; w++) {
    if (f->data && f->data[w]) mj_deleteData(f->data[w]);
    if (f->models) nds_model_free(&f->models[w]);
  }
  nds_model_free(&f->proto);
  free(f->data);
  free(f->models);
  free(f->cur);
  nd_cem_free(f->cem);
  free(f->theta);
  free(f->terms);
  free(f->done);
  free(f->left);
  free(f->cut);
  free(f->top);
  free(f->order);
  if (f->lock_init) pthread_mutex_destroy(&f->lock);
  free(f);
}

nds_fit *nds_fit_create(const nds_model *proto, const nds_fit_cfg *cfg, nd_pool *pool,
                        char *err, int errlen) {
  if (nds_fit_cfg_check(cfg, err, errlen)) return NULL;
  nds_fit *f = calloc(1, sizeof(*f));
  if (!f) goto oom;
  f->cfg = *cfg;
  f->pool = pool;
  if (nds_model_copy(&f->proto, proto, err, errlen)) {
    nds_fit_free(f);
    return NULL;
  }
  f->nworkers = nd_pool_size(pool);
  f->models = calloc(f->nworkers, sizeof(*f->models));
  f->data = calloc(f->nworkers, sizeof(*f->data));
  f->cur = malloc(sizeof(double) * ND_NTHETA * f->nworkers);
  if (!f->models || !f->data || !f->cur) goto oom;
  for (int w = 0; w < f->nworkers; w++) {
    if (nds_model_copy(&f->models[w], proto, err, errlen)) {
      nds_fit_free(f);
      return NULL;
    }
    f->data[w] = mj_makeData(f->models[w].m);
    if (!f->data[w]) goto oom;
    for (int i = 0; i < ND_NTHETA; i++) f->cur[ND_NTHETA * w + i] = NAN;
  }

  double lower[ND_NTHETA], upper[ND_NTHETA];
  for (int i = 0; i < ND_NTHETA; i++) {
    if (!cfg->fit[i]) continue;
    f->idx[f->nfit] = i;
    f->scale[f->nfit] = cfg->logfit[i] ? cfg->sigma0[i] / fmax(cfg->lower, cfg->mu0[i])
                                       : cfg->sigma0[i];
    lower[f->nfit] = nds_fit_x(f, f->nfit, nds_fit_floor(cfg, i));
    upper[f->nfit] = isfinite(cfg->upper[i]) ? nds_fit_x(f, f->nfit, cfg->upper[i]) : INFINITY;
    f->nfit++;
  }
  nd_cem_cfg cc;
  nd_cem_cfg_default(&cc, 1, f->nfit, cfg->pop, cfg->iters);
  cc.elite_frac = cfg->elite_frac;
  cc.std_min = cfg->std_floor;  /* in units of sigma0 */
  cc.step_std = cfg->step_std;
  cc.step_gate = cfg->step_gate;
  cc.lower = lower;
  cc.upper = upper;
  f->cem = nd_cem_create(&cc, err, errlen);
  if (!f->cem) {
    nds_fit_free(f);
    return NULL;
  }
  f->cand_cap = nd_cem_max_batch(f->cem) + 1;
  if (f->cand_cap < NDS_FIT_MAX_SCAN + 1) f->cand_cap = NDS_FIT_MAX_SCAN + 1;
  /* nd_cem's elite count (nd_cem.c): a different count here would prune real elites or
   * prune less; test_replay checks that pruning changes no result. */
  f->nelite = (int)(cfg->elite_frac * cfg->pop + 0.5);
  if (f->nelite < 1) f->nelite = 1;
  if (f->nelite > cfg->pop) f->nelite = cfg->pop;
  f->theta = malloc(sizeof(double) * ND_NTHETA * f->cand_cap);
  f->done = malloc(sizeof(double) * f->cand_cap);
  f->left = malloc(sizeof(int) * f->cand_cap);
  f->cut = malloc(f->cand_cap);
  f->top = malloc(sizeof(double) * f->nelite);
  f->order = malloc(sizeof(int) * f->cand_cap);
  if (!f->theta || !f->done || !f->left || !f->cut || !f->top || !f->order) goto oom;
  if (pthread_mutex_init(&f->lock, NULL)) goto oom;
  f->lock_init = 1;
  nd_rng_seed(&f->rng, cfg->seed, 0);
  memcpy(f->hold, cfg->mu0, sizeof(f->hold));
  if (nds_fit_set_dist(f, cfg->mu0, cfg->sigma0, err, errlen)) {
    nds_fit_free(f);
    return NULL;
  }
  return f;
oom:
  snprintf(err, errlen, "fit: out of memory");
  nds_fit_free(f);
  return NULL;
}

int nds_fit_set_dist(nds_fit *f, const double mean[ND_NTHETA], const double std[ND_NTHETA],
                     char *err, int errlen) {
  double th[ND_NTHETA], xm[ND_NTHETA], xs[ND_NTHETA];
  for (int i = 0; i < ND_NTHETA; i++) {
    if (f->cfg.fit[i] && !(isfinite(mean[i]) && isfinite(std[i]) && std[i] >= 0)) {
      snprintf(err, errlen, "fit: %s mean = %g, std = %g: need finite, std >= 0", nd_theta_key[i],
               mean[i], std[i]);
      return -1;
    }
    th[i] = f->cfg.fit[i] ? fmax(nds_fit_floor(&f->cfg, i), mean[i]) : mean[i];
  }
  char terr[160];
  if (nd_theta_check(th, terr, sizeof(terr))) {
    snprintf(err, errlen, "fit: distribution mean: %s", terr);
    return -1;
  }
  for (int j = 0; j < f->nfit; j++) {
    xm[j] = nds_fit_x(f, j, mean[f->idx[j]]);
    xs[j] = nds_fit_xstd(f, j, mean[f->idx[j]], std[f->idx[j]]);
  }
  nd_cem_set_dist(f->cem, xm, xs);
  for (int i = 0; i < ND_NTHETA; i++)
    if (!f->cfg.fit[i]) f->hold[i] = mean[i];
  return 0;
}

void nds_fit_dist(const nds_fit *f, double mean[ND_NTHETA], double std[ND_NTHETA]) {
  const double *xm = nd_cem_mean(f->cem), *xs = nd_cem_std(f->cem);
  for (int i = 0; i < ND_NTHETA; i++) {
    mean[i] = f->hold[i];
    std[i] = 0;
  }
  for (int j = 0; j < f->nfit; j++) {
    mean[f->idx[j]] = nds_fit_th(f, j, xm[j]);
    std[f->idx[j]] = nds_fit_thstd(f, j, mean[f->idx[j]], xs[j]);
  }
}

/* Fitted parameter j is searched as ln theta (cfg.logfit). */
static int is_log(const nds_fit *f, int j) { return f->cfg.logfit[f->idx[j]]; }

double nds_fit_x(const nds_fit *f, int j, double th) {
  return is_log(f, j) ? log(fmax(f->cfg.lower, th)) / f->scale[j] : th / f->scale[j];
}

double nds_fit_th(const nds_fit *f, int j, double x) {
  return fmax(nds_fit_floor(&f->cfg, f->idx[j]),
              is_log(f, j) ? exp(x * f->scale[j]) : x * f->scale[j]);
}

double nds_fit_xstd(const nds_fit *f, int j, double th, double std) {
  return is_log(f, j) ? std / fmax(f->cfg.lower, th) / f->scale[j] : std / f->scale[j];
}

double nds_fit_thstd(const nds_fit *f, int j, double th, double xstd) {
  return is_log(f, j) ? xstd * f->scale[j] * th : xstd * f->scale[j];
}

int nds_fit_hold(nds_fit *f, int worker, const double th[ND_NTHETA]) {
  double *cur = f->cur + (size_t)ND_NTHETA * worker;
  if (memcmp(cur, th, sizeof(double) * ND_NTHETA) == 0) return 0;
  char err[160];
  const int ok = nds_theta_apply(&f->models[worker], th, err, sizeof(err)) == 0;
  for (int i = 0; i < ND_NTHETA; i++) cur[i] = ok ? th[i] : NAN;
  return ok ? 0 : -1;
}

void nds_fit_to_theta(const nds_fit *f, const double *x, double *th) {
  memcpy(th, f->hold, sizeof(double) * ND_NTHETA);
  for (int j = 0; j < f->nfit; j++) th[f->idx[j]] = nds_fit_th(f, j, x[j]);
}

/* Put candidate c's complete total L into the nelite best of the batch (under lock). */
static void top_insert(nds_fit *f, double L) {
  int i;
  if (f->ntop < f->nelite) i = f->ntop++;
  else if (L < f->top[f->nelite - 1]) i = f->nelite - 1;
  else return;
  while (i > 0 && f->top[i - 1] > L) {
    f->top[i] = f->top[i - 1];
    i--;
  }
  f->top[i] = L;
}

/* What a rollout's replay adds to its candidate's cost in the current batch. */
static double score(const nds_fit *f, const nds_replay_terms *t) {
  return f->robust > 0 ? t->robust : nds_replay_loss(t, f->cfg.k1, f->cfg.k2);
}

/* One (candidate, rollout) replay.
 *
 * A worker's model must hold exactly the candidate's theta; nds_theta_apply sets every
 * theta-dependent value from the model as loaded, so the result does not depend on which
 * candidates the worker ran before. Skipped when it already holds this very theta.
 *
 * Pruning. Once nelite candidates of the batch are complete, the nelite-th best total T*
 * bounds the elites from above: the nelite best of the whole batch are at most T*. A
 * replay whose candidate's L so far (finished replays plus this one's running sums, which
 * only grow) passes T* (with a 1e-9 relative margin for summation order) therefore belongs
 * to a candidate that is no elite, whatever remains; it stops, and the candidate's other
 * replays are skipped. Its cost becomes +inf. Elites are never pruned and their costs are
 * exact, so nd_cem selects and updates exactly as without pruning: the results do not
 * depend on the timing that decides what gets pruned. */
static void replay_task(void *ctx, int task, int worker) {
  nds_fit *f = ctx;
  int c = f->order[task / f->nrp], r = f->r0 + task % f->nrp;
  nds_replay_terms *out = &f->terms[(size_t)c * f->nr + r];
  double bound = INFINITY;
  pthread_mutex_lock(&f->lock);
  int skip = f->bounded && f->cut[c];
  if (f->bounded && !skip && f->ntop == f->nelite)
    bound = f->top[f->nelite - 1] * (1 + 1e-9) - f->done[c];
  f->nrun += !skip;
  pthread_mutex_unlock(&f->lock);

  char err[160];
  int failed = 0;
  if (skip) {
    memset(out, 0, sizeof(*out));
    out->cut = 1;
  } else {
    nds_model *nm = &f->models[worker];
    if (nds_fit_hold(f, worker, f->theta + (size_t)ND_NTHETA * c)) {
      memset(out, 0, sizeof(*out));
      out->pos_o = out->pos_ee = out->rot_o = out->robust = NDS_REPLAY_DIVERGED;
      out->diverged = 1;
    } else {
      const int ph = f->cfg.phases;
      nds_replay_cfg rc = f->cfg.replay;
      rc.phase = (r % ph) * rc.window / ph;
      if (nds_replay_bounded(nm, f->data[worker], &rc, &f->rs[r / ph], f->cfg.k1, f->cfg.k2,
                             f->robust, bound, out, err, sizeof(err)))
        failed = 1;
    }
  }

  pthread_mutex_lock(&f->lock);
  f->task_err |= failed;
  if (f->bounded) {
    f->done[c] += score(f, out);
    if (out->cut) f->cut[c] = 1;
    if (--f->left[c] == 0 && !f->cut[c]) top_insert(f, f->done[c]);
  }
  pthread_mutex_unlock(&f->lock);
}

/* Make room for ncand x nr terms. */
static int reserve(nds_fit *f, int nr, char *err, int errlen) {
  size_t need = (size_t)f->cand_cap * nr;
  if (need <= f->terms_cap) return 0;
  nds_replay_terms *t = realloc(f->terms, need * sizeof(*t));
  if (!t) {
    snprintf(err, errlen, "fit: out of memory for %d rollouts", nr);
    return -1;
  }
  f->terms = t;
  f->terms_cap = need;
  return 0;
}

/* Sort f->order[0, ncand) by f->done, ascending (insertion sort: stable, and ncand is a
 * population). */
static void order_by_done(nds_fit *f, int ncand) {
  for (int i = 1; i < ncand; i++) {
    int v = f->order[i], j = i - 1;
    while (j >= 0 && f->done[f->order[j]] > f->done[v]) {
      f->order[j + 1] = f->order[j];
      j--;
    }
    f->order[j + 1] = v;
  }
}

/* Replay f->theta[0, ncand) on the current buffer; loss[c] sums each candidate's rollout
 * scores in buffer order, so the result does not depend on which worker ran what. The
 * score is the robust one with robust > 0, else L. prune: a CEM iteration, pruned as
 * cfg.prune says (pruned candidates get +inf); the order candidates are replayed in
 * changes only what is pruned, never a result. */
static void eval_batch(nds_fit *f, int ncand, int prune, double robust, double *loss) {
  f->bounded = prune && f->cfg.prune && ncand > f->nelite;
  f->robust = robust;
  f->ntop = 0;
  for (int c = 0; c < ncand; c++) {
    f->done[c] = 0;
    f->left[c] = f->nr;
    f->cut[c] = 0;
    f->order[c] = c;
  }
  if (f->bounded && f->nr == 1) {
    /* Candidates nearest the sampling mean first: near convergence they are the likely
     * elites, and the sooner good totals are complete the tighter the pruning bound. */
    const double *xm = nd_cem_mean(f->cem);
    for (int c = 0; c < ncand; c++) {
      double d2 = 0;
      for (int j = 0; j < f->nfit; j++) {
        double e = nds_fit_x(f, j, f->theta[ND_NTHETA * c + f->idx[j]]) - xm[j];
        d2 += e * e;
      }
      f->done[c] = d2;  /* scratch until the pool runs */
    }
    order_by_done(f, ncand);
    for (int c = 0; c < ncand; c++) f->done[c] = 0;
  }
  if (f->bounded && f->nr > 1) {
    /* Two passes: every candidate's first rollout, then the rest in the order of that
     * first score. The candidates likely to be elites then complete first, and the bound
     * is tight while most of the others still have rollouts to go (a smooth L ranks on
     * one rollout nearly as on all; doc/decisions.md#prune). */
    f->r0 = 0, f->nrp = 1;
    nd_pool_run(f->pool, ncand, replay_task, f);
    order_by_done(f, ncand);
    f->r0 = 1, f->nrp = f->nr - 1;
    nd_pool_run(f->pool, ncand * f->nrp, replay_task, f);
  } else {
    f->r0 = 0, f->nrp = f->nr;
    nd_pool_run(f->pool, ncand * f->nr, replay_task, f);
  }
  for (int c = 0; c < ncand; c++) {
    double L = 0;
    for (int r = 0; r < f->nr; r++) L += score(f, &f->terms[(size_t)c * f->nr + r]);
    loss[c] = f->cut[c] ? INFINITY : L / f->cfg.phases;
  }
}

static int cem_cost(void *ctx, const double *x, int n, double *cost) {
  nds_fit *f = ctx;
  for (int c = 0; c < n; c++) nds_fit_to_theta(f, x + (size_t)c * f->nfit, f->theta + ND_NTHETA * c);
  eval_batch(f, n, 1, f->cfg.robust, cost);
  for (int c = 0; c < n; c++) {
    if (isfinite(cost[c])) {
      f->cost_lo = fmin(f->cost_lo, cost[c]);
      f->cost_hi = fmax(f->cost_hi, cost[c]);
    } else {
      f->cost_cut = 1;
    }
  }
  return f->task_err;
}

static int check_buffer(nds_fit *f, const nd_rollout *rs, int n, char *err, int errlen) {
  if (n < 1 || !rs) {
    snprintf(err, errlen, "fit: empty rollout buffer");
    return -1;
  }
  for (int i = 0; i < n; i++) {
    char rerr[200];
    if (nds_replay_check(&f->proto, &rs[i], rerr, sizeof(rerr))) {
      snprintf(err, errlen, "fit: rollout %d: %s", i, rerr);
      return -1;
    }
  }
  return reserve(f, n * f->cfg.phases, err, errlen);
}

/* nds_fit_loss and nds_fit_score: theta alone, scored with robust. */
static int eval_one(nds_fit *f, const double theta[ND_NTHETA], const nd_rollout *rs, int n,
                    double robust, double *loss, nds_replay_terms *per, char *err,
                    int errlen) {
  if (nd_theta_check(theta, err, errlen) || check_buffer(f, rs, n, err, errlen)) return -1;
  const int ph = f->cfg.phases;
  f->rs = rs;
  f->nr = n * ph;
  f->task_err = 0;
  memcpy(f->theta, theta, sizeof(double) * ND_NTHETA);
  f->nrun = 0;
  eval_batch(f, 1, 0, robust, loss);
  for (int r = 0; per && r < n; r++) {
    /* A rollout's terms: the mean over its phases. */
    nds_replay_terms *o = &per[r];
    *o = f->terms[(size_t)r * ph];
    for (int i = 1; i < ph; i++) {
      const nds_replay_terms *t = &f->terms[(size_t)r * ph + i];
      o->pos_o += t->pos_o, o->pos_ee += t->pos_ee, o->rot_o += t->rot_o;
      o->diverged |= t->diverged;
    }
    o->pos_o /= ph, o->pos_ee /= ph, o->rot_o /= ph;
    if (o->diverged) o->pos_o = o->pos_ee = o->rot_o = NDS_REPLAY_DIVERGED;
  }
  return 0;
}

int nds_fit_loss(nds_fit *f, const double theta[ND_NTHETA], const nd_rollout *rs, int n,
                 double *loss, nds_replay_terms *per, char *err, int errlen) {
  return eval_one(f, theta, rs, n, 0, loss, per, err, errlen);
}

int nds_fit_score(nds_fit *f, const double theta[ND_NTHETA], const nd_rollout *rs, int n,
                  double *score, nds_replay_terms *per, char *err, int errlen) {
  return eval_one(f, theta, rs, n, f->cfg.robust, score, per, err, errlen);
}

/* cfg.scan: for each scanned parameter, the mean and the mean with that parameter at each
 * grid point in one batch (L, unpruned); the lowest L below the mean's moves the mean
 * there, the std kept. Returns the parameters moved, or -1 when a replay failed. */
static int scan(nds_fit *f) {
  int moved = 0;
  for (int j = 0; j < f->nfit; j++) {
    const int i = f->idx[j], k = f->cfg.scan[i];
    if (k < 2) continue;
    double x[ND_NTHETA], loss[NDS_FIT_MAX_SCAN + 1];
    memcpy(x, nd_cem_mean(f->cem), sizeof(double) * f->nfit);
    nds_fit_to_theta(f, x, f->theta);
    const double lo = f->cfg.scan_lo[i], hi = f->cfg.scan_hi[i];
    for (int c = 1; c <= k; c++) {
      const double s = (c - 1.0) / (k - 1.0);
      double *th = f->theta + (size_t)ND_NTHETA * c;
      memcpy(th, f->theta, sizeof(double) * ND_NTHETA);
      th[i] = f->cfg.logfit[i] ? lo * pow(hi / lo, s) : lo + s * (hi - lo);
    }
    eval_batch(f, k + 1, 0, 0, loss);
    if (f->task_err) return -1;
    int best = 0;
    for (int c = 1; c <= k; c++)
      if (loss[c] < loss[best]) best = c;
    if (best == 0) continue;
    x[j] = nds_fit_x(f, j, f->theta[(size_t)ND_NTHETA * best + i]);
    double xs[ND_NTHETA];
    memcpy(xs, nd_cem_std(f->cem), sizeof(double) * f->nfit);
    nd_cem_set_dist(f->cem, x, xs);
    moved++;
  }
  return moved;
}

int nds_fit_run(nds_fit *f, const nd_rollout *rs, int n, nds_fit_out *out, char *err,
                int errlen) {
  if (check_buffer(f, rs, n, err, errlen)) return -1;
  f->rs = rs;
  f->nr = n * f->cfg.phases;
  f->task_err = 0;
  f->nrun = 0;

  /* A failed run must leave the distribution and the generator as they were. */
  double m0[ND_NTHETA], s0[ND_NTHETA];
  memcpy(m0, nd_cem_mean(f->cem), sizeof(double) * f->nfit);
  memcpy(s0, nd_cem_std(f->cem), sizeof(double) * f->nfit);
  nd_rng r0 = f->rng;
  if (f->cfg.rel_floor > 0 || f->cfg.shift_floor > 0) {
    double xs[ND_NTHETA];
    for (int j = 0; j < f->nfit; j++) {
      const int i = f->idx[j];
      const double th = nds_fit_th(f, j, m0[j]);
      const double lo = fmax(f->cfg.rel_floor * fabs(th),
                             nd_theta_signed(i) ? f->cfg.shift_floor * f->cfg.sigma0[i] : 0);
      xs[j] = fmax(s0[j], nds_fit_xstd(f, j, th, lo));
    }
    nd_cem_set_dist(f->cem, m0, xs);
  }
  const int moved = scan(f);
  f->cost_lo = INFINITY;
  f->cost_hi = -INFINITY;
  f->cost_cut = 0;
  if (moved < 0 || nd_cem_run(f->cem, &f->rng, cem_cost, f)) {
    nd_cem_set_dist(f->cem, m0, s0);
    f->rng = r0;
    snprintf(err, errlen, "fit: a record could not be replayed");
    return -1;
  }
  /* On a flat loss the elites are a draw of ties: CEM would wander and, with step_std,
   * widen its std on nothing. Keep the distribution instead. */
  const int flat = !f->cost_cut && f->cost_hi - f->cost_lo <= FLAT_COST;
  if (flat) nd_cem_set_dist(f->cem, m0, s0);

  memset(out, 0, sizeof(*out));
  out->flat = flat;
  out->scan_moved = flat ? 0 : moved;
  if (f->cfg.lm_iters > 0 && !flat) {
    double th[ND_NTHETA], sd[ND_NTHETA], xm[ND_NTHETA];
    nds_fit_dist(f, th, sd);
    if (nds_fit_refine(f, rs, n, th, out, err, errlen)) {
      nd_cem_set_dist(f->cem, m0, s0);
      f->rng = r0;
      return -1;
    }
    double xs[ND_NTHETA];
    memcpy(xs, nd_cem_std(f->cem), sizeof(double) * f->nfit);
    for (int j = 0; j < f->nfit; j++) xm[j] = nds_fit_x(f, j, th[f->idx[j]]);
    nd_cem_set_dist(f->cem, xm, xs);
  }
  nds_fit_dist(f, out->mean, out->std);
  nds_fit_to_theta(f, nd_cem_best(f->cem), out->best);
  out->best_loss = nd_cem_best_cost(f->cem);
  out->iters = f->cfg.iters;
  for (int i = 0; i < out->iters; i++) out->iter_best[i] = nd_cem_iter_best(f->cem, i);

  memcpy(f->theta, out->mean, sizeof(out->mean));
  eval_batch(f, 1, 0, 0, &out->loss_mean);
  for (int r = 0; r < f->nr; r++) out->diverged_mean += f->terms[r].diverged;
  out->replays = f->nrun + out->lm_replays;
  return 0;
}
