/* experiment: what the files of nudge-experiment share.
 *
 *   main.c       options and wiring
 *   study.c      the study: tasks, refits, evaluations (paper sec. IV-A)
 *   report.c     per-run CSVs, summary.csv, figures with gnuplot, the printed figures
 *   landscape.c  the --landscape diagnostic: the loss along each friction
 *
 * For each prior width D and each of R runs: draw the initial mean mu0 ~ U(theta - D theta,
 * theta + D theta) of the three frictions (sphere mass held at the truth) with the paper's
 * sigma0; then E times: run a training task with the planner on the current theta mean in
 * the ground-truth world (the paused-world protocol of nds_episode), record it, append it
 * to the run's replay-buffer file, read the file back and refit theta on all of it (CEM, Q
 * 32, C 2). Before the first episode and after each one, evaluate the current mean: success
 * and time on the evaluation tasks, the replay loss on validation rollouts recorded once
 * with the true theta, and each parameter's error. Everything is seeded: the same command
 * gives the same numbers, whatever --threads is. */
#ifndef EXPERIMENT_H
#define EXPERIMENT_H

#include <stdint.h>
#include <stdio.h>

#include "nds_episode.h"
#include "nds_fit.h"
#include "nds_record.h"
#include "nds_setup.h"

#define PROG "nudge-experiment"
#define MAX_D 8
#define MAX_EVAL NDS_DEMO_GOALS
#define NFIT 3   /* the fitted frictions: sliding, torsional, rolling */
#define NTRAIN 10

/* Training goals, used in this order, cycling (study.c). */
extern const nd_goal exp_train_goals[NTRAIN];

typedef struct {
  int runs, episodes, threads, pop, iters, neval, mode, force, quick, landscape, draws;
  double tau, plan_dt, window;
  double step_std, step_gate, rel_floor, k2, robust;  /* the fit's (nds_fit_cfg) */
  uint64_t seed;
  double D[MAX_D];
  int nD;
  const char *out;
} exp_opts;

/* One evaluation point of one run: the state after `episode` refits. */
typedef struct {
  double mean[ND_NTHETA], std[ND_NTHETA], err_pct[NFIT];
  double success, mean_time, val_loss, fit_loss, fit_s;
  double train_reached, train_time;
  int train_steps;
} exp_row;

typedef struct {
  const exp_opts *o;
  nds_setup su;                 /* world, planning model, pool, start */
  nds_model fitm;               /* the refits' model: the world's copy */
  nds_record rec;
  nds_planner_cfg pcfg;
  nds_episode_cfg ecfg;
  nd_rollout val[MAX_EVAL];
  int nval;
  double val_success, val_time; /* the evaluation tasks under the true theta */
  double band_lo, band_hi;      /* the validation loss's resolution (study.c) */
  /* for the ETA: measured cost of a task and of one rollout-replay-set of a refit */
  double t0, task_s, fit_s;
  long tasks_done, fit_units_done, tasks_total, fit_units_total;
} exp_study;

/* study.c */
double exp_now(void);
uint64_t exp_mix(uint64_t seed, uint64_t a, uint64_t b, uint64_t c);
void exp_fit_cfg(const exp_opts *o, int mode, nds_fit_cfg *fc);
int exp_study_init(exp_study *s, const exp_opts *o, char *err, int errlen);
void exp_study_free(exp_study *s);
int exp_record_truth(exp_study *s, const nd_goal *g, int n, uint64_t kind, nd_rollout *rs,
                     const char *path, char *err, int errlen);
int exp_study_run(const exp_opts *o, int argc, char **argv);
/* The initial mean (mass at the truth) and std of run `run` at prior width D: the paper's
 * draw, seeded from --seed, D and the run only. */
uint64_t exp_dkey(double D);
void exp_draw(const exp_opts *o, double D, int run, double lower, double mu0[ND_NTHETA],
              double sigma0[ND_NTHETA]);
/* --draws: "D run S,T,R,M" per run and D on stdout, the means the study starts from. */
int exp_draws_print(const exp_opts *o);

/* report.c */
void exp_path(char *buf, size_t cap, const char *dir, const char *name);
int exp_mkdir(const char *path, char *err, int errlen);
void exp_dname(double D, char *buf, size_t cap);
void exp_progress(exp_study *s, double D, int run, int ep, const exp_row *r);
extern const char *exp_run_header;
void exp_csv_row(FILE *f, int ep, double D, int run, const exp_row *r);
exp_row *exp_row_at(exp_row *rows, const exp_opts *o, int di, int run, int ep);
int exp_write_summary(const exp_opts *o, exp_row *rows, const int *nrun, char *err, int errlen);
int exp_write_plots(const exp_opts *o, const int *nrun, char *err, int errlen);
void exp_write_config(const exp_opts *o, int argc, char **argv);
void exp_print_figures(const exp_opts *o, const exp_study *s, exp_row *rows, int di, int nrun);

/* landscape.c */
int exp_landscape_run(const exp_opts *o);

#endif
