/* nudge-experiment: the paper's simulation study (sec. IV-A, DESIGN.md sec. 5) in one
 * process on the same sim code as the live system.
 *
 * For each prior width D and each of R runs: draw the initial mean mu0 ~ U(theta - D theta,
 * theta + D theta) of the three frictions (sphere mass held at the truth) with the paper's
 * sigma0; then E times: run a training task with the planner on the current theta mean in
 * the ground-truth world (the paused-world protocol of nds_episode), record it, append it
 * to the run's replay-buffer file, read the file back and refit theta on all of it (CEM, Q
 * 32, C 2). Before the first episode and after each one, evaluate the current mean: success
 * and time on the evaluation tasks, the replay loss on validation rollouts recorded once
 * with the true theta, and each parameter's error. Everything is seeded: the same command
 * gives the same numbers, whatever --threads is.
 *
 * --landscape instead records the training tasks with the true theta and writes the loss
 * along each friction for the FORCE and SETPOINT replay modes (how the default replay
 * mode and what torsional friction needs were chosen), after a report of how far pushing
 * lifts the box off the table (why re-anchoring puts back the box's full pose). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "nd_math.h"
#include "nd_parse.h"
#include "nd_rbuf.h"
#include "nds_episode.h"
#include "nds_fit.h"
#include "nds_record.h"

#define PROG "nudge-experiment"
#define MAX_D 8
#define MAX_EVAL 5
#define NFIT 3 /* the fitted frictions: sliding, torsional, rolling */

/* The demo's five goals: the evaluation tasks, and (run with the true theta) the
 * validation rollouts. */
static const nd_goal eval_goals[MAX_EVAL] = {
    {.x = 0.20, .y = 0.00, .yaw = 0.0}, {.x = 0.15, .y = 0.12, .yaw = 0.6}, {.x = 0.15, .y = -0.12, .yaw = -0.6}, {.x = 0.05, .y = 0.20, .yaw = 1.2},
    {.x = -0.10, .y = -0.15, .yaw = -0.5},
};

/* Training goals, used in this order, cycling. Most ask for a turn of 0.4-1.3 rad, so the
 * box rotates under the sphere (the only motion torsional friction shows in); two are
 * straight pushes, one nearly a turn on the spot. */
#define NTRAIN 10
/* The validation loss's scale near the truth: BAND_N models with sliding friction spread
 * evenly over truth (1 +- BAND_DU), never exactly the truth (which replays to L ~ 1e-19). */
#define BAND_N 16
#define BAND_DU 0.01
static const nd_goal train_goals[NTRAIN] = {
    {.x = 0.15, .y = 0.05, .yaw = 0.8},  {.x = 0.12, .y = -0.10, .yaw = -0.9}, {.x = 0.20, .y = 0.00, .yaw = 0.0},   {.x = 0.05, .y = 0.12, .yaw = 1.3},
    {.x = 0.18, .y = -0.05, .yaw = -0.5}, {.x = 0.03, .y = 0.00, .yaw = 1.0},  {.x = 0.12, .y = 0.12, .yaw = -0.7},  {.x = 0.10, .y = -0.15, .yaw = 0.9},
    {.x = 0.22, .y = 0.08, .yaw = 0.0},  {.x = 0.08, .y = 0.04, .yaw = -1.2},
};

static const char *pname[NFIT] = {"slide", "torsion", "roll"};

typedef struct {
  int runs, episodes, threads, pop, iters, neval, mode, force, quick, landscape;
  double tau, plan_dt, window;
  double step_std, step_gate, rel_floor, k2, robust;  /* the fit's (nds_fit_cfg) */
  uint64_t seed;
  double D[MAX_D];
  int nD;
  const char *out;
} opts;

/* One evaluation point of one run: the state after `episode` refits. */
typedef struct {
  double mean[ND_NTHETA], std[ND_NTHETA], err_pct[NFIT];
  double success, mean_time, val_loss, fit_loss, fit_s;
  double train_reached, train_time;
  int train_steps;
} ep_row;

typedef struct {
  const opts *o;
  nds_model world, plan, fitm;
  nd_pool *pool;
  mjData *d;
  nds_record rec;
  nds_state start;
  nds_planner_cfg pcfg;
  nds_episode_cfg ecfg;
  nd_rollout val[MAX_EVAL];
  int nval;
  double val_success, val_time; /* the evaluation tasks under the true theta */
  double band_lo, band_hi;      /* the validation loss's resolution (truth_band) */
  /* for the ETA: measured cost of a task and of one rollout-replay-set of a refit */
  double t0, task_s, fit_s;
  long tasks_done, fit_units_done, tasks_total, fit_units_total;
} study;

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* splitmix64 over a list of words: seeds that differ in any word are unrelated. */
static uint64_t mix(uint64_t seed, uint64_t a, uint64_t b, uint64_t c) {
  uint64_t x = seed, w[3] = {a, b, c};
  for (int i = 0; i < 3; i++) {
    x += 0x9E3779B97F4A7C15ULL + w[i];
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    x ^= x >> 31;
  }
  return x;
}

static void usage(FILE *f) {
  fprintf(f,
"usage: " PROG " --out DIR [options]\n"
"The paper's simulation study (sec. IV-A): incremental refits of the three frictions from\n"
"planned pushing tasks, evaluated after every episode. Seeded and reproducible.\n\n"
"  --out DIR        results directory (created); refuses one holding a non-empty\n"
"                   summary.csv unless --force\n"
"  --force          overwrite the results in DIR\n"
"  --runs R         runs per D, independent initial means (default 10, the paper's)\n"
"  --episodes E     training episodes per run (default 10)\n"
"  --d LIST         prior widths D, comma-separated (default 0.2,1.0)\n"
"  --seed N         master seed (default 1)\n"
"  --threads N      workers for planning and refits, 1..64 (default: online cores);\n"
"                   results do not depend on it\n"
"  --pop N          planner population (default 128, the paper's)\n"
"  --iters N        planner iterations (default 4)\n"
"  --tau S          task time limit, s (default 5)\n"
"  --eval-tasks K   evaluation tasks (the demo's goals), 1..5 (default 5)\n"
"  --replay MODE    refit replay: force (default) or setpoint (see below)\n"
"  --window S       refit replay re-anchored on the observed pose every S s (default\n"
"                   0.005; 0: one shot from the initial state, the paper's; nds_replay.h)\n"
"  --step-std K     refit CEM: the std at least K times the mean's last step (default\n"
"                   2; 0: the paper's plain CEM; nds_fit.c)\n"
"  --step-gate G    refit CEM: --step-std only for steps of at least G sampling stds\n"
"                   (default 0.75; 0: every step; nds_fit.c)\n"
"  --rel-floor R    refit CEM: each refit starts with std >= R |mean|, 0..0.99\n"
"                   (default 0.05; 0: off)\n"
"  --rot-weight K2  refit loss: weight of the object's yaw term, m^2/rad, 0..1\n"
"                   (default 0.001; 0: positions only)\n"
"  --robust S       refit CEM ranks candidates by each window's L through a Cauchy\n"
"                   loss of scale S, m^2, 0..1 (default 0: by L, the paper's;\n"
"                   nds_fit.c). Reported losses are L either way\n"
"  --plan-dt S      planning model timestep, s (default 0.005; world and refit: 0.001)\n"
"  --quick          a preset for a first look, under 10 min on 2 cores: --runs 3\n"
"                   --episodes 4 --pop 32 --iters 2 --tau 3 (explicit options win)\n"
"  --landscape      instead of the study: record the 10 training tasks with the true\n"
"                   theta and write DIR/landscape.csv, the loss along each friction for\n"
"                   both replay modes (re-anchored as --window says), with a summary\n"
"                   of each curve, and the robust score (--robust, else 1e-9) beside L\n"
"                   along sliding friction; first, `lift` lines: how often the pushed\n"
"                   box stands on fewer than 3 table contacts (MuJoCo's soft contact\n"
"                   lifts a sliding box), why re-anchoring puts back its full pose\n"
"  -h, --help       this text\n\n"
"Replay modes: force replays the recorded force on the sphere open loop (the paper's\n"
"simulation); setpoint replays the recorded setpoints through the robot's tracking\n"
"controller, which keeps the sphere on its path under a wrong theta but hides most of\n"
"what sliding friction does. Re-anchoring keeps force's open loop from running away.\n\n"
"Writes DIR/run_d<D>_r<run>.csv (one row per episode, 0 = the initial mean),\n"
"DIR/summary.csv (per D and episode: mean, std, min, max, median over runs),\n"
"DIR/buffer_d<D>_r<run>.nbuf (the replay buffers), DIR/validation.nbuf, DIR/config.txt,\n"
"and, with gnuplot, DIR/fig2_param_errors.png and DIR/fig3_performance.png.\n"
"Progress with an ETA goes to stderr. Ends with `name value unit` lines per D (suffix\n"
"_d<D>, e.g. _d1 for D = 1.0):\n"
"  sliding_err_pct_ep2       median over runs of |mu - theta| / theta after episode 2\n"
"  torsional_err_drop_pct_last  100 (1 - mean error at the last episode / mean error at\n"
"                            episode 0), means over runs\n"
"  val_loss_ratio_ep2        L(mean) after episode 2 over L(mu0), the worst run\n"
"  val_loss_ratio_ep2_resolved  the same over the runs whose L(mu0) is above\n"
"                            val_loss_band_max (nan if none)\n"
"  runs_val_loss_resolved_ep0   those runs\n"
"  success_rate_last         mean over runs at the last episode\n"
"  runs_sliding_within5pct_ep2  runs whose sliding error is below 5%% after episode 2\n"
"and once: val_loss_band_min/max, the validation loss of %d models whose sliding friction\n"
"is within +-%g%% of the truth (the rest exact): how low the validation loss gets for\n"
"models that close.\n",
          BAND_N, 100 * BAND_DU);
}

/* ---- options ---- */

static int parse_dlist(const char *s, opts *o, char *err, int errlen) {
  char buf[256];
  if (strlen(s) >= sizeof(buf)) {
    snprintf(err, errlen, "--d: list too long");
    return -1;
  }
  strcpy(buf, s);
  o->nD = 0;
  char *save = NULL;
  for (char *t = strtok_r(buf, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
    if (o->nD == MAX_D) {
      snprintf(err, errlen, "--d: at most %d values", MAX_D);
      return -1;
    }
    if (nd_parse_double(t, "--d", 1e-3, 5.0, &o->D[o->nD], err, errlen)) return -1;
    for (int i = 0; i < o->nD; i++)
      if (o->D[i] == o->D[o->nD]) {
        snprintf(err, errlen, "--d: %g appears twice", o->D[i]);
        return -1;
      }
    o->nD++;
  }
  /* "1.0," or ",1.0" would silently drop an empty entry. */
  if (o->nD == 0 || s[0] == ',' || s[strlen(s) - 1] == ',' || strstr(s, ",,")) {
    snprintf(err, errlen, "--d: expected a comma-separated list of numbers, got '%s'", s);
    return -1;
  }
  return 0;
}

/* 0 on success, 1 after --help, 2 on a bad argument (message printed). */
static int parse_args(int argc, char **argv, opts *o) {
  char err[256];
  int runs = -1, episodes = -1, pop = -1, iters = -1, neval = -1;
  double tau = -1;
  memset(o, 0, sizeof(*o));
  o->threads = (int)sysconf(_SC_NPROCESSORS_ONLN);
  if (o->threads < 1) o->threads = 1;
  if (o->threads > 64) o->threads = 64;
  o->seed = 1;
  o->plan_dt = 0.005;
  {
    nds_fit_cfg fd;  /* the fit's defaults */
    nds_fit_cfg_default(&fd);
    o->mode = fd.replay.mode;
    o->window = fd.replay.window;
    o->step_std = fd.step_std;
    o->step_gate = fd.step_gate;
    o->rel_floor = fd.rel_floor;
    o->k2 = fd.k2;
    o->robust = fd.robust;
  }
  o->D[0] = 0.2, o->D[1] = 1.0, o->nD = 2;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 1;
    }
    if (!strcmp(a, "--quick")) { o->quick = 1; continue; }
    if (!strcmp(a, "--force")) { o->force = 1; continue; }
    if (!strcmp(a, "--landscape")) { o->landscape = 1; continue; }
    static const char *const with_value[] = {
        "--out", "--runs", "--episodes", "--seed", "--threads", "--pop",
        "--iters", "--tau", "--eval-tasks", "--plan-dt", "--d", "--replay", "--window",
        "--step-std", "--step-gate", "--rel-floor", "--rot-weight", "--robust"};
    int known = 0;
    for (size_t k = 0; k < sizeof(with_value) / sizeof(with_value[0]); k++)
      known |= !strcmp(a, with_value[k]);
    if (!known || i + 1 >= argc) {
      fprintf(stderr, known ? PROG ": %s needs a value\n" : PROG ": unknown option: %s\n", a);
      usage(stderr);
      return 2;
    }
    const char *v = argv[++i];
    int rc;
    if (!strcmp(a, "--out")) o->out = v, rc = 0;
    else if (!strcmp(a, "--runs")) rc = nd_parse_int(v, a, 1, 1000, &runs, err, sizeof(err));
    else if (!strcmp(a, "--episodes")) rc = nd_parse_int(v, a, 1, 1000, &episodes, err, sizeof(err));
    else if (!strcmp(a, "--seed")) rc = nd_parse_u64(v, a, &o->seed, err, sizeof(err));
    else if (!strcmp(a, "--threads")) rc = nd_parse_int(v, a, 1, 64, &o->threads, err, sizeof(err));
    else if (!strcmp(a, "--pop")) rc = nd_parse_int(v, a, 4, 100000, &pop, err, sizeof(err));
    else if (!strcmp(a, "--iters")) rc = nd_parse_int(v, a, 1, 100, &iters, err, sizeof(err));
    else if (!strcmp(a, "--tau")) rc = nd_parse_double(v, a, 0.1, 600, &tau, err, sizeof(err));
    else if (!strcmp(a, "--eval-tasks")) rc = nd_parse_int(v, a, 1, MAX_EVAL, &neval, err, sizeof(err));
    else if (!strcmp(a, "--plan-dt")) rc = nd_parse_double(v, a, 1e-3, 0.02, &o->plan_dt, err, sizeof(err));
    else if (!strcmp(a, "--d")) rc = parse_dlist(v, o, err, sizeof(err));
    else if (!strcmp(a, "--window")) rc = nd_parse_double(v, a, 0, 600, &o->window, err, sizeof(err));
    else if (!strcmp(a, "--step-std")) rc = nd_parse_double(v, a, 0, 100, &o->step_std, err, sizeof(err));
    else if (!strcmp(a, "--step-gate")) rc = nd_parse_double(v, a, 0, 100, &o->step_gate, err, sizeof(err));
    else if (!strcmp(a, "--rel-floor")) rc = nd_parse_double(v, a, 0, 0.99, &o->rel_floor, err, sizeof(err));
    else if (!strcmp(a, "--rot-weight")) rc = nd_parse_double(v, a, 0, 1, &o->k2, err, sizeof(err));
    else if (!strcmp(a, "--robust")) rc = nd_parse_double(v, a, 0, 1, &o->robust, err, sizeof(err));
    else if (!strcmp(a, "--replay")) {
      rc = 0;
      if (!strcmp(v, "setpoint")) o->mode = NDS_REPLAY_SETPOINT;
      else if (!strcmp(v, "force")) o->mode = NDS_REPLAY_FORCE;
      else snprintf(err, sizeof(err), "--replay: expected setpoint or force, got '%s'", v), rc = -1;
    } else {
      fprintf(stderr, PROG ": unknown option: %s\n", a);
      usage(stderr);
      return 2;
    }
    if (rc) {
      fprintf(stderr, PROG ": %s\n", err);
      return 2;
    }
  }
  if (!o->out || !o->out[0]) {
    fprintf(stderr, PROG ": --out DIR is required\n");
    usage(stderr);
    return 2;
  }
  /* The preset first, explicit values over it. */
  o->runs = o->quick ? 3 : 10;
  o->episodes = o->quick ? 4 : 10;
  o->pop = o->quick ? 32 : 128;
  o->iters = o->quick ? 2 : 4;
  o->tau = o->quick ? 3.0 : 5.0;
  o->neval = MAX_EVAL;
  if (runs > 0) o->runs = runs;
  if (episodes > 0) o->episodes = episodes;
  if (pop > 0) o->pop = pop;
  if (iters > 0) o->iters = iters;
  if (tau > 0) o->tau = tau;
  if (neval > 0) o->neval = neval;
  return 0;
}

/* ---- files ---- */

static int mkdir_p(const char *path, char *err, int errlen) {
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

static void path_in(char *buf, size_t cap, const char *dir, const char *name) {
  snprintf(buf, cap, "%s/%s", dir, name);
}

/* The refit's configuration: the fit's defaults with the options' replay and CEM
 * settings, replaying in mode. */
static void fit_cfg(const opts *o, int mode, nds_fit_cfg *fc) {
  nds_fit_cfg_default(fc);
  fc->replay.mode = mode;
  fc->replay.window = o->window;
  fc->step_std = o->step_std;
  fc->step_gate = o->step_gate;
  fc->rel_floor = o->rel_floor;
  fc->k2 = o->k2;
  fc->robust = o->robust;
}

/* "%g" of D with the dot kept out of names: 0.2 -> "0.2", 1.0 -> "1". */
static void dname(double D, char *buf, size_t cap) { snprintf(buf, cap, "%g", D); }

/* ---- tasks ---- */

/* Run goal g from the start pose with a fresh planner (seed pseed) on theta; record it
 * into s->rec if rec. */
static int run_task(study *s, const double theta[ND_NTHETA], uint64_t pseed, const nd_goal *g,
                    int rec, int64_t task_id, nds_episode_out *out, char *err, int errlen) {
  nds_planner_cfg c = s->pcfg;
  c.seed = pseed;
  double t0 = now_s();
  nds_planner *p = nds_planner_create(&s->plan, &c, s->pool, err, errlen);
  if (!p) return -1;
  int rc = nds_planner_set_theta(p, theta, err, errlen);
  if (!rc && rec)
    rc = nds_record_begin(&s->rec, &s->world, &s->start, task_id, 0, g, theta, err, errlen);
  if (!rc) {
    nds_planner_reset(p);
    rc = nds_episode_run(&s->world, s->d, p, &c.ctrl, &s->ecfg, &s->start, g,
                         rec ? nds_record_hook : NULL, rec ? &s->rec : NULL, out, err, errlen);
  }
  if (!rc && rec)
    rc = nds_record_finish(&s->rec, out->reached ? ND_OUTCOME_SUCCESS : ND_OUTCOME_TIMEOUT, err,
                           errlen);
  nds_planner_free(p);
  s->task_s += now_s() - t0;
  s->tasks_done++;
  return rc;
}


/* Termination time of a task as the paper counts it: success time, else the limit. */
static double task_time(const study *s, const nds_episode_out *o) {
  return o->reached ? o->t_reached : s->ecfg.tau;
}

/* The evaluation of theta: tasks (common seeds for every run and episode, so differences
 * come from theta, not from the planner's draws), validation loss, errors. */
static int evaluate(study *s, nds_fit *fit, const double mean[ND_NTHETA],
                    const double std[ND_NTHETA], ep_row *row, char *err, int errlen) {
  memcpy(row->mean, mean, sizeof(row->mean));
  memcpy(row->std, std, sizeof(row->std));
  for (int i = 0; i < NFIT; i++)
    row->err_pct[i] = 100.0 * fabs(mean[i] - nd_theta_true[i]) / nd_theta_true[i];
  int ok = 0;
  double t = 0;
  for (int j = 0; j < s->o->neval; j++) {
    nds_episode_out o;
    if (run_task(s, mean, mix(s->o->seed, 3, (uint64_t)j, 0), &eval_goals[j], 0, 0, &o, err,
                 errlen))
      return -1;
    ok += o.reached;
    t += task_time(s, &o);
  }
  row->success = (double)ok / s->o->neval;
  row->mean_time = t / s->o->neval;
  return nds_fit_loss(fit, mean, s->val, s->nval, &row->val_loss, NULL, err, errlen);
}

/* ---- output ---- */

static void fmt_hms(double sec, char *buf, size_t cap) {
  long t = (long)(sec + 0.5);
  snprintf(buf, cap, "%ld:%02ld:%02ld", t / 3600, t / 60 % 60, t % 60);
}

static void progress(study *s, double D, int run, int ep, const ep_row *r) {
  double el = now_s() - s->t0;
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

static const char *run_header =
    "episode,D,run,slide_mean,torsion_mean,roll_mean,slide_std,torsion_std,roll_std,"
    "slide_err_pct,torsion_err_pct,roll_err_pct,success,mean_time_s,val_loss,fit_loss,"
    "fit_s,train_goal_x,train_goal_y,train_goal_yaw,train_reached,train_time_s,train_steps\n";

static void csv_row(FILE *f, int ep, double D, int run, const ep_row *r) {
  fprintf(f, "%d,%g,%d", ep, D, run);
  for (int i = 0; i < NFIT; i++) csv_num(f, r->mean[i]);
  for (int i = 0; i < NFIT; i++) csv_num(f, r->std[i]);
  for (int i = 0; i < NFIT; i++) csv_num(f, r->err_pct[i]);
  csv_num(f, r->success);
  csv_num(f, r->mean_time);
  csv_num(f, r->val_loss);
  csv_num(f, r->fit_loss);
  csv_num(f, r->fit_s);
  const nd_goal *g = ep > 0 ? &train_goals[(ep - 1) % NTRAIN] : NULL;
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
static double metric(const ep_row *r, int m) {
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

typedef struct {
  double mean, std, min, max, median;
} stats;

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* Stats of the finite values among v[0, n) (sorted in place); NaN if none. */
static stats stats_of(double *v, int n) {
  stats s = {NAN, NAN, NAN, NAN, NAN};
  int k = 0;
  for (int i = 0; i < n; i++)
    if (isfinite(v[i])) v[k++] = v[i];
  if (!k) return s;
  qsort(v, k, sizeof(double), cmp_double);
  double sum = 0, ss = 0;
  for (int i = 0; i < k; i++) sum += v[i];
  s.mean = sum / k;
  for (int i = 0; i < k; i++) ss += (v[i] - s.mean) * (v[i] - s.mean);
  s.std = k > 1 ? sqrt(ss / (k - 1)) : 0;
  s.min = v[0];
  s.max = v[k - 1];
  s.median = k % 2 ? v[k / 2] : 0.5 * (v[k / 2 - 1] + v[k / 2]);
  return s;
}

/* rows[(di * runs + run) * (E + 1) + ep]; nrun[di] runs complete. */
static ep_row *row_at(ep_row *rows, const opts *o, int di, int run, int ep) {
  return &rows[((size_t)di * o->runs + run) * (o->episodes + 1) + ep];
}

static stats metric_stats(ep_row *rows, const opts *o, int di, int nrun, int ep, int m) {
  double v[1000];
  for (int r = 0; r < nrun; r++) v[r] = metric(row_at(rows, o, di, r, ep), m);
  return stats_of(v, nrun);
}

/* summary.csv, and the per-D data files the plots read. Rewritten after every run. */
static int write_summary(const opts *o, ep_row *rows, const int *nrun, char *err, int errlen) {
  char path[1200];
  path_in(path, sizeof(path), o->out, "summary.csv");
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
    dname(o->D[di], dn, sizeof(dn));
    char nm[64];
    snprintf(nm, sizeof(nm), "plot_d%s.dat", dn);
    path_in(dpath, sizeof(dpath), o->out, nm);
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
        stats st = metric_stats(rows, o, di, nrun[di], ep, m);
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
static int write_plots(const opts *o, const int *nrun, char *err, int errlen) {
  char gp[1200];
  path_in(gp, sizeof(gp), o->out, "plots.gp");
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
        dname(o->D[di], dn, sizeof(dn));
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

/* ---- the study ---- */

static int study_init(study *s, const opts *o, char *err, int errlen) {
  memset(s, 0, sizeof(*s));
  s->o = o;
  nds_scene_cfg wc, pc;
  nds_scene_cfg_default(&wc);
  pc = wc;
  pc.timestep = o->plan_dt;
  if (nds_model_init(&s->world, &wc, err, errlen) || nds_model_init(&s->plan, &pc, err, errlen) ||
      nds_model_copy(&s->fitm, &s->world, err, errlen))
    return -1;
  if (!(s->pool = nd_pool_create(o->threads, err, errlen))) return -1;
  if (!(s->d = mj_makeData(s->world.m))) {
    snprintf(err, errlen, "out of memory for the world's mjData");
    return -1;
  }
  if (nds_record_init(&s->rec, o->tau, s->world.m->opt.timestep, err, errlen)) return -1;
  nds_planner_cfg_default(&s->pcfg);
  s->pcfg.pop = o->pop;
  s->pcfg.iters = o->iters;
  nds_episode_cfg_default(&s->ecfg);
  s->ecfg.tau = o->tau;
  /* The paper's terminal condition: a task ends when it succeeds (eps 1e-2), so the
   * recorded rollout ends there too. */
  s->ecfg.eps_fine = s->ecfg.eps;
  const double ee0[2] = {-0.10, 0.0};
  nds_state_rest(&s->world, 0.0, 0.0, 0.0, ee0, &s->start);
  s->t0 = now_s();
  return 0;
}

static void study_free(study *s) {
  for (int i = 0; i < s->nval; i++) nd_rollout_free(&s->val[i]);
  nds_record_free(&s->rec);
  if (s->d) mj_deleteData(s->d);
  nd_pool_free(s->pool);
  nds_model_free(&s->fitm);
  nds_model_free(&s->plan);
  nds_model_free(&s->world);
}

/* Record the goals g[0, n) with the true theta (planner seeds as the evaluation's) into
 * rs, appending them to path if not NULL. Sets s->val_success / val_time. */
static int record_truth(study *s, const nd_goal *g, int n, uint64_t kind, nd_rollout *rs,
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
    if (run_task(s, nd_theta_true, mix(s->o->seed, kind, (uint64_t)j, 0), &g[j], 1, j, &o, err,
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
static int truth_band(study *s, char *err, int errlen) {
  nds_fit_cfg fc;
  fit_cfg(s->o, s->o->mode, &fc);
  nds_fit *fit = nds_fit_create(&s->fitm, &fc, s->pool, err, errlen);
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

static int run_one(study *s, int di, int run, ep_row *rows, char *err, int errlen) {
  const opts *o = s->o;
  const double D = o->D[di];
  char dn[32], name[96], path[1200];
  dname(D, dn, sizeof(dn));
  nds_fit_cfg fc;
  fit_cfg(o, o->mode, &fc);
  /* Seeds from D's value, not its place in --d: "--d 1" repeats the D = 1 runs of the
   * default "--d 0.2,1.0" exactly. */
  uint64_t dkey;
  memcpy(&dkey, &D, sizeof(dkey));
  fc.seed = mix(o->seed, 4, dkey, (uint64_t)run);
  nd_rng rr;
  nd_rng_seed(&rr, o->seed, mix(0, 1, dkey, (uint64_t)run));
  nds_fit_paper_prior(nd_theta_true, D, fc.lower, &rr, fc.mu0, fc.sigma0);
  fc.mu0[ND_TH_MASS] = nd_theta_true[ND_TH_MASS];
  nds_fit *fit = nds_fit_create(&s->fitm, &fc, s->pool, err, errlen);
  if (!fit) return -1;

  snprintf(name, sizeof(name), "run_d%s_r%02d.csv", dn, run);
  path_in(path, sizeof(path), o->out, name);
  FILE *csv = fopen(path, "w");
  snprintf(name, sizeof(name), "buffer_d%s_r%02d.nbuf", dn, run);
  char bpath[1200];
  path_in(bpath, sizeof(bpath), o->out, name);
  unlink(bpath);
  nd_rfile_writer w = {.fd = -1};
  int rc = -1;
  if (!csv) {
    snprintf(err, errlen, "%.300s: %s", path, strerror(errno));
    goto done;
  }
  if (nd_rbuf_open(&w, bpath, NULL, err, errlen)) goto done;
  fputs(run_header, csv);

  double mean[ND_NTHETA], std[ND_NTHETA];
  nds_fit_dist(fit, mean, std);
  ep_row *r0 = row_at(rows, o, di, run, 0);
  if (evaluate(s, fit, mean, std, r0, err, errlen)) goto done;
  r0->fit_loss = r0->fit_s = r0->train_reached = r0->train_time = NAN;
  r0->train_steps = 0;
  csv_row(csv, 0, D, run, r0);
  fflush(csv);
  progress(s, D, run, 0, r0);

  for (int ep = 1; ep <= o->episodes; ep++) {
    ep_row *r = row_at(rows, o, di, run, ep);
    const nd_goal *g = &train_goals[(ep - 1) % NTRAIN];
    nds_episode_out eo;
    if (run_task(s, mean, mix(o->seed, 2, dkey ^ (uint64_t)run, (uint64_t)ep),
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
    double t0 = now_s();
    int frc = nds_fit_run(fit, rs, n, &fo, err, errlen);
    r->fit_s = now_s() - t0;
    nd_rbuf_free_all(rs, n);
    if (frc) goto done;
    s->fit_s += r->fit_s;
    s->fit_units_done += n;
    r->fit_loss = fo.loss_mean;
    nds_fit_dist(fit, mean, std);
    if (evaluate(s, fit, mean, std, r, err, errlen)) goto done;
    csv_row(csv, ep, D, run, r);
    fflush(csv);
    progress(s, D, run, ep, r);
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

static void write_config(const opts *o, int argc, char **argv) {
  char path[1200];
  path_in(path, sizeof(path), o->out, "config.txt");
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
static void print_figures(const opts *o, const study *s, ep_row *rows, int di, int nrun) {
  char sfx[32];
  snprintf(sfx, sizeof(sfx), "_d%g", o->D[di]);
  const int E = o->episodes, e2 = E >= 2 ? 2 : E;
  char e2s[16];
  snprintf(e2s, sizeof(e2s), "ep%d", e2);
  stats s2 = metric_stats(rows, o, di, nrun, e2, M_SLIDE);
  printf("sliding_err_pct_%s%s %.3f %%\n", e2s, sfx, s2.median);
  stats t0 = metric_stats(rows, o, di, nrun, 0, M_TORSION);
  stats tE = metric_stats(rows, o, di, nrun, E, M_TORSION);
  printf("torsional_err_drop_pct_last%s %.1f %%\n", sfx, 100 * (1 - tE.mean / t0.mean));
  stats r0 = metric_stats(rows, o, di, nrun, 0, M_ROLL);
  stats rE = metric_stats(rows, o, di, nrun, E, M_ROLL);
  printf("rolling_err_drop_pct_last%s %.1f %%\n", sfx, 100 * (1 - rE.mean / r0.mean));
  double worst = 0, worst_res = NAN;
  int within = 0, resolved = 0;
  for (int r = 0; r < nrun; r++) {
    const double L0 = row_at(rows, o, di, r, 0)->val_loss;
    double q = row_at(rows, o, di, r, e2)->val_loss / L0;
    if (!(q <= worst)) worst = q;
    if (L0 > s->band_hi) {
      resolved++;
      if (!(q <= worst_res)) worst_res = q;
    }
    within += row_at(rows, o, di, r, e2)->err_pct[0] < 5.0;
  }
  printf("val_loss_ratio_%s%s %.4g ratio\n", e2s, sfx, worst);
  printf("val_loss_ratio_%s_resolved%s %.4g ratio\n", e2s, sfx, worst_res);
  printf("runs_val_loss_resolved_ep0%s %d/%d runs\n", sfx, resolved, nrun);
  stats sl = metric_stats(rows, o, di, nrun, E, M_SUCCESS);
  printf("success_rate_last%s %.3f ratio\n", sfx, sl.mean);
  stats s0 = metric_stats(rows, o, di, nrun, 0, M_SUCCESS);
  printf("success_rate_ep0%s %.3f ratio\n", sfx, s0.mean);
  stats tl = metric_stats(rows, o, di, nrun, E, M_TIME);
  printf("mean_time_last%s %.3f s\n", sfx, tl.mean);
  printf("runs_sliding_within5pct_%s%s %d/%d runs\n", e2s, sfx, within, nrun);
  stats sE = metric_stats(rows, o, di, nrun, E, M_SLIDE);
  printf("sliding_err_pct_last%s %.3f %%\n", sfx, sE.median);
  double fsum = 0;
  for (int r = 0; r < nrun; r++)
    for (int ep = 1; ep <= E; ep++) fsum += row_at(rows, o, di, r, ep)->fit_s;
  printf("refit_s_mean%s %.2f s\n", sfx, fsum / (nrun * E));
}

static int study_run(const opts *o, int argc, char **argv) {
  char err[512] = "";
  study s;
  int status = 1;
  ep_row *rows = NULL;
  int nrun[MAX_D] = {0};
  if (study_init(&s, o, err, sizeof(err))) goto done;
  write_config(o, argc, argv);
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
  path_in(vpath, sizeof(vpath), o->out, "validation.nbuf");
  s.nval = 0;
  if (record_truth(&s, eval_goals, o->neval, 3, s.val, vpath, err, sizeof(err))) goto done;
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
      if (write_summary(o, rows, nrun, err, sizeof(err))) goto done;
    }
  }
  if (write_plots(o, nrun, err, sizeof(err))) fprintf(stderr, PROG ": warning: %s\n", err);
  err[0] = 0;

  printf("nudge-experiment: %s\n", o->out);
  printf("truth_success_rate %.3f ratio\n", s.val_success);
  printf("truth_mean_time %.3f s\n", s.val_time);
  printf("val_loss_band_min %.4g loss\n", s.band_lo);
  printf("val_loss_band_max %.4g loss\n", s.band_hi);
  for (int di = 0; di < o->nD; di++) print_figures(o, &s, rows, di, nrun[di]);
  printf("experiment_s %.1f s\n", now_s() - s.t0);
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  free(rows);
  study_free(&s);
  return status;
}

/* ---- the landscape ---- */

/* Curve shape on a grid x[0, n) holding the truth at x[it]. roughness = total variation /
 * (descent into the minimum + ascent out of it): 1 for a curve that falls to one minimum
 * and rises, more for every extra wiggle. monotone = fraction of grid steps that go the way
 * a curve with its one minimum at the truth goes (down before it, up after it). */
static void curve_shape(const double *x, const double *L, int n, int it, double *argmin,
                        double *rough, double *monotone, int *nmin) {
  int im = 0, good = 0;
  double tv = 0;
  for (int i = 0; i < n; i++) {
    if (L[i] < L[im]) im = i;
    if (i) {
      tv += fabs(L[i] - L[i - 1]);
      good += i <= it ? L[i] < L[i - 1] : L[i] > L[i - 1];
    }
  }
  *argmin = x[im];
  double need = (L[0] - L[im]) + (L[n - 1] - L[im]);
  *rough = need > 0 ? tv / need : INFINITY;
  *monotone = (double)good / (n - 1);
  *nmin = 0;
  for (int i = 0; i < n; i++) {
    int lo = i == 0 || L[i] < L[i - 1], hi = i == n - 1 || L[i] < L[i + 1];
    *nmin += lo && hi;
  }
}

/* A scripted push recorded in the world with the true theta (no planner): the sphere's
 * setpoint follows a smooth (quintic time-scaled) path for T s, then holds 0.3 s.
 * kind 0: straight through the box's centre along x, 20 cm (no rotation, the control);
 * kind 1, 2: the sphere pushes the long face near one end and follows a circle of 6.8 cm
 * around the box's centre, 2 rad counter-clockwise / clockwise: the box spins about its
 * centre, the motion torsional friction resists. */
static int scripted_push(study *s, int kind, nd_rollout *out, char *err, int errlen) {
  const double T = 4.0, hold = 0.3, dt = s->world.m->opt.timestep;
  const double r = 0.068, dphi = kind == 1 ? 2.0 : -2.0;
  const double phi0 = kind == 1 ? atan2(-0.055, 0.04) - 0.08 : atan2(-0.055, -0.04) + 0.08;
  double ee0[2];
  if (kind == 0) ee0[0] = -0.10, ee0[1] = 0.0;
  else ee0[0] = r * cos(phi0), ee0[1] = r * sin(phi0);
  nds_state st;
  nds_state_rest(&s->world, 0.0, 0.0, 0.0, ee0, &st);
  const nd_goal g = {.x = 0, .y = 0, .yaw = 0};
  if (nds_record_begin(&s->rec, &s->world, &st, 100 + kind, 0, &g, nd_theta_true, err, errlen) ||
      nds_state_set(&s->world, s->d, &st, err, errlen))
    return -1;
  nds_ctrl_cfg cc;
  nds_ctrl_cfg_default(&cc);
  nds_ctrl pid;
  nds_ctrl_reset(&pid);
  const int n = (int)lround((T + hold) / dt);
  for (int k = 0; k < n && k < s->rec.cap; k++) {
    double t = fmin(k * dt / T, 1.0);
    /* quintic s(t) = 10 t^3 - 15 t^4 + 6 t^5 and its time derivatives */
    double q = ((6 * t - 15) * t + 10) * t * t * t;
    double qd = k * dt < T ? 30 * t * t * (t - 1) * (t - 1) / T : 0;
    double qdd = k * dt < T ? 60 * t * (2 * t * t - 3 * t + 1) / (T * T) : 0;
    double sp[2][4] = {{0}};
    if (kind == 0) {
      sp[0][0] = ee0[0] + 0.2 * q, sp[0][1] = 0.2 * qd, sp[0][2] = 0.2 * qdd;
      sp[1][0] = 0;
    } else {
      double ph = phi0 + dphi * q, w = dphi * qd, al = dphi * qdd, c = cos(ph), sn = sin(ph);
      sp[0][0] = r * c, sp[1][0] = r * sn;
      sp[0][1] = -r * w * sn, sp[1][1] = r * w * c;
      sp[0][2] = -r * al * sn - r * w * w * c, sp[1][2] = r * al * c - r * w * w * sn;
    }
    const double pos[2] = {s->d->qpos[s->world.ee_qpos[0]], s->d->qpos[s->world.ee_qpos[1]]};
    const double vel[2] = {s->d->qvel[s->world.ee_dof[0]], s->d->qvel[s->world.ee_dof[1]]};
    double f[2];
    nds_ctrl_pid(&cc, &pid, (const double(*)[4])sp, pos, vel, dt, f);
    s->d->qfrc_applied[s->world.ee_dof[0]] = f[0];
    s->d->qfrc_applied[s->world.ee_dof[1]] = f[1];
    mj_step(s->world.m, s->d);
    nds_record_hook(&s->rec, &s->world, s->d, (const double(*)[4])sp, f);
  }
  if (nds_record_finish(&s->rec, ND_OUTCOME_TIMEOUT, err, errlen) ||
      nd_rollout_copy(out, &s->rec.r)) {
    if (!err[0]) snprintf(err, errlen, "out of memory");
    return -1;
  }
  return 0;
}

/* Rollout classes of the landscape: the planned training tasks, then the scripted ones. */
enum { NSCRIPT = 3, NLAND = NTRAIN + NSCRIPT };
static int land_class(int i) { return i < NTRAIN ? 0 : i == NTRAIN ? 1 : 2; }
static const char *land_cname[3] = {"planned", "straight", "spin"};

/* Grids in units of the truth, each holding it: sliding 0.5..1.5 in steps of 0.025,
 * torsional and rolling 0..3 in steps of 0.05 (0 as the fit's lower bound). */
enum { NG_MAX = 61 };
static const double land_hi[NFIT] = {1.5, 3.0, 3.0}, land_lo[NFIT] = {0.5, 0.0, 0.0};
static const int land_ng[NFIT] = {41, 61, 61};

/* The index of the truth in parameter p's landscape grid, and grid point g. */
static int land_it(int p) {
  return (int)lround((1.0 - land_lo[p]) / (land_hi[p] - land_lo[p]) * (land_ng[p] - 1));
}
static double land_x(int p, int g) {
  if (g == land_it(p)) return nd_theta_true[p];
  const double u = land_lo[p] + (land_hi[p] - land_lo[p]) * g / (land_ng[p] - 1);
  return fmax(1e-7, nd_theta_true[p] * u);
}

/* How pushing lifts the box, why re-anchoring puts back its full pose (nds_fit.c). MuJoCo's
 * soft contact lets a box that slides rise off the table (a sliding contact separates at a
 * rate that grows with its slip), so while pushed it hops on fewer than its four corners
 * and each landing's timing moves with theta. Each rollout is replayed once under the
 * true theta in the world (force replay from its start: bit for bit the recording),
 * counting the steps the sphere touches the box and, of those, the steps the box stands
 * on fewer than 3 table contacts, and its highest rise above its settled rest height. */
static void lift_replay(study *s, const nd_rollout *r, double z_rest, int *touch, int *lifted,
                        double *rise) {
  const nds_model *w = &s->world;
  nds_state st;
  char err[64];
  nds_replay_start_get(r, &st);
  *touch = *lifted = 0;
  *rise = 0;
  if (nds_state_set(w, s->d, &st, err, sizeof(err))) return;
  for (int k = 0; k < r->n; k++) {
    s->d->qfrc_applied[w->ee_dof[0]] = r->u[2 * k];
    s->d->qfrc_applied[w->ee_dof[1]] = r->u[2 * k + 1];
    mj_step(w->m, s->d);
    int nt, ne;
    nds_contacts(w, s->d, &nt, &ne);
    if (!ne) continue;
    (*touch)++;
    *lifted += nt < 3;
    *rise = fmax(*rise, s->d->qpos[w->obj_qpos + 2] - z_rest);
  }
}

/* The lift report: the rollouts by class, then a push with no sphere at all, F along x
 * at the box's centre for 0.3 s after 0.3 s of settling (the settled height is z_rest). */
static void lift_report(study *s, const nd_rollout *rs, int nr) {
  const nds_model *w = &s->world;
  mjData *d = s->d;
  nds_state st;
  char err[64];
  const double ee_far[2] = {-0.3, 0.0}, F = 8.0, dt = w->m->opt.timestep;
  nds_state_rest(w, 0.0, 0.0, 0.0, ee_far, &st);
  if (nds_state_set(w, d, &st, err, sizeof(err))) return;
  const int nset = (int)lround(0.3 / dt), npush = (int)lround(0.3 / dt);
  for (int k = 0; k < nset; k++) mj_step(w->m, d);
  const double z_rest = d->qpos[w->obj_qpos + 2];
  double *xf = d->xfrc_applied + 6 * w->obj_body;
  int lifted = 0;
  double rise = 0;
  for (int k = 0; k < npush; k++) {
    xf[0] = F;
    mj_step(w->m, d);
    int nt, ne;
    nds_contacts(w, d, &nt, &ne);
    lifted += nt < 3;
    rise = fmax(rise, d->qpos[w->obj_qpos + 2] - z_rest);
  }
  const double v = d->qvel[w->obj_dof];
  xf[0] = 0;  /* d is the study's world: leave no force behind */
  for (int c = 0; c < 3; c++) {
    int touch = 0, lift = 0, n = 0;
    double top = 0;
    for (int i = 0; i < nr; i++) {
      if (land_class(i) != c) continue;
      int t, l;
      double h;
      lift_replay(s, &rs[i], z_rest, &t, &l, &h);
      touch += t, lift += l, n++;
      top = fmax(top, h);
    }
    printf("lift %-8s %d rollouts: the sphere touches the box in %d steps; in %.0f%% of "
           "them the box stands on < 3 table contacts; it rises up to %.0f um above rest\n",
           land_cname[c], n, touch, touch ? 100.0 * lift / touch : 0.0, 1e6 * top);
  }
  printf("lift free-push  %.0f N along x at the box's centre for %.1f s, no sphere: < 3 table "
         "contacts in %.0f%% of the steps, rise up to %.0f um, speed %.2f m/s at the end\n",
         F, npush * dt, 100.0 * lifted / npush, 1e6 * rise, v);
  fflush(stdout);
}

static int landscape_run(const opts *o) {
  char err[512] = "";
  study s;
  int status = 1;
  nd_rollout rs[NLAND] = {{0}};
  int nr = 0;
  nds_fit *fits[2] = {NULL, NULL}, *rfit = NULL;
  FILE *f = NULL;
  double *Lb = NULL, *per = NULL;
  if (study_init(&s, o, err, sizeof(err))) goto done;
  char path[1200];
  path_in(path, sizeof(path), o->out, "landscape.nbuf");
  fprintf(stderr, PROG ": recording the %d training tasks with the true theta\n", NTRAIN);
  if (record_truth(&s, train_goals, NTRAIN, 5, rs, path, err, sizeof(err))) goto done;
  nr = NTRAIN;
  for (int k = 0; k < NSCRIPT; k++) {
    if (scripted_push(&s, k, &rs[nr], err, sizeof(err))) goto done;
    nr++;
  }
  for (int i = 0; i < nr; i++) {
    const double *e = nd_rollout_obj(&rs[i], rs[i].n - 1);
    fprintf(stderr, "  rollout %2d (%s): goal (%+.2f, %+.2f, %+.2f), %.2f s, object moved "
            "%.3f m, turned %+.3f rad\n", i, land_cname[land_class(i)], rs[i].goal[0],
            rs[i].goal[1], rs[i].goal[2], rs[i].n * rs[i].dt, hypot(e[0], e[1]),
            nd_quat_yaw(e + 3));
  }
  lift_report(&s, rs, nr);
  const int modes[2] = {NDS_REPLAY_FORCE, NDS_REPLAY_SETPOINT};
  for (int k = 0; k < 2; k++) {
    nds_fit_cfg fc;
    fit_cfg(o, modes[k], &fc);
    if (!(fits[k] = nds_fit_create(&s.fitm, &fc, s.pool, err, sizeof(err)))) goto done;
  }
  {
    /* The study's robust score (--robust, or nds_fit.h's scale), in the study's mode. */
    nds_fit_cfg fc;
    fit_cfg(o, o->mode, &fc);
    if (!(fc.robust > 0)) fc.robust = NDS_FIT_ROBUST_SCALE;
    if (!(rfit = nds_fit_create(&s.fitm, &fc, s.pool, err, sizeof(err)))) goto done;
  }
  path_in(path, sizeof(path), o->out, "landscape.csv");
  if (!(f = fopen(path, "w"))) {
    snprintf(err, sizeof(err), "%.300s: %s", path, strerror(errno));
    goto done;
  }
  fputs("mode,param,value,rollout,class,turn_rad,L,pos_o,pos_ee,rot_o,diverged\n", f);
  Lb = malloc(sizeof(double) * NG_MAX * 6);   /* L per grid point and class; then S */
  per = malloc(sizeof(double) * NG_MAX * 2);
  if (!Lb || !per) {
    snprintf(err, sizeof(err), "out of memory");
    goto done;
  }
  nds_replay_terms terms[NLAND];
  double x[NG_MAX];
  nds_fit_cfg wcfg;
  fit_cfg(o, o->mode, &wcfg);
  for (int p = 0; p < NFIT; p++) {
    const int NG = land_ng[p], it = land_it(p);
    for (int k = 0; k < 2; k++) {
      /* L of each class of rollouts. */
      for (int g = 0; g < NG; g++) {
        double th[ND_NTHETA];
        memcpy(th, nd_theta_true, sizeof(th));
        th[p] = x[g] = land_x(p, g);
        double L;
        if (nds_fit_loss(fits[k], th, rs, nr, &L, terms, err, sizeof(err))) goto done;
        Lb[3 * g] = Lb[3 * g + 1] = Lb[3 * g + 2] = 0;
        for (int i = 0; i < nr; i++) {
          double Li = nds_replay_loss(&terms[i], wcfg.k1, wcfg.k2);
          const double turn = nd_quat_yaw(nd_rollout_obj(&rs[i], rs[i].n - 1) + 3);
          fprintf(f, "%s,%s,%.9g,%d,%s,%.4f,%.9g,%.9g,%.9g,%.9g,%d\n",
                  nds_replay_mode_name(modes[k]), pname[p], x[g], i, land_cname[land_class(i)],
                  turn, Li, terms[i].pos_o, terms[i].pos_ee, terms[i].rot_o, terms[i].diverged);
          Lb[3 * g + land_class(i)] += Li;
        }
      }
      for (int q = 0; q < 3; q++) {
        for (int g = 0; g < NG; g++) per[g] = Lb[3 * g + q];
        double am, rough, mono;
        int nmin;
        curve_shape(x, per, NG, it, &am, &rough, &mono, &nmin);
        /* Depth 20% and 50% either side of the truth (nearest grid points), and the plateau
         * a 0.1% offset already reaches (the chaos floor, below). */
        int d20 = (int)lround(0.2 / (land_hi[p] - land_lo[p]) * (NG - 1));
        int d50 = (int)lround(0.5 / (land_hi[p] - land_lo[p]) * (NG - 1));
        printf("landscape %-8s %-7s %-8s argmin %.4g (truth %.4g), monotone %.2f, roughness "
               "%.2f, local minima %d, L(-50%%) %.2e, L(-20%%) %.2e, L(+20%%) %.2e, "
               "L(+50%%) %.2e\n",
               nds_replay_mode_name(modes[k]), pname[p], land_cname[q], am, nd_theta_true[p],
               mono, rough, nmin, per[it - d50], per[it - d20], per[it + d20], per[it + d50]);
      }
    }
  }
  /* The robust score along sliding friction beside L, from the same replays: how each
   * ranks candidates near the truth (nds_fit.c). Per class: both curves' shape, and both at
   * -10, -5, -2.5, +2.5, +5 and +10 % of the truth. */
  {
    const int p = ND_TH_SLIDE, NG = land_ng[p], it = land_it(p);
    double *Sb = Lb + 3 * NG_MAX, *Sper = per + NG_MAX;
    for (int g = 0; g < NG; g++) {
      double th[ND_NTHETA], S;
      memcpy(th, nd_theta_true, sizeof(th));
      th[p] = x[g] = land_x(p, g);
      if (nds_fit_score(rfit, th, rs, nr, &S, terms, err, sizeof(err))) goto done;
      for (int q = 0; q < 3; q++) Lb[3 * g + q] = Sb[3 * g + q] = 0;
      for (int i = 0; i < nr; i++) {
        Lb[3 * g + land_class(i)] += nds_replay_loss(&terms[i], wcfg.k1, wcfg.k2);
        Sb[3 * g + land_class(i)] += terms[i].robust;
      }
    }
    static const int off[6] = {-4, -2, -1, 1, 2, 4};
    for (int q = 0; q < 3; q++) {
      double am[2], rough[2], mono[2];
      int nmin[2];
      for (int g = 0; g < NG; g++) per[g] = Lb[3 * g + q], Sper[g] = Sb[3 * g + q];
      curve_shape(x, per, NG, it, &am[0], &rough[0], &mono[0], &nmin[0]);
      curve_shape(x, Sper, NG, it, &am[1], &rough[1], &mono[1], &nmin[1]);
      printf("robust-vs-L %-8s slide %-8s L: argmin %.4g, monotone %.2f, local minima %d; "
             "S: argmin %.4g, monotone %.2f, local minima %d; -10..+10%%: L",
             nds_replay_mode_name(o->mode), land_cname[q], am[0], mono[0], nmin[0], am[1],
             mono[1], nmin[1]);
      for (int i = 0; i < 6; i++) printf(" %.2e", per[it + off[i]]);
      printf(", S");
      for (int i = 0; i < 6; i++) printf(" %.3f", Sper[it + off[i]]);
      printf("\n");
    }
    fflush(stdout);
  }
  /* How fast L leaves 0 around the truth: relative offsets from 1e-9 up. An L that jumps
   * to its plateau at tiny offsets is chaos in the contacts, not information. */
  {
    static const double rel[] = {1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 0.05, 0.2, 0.5};
    enum { NREL = sizeof(rel) / sizeof(rel[0]) };
    for (int p = 0; p < NFIT; p++) {
      for (int k = 0; k < 2; k++) {
        for (int c = 0; c < 3; c++) {
          printf("near-truth %-8s %-7s %-8s", nds_replay_mode_name(modes[k]), pname[p],
                 land_cname[c]);
          for (int q = 0; q < NREL; q++) {
            double Lpm = 0;
            for (int sg = 0; sg < 2; sg++) {
              double th[ND_NTHETA];
              memcpy(th, nd_theta_true, sizeof(th));
              th[p] *= 1 + (sg ? -rel[q] : rel[q]);
              double L;
              if (nds_fit_loss(fits[k], th, rs, nr, &L, terms, err, sizeof(err))) goto done;
              for (int i = 0; i < nr; i++)
                if (land_class(i) == c) Lpm += 0.5 * nds_replay_loss(&terms[i], wcfg.k1, wcfg.k2);
            }
            printf(" %g:%.1e", rel[q], Lpm);
          }
          printf("\n");
        }
      }
    }
  }
  /* What the refit makes of it: torsional friction alone fitted (the others held at the
   * truth), D = 1 prior, 10 refits on the planned or on the spin rollouts, 3 seeds. */
  for (int c = 0; c < 3; c += 2) {
    const nd_rollout *sub = c == 0 ? rs : rs + NTRAIN + 1;
    const int nsub = c == 0 ? NTRAIN : 2;
    for (int k = 0; k < 2; k++) {
      double e0 = 0, e1 = 0;
      printf("torsion-fit %-8s %-8s", nds_replay_mode_name(modes[k]), land_cname[c]);
      for (int seed = 1; seed <= 3; seed++) {
        nds_fit_cfg fc;
        fit_cfg(o, modes[k], &fc);
        fc.fit[ND_TH_SLIDE] = fc.fit[ND_TH_ROLL] = 0;
        fc.seed = (uint64_t)seed;
        nd_rng rr;
        nd_rng_seed(&rr, (uint64_t)seed, 77);
        double mu0[ND_NTHETA], sg0[ND_NTHETA];
        nds_fit_paper_prior(nd_theta_true, 1.0, fc.lower, &rr, mu0, sg0);
        memcpy(fc.mu0, nd_theta_true, sizeof(fc.mu0));
        fc.mu0[ND_TH_TORSION] = mu0[ND_TH_TORSION];
        fc.sigma0[ND_TH_TORSION] = sg0[ND_TH_TORSION];
        nds_fit *ft = nds_fit_create(&s.fitm, &fc, s.pool, err, sizeof(err));
        if (!ft) goto done;
        nds_fit_out fo;
        for (int e = 0; e < 10; e++)
          if (nds_fit_run(ft, sub, nsub, &fo, err, sizeof(err))) {
            nds_fit_free(ft);
            goto done;
          }
        nds_fit_free(ft);
        double a = 100 * fabs(fc.mu0[1] / nd_theta_true[1] - 1),
               b = 100 * fabs(fo.mean[1] / nd_theta_true[1] - 1);
        printf("  seed %d: %.1f%% -> %.1f%%", seed, a, b);
        e0 += a / 3, e1 += b / 3;
      }
      printf("  | mean %.1f%% -> %.1f%%\n", e0, e1);
      fflush(stdout);
    }
  }
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  if (f) fclose(f);
  free(Lb);
  free(per);
  for (int k = 0; k < 2; k++) nds_fit_free(fits[k]);
  nds_fit_free(rfit);
  for (int i = 0; i < nr; i++) nd_rollout_free(&rs[i]);
  study_free(&s);
  return status;
}

int main(int argc, char **argv) {
  opts o;
  int rc = parse_args(argc, argv, &o);
  if (rc) return rc == 1 ? 0 : rc;
  /* The results (CSVs, gnuplot's figures, the buffers) must not be world-writable, even
   * under umask 0. */
  nd_rfile_umask_no_world_write();
  char err[512];
  if (mkdir_p(o.out, err, sizeof(err))) {
    fprintf(stderr, PROG ": %s\n", err);
    return 1;
  }
  if (o.landscape) return landscape_run(&o);
  char path[1200];
  path_in(path, sizeof(path), o.out, "summary.csv");
  struct stat st;
  if (!o.force && stat(path, &st) == 0 && st.st_size > 0) {
    fprintf(stderr, PROG ": %s holds results (%s); pass --force to overwrite them\n", o.out,
            path);
    return 1;
  }
  return study_run(&o, argc, argv);
}
