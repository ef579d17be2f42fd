/* options: nudge-adapter's command line, and the fit's configuration from it (adapter.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "adapter.h"
#include "nd_opt.h"

static const char *const mode_words[] = {"force", "velocity", "setpoint", NULL};

static int parse_fit(const char *v, const char *what, void *dst, char *err, int errlen) {
  return nd_theta_parse_mask(v, what, dst, err, errlen);
}

/* A parameter list, or none. */
static int parse_list(const char *v, const char *what, void *dst, char *err, int errlen) {
  if (!strcmp(v, "none")) {
    *(unsigned *)dst = 0;
    return 0;
  }
  return nd_theta_parse_mask(v, what, dst, err, errlen);
}

int adapter_options(int argc, char **argv, adapter_opts *o, nds_fit_cfg *fc) {
  const char *history = NULL;
  nds_fit_cfg_default(fc);
  o->threads = ndp_default_threads();
  o->fit = 1u << ND_TH_SLIDE | 1u << ND_TH_TORSION | 1u << ND_TH_ROLL;
  o->scan = 1u << ND_TH_TORSION;
  memcpy(o->theta, nd_theta_true, sizeof(o->theta));
  memcpy(o->ref, nd_theta_true, sizeof(o->ref));
  o->D = 1.0, o->seed = 1, o->nice = 10, o->scan_points = 9;
  /* The recorded step: a coarser replay model biases the fit, whatever it saves in time
   * (doc/decisions.md#live-bias). */
  o->replay_dt = 0.001;
  o->replay_mode = fc->replay.mode;
  o->replay_window = NDS_FIT_WINDOW_MOCAP;
  o->replay_skip = fc->replay.skip_clear;
  for (int i = 0; i < ND_NTHETA; i++) o->score[i] = NAN;
  nd_opt opts[] = {
      {"buffer", ND_OPT_STRING, &o->buffer, .arg = "FILE",
       .help = "replay buffer to watch (need not exist yet)"},
      {"history", ND_OPT_STRING, &history, .arg = "FILE", .def = "<buffer>.history",
       .help = "parameter history"},
      {"fit", ND_OPT_CUSTOM, &o->fit, .parse = parse_fit, .arg = "LIST", .def = "slide,torsion,roll",
       .help = "fitted parameters, comma-separated from slide, torsion, roll, mass, box_scale, "
               "com_x, com_y; the others are held at --theta"},
      {"log-fit", ND_OPT_CUSTOM, &o->logfit, .parse = parse_list, .arg = "LIST", .def = "none",
       .help = "fitted parameters searched as ln theta, with the paper's prior std taken of "
               "ln theta, ln((r + D r) / max(1e-7, r - D r)) / 16: for a prior that spans "
               "decades, as torsional friction started at 1, and kept at most r + D r, where the "
               "loss is flat beyond; held parameters ignore it (doc/decisions.md#log-fit, "
               "#log-upper)"},
      {"scan", ND_OPT_CUSTOM, &o->scan, .parse = parse_list, .arg = "LIST", .def = "torsion",
       .help = "fitted parameters each refit first tries at --scan-points points spread "
               "over the prior's range, max(1e-7, r - D r) to r + D r (geometrically with "
               "--log-fit), the rest held at the mean; the best moves the mean there if it "
               "beats it, for a loss too flat away from the truth for CEM's local steps "
               "(doc/decisions.md#scan); held parameters ignore it; none: off"},
      {"scan-points", ND_OPT_INT, &o->scan_points, 2, NDS_FIT_MAX_SCAN, .arg = "K",
       .help = "points of --scan per parameter, each one replay of the buffer"},
      {"theta", ND_OPT_THETA, o->theta, .def = "the simulation's ground truth",
       .help = "prior mean: sliding, torsional, rolling friction, sphere mass in kg, and "
               "optionally the box's mass scale and centre-of-mass shift x, y in m from the "
               "model's (default 1, 0, 0; give the planner's --theta to start the loop from a "
               "wrong model)"},
      {"prior-d", ND_OPT_DOUBLE, &o->D, 0.01, 10.0, .arg = "D",
       .help = "prior std per parameter (r + D r - max(1e-7, r - D r)) / 16, the paper's "
               "formula, with r the nominal theta of --prior-ref; for a centre-of-mass shift "
               "2 D s / 16 with s = 0.02 m"},
      {"prior-ref", ND_OPT_THETA, o->ref, .def = "the simulation's ground truth",
       .help = "nominal theta that sizes the prior std; not --theta: a wrong mean must not "
               "also shrink the std (0.3 instead of 1 would give the truth a 19-std distance "
               "instead of 5.6)"},
      {"threads", ND_OPT_INT, &o->threads, 1, 256,
       .def = "one per core", .help = "replay workers"},
      {"nice", ND_OPT_INT, &o->nice, 0, 19,
       .help = "scheduling niceness of the whole process: on a small machine refits must not "
               "slow the planner"},
      {"replay-dt", ND_OPT_DOUBLE, &o->replay_dt, 1e-4, 0.01, .arg = "S",
       .help = "model timestep of the replays, a whole multiple of the recorded dt"},
      {"replay-mode", ND_OPT_CHOICE, &o->replay_mode, .choices = mode_words, .arg = "MODE",
       .help = "force, velocity or setpoint: how rollouts are replayed (sim/nds_replay.h)"},
      {"replay-window", ND_OPT_DOUBLE, &o->replay_window, 0, 60, .arg = "S",
       .help = "re-anchor each replay on the observed pose every S s (for poses interpolated "
               "from 240 Hz MOCAP; 0.005 for poses observed at every step, as the study's; 0: "
               "one shot, the paper's)"},
      {"replay-skip", ND_OPT_DOUBLE, &o->replay_skip, 0, 1, .arg = "M",
       .help = "with velocity replay and a window: windows whose recorded sphere keeps M m "
               "from the box, the box at rest, are scored without stepping the model; they "
               "cannot tell theta (0: every window stepped)"},
      {"anchor-fit", ND_OPT_DOUBLE, &o->anchor_fit, 0, 1, .arg = "S",
       .help = "re-anchor the object on a straight-line fit of its observations within S s "
               "(of the fits around, before and after the anchor the closest), which averages "
               "motion capture's noise out of the anchors' rates (0: on the observation and a "
               "one-step difference, exact for noiseless records)"},
      {"replay-phases", ND_OPT_INT, &fc->phases, 1, NDS_FIT_MAX_PHASES, .arg = "P",
       .help = "replay each rollout P times, its anchors shifted by the window / P each "
               "time, and score the mean: the contact chaos each set of anchors sets off "
               "averages out of the loss, at P times the replays (needs a --replay-window; "
               "not with --robust or --lm-iters)"},
      {"robust", ND_OPT_DOUBLE, &o->robust, 0, 1, .arg = "S",
       .help = "rank candidates by the replay windows' robust score of scale S m^2 (0: by L, "
               "the paper's)"},
      {"max-rollouts", ND_OPT_INT, &o->max_rollouts, 0, 1000000, .arg = "K",
       .help = "refit on the buffer's newest K rollouts and keep only those in memory, so "
               "that a refit's time and the adapter's memory stay bounded on a buffer a robot "
               "adds to for days (0: all of them, the paper's)"},
      {"score", ND_OPT_THETA, o->score, .def = "off",
       .help = "do not watch: replay every rollout of the buffer once at this theta with the "
               "replay options above, print its loss L and L's terms summed over the rollouts "
               "as 'name value unit' lines and exit (a validation loss on held-out rollouts, "
               "as nudge-study uses it)"},
      {"offline", ND_OPT_FLAG, &o->offline,
       .help = "do not watch: refit as the watching adapter would have while the buffer grew "
               "one rollout at a time (on its first 1, 2, ... rollouts, or the newest "
               "--max-rollouts), each refit warm-started from the last; print each refit's "
               "line, then the last one's loss and theta as 'name value unit' lines, and exit. "
               "No history, no LCM: a recorded buffer refitted with other options, as "
               "doc/study.md#refit does a study's"},
      {"shift-restart", ND_OPT_DOUBLE, &fc->shift_floor, 0, 16, .arg = "K",
       .help = "each refit starts the box's centre-of-mass shifts' std at K prior stds or "
               "more, so that a refit warm-started from a narrowed distribution can still "
               "move them (0: off; the std never falls below 0.25 prior stds anyway)"},
      {"pop", ND_OPT_INT, &fc->pop, 2, 4096, .arg = "Q",
       .help = "CEM population Q (the paper's 32)"},
      {"iters", ND_OPT_INT, &fc->iters, 1, NDS_FIT_MAX_ITERS, .arg = "C",
       .help = "CEM iterations C (the paper's 2)"},
      {"lm-iters", ND_OPT_INT, &fc->lm_iters, 0, 50, .arg = "N",
       .help = "Levenberg-Marquardt iterations on the replays' residuals after CEM, from its "
               "mean (0: off); --pop 4 --iters 1 --lm-iters 3 needs under half the replays "
               "of the default on nudge-bench's records (refit_replays_lm) but fitted worse "
               "live (doc/decisions.md#lm-step); PARAMS' std stays CEM's"},
      {"seed", ND_OPT_U64, &o->seed, .help = "CEM seed (a restart adds the history's version)"},
      {"lcm-url", ND_OPT_STRING, &o->url, .arg = "URL", .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL,
       .help = "LCM URL"},
  };
  nd_opt_spec spec = {PROG, "--buffer FILE [options]",
                      "Incremental adaptation: watches the replay buffer FILE (appended to by "
                      "nudge-tasks --record); whenever it holds rollouts the last fit did not "
                      "use, refits theta with CEM on all of them (or the newest "
                      "--max-rollouts; Q 32, C 2, elite fraction 0.2, unless --pop, --iters), "
                      "publishes PARAMS (mean, std, loss, buffer size, version) and appends "
                      "the fit to the parameter history. PARAMS is republished at 1 Hz. "
                      "A restarted adapter goes on from its history: version numbers and the "
                      "CEM distribution continue.",
                      "stdout: one line per refit (--score: its figures). Exit status: 0 after "
                      "SIGINT/SIGTERM (--score: scored; --offline: refitted), 1 on a runtime "
                      "failure\n(history locked by another adapter, unreadable), 2 on bad "
                      "arguments.\n", opts, sizeof(opts) / sizeof(opts[0])};
  int rc = nd_opt_parse(&spec, argc, argv);
  if (rc != ND_OPT_RUN) return rc;
  if (!o->buffer) return nd_opt_fail(&spec, "--buffer FILE is required");
  if (o->offline && !isnan(o->score[0]))
    return nd_opt_fail(&spec, "--offline and --score: one or the other");
  const int n = history ? snprintf(o->history, sizeof(o->history), "%s", history)
                        : snprintf(o->history, sizeof(o->history), "%s.history", o->buffer);
  if (n < 0 || n >= (int)sizeof(o->history) || strlen(o->buffer) >= ND_RFILE_PATH_MAX)
    return nd_opt_fail(&spec, "--buffer / --history: path too long");
  if (fc->phases > 1 && !(o->replay_window > 0 && o->robust == 0 && fc->lm_iters == 0))
    return nd_opt_fail(&spec, "--replay-phases %d needs --replay-window above 0 and neither "
                       "--robust nor --lm-iters", fc->phases);
  /* The box's centre of mass is fitted within the model's box (the adapter's model is the
   * default scene, main.c), where the planner's model, built alike, takes it too. */
  nds_scene_cfg box;
  nds_scene_cfg_default(&box);
  for (int k = 0; k < 2; k++)
    fc->upper[ND_TH_COM_X + k] = fmin(fc->upper[ND_TH_COM_X + k], box.obj_half[k]);
  for (int i = 0; i < ND_NTHETA; i++) {
    /* The paper's width vanishes for a nominal value of 0 (a shift's is not the paper's). */
    if ((o->fit >> i & 1) && !nd_theta_signed(i) && !(o->ref[i] > 0.0))
      return nd_opt_fail(&spec, "--prior-ref: %s is fitted, so its nominal value must be > 0",
                         nd_theta_key[i]);
    /* The paper sizes the std from the true theta and draws the mean around it; here the
     * mean is given (--theta) and the nominal theta stands in for the truth. */
    const double r = o->ref[i], D = o->D;
    double lo, hi;
    nds_fit_prior_range(r, D, fc->lower, i, &lo, &hi);
    fc->fit[i] = o->fit >> i & 1;
    fc->mu0[i] = o->theta[i];
    fc->sigma0[i] = nds_fit_prior_std(r, D, fc->lower, i);
    if ((o->scan >> i & 1) && fc->fit[i]) {
      fc->scan[i] = o->scan_points;
      fc->scan_lo[i] = fmax(nds_fit_floor(fc, i), lo);
      fc->scan_hi[i] = fmin(fc->upper[i], hi);
    }
    if ((o->logfit >> i & 1) && fc->fit[i]) {
      /* nds_fit takes a log parameter's std as theta times the std of ln theta. */
      fc->logfit[i] = 1;
      fc->sigma0[i] = log(hi / lo) / 16 * fmax(fc->lower, o->theta[i]);
      /* Searched within the prior's range: where the prior spans decades its top is
       * already where the parameter stops mattering (torsional friction 1 lets no box
       * turn), and the loss is flat beyond, which a log search would walk along for
       * decades (doc/decisions.md#log-upper). */
      fc->upper[i] = fmax(hi, o->theta[i]);
    }
  }
  fc->replay.mode = o->replay_mode;
  fc->replay.window = o->replay_window;
  fc->replay.smooth = o->anchor_fit;
  fc->replay.skip_clear = o->replay_skip;
  fc->robust = o->robust;
  return ND_OPT_RUN;
}

