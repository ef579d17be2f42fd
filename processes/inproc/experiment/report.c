/* report: what nudge-experiment writes: per-run CSVs, summary.csv, the figures with
 * gnuplot, config.txt, the printed figures (experiment.h). */
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "experiment.h"
#include "nd_stats.h"

int exp_mkdir(const char *path, char *err, int errlen) {
  char buf[1024];
  if (strlen(path) > 900) {
    snprintf(err, errlen, "--out: path longer than 900 characters");
    return -1;
  }
  strcpy(buf, path);
  for (char *p = buf + 1;; p++) {
    if (*p == '/' || *p == 0) {
      char c = *p;
      *p = 0;
      if (mkdir(buf, 0755) && errno != EEXIST) {
        snprintf(err, errlen, "%.300s: cannot create: %s", buf, strerror(errno));
        return -1;
      }
      *p = c;
      if (!c) break;
    }
  }
  struct stat st;
  if (stat(path, &st) || !S_ISDIR(st.st_mode)) {
    snprintf(err, errlen, "%.300s: not a directory", path);
    return -1;
  }
  return 0;
}

void exp_path(char *buf, size_t cap, const char *dir, const char *name) {
  snprintf(buf, cap, "%s/%s", dir, name);
}

/* "%g" of D with the dot kept out of names: 0.2 -> "0.2", 1.0 -> "1". */
void exp_dname(double D, char *buf, size_t cap) { snprintf(buf, cap, "%g", D); }
static void fmt_hms(double sec, char *buf, size_t cap) {
  long t = (long)(sec + 0.5);
  snprintf(buf, cap, "%ld:%02ld:%02ld", t / 3600, t / 60 % 60, t % 60);
}

void exp_progress(exp_study *s, double D, int run, int ep, const exp_row *r) {
  double el = exp_now() - s->t0;
  double per_task = s->tasks_done ? s->task_s / s->tasks_done : 0;
  double per_fit = s->fit_units_done ? s->fit_s / s->fit_units_done : 0;
  double left = (s->tasks_total - s->tasks_done) * per_task +
                (s->fit_units_total - s->fit_units_done) * per_fit;
  double done = el / (el + left);
  char e1[32], e2[32];
  fmt_hms(el, e1, sizeof(e1));
  fmt_hms(left, e2, sizeof(e2));
  fprintf(stderr,
          "[%3.0f%%] D %g run %d/%d ep %2d/%d: err slide %5.1f%% tors %5.1f%% roll %5.1f%%, "
          "success %.2f, time %.2f s, val L %.2e, fit %.1f s | elapsed %s, ETA %s\n",
          100 * done, D, run + 1, s->o->runs, ep, s->o->episodes, r->err_pct[0], r->err_pct[1],
          r->err_pct[2], r->success, r->mean_time, r->val_loss, r->fit_s, e1, e2);
}

static void csv_num(FILE *f, double v) {
  if (isnan(v)) fputs(",nan", f);
  else fprintf(f, ",%.9g", v);
}

const char *exp_run_header =
    "episode,D,run,slide_mean,torsion_mean,roll_mean,slide_std,torsion_std,roll_std,"
    "slide_err_pct,torsion_err_pct,roll_err_pct,success,mean_time_s,val_loss,fit_loss,"
    "fit_s,train_goal_x,train_goal_y,train_goal_yaw,train_reached,train_time_s,train_steps\n";

void exp_csv_row(FILE *f, int ep, double D, int run, const exp_row *r) {
  fprintf(f, "%d,%g,%d", ep, D, run);
  for (int i = 0; i < NFIT; i++) csv_num(f, r->mean[i]);
  for (int i = 0; i < NFIT; i++) csv_num(f, r->std[i]);
  for (int i = 0; i < NFIT; i++) csv_num(f, r->err_pct[i]);
  csv_num(f, r->success);
  csv_num(f, r->mean_time);
  csv_num(f, r->val_loss);
  csv_num(f, r->fit_loss);
  csv_num(f, r->fit_s);
  const nd_goal *g = ep > 0 ? &exp_train_goals[(ep - 1) % NTRAIN] : NULL;
  csv_num(f, g ? g->x : NAN);
  csv_num(f, g ? g->y : NAN);
  csv_num(f, g ? g->yaw : NAN);
  csv_num(f, r->train_reached);
  csv_num(f, r->train_time);
  fprintf(f, ",%d\n", r->train_steps);
}

/* Metrics of the summary, by accessor. */
enum { M_SLIDE, M_TORSION, M_ROLL, M_SUCCESS, M_TIME, M_VAL, M_FIT, M_FIT_S, M_N };
static const char *mname[M_N] = {"slide_err_pct", "torsion_err_pct", "roll_err_pct",
                                 "success", "mean_time_s", "val_loss", "fit_loss", "fit_s"};
static double metric(const exp_row *r, int m) {
  switch (m) {
    case M_SLIDE: return r->err_pct[0];
    case M_TORSION: return r->err_pct[1];
    case M_ROLL: return r->err_pct[2];
    case M_SUCCESS: return r->success;
    case M_TIME: return r->mean_time;
    case M_VAL: return r->val_loss;
    case M_FIT: return r->fit_loss;
    default: return r->fit_s;
  }
}

/* rows[(di * runs + run) * (E + 1) + ep]; nrun[di] runs complete. */
exp_row *exp_row_at(exp_row *rows, const exp_opts *o, int di, int run, int ep) {
  return &rows[((size_t)di * o->runs + run) * (o->episodes + 1) + ep];
}

static nd_stats metric_stats(exp_row *rows, const exp_opts *o, int di, int nrun, int ep, int m) {
  double v[1000];
  for (int r = 0; r < nrun; r++) v[r] = metric(exp_row_at(rows, o, di, r, ep), m);
  return nd_stats_of(v, nrun);
}

/* summary.csv, and the per-D data files the plots read. Rewritten after every run. */
int exp_write_summary(const exp_opts *o, exp_row *rows, const int *nrun, char *err, int errlen) {
  char path[1200];
  exp_path(path, sizeof(path), o->out, "summary.csv");
  FILE *f = fopen(path, "w");
  if (!f) {
    snprintf(err, errlen, "%.300s: %s", path, strerror(errno));
    return -1;
  }
  fputs("D,episode,runs", f);
  for (int m = 0; m < M_N; m++)
    fprintf(f, ",%s_mean,%s_std,%s_min,%s_max,%s_median", mname[m], mname[m], mname[m],
            mname[m], mname[m]);
  fputc('\n', f);
  for (int di = 0; di < o->nD; di++) {
    if (!nrun[di]) continue;
    char dn[32], dpath[1200];
    exp_dname(o->D[di], dn, sizeof(dn));
    char nm[64];
    snprintf(nm, sizeof(nm), "plot_d%s.dat", dn);
    exp_path(dpath, sizeof(dpath), o->out, nm);
    FILE *g = fopen(dpath, "w");
    if (!g) {
      fclose(f);
      snprintf(err, errlen, "%.300s: %s", dpath, strerror(errno));
      return -1;
    }
    fputs("# episode, then per metric: mean min max (metrics:", g);
    for (int m = 0; m < M_N; m++) fprintf(g, " %s", mname[m]);
    fputs(")\n", g);
    for (int ep = 0; ep <= o->episodes; ep++) {
      fprintf(f, "%g,%d,%d", o->D[di], ep, nrun[di]);
      fprintf(g, "%d", ep);
      for (int m = 0; m < M_N; m++) {
        nd_stats st = metric_stats(rows, o, di, nrun[di], ep, m);
        csv_num(f, st.mean);
        csv_num(f, st.std);
        csv_num(f, st.min);
        csv_num(f, st.max);
        csv_num(f, st.median);
        fprintf(g, " %.9g %.9g %.9g", st.mean, st.min, st.max);
      }
      fputc('\n', f);
      fputc('\n', g);
    }
    fclose(g);
  }
  if (fclose(f)) {
    snprintf(err, errlen, "%.300s: %s", path, strerror(errno));
    return -1;
  }
  return 0;
}

/* Run gnuplot plots.gp in dir, without a shell: the directory name reaches chdir(2) as it
 * is, so no character of --out can act as shell syntax. Return gnuplot's exit status (127:
 * it could not be started, 128 + N: killed by signal N), or -1 if fork failed. */
static int run_gnuplot(const char *dir) {
  fflush(NULL);  /* the child must not flush our buffered output a second time */
  const pid_t pid = fork();
  if (pid < 0) return -1;
  if (pid == 0) {  /* only chdir and exec: locks the pool's threads held are not ours */
    if (chdir(dir) == 0) execlp("gnuplot", "gnuplot", "plots.gp", (char *)NULL);
    _exit(127);
  }
  int st;
  while (waitpid(pid, &st, 0) < 0)
    if (errno != EINTR) return -1;
  return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

/* The figures: gnuplot reads the per-D data files. Column of metric m's mean in them: 2 +
 * 3 m (then min, max). Returns 0, or -1 if gnuplot failed or is missing (a warning). */
int exp_write_plots(const exp_opts *o, const int *nrun, char *err, int errlen) {
  char gp[1200];
  exp_path(gp, sizeof(gp), o->out, "plots.gp");
  FILE *f = fopen(gp, "w");
  if (!f) {
    snprintf(err, errlen, "%.300s: %s", gp, strerror(errno));
    return -1;
  }
  static const char *colors[MAX_D] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd",
                                      "#ff7f0e", "#8c564b", "#e377c2", "#7f7f7f"};
  fprintf(f, "# written by " PROG "; run with: gnuplot plots.gp (in this directory)\n"
             "set terminal pngcairo size 1500,420 font ',10'\n"
             "set xlabel 'episode'\nset xtics 1\nset grid\nset key top right\n"
             "set style fill transparent solid 0.2 noborder\n");
  struct {
    const char *file, *title[3], *ylabel[3];
    int m[3], logy[3];
  } figs[2] = {
      {"fig2_param_errors.png",
       {"sliding friction", "torsional friction", "rolling friction"},
       {"|mu - theta| / theta, %", "|mu - theta| / theta, %", "|mu - theta| / theta, %"},
       {M_SLIDE, M_TORSION, M_ROLL}, {0, 0, 0}},
      {"fig3_performance.png",
       {"success rate (evaluation tasks)", "mean execution time", "validation loss L(mu)"},
       {"success rate", "time, s", "L"},
       {M_SUCCESS, M_TIME, M_VAL}, {0, 0, 1}},
  };
  for (int k = 0; k < 2; k++) {
    fprintf(f, "set output '%s'\nset multiplot layout 1,3 title 'mean over runs, band: min to "
               "max across runs'\n", figs[k].file);
    for (int p = 0; p < 3; p++) {
      fprintf(f, "set title '%s'\nset ylabel '%s'\n%s\n", figs[k].title[p], figs[k].ylabel[p],
              figs[k].logy[p] ? "set logscale y\nset format y '%.0e'" : "unset logscale y\nset format y '%g'");
      if (figs[k].m[p] == M_SUCCESS) fputs("set yrange [0:1.05]\n", f);
      else fputs("set yrange [*:*]\n", f);
      fputs("plot ", f);
      int first = 1;
      for (int di = 0; di < o->nD; di++) {
        if (!nrun[di]) continue;
        char dn[32];
        exp_dname(o->D[di], dn, sizeof(dn));
        int c = 2 + 3 * figs[k].m[p];
        fprintf(f, "%s'plot_d%s.dat' using 1:%d:%d with filledcurves lc rgb '%s' notitle, "
                   "'plot_d%s.dat' using 1:%d with linespoints lw 2 pt 7 lc rgb '%s' "
                   "title 'D = %s'",
                first ? "" : ", ", dn, c + 1, c + 2, colors[di], dn, c, colors[di], dn);
        first = 0;
      }
      fputc('\n', f);
    }
    fputs("unset multiplot\n", f);
  }
  fclose(f);
  const int rc = run_gnuplot(o->out);
  if (rc != 0) {
    snprintf(err, errlen, "gnuplot failed or is missing (exit %d); the data and plots.gp are "
             "in %.300s", rc, o->out);
    return -1;
  }
  return 0;
}
void exp_write_config(const exp_opts *o, int argc, char **argv) {
  char path[1200];
  exp_path(path, sizeof(path), o->out, "config.txt");
  FILE *f = fopen(path, "w");
  if (!f) return;
  fputs("command:", f);
  for (int i = 0; i < argc; i++) fprintf(f, " %s", argv[i]);
  fprintf(f, "\nruns %d\nepisodes %d\nD", o->runs, o->episodes);
  for (int i = 0; i < o->nD; i++) fprintf(f, " %g", o->D[i]);
  fprintf(f, "\nseed %llu\nplanner N %d C %d, plan dt %g s\ntau %g s\neval tasks %d\n"
             "refit Q 32 C 2, replay %s, window %g s, step_std %g, step_gate %g, rel_floor %g, "
             "rot weight %g m^2/rad, robust %g m^2, world and refit dt "
             "0.001 s\n"
             "threads %d\n",
          (unsigned long long)o->seed, o->pop, o->iters, o->plan_dt, o->tau, o->neval,
          nds_replay_mode_name(o->mode), o->window, o->step_std, o->step_gate, o->rel_floor,
          o->k2, o->robust, o->threads);
  fclose(f);
}

/* The figures of one D as `name value unit` lines. */
void exp_print_figures(const exp_opts *o, const exp_study *s, exp_row *rows, int di, int nrun) {
  char sfx[32];
  snprintf(sfx, sizeof(sfx), "_d%g", o->D[di]);
  const int E = o->episodes, e2 = E >= 2 ? 2 : E;
  char e2s[16];
  snprintf(e2s, sizeof(e2s), "ep%d", e2);
  nd_stats s2 = metric_stats(rows, o, di, nrun, e2, M_SLIDE);
  printf("sliding_err_pct_%s%s %.3f %%\n", e2s, sfx, s2.median);
  nd_stats t0 = metric_stats(rows, o, di, nrun, 0, M_TORSION);
  nd_stats tE = metric_stats(rows, o, di, nrun, E, M_TORSION);
  printf("torsional_err_drop_pct_last%s %.1f %%\n", sfx, 100 * (1 - tE.mean / t0.mean));
  nd_stats r0 = metric_stats(rows, o, di, nrun, 0, M_ROLL);
  nd_stats rE = metric_stats(rows, o, di, nrun, E, M_ROLL);
  printf("rolling_err_drop_pct_last%s %.1f %%\n", sfx, 100 * (1 - rE.mean / r0.mean));
  double worst = 0, worst_res = NAN;
  int within = 0, resolved = 0;
  for (int r = 0; r < nrun; r++) {
    const double L0 = exp_row_at(rows, o, di, r, 0)->val_loss;
    double q = exp_row_at(rows, o, di, r, e2)->val_loss / L0;
    if (!(q <= worst)) worst = q;
    if (L0 > s->band_hi) {
      resolved++;
      if (!(q <= worst_res)) worst_res = q;
    }
    within += exp_row_at(rows, o, di, r, e2)->err_pct[0] < 5.0;
  }
  printf("val_loss_ratio_%s%s %.4g ratio\n", e2s, sfx, worst);
  printf("val_loss_ratio_%s_resolved%s %.4g ratio\n", e2s, sfx, worst_res);
  printf("runs_val_loss_resolved_ep0%s %d/%d runs\n", sfx, resolved, nrun);
  nd_stats sl = metric_stats(rows, o, di, nrun, E, M_SUCCESS);
  printf("success_rate_last%s %.3f ratio\n", sfx, sl.mean);
  nd_stats s0 = metric_stats(rows, o, di, nrun, 0, M_SUCCESS);
  printf("success_rate_ep0%s %.3f ratio\n", sfx, s0.mean);
  nd_stats tl = metric_stats(rows, o, di, nrun, E, M_TIME);
  printf("mean_time_last%s %.3f s\n", sfx, tl.mean);
  printf("runs_sliding_within5pct_%s%s %d/%d runs\n", e2s, sfx, within, nrun);
  nd_stats sE = metric_stats(rows, o, di, nrun, E, M_SLIDE);
  printf("sliding_err_pct_last%s %.3f %%\n", sfx, sE.median);
  double fsum = 0;
  for (int r = 0; r < nrun; r++)
    for (int ep = 1; ep <= E; ep++) fsum += exp_row_at(rows, o, di, r, ep)->fit_s;
  printf("refit_s_mean%s %.2f s\n", sfx, fsum / (nrun * E));
}

