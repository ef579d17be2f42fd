/* nudge-experiment: the paper's simulation study (sec. IV-A) in one process on the same sim
 * code as the live system (experiment.h says what each file does). */
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "experiment.h"
#include "nd_opt.h"
#include "nd_parse.h"
#include "nd_rfile.h"

static const char *const replay_words[] = {"force", "setpoint", NULL};
static const int replay_modes[] = {NDS_REPLAY_FORCE, NDS_REPLAY_SETPOINT};

/* --d LIST: distinct prior widths, comma-separated. */
static int parse_dlist(const char *s, const char *what, void *dst, char *err, int errlen) {
  exp_opts *o = dst;
  const char *p = s;
  o->nD = 0;
  for (;;) {
    const size_t n = strcspn(p, ",");
    char tok[64];
    if (n == 0 || n >= sizeof tok || o->nD == MAX_D) {
      snprintf(err, errlen, "%s: expected up to %d comma-separated numbers, got '%s'", what,
               MAX_D, s);
      return -1;
    }
    memcpy(tok, p, n);
    tok[n] = '\0';
    if (nd_parse_double(tok, what, 1e-3, 5.0, &o->D[o->nD], err, errlen)) return -1;
    for (int i = 0; i < o->nD; i++)
      if (o->D[i] == o->D[o->nD]) {
        snprintf(err, errlen, "%s: %g appears twice", what, o->D[i]);
        return -1;
      }
    o->nD++;
    if (!p[n]) return 0;
    p += n + 1;
  }
}

static const char *epilog =
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
    "  runs_sliding_within5pct_ep2  runs whose sliding error is below 5% after episode 2\n"
    "and once: val_loss_band_min/max, the validation loss of 16 models whose sliding\n"
    "friction is within +-1% of the truth (the rest exact): how low the validation loss\n"
    "gets for models that close.\n";

int main(int argc, char **argv) {
  static exp_opts o;
  int replay = 0;
  nds_fit_cfg fd; /* the fit's defaults */
  nds_fit_cfg_default(&fd);
  o.threads = nds_setup_cores(64);
  o.seed = 1;
  o.plan_dt = 0.005;
  o.window = fd.replay.window;
  o.step_std = fd.step_std;
  o.step_gate = fd.step_gate;
  o.rel_floor = fd.rel_floor;
  o.k2 = fd.k2;
  o.robust = fd.robust;
  o.D[0] = 0.2, o.D[1] = 1.0, o.nD = 2;
  o.runs = o.episodes = 10, o.pop = 128, o.iters = 4, o.tau = 5.0, o.neval = MAX_EVAL;
  nd_opt opts[] = {
      {"out", ND_OPT_STRING, &o.out, .arg = "DIR",
       .help = "results directory (created); refuses one holding a non-empty summary.csv "
               "unless --force"},
      {"force", ND_OPT_FLAG, &o.force, .help = "overwrite the results in DIR"},
      {"runs", ND_OPT_INT, &o.runs, 1, 1000, .arg = "R",
       .help = "runs per D, independent initial means (the paper's 10; 3 with --quick)"},
      {"episodes", ND_OPT_INT, &o.episodes, 1, 1000, .arg = "E",
       .help = "training episodes per run (4 with --quick)"},
      {"d", ND_OPT_CUSTOM, &o, .parse = parse_dlist, .arg = "LIST", .def = "0.2,1",
       .help = "prior widths D, comma-separated, each 0.001..5"},
      {"seed", ND_OPT_U64, &o.seed, .help = "master seed"},
      {"threads", ND_OPT_INT, &o.threads, 1, 64, .def = "online cores",
       .help = "workers for planning and refits; results do not depend on it"},
      {"pop", ND_OPT_INT, &o.pop, 4, 100000,
       .help = "planner population (the paper's 128; 32 with --quick)"},
      {"iters", ND_OPT_INT, &o.iters, 1, 100, .help = "planner iterations (2 with --quick)"},
      {"tau", ND_OPT_DOUBLE, &o.tau, 0.1, 600, .arg = "S",
       .help = "task time limit, s (3 with --quick)"},
      {"eval-tasks", ND_OPT_INT, &o.neval, 1, MAX_EVAL, .arg = "K",
       .help = "evaluation tasks (the demo's goals)"},
      {"replay", ND_OPT_CHOICE, &replay, .choices = replay_words, .arg = "MODE",
       .help = "refit replay: force or setpoint (below)"},
      {"window", ND_OPT_DOUBLE, &o.window, 0, 600, .arg = "S",
       .help = "refit replay re-anchored on the observed pose every S s (0: one shot from "
               "the initial state, the paper's; sim/nds_replay.h)"},
      {"step-std", ND_OPT_DOUBLE, &o.step_std, 0, 100, .arg = "K",
       .help = "refit CEM: the std at least K times the mean's last step (0: the paper's "
               "plain CEM; doc/decisions.md)"},
      {"step-gate", ND_OPT_DOUBLE, &o.step_gate, 0, 100, .arg = "G",
       .help = "refit CEM: --step-std only for steps of at least G sampling stds (0: every "
               "step)"},
      {"rel-floor", ND_OPT_DOUBLE, &o.rel_floor, 0, 0.99, .arg = "R",
       .help = "refit CEM: each refit starts with std >= R |mean| (0: off)"},
      {"rot-weight", ND_OPT_DOUBLE, &o.k2, 0, 1, .arg = "K2",
       .help = "refit loss: weight of the object's yaw term, m^2/rad (0: positions only)"},
      {"robust", ND_OPT_DOUBLE, &o.robust, 0, 1, .arg = "S",
       .help = "refit CEM ranks candidates by each window's L through a Cauchy loss of "
               "scale S, m^2 (0: by L, the paper's). Reported losses are L either way"},
      {"plan-dt", ND_OPT_DOUBLE, &o.plan_dt, 1e-3, 0.02, .arg = "S",
       .help = "planning model timestep, s (world and refit: 0.001)"},
      {"quick", ND_OPT_FLAG, &o.quick,
       .help = "a preset for a first look, under 10 min on 2 cores: --runs 3 --episodes 4 "
               "--pop 32 --iters 2 --tau 3 (explicit options win)"},
      {"draws", ND_OPT_FLAG, &o.draws,
       .help = "print each run's initial theta as 'D run S,T,R,M' lines and exit (no --out): "
               "the live study, nudge-study, starts its runs from the same draws"},
      {"landscape", ND_OPT_FLAG, &o.landscape,
       .help = "instead of the study: record the 10 training tasks with the true theta and "
               "write DIR/landscape.csv, the loss along each friction for both replay modes "
               "(re-anchored as --window says), with a summary of each curve, and the robust "
               "score (--robust, else 1e-9) beside L along sliding friction; first, `lift` "
               "lines: how often the pushed box stands on fewer than 3 table contacts"},
  };
  nd_opt_spec spec = {PROG, "--out DIR [options]",
                      "The paper's simulation study (sec. IV-A): incremental refits of the "
                      "three frictions from planned pushing tasks, evaluated after every "
                      "episode. Seeded and reproducible.",
                      epilog, opts, sizeof(opts) / sizeof(opts[0])};
  const int rc = nd_opt_parse(&spec, argc, argv);
  if (rc != ND_OPT_RUN) return rc;
  o.mode = replay_modes[replay];
  if (o.draws) return exp_draws_print(&o);
  if (!o.out) return nd_opt_fail(&spec, "--out DIR is required");
  if (o.quick) { /* the preset, explicit values over it */
    if (!nd_opt_find(&spec, "runs")->given) o.runs = 3;
    if (!nd_opt_find(&spec, "episodes")->given) o.episodes = 4;
    if (!nd_opt_find(&spec, "pop")->given) o.pop = 32;
    if (!nd_opt_find(&spec, "iters")->given) o.iters = 2;
    if (!nd_opt_find(&spec, "tau")->given) o.tau = 3.0;
  }

  /* The results (CSVs, gnuplot's figures, the buffers) must not be world-writable, even
   * under umask 0. */
  nd_rfile_umask_no_world_write();
  char err[512];
  if (exp_mkdir(o.out, err, sizeof(err))) {
    fprintf(stderr, PROG ": %s\n", err);
    return 1;
  }
  if (o.landscape) return exp_landscape_run(&o);
  char path[1200];
  exp_path(path, sizeof(path), o.out, "summary.csv");
  struct stat st;
  if (!o.force && stat(path, &st) == 0 && st.st_size > 0) {
    fprintf(stderr, PROG ": %s holds results (%s); pass --force to overwrite them\n", o.out,
            path);
    return 1;
  }
  return exp_study_run(&o, argc, argv);
}
