/* nudge-bench: throughput and latency figures of the planning stack.
 *
 * Prints a human-readable report, then one `name value unit` line per figure. Figures are
 * measured in one run so ratios compare like with like; latencies are medians and p90s
 * over repeated plans. Not a test: nothing here asserts. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "nd_opt.h"
#include "nd_stats.h"
#include "nd_snap.h"
#include "nds_fit.h"
#include "nds_planner.h"
#include "nds_setup.h"

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* The start of a push: object at the origin, sphere 8 cm behind it, setpoint at the sphere. */
static void push_start(const nds_model *nm, nds_state *s, double sp[2][4]) {
  const double ee[2] = {-0.08, 0.0};
  nds_state_rest(nm, 0.0, 0.0, 0.0, ee, s);
  memset(sp, 0, 8 * sizeof(double));
  sp[0][0] = ee[0];
  sp[1][0] = ee[1];
}

/* A family of pushing keypoint sequences through the object, varied by i. */
static void push_keys(int i, double keys[8]) {
  double ang = 0.3 * sin(1.7 * i), reach = 0.08 + 0.04 * (i % 5) / 4.0;
  keys[0] = 0.02 * cos(ang), keys[1] = 0.02 * sin(ang) + 0.01 * (i % 3 - 1);
  keys[2] = 0.3 * cos(ang), keys[3] = 0.3 * sin(ang);
  keys[4] = keys[0] + reach * cos(ang), keys[5] = keys[1] + reach * sin(ang);
  keys[6] = keys[7] = 0.0;
}

/* A recorded 5 s push for the refit figure: the 1 ms world's tracking controller drives
 * the sphere along 8 min-snap segments of 0.6 s from behind the box at angle 0.6 i, through
 * it at 5 cm/s with a slight weave, then holds for 0.2 s; forces and observations are
 * recorded as the tasks process records them. Returns 0, or -1 out of memory. */
static int record_push5(const nds_model *w, mjData *d, int i, nd_rollout *r) {
  double a = 0.6 * i, c = cos(a), s = sin(a), lat = 0.008 * (i % 3 - 1);
  const double ee0[2] = {-0.09 * c - lat * s, -0.09 * s + lat * c};
  nds_state s0;
  nds_state_rest(w, 0.0, 0.0, 0.2 * i, ee0, &s0);
  const int M = 8;
  const double T = 0.6, dt = w->m->opt.timestep;
  const int n = (int)lround((M * T + 0.2) / dt);
  memset(r, 0, sizeof(*r));
  if (nd_rollout_alloc(r, n)) return -1;
  r->dt = dt, r->control = ND_CTRL_FORCE, r->outcome = ND_OUTCOME_TIMEOUT;
  nds_replay_start_put(r, &s0);
  char err[128];
  nds_state_set(w, d, &s0, err, sizeof(err));
  nd_snap_seg seg[8];
  double sp[2][4] = {{ee0[0], 0, 0, 0}, {ee0[1], 0, 0, 0}};
  for (int j = 0; j < M; j++) {
    double dist = 0.04 + 0.03 * j, bend = 0.01 * sin(0.8 * j), vs = j < M - 1 ? 0.05 : 0.0;
    const double p1[2] = {ee0[0] + c * dist - s * bend, ee0[1] + s * dist + c * bend};
    const double v1[2] = {vs * c, vs * s};
    nd_snap_seg_make(&seg[j], (const double(*)[4])sp, p1, v1, T);
    nd_snap_seg_eval(&seg[j], T, sp);
  }
  nds_ctrl_cfg ctrl;
  nds_ctrl_cfg_default(&ctrl);
  nds_ctrl pid;
  nds_ctrl_reset(&pid);
  for (int k = 0; k < n; k++) {
    int j = (int)(k * dt / T);
    if (j > M - 1) j = M - 1;
    nd_snap_seg_eval(&seg[j], k * dt - j * T, sp);
    const double pos[2] = {d->qpos[w->ee_qpos[0]], d->qpos[w->ee_qpos[1]]};
    const double vel[2] = {d->qvel[w->ee_dof[0]], d->qvel[w->ee_dof[1]]};
    nds_ctrl_pid(&ctrl, &pid, (const double(*)[4])sp, pos, vel, dt, r->u + 2 * k);
    nds_replay_sp_put(r->sp + 6 * k, (const double(*)[4])sp);
    d->qfrc_applied[w->ee_dof[0]] = r->u[2 * k];
    d->qfrc_applied[w->ee_dof[1]] = r->u[2 * k + 1];
    mj_step(w->m, d);
    nds_replay_observe(w, d, nd_rollout_obj(r, k), r->ee + 2 * k);
  }
  return 0;
}

int main(int argc, char **argv) {
  char err[512];
  int reps = 30;
  double plan_dt = 0.005, robust = NDS_FIT_ROBUST_SCALE;
  nd_opt opts[] = {
      {"reps", ND_OPT_INT, &reps, 3, 10000, .help = "plans per latency figure"},
      {"plan-dt", ND_OPT_DOUBLE, &plan_dt, 1e-4, 0.02, .arg = "S",
       .help = "planning model timestep, s"},
      {"robust", ND_OPT_DOUBLE, &robust, 1e-12, 1, .arg = "S",
       .help = "scale of the robust score timed as refit_s_10x5s_robust, m^2"},
  };
  nd_opt_spec spec = {"nudge-bench", "[options]",
                      "Measures the raw mj_step rate, batched rollout efficiency on 1 and 2 "
                      "workers, plan latency at the paper's settings, the planning model's "
                      "prediction error and the adapter's refit time. Prints a report, then "
                      "one `name value unit` line per figure. Not a test: nothing here "
                      "asserts.",
                      NULL, opts, sizeof(opts) / sizeof(opts[0])};
  const int prc = nd_opt_parse(&spec, argc, argv);
  if (prc != ND_OPT_RUN) return prc;

  const int ncores = nds_setup_cores(256);
  nds_setup su;
  if (nds_setup_init(&su, plan_dt, ncores, err, sizeof(err))) {
    fprintf(stderr, "nudge-bench: %s\n", err);
    return 1;
  }
  nds_model nm = su.plan;
  const nds_scene_cfg pc = nm.cfg;
  nds_ctrl_cfg ctrl;
  nds_ctrl_cfg_default(&ctrl);
  nds_state s0;
  double sp0[2][4];
  push_start(&nm, &s0, sp0);
  const int M = 2;
  const double T = 0.3;
  const int nsteps = (int)lround(M * T / plan_dt);
  printf("nudge-bench: plan model dt %.4f s (%d steps per 0.6 s rollout), condim %d, %d cores\n",
         plan_dt, nsteps, pc.condim, ncores);

  /* 1. Raw mj_step rate: the same pushes without setpoints or controller, one thread. */
  mjData *d = mj_makeData(nm.m);
  const int nroll = 400;
  double t0 = now_s();
  for (int r = 0; r < nroll; r++) {
    nds_state_set(&nm, d, &s0, err, sizeof(err));
    for (int k = 0; k < nsteps; k++) {
      d->qfrc_applied[nm.ee_dof[0]] = 4.0 + 0.01 * (r % 7);
      mj_step(nm.m, d);
    }
  }
  double raw_rate = nroll * (double)nsteps / (now_s() - t0);
  printf("raw mj_step: %.0f steps/s on one thread (%.2f us/step)\n", raw_rate, 1e6 / raw_rate);

  /* 2. Batched rollouts on 1 and 2 workers, against the raw rate. */
  const int nbatch = 128;
  double *keys = malloc(sizeof(double) * nbatch * 8);
  nds_rollout_out *outs = malloc(sizeof(*outs) * nbatch);
  for (int i = 0; i < nbatch; i++) push_keys(i, keys + 8 * i);
  double rate[3] = {0};
  for (int w = 1; w <= 2; w++) {
    nd_pool *pool = nd_pool_create(w, err, sizeof(err));
    nds_batch *b = pool ? nds_batch_create(&nm, pool, err, sizeof(err)) : NULL;
    if (!b) {
      fprintf(stderr, "nudge-bench: %s\n", err);
      return 1;
    }
    nds_batch_rollouts(b, &ctrl, &s0, sp0, keys, nbatch, M, T, outs);  /* warm caches */
    const int rounds = 4;
    t0 = now_s();
    for (int r = 0; r < rounds; r++) nds_batch_rollouts(b, &ctrl, &s0, sp0, keys, nbatch, M, T, outs);
    rate[w] = rounds * nbatch * (double)nsteps / (now_s() - t0);
    printf("batched rollouts, %d worker(s): %.0f steps/s = %.2f x raw mj_step\n", w, rate[w],
           rate[w] / raw_rate);
    nds_batch_free(b);
    nd_pool_free(pool);
  }
  double eff2 = rate[2] / (2.0 * raw_rate);
  printf("parallel efficiency on 2 workers: %.2f of 2 x raw mj_step, %.2f of 2 x 1-worker batch\n",
         eff2, rate[2] / (2.0 * rate[1]));

  /* 3. Plan latency at the paper's settings on every core, warm-started like the MPC. */
  const int settings[2][2] = {{128, 4}, {50, 2}};
  double med[2], p90[2];
  double *lat = malloc(sizeof(double) * reps);
  nd_pool *pool = su.pool;
  for (int k = 0; k < 2; k++) {
    nds_planner_cfg cfg;
    nds_planner_cfg_default(&cfg);
    cfg.pop = settings[k][0];
    cfg.iters = settings[k][1];
    nds_planner *p = nds_planner_create(&nm, &cfg, pool, err, sizeof(err));
    if (!p) {
      fprintf(stderr, "nudge-bench: %s\n", err);
      return 1;
    }
    const nd_goal goal = {.x = 0.2, .y = 0.05, .yaw = 0.3};
    nds_plan plan;
    for (int r = 0; r < reps; r++) {
      double t = now_s();
      nds_planner_plan(p, &s0, sp0, &goal, &plan, err, sizeof(err));
      lat[r] = 1e3 * (now_s() - t);
    }
    med[k] = nd_quantile(lat, reps, 0.5);
    p90[k] = nd_quantile(lat, reps, 0.9);
    printf("plan N %3d C %d, H 0.6 s, M 2, %d workers: median %.1f ms, p90 %.1f ms (%d rollouts)\n",
           cfg.pop, cfg.iters, nd_pool_size(pool), med[k], p90[k], plan.evals);
    nds_planner_free(p);
  }

  /* 4. What the coarse planning step costs: the same pushes in the planning model and in
   * the 1 ms world, final object position after the 0.6 s horizon, for several steps. */
  const nds_model world = su.world;
  const nds_scene_cfg wc = world.cfg;
  mjData *dw = su.d;
  nds_rollout_out *ref = malloc(sizeof(*ref) * nbatch);
  double *perr = malloc(sizeof(double) * nbatch);
  double moved = 0.0;
  for (int i = 0; i < nbatch; i++) {
    nds_rollout(&world, dw, &ctrl, &s0, sp0, keys + 8 * i, M, T, &ref[i]);
    moved += hypot(ref[i].obj_xy[0] - s0.obj_pos[0], ref[i].obj_xy[1] - s0.obj_pos[1]) / nbatch;
  }
  const double dts[4] = {0.002, 0.005, 0.010, plan_dt};
  double pe_med = 0.0;
  printf("planning step vs the 1 ms world, %d pushes over 0.6 s (object moved %.3f m on average):\n",
         nbatch, moved);
  for (int k = 0; k < 4; k++) {
    if (k == 3 && (plan_dt == 0.002 || plan_dt == 0.005 || plan_dt == 0.010)) break;
    nds_scene_cfg c = pc;
    c.timestep = dts[k];
    nds_model m2 = {0};
    if (nds_model_init(&m2, &c, err, sizeof(err))) {
      fprintf(stderr, "nudge-bench: %s\n", err);
      return 1;
    }
    mjData *d2 = mj_makeData(m2.m);
    t0 = now_s();
    for (int i = 0; i < nbatch; i++) {
      nds_rollout_out o;
      nds_rollout(&m2, d2, &ctrl, &s0, sp0, keys + 8 * i, M, T, &o);
      perr[i] = hypot(o.obj_xy[0] - ref[i].obj_xy[0], o.obj_xy[1] - ref[i].obj_xy[1]);
    }
    double ms = 1e3 * (now_s() - t0) / nbatch;
    double med_k = nd_quantile(perr, nbatch, 0.5);
    printf("  dt %.3f s: %.3f ms per rollout, object position error median %.4f m, max %.4f m\n",
           dts[k], ms, med_k, perr[nbatch - 1]);
    if (dts[k] == plan_dt) pe_med = med_k;
    mj_deleteData(d2);
    nds_model_free(&m2);
  }

  /* 5. The adapter's refit: CEM at the paper's Q 32, C 2 on 2 workers over a buffer of ten
   * 5 s pushes recorded in the 1 ms world, from a D = 1 prior; in the fit's default replay
   * mode with two record steps per model step and the adapter's window, as the adapter runs
   * it (a 2 ms model, whose replay of the true theta is not exact: its L(theta_true) says
   * how far the coarse step strays), in a 1 ms one, in the other replay mode at 1 ms for
   * comparison, ranked by the robust score (--robust; NDS_FIT_ROBUST_SCALE by default),
   * and with the study's 5 ms window at the adapter's step. */
  enum { NREC = 10 };
  nd_rollout recs[NREC];
  for (int i = 0; i < NREC; i++) {
    if (record_push5(&world, dw, i, &recs[i])) {
      fprintf(stderr, "nudge-bench: out of memory\n");
      return 1;
    }
  }
  nd_pool *fpool = nd_pool_create(2, err, sizeof(err));
  if (!fpool) {
    fprintf(stderr, "nudge-bench: %s\n", err);
    return 1;
  }
  nds_fit_cfg dcfg;
  nds_fit_cfg_default(&dcfg);
  const int dmode = dcfg.replay.mode;
  const int omode = dmode == NDS_REPLAY_SETPOINT ? NDS_REPLAY_FORCE : NDS_REPLAY_SETPOINT;
  /* The adapter's default model step and window first (nudge-adapter --replay-dt,
   * --replay-window); last, its model step with the study's window (nds_fit's default,
   * for poses observed at every step). */
  enum { NFIT = 5 };
  const double W = NDS_FIT_WINDOW_MOCAP;
  double refit_s[NFIT] = {0}, fit_dt[NFIT] = {0.002, 0.001, 0.001, 0.002, 0.002};
  const int fit_mode[NFIT] = {dmode, dmode, omode, dmode, dmode};
  const double fit_robust[NFIT] = {dcfg.robust, dcfg.robust, dcfg.robust, robust, dcfg.robust};
  const double fit_window[NFIT] = {W, W, W, W, dcfg.replay.window};
  /* The adapter's configuration is timed REFIT_REPS times (same seed, so the same work):
   * its figure is the median, as the target is checked against it. */
  enum { REFIT_REPS = 3 };
  double rep_s[REFIT_REPS] = {0};
  for (int k = 0; k < NFIT; k++) {
    const int reps = k == 0 ? REFIT_REPS : 1;
    for (int rep = 0; rep < reps; rep++) {
      nds_scene_cfg fc = wc;
      fc.timestep = fit_dt[k];
      nds_model fm = {0};
      nds_fit_cfg cfg;
      nds_fit_cfg_default(&cfg);
      cfg.replay.mode = fit_mode[k];
      cfg.replay.window = fit_window[k];
      cfg.robust = fit_robust[k];
      nd_rng rr;
      nd_rng_seed(&rr, 1, 7);
      nds_fit_paper_prior(nd_theta_true, 1.0, cfg.lower, &rr, cfg.mu0, cfg.sigma0);
      cfg.mu0[ND_TH_MASS] = nd_theta_true[ND_TH_MASS];
      nds_fit *fit = NULL;
      nds_fit_out fo;
      double l_true = 0;
      if (nds_model_init(&fm, &fc, err, sizeof(err)) ||
          !(fit = nds_fit_create(&fm, &cfg, fpool, err, sizeof(err))) ||
          nds_fit_loss(fit, nd_theta_true, recs, NREC, &l_true, NULL, err, sizeof(err))) {
        fprintf(stderr, "nudge-bench: %s\n", err);
        return 1;
      }
      t0 = now_s();
      if (nds_fit_run(fit, recs, NREC, &fo, err, sizeof(err))) {
        fprintf(stderr, "nudge-bench: %s\n", err);
        return 1;
      }
      refit_s[k] = now_s() - t0;
      if (k == 0) rep_s[rep] = refit_s[k];
      printf("refit %d x 5 s, Q %d C %d, 2 workers, %s replay%s, model dt %.3f s, window "
             "%g s, robust %g: %.2f s (%d replays), sliding %.3f -> %.3f, L(mean) %.3g, "
             "L(theta_true) %.3g\n",
             NREC, cfg.pop, cfg.iters, nds_replay_mode_name(fit_mode[k]),
             k == 0 ? " (the adapter's default)" : "", fit_dt[k], cfg.replay.window, cfg.robust,
             refit_s[k],
             fo.replays,
             cfg.mu0[0], fo.mean[0], fo.loss_mean, l_true);
      nds_fit_free(fit);
      nds_model_free(&fm);
    }
  }
  refit_s[0] = nd_quantile(rep_s, REFIT_REPS, 0.5);  /* sorts rep_s */
  printf("refit in the adapter's configuration, %d times: median %.2f s (%.2f..%.2f)\n",
         REFIT_REPS, refit_s[0], rep_s[0], rep_s[REFIT_REPS - 1]);
  nd_pool_free(fpool);
  for (int i = 0; i < NREC; i++) nd_rollout_free(&recs[i]);
  printf("refit_s_10x5s %.2f s\n", refit_s[0]);
  printf("refit_s_10x5s_1ms %.2f s\n", refit_s[1]);
  /* The other replay mode at 1 ms, by name. */
  printf("refit_s_10x5s_1ms_%s %.2f s\n", nds_replay_mode_name(omode), refit_s[2]);
  printf("refit_s_10x5s_robust %.2f s\n", refit_s[3]);
  printf("refit_s_10x5s_window5ms %.2f s\n", refit_s[4]);

  printf("mj_step_rate %.0f steps/s\n", raw_rate);
  printf("rollout_ratio_1w %.3f ratio\n", rate[1] / raw_rate);
  printf("rollout_efficiency_2w %.3f ratio\n", eff2);
  printf("plan_ms_median_n128_c4 %.1f ms\n", med[0]);
  printf("plan_ms_median_n50_c2 %.1f ms\n", med[1]);
  printf("plan_ms_p90_n50_c2 %.1f ms\n", p90[1]);
  printf("plan_dt %.4f s\n", plan_dt);
  printf("prediction_error_m %.4f m\n", pe_med);

  free(perr);
  free(ref);
  free(lat);
  free(keys);
  free(outs);
  mj_deleteData(d);
  nds_setup_free(&su);
  return 0;
}
