/* study: the paper's simulation study, run by run (experiment.h). */
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "experiment.h"
#include "nd_rbuf.h"

/* The validation loss's scale near the truth: BAND_N models with sliding friction spread
 * evenly over truth (1 +- BAND_DU), never exactly the truth (which replays to L ~ 1e-19). */
#define BAND_N 16
#define BAND_DU 0.01

/* Most ask for a turn of 0.4-1.3 rad, so the box rotates under the sphere (the only motion
 * torsional friction shows in); two are straight pushes, one nearly a turn on the spot. */
const nd_goal exp_train_goals[NTRAIN] = {
    {.x = 0.15, .y = 0.05, .yaw = 0.8},   {.x = 0.12, .y = -0.10, .yaw = -0.9},
    {.x = 0.20, .y = 0.00, .yaw = 0.0},   {.x = 0.05, .y = 0.12, .yaw = 1.3},
    {.x = 0.18, .y = -0.05, .yaw = -0.5}, {.x = 0.03, .y = 0.00, .yaw = 1.0},
    {.x = 0.12, .y = 0.12, .yaw = -0.7},  {.x = 0.10, .y = -0.15, .yaw = 0.9},
    {.x = 0.22, .y = 0.08, .yaw = 0.0},   {.x = 0.08, .y = 0.04, .yaw = -1.2},
};

double exp_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* splitmix64 over a list of words: seeds that differ in any word are unrelated. */
uint64_t exp_mix(uint64_t seed, uint64_t a, uint64_t b, uint64_t c) {
  uint64_t x = seed, w[3] = {a, b, c};
  for (int i = 0; i < 3; i++) {
    x += 0x9E3779B97F4A7C15ULL + w[i];
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    x ^= x >> 31;
  }
  return x;
}

/* The refit's configuration: the fit's defaults with the options' replay and CEM
 * settings, replaying in mode. */
void exp_fit_cfg(const exp_opts *o, int mode, nds_fit_cfg *fc) {
  nds_fit_cfg_default(fc);
  fc->replay.mode = mode;
  fc->replay.window = o->window;
  fc->step_std = o->step_std;
  fc->step_gate = o->step_gate;
  fc->rel_floor = o->rel_floor;
  fc->k2 = o->k2;
  fc->robust = o->robust;
}

/* Run goal g from the start pose with a fresh planner (seed pseed) on theta; record it
 * into s->rec if rec. */
static int run_task(exp_study *s, const double theta[ND_NTHETA], uint64_t pseed, const nd_goal *g,
                    int rec, int64_t task_id, nds_episode_out *out, char *err, int errlen) {
  nds_planner_cfg c = s->pcfg;
  c.seed = pseed;
  double t0 = exp_now();
  nds_planner *p = nds_planner_create(&s->su.plan, &c, s->su.pool, err, errlen);
  if (!p) return -1;
  int rc = nds_planner_set_theta(p, theta, err, errlen);
  if (!rc && rec)
    rc = nds_record_begin(&s->rec, &s->su.world, &s->su.start, task_id, 0, g, theta, err, errlen);
  if (!rc) {
    nds_planner_reset(p);
    rc = nds_episode_run(&s->su.world, s->su.d, p, &c.ctrl, &s->ecfg, &s->su.start, g,
                         rec ? nds_record_hook : NULL, rec ? &s->rec : NULL, out, err, errlen);
  }
  if (!rc && rec)
    rc = nds_record_finish(&s->rec, out->reached ? ND_OUTCOME_SUCCESS : ND_OUTCOME_TIMEOUT, err,
                           errlen);
  nds_planner_free(p);
  s->task_s += exp_now() - t0;
  s->tasks_done++;
  return rc;
}


/* Termination time of a task as the paper counts it: success time, else the limit. */
static double task_time(const exp_study *s, const nds_episode_out *o) {
  return o->reached ? o->t_reached : s->ecfg.tau;
}

/* The evaluation of theta: tasks (common seeds for every run and episode, so differences
 * come from theta, not from the planner's draws), validation loss, errors. */
static int evaluate(exp_study *s, nds_fit *fit, const double mean[ND_NTHETA],
                    const double std[ND_NTHETA], exp_row *row, char *err, int errlen) {
  memcpy(row->mean, mean, sizeof(row->mean));
  memcpy(row->std, std, sizeof(row->std));
  for (int i = 0; i < NFIT; i++)
    row->err_pct[i] = 100.0 * fabs(mean[i] - nd_theta_true[i]) / nd_theta_true[i];
  int ok = 0;
  double t = 0;
  for (int j = 0; j < s->o->neval; j++) {
    nds_episode_out o;
    if (run_task(s, mean, exp_mix(s->o->seed, 3, (uint64_t)j, 0), &nds_demo_goals[j], 0, 0, &o, err,
                 errlen))
      return -1;
    ok += o.reached;
    t += task_time(s, &o);
  }
  row->success = (double)ok / s->o->neval;
  row->mean_time = t / s->o->neval;
  return nds_fit_loss(fit, mean, s->val, s->nval, &row->val_loss, NULL, err, errlen);
}

int exp_study_init(exp_study *s, const exp_opts *o, char *err, int errlen) {
  memset(s, 0, sizeof(*s));
  s->o = o;
  if (nds_setup_init(&s->su, o->plan_dt, o->threads, err, errlen) ||
      nds_model_copy(&s->fitm, &s->su.world, err, errlen) ||
      nds_record_init(&s->rec, o->tau, s->su.world.m->opt.timestep, err, errlen))
    return -1;
  nds_planner_cfg_default(&s->pcfg);
  s->pcfg.pop = o->pop;
  s->pcfg.iters = o->iters;
  nds_episode_cfg_default(&s->ecfg);
  s->ecfg.tau = o->tau;
  /* The paper's terminal condition: a task ends when it succeeds (eps 1e-2), so the
   * recorded rollout ends there too. */
  s->ecfg.eps_fine = s->ecfg.eps;
  s->t0 = exp_now();
  return 0;
}

void exp_study_free(exp_study *s) {
  for (int i = 0; i < s->nval; i++) nd_rollout_free(&s->val[i]);
  nds_record_free(&s->rec);
  nds_model_free(&s->fitm);
  nds_setup_free(&s->su);
}

/* Record the goals g[0, n) with the true theta (planner seeds as the evaluation's) into
 * rs, appending them to path if not NULL. Sets s->val_success / val_time. */
int exp_record_truth(exp_study *s, const nd_goal *g, int n, uint64_t kind, nd_rollout *rs,
                     const char *path, char *err, int errlen) {
  nd_rfile_writer w = {.fd = -1};
  if (path) {
    unlink(path);
    if (nd_rbuf_open(&w, path, NULL, err, errlen)) return -1;
  }
  int ok = 0;
  double t = 0;
  for (int j = 0; j < n; j++) {
    nds_episode_out o;
    if (run_task(s, nd_theta_true, exp_mix(s->o->seed, kind, (uint64_t)j, 0), &g[j], 1, j, &o, err,
                 errlen) ||
        nd_rollout_copy(&rs[j], &s->rec.r) || (path && nd_rbuf_append(&w, &rs[j], err, errlen))) {
      nd_rfile_writer_close(&w);
      if (!err[0]) snprintf(err, errlen, "out of memory");
      return -1;
    }
    ok += o.reached;
    t += task_time(s, &o);
  }
  nd_rfile_writer_close(&w);
  s->val_success = (double)ok / n;
  s->val_time = t / n;
  return 0;
}

/* L on the validation rollouts of models within BAND_DU of the true sliding friction:
 * the loss a model better than the 5 % target can have. Re-anchored replay near the truth
 * is rough (a 1e-4 change of friction shifts a contact by a step), so this band, not the
 * truth's own L, is how low a fitted mean can be expected to score. */
static int truth_band(exp_study *s, char *err, int errlen) {
  nds_fit_cfg fc;
  exp_fit_cfg(s->o, s->o->mode, &fc);
  nds_fit *fit = nds_fit_create(&s->fitm, &fc, s->su.pool, err, errlen);
  if (!fit) return -1;
  s->band_lo = INFINITY;
  s->band_hi = 0;
  for (int k = 0; k < BAND_N; k++) {
    double th[ND_NTHETA], L;
    memcpy(th, nd_theta_true, sizeof(th));
    th[ND_TH_SLIDE] *= 1 + BAND_DU * (2.0 * (k + 0.5) / BAND_N - 1);
    if (nds_fit_loss(fit, th, s->val, s->nval, &L, NULL, err, errlen)) {
      nds_fit_free(fit);
      return -1;
    }
    s->band_lo = fmin(s->band_lo, L);
    s->band_hi = fmax(s->band_hi, L);
  }
  nds_fit_free(fit);
  return 0;
}

/* D's bits: seeds come from D's value, not its place in --d, so "--d 1" repeats the
 * D = 1 runs of the default "--d 0.2,1.0" exactly. */
uint64_t exp_dkey(double D) {
  uint64_t k;
  memcpy(&k, &D, sizeof(k));
  return k;
}

void exp_draw(const exp_opts *o, double D, int run, double lower, double mu0[ND_NTHETA],
              double sigma0[ND_NTHETA]) {
  nd_rng rr;
  nd_rng_seed(&rr, o->seed, exp_mix(0, 1, exp_dkey(D), (uint64_t)run));
  nds_fit_paper_prior(nd_theta_true, D, lower, &rr, mu0, sigma0);
  mu0[ND_TH_MASS] = nd_theta_true[ND_TH_MASS];
}

int exp_draws_print(const exp_opts *o) {
  nds_fit_cfg fc;
  exp_fit_cfg(o, o->mode, &fc);
  for (int di = 0; di < o->nD; di++)
    for (int run = 0; run < o->runs; run++) {
      double mu0[ND_NTHETA], sg0[ND_NTHETA];
      exp_draw(o, o->D[di], run, fc.lower, mu0, sg0);
      printf("%g %d %.9g,%.9g,%.9g,%.9g\n", o->D[di], run, mu0[0], mu0[1], mu0[2], mu0[3]);
    }
  return 0;
}

static int run_one(exp_study *s, int di, int run, exp_row *rows, char *err, int errlen) {
  const exp_opts *o = s->o;
  const double D = o->D[di];
  char dn[32], name[96], path[1200];
  exp_dname(D, dn, sizeof(dn));
  nds_fit_cfg fc;
  exp_fit_cfg(o, o->mode, &fc);
  fc.seed = exp_mix(o->seed, 4, exp_dkey(D), (uint64_t)run);
  exp_draw(o, D, run, fc.lower, fc.mu0, fc.sigma0);
  nds_fit *fit = nds_fit_create(&s->fitm, &fc, s->su.pool, err, errlen);
  if (!fit) return -1;

  snprintf(name, sizeof(name), "run_d%s_r%02d.csv", dn, run);
  exp_path(path, sizeof(path), o->out, name);
  FILE *csv = fopen(path, "w");
  snprintf(name, sizeof(name), "buffer_d%s_r%02d.nbuf", dn, run);
  char bpath[1200];
  exp_path(bpath, sizeof(bpath), o->out, name);
  unlink(bpath);
  nd_rfile_writer w = {.fd = -1};
  int rc = -1;
  if (!csv) {
    snprintf(err, errlen, "%.300s: %s", path, strerror(errno));
    goto done;
  }
  if (nd_rbuf_open(&w, bpath, NULL, err, errlen)) goto done;
  fputs(exp_run_header, csv);

  double mean[ND_NTHETA], std[ND_NTHETA];
  nds_fit_dist(fit, mean, std);
  exp_row *r0 = exp_row_at(rows, o, di, run, 0);
  if (evaluate(s, fit, mean, std, r0, err, errlen)) goto done;
  r0->fit_loss = r0->fit_s = r0->train_reached = r0->train_time = NAN;
  r0->train_steps = 0;
  exp_csv_row(csv, 0, D, run, r0);
  fflush(csv);
  exp_progress(s, D, run, 0, r0);

  for (int ep = 1; ep <= o->episodes; ep++) {
    exp_row *r = exp_row_at(rows, o, di, run, ep);
    const nd_goal *g = &exp_train_goals[(ep - 1) % NTRAIN];
    nds_episode_out eo;
    if (run_task(s, mean, exp_mix(o->seed, 2, exp_dkey(D) ^ (uint64_t)run, (uint64_t)ep),
                 g, 1, ep, &eo, err, errlen) ||
        nd_rbuf_append(&w, &s->rec.r, err, errlen))
      goto done;
    r->train_reached = eo.reached;
    r->train_time = task_time(s, &eo);
    r->train_steps = s->rec.r.n;

    /* The refit reads the buffer back from its file, as the adapter does. */
    nd_rollout *rs = NULL;
    int n = 0;
    if (nd_rbuf_read_all(bpath, &rs, &n, NULL, err, errlen)) goto done;
    nds_fit_out fo;
    double t0 = exp_now();
    int frc = nds_fit_run(fit, rs, n, &fo, err, errlen);
    r->fit_s = exp_now() - t0;
    nd_rbuf_free_all(rs, n);
    if (frc) goto done;
    s->fit_s += r->fit_s;
    s->fit_units_done += n;
    r->fit_loss = fo.loss_mean;
    nds_fit_dist(fit, mean, std);
    if (evaluate(s, fit, mean, std, r, err, errlen)) goto done;
    exp_csv_row(csv, ep, D, run, r);
    fflush(csv);
    exp_progress(s, D, run, ep, r);
  }
  rc = 0;
done:
  nd_rfile_writer_close(&w);
  if (csv && fclose(csv) && !rc) {
    snprintf(err, errlen, "%.300s: %s", path, strerror(errno));
    rc = -1;
  }
  nds_fit_free(fit);
  return rc;
}

int exp_study_run(const exp_opts *o, int argc, char **argv) {
  char err[512] = "";
  exp_study s;
  int status = 1;
  exp_row *rows = NULL;
  int nrun[MAX_D] = {0};
  if (exp_study_init(&s, o, err, sizeof(err))) goto done;
  exp_write_config(o, argc, argv);
  rows = calloc((size_t)o->nD * o->runs * (o->episodes + 1), sizeof(*rows));
  if (!rows) {
    snprintf(err, sizeof(err), "out of memory");
    goto done;
  }
  const int runs_total = o->nD * o->runs;
  s.tasks_total = o->neval + (long)runs_total * (o->episodes + (long)(o->episodes + 1) * o->neval);
  s.fit_units_total = (long)runs_total * o->episodes * (o->episodes + 1) / 2;
  fprintf(stderr, PROG ": %d D x %d runs x %d episodes, planner N %d C %d, tau %g s, "
          "%d eval tasks, replay %s, %d worker(s)\n", o->nD, o->runs, o->episodes, o->pop,
          o->iters, o->tau, o->neval, nds_replay_mode_name(o->mode), o->threads);

  char vpath[1200];
  exp_path(vpath, sizeof(vpath), o->out, "validation.nbuf");
  s.nval = 0;
  if (exp_record_truth(&s, nds_demo_goals, o->neval, 3, s.val, vpath, err, sizeof(err))) goto done;
  s.nval = o->neval;
  fprintf(stderr, PROG ": validation rollouts recorded with the true theta: success %.2f, "
          "mean time %.2f s\n", s.val_success, s.val_time);
  if (truth_band(&s, err, sizeof(err))) goto done;
  fprintf(stderr, PROG ": validation loss within %g%% of the true sliding friction: "
          "%.3g..%.3g\n", 100 * BAND_DU, s.band_lo, s.band_hi);

  for (int di = 0; di < o->nD; di++) {
    for (int run = 0; run < o->runs; run++) {
      if (run_one(&s, di, run, rows, err, sizeof(err))) goto done;
      nrun[di] = run + 1;
      if (exp_write_summary(o, rows, nrun, err, sizeof(err))) goto done;
    }
  }
  if (exp_write_plots(o, nrun, err, sizeof(err))) fprintf(stderr, PROG ": warning: %s\n", err);
  err[0] = 0;

  printf("nudge-experiment: %s\n", o->out);
  printf("truth_success_rate %.3f ratio\n", s.val_success);
  printf("truth_mean_time %.3f s\n", s.val_time);
  printf("val_loss_band_min %.4g loss\n", s.band_lo);
  printf("val_loss_band_max %.4g loss\n", s.band_hi);
  for (int di = 0; di < o->nD; di++) exp_print_figures(o, &s, rows, di, nrun[di]);
  printf("experiment_s %.1f s\n", exp_now() - s.t0);
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  free(rows);
  exp_study_free(&s);
  return status;
}