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

#include "nd_math.h"
#include "nd_opt.h"
#include "nd_stats.h"
#include "nd_snap.h"
#include "nds_fit.h"
#include "nds_planner.h"
#include "nds_reach.h"
#include "nds_setup.h"
#include "nds_world.h"

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* The start of a push: object at the origin, sphere 8 cm behind it, setpoint at the sphere. */
static const double push_ee[2] = {-0.08, 0.0};

static void push_start(const nds_model *nm, nds_state *s, double sp[2][4]) {
  nds_state_rest(nm, 0.0, 0.0, 0.0, push_ee, s);
  memset(sp, 0, 8 * sizeof(double));
  sp[0][0] = push_ee[0];
  sp[1][0] = push_ee[1];
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
  nds_ctrl_reset(&pid, w->m->body_mass[w->ee_body]);
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

/* Sections of the bench, as --sections names them. */
enum { SEC_PLAN = 1, SEC_PREDICT = 2, SEC_LAB = 4, SEC_FIT = 8 };
static const char *const sec_words[] = {"plan", "predict", "lab", "fit"};

static int parse_sections(const char *v, const char *what, void *dst, char *err, int errlen) {
  int *sec = dst, n = 0;
  *sec = 0;
  for (const char *p = v; *p; n++) {
    const size_t len = strcspn(p, ",");
    int k = 0;
    while (k < 4 && !(strlen(sec_words[k]) == len && !strncmp(p, sec_words[k], len))) k++;
    if (k == 4) {
      snprintf(err, errlen, "%s: '%.*s' is not one of plan, predict, lab, fit", what, (int)len, p);
      return -1;
    }
    *sec |= 1 << k;
    p += len + (p[len] == ',');
  }
  if (!n) {
    snprintf(err, errlen, "%s: name at least one section", what);
    return -1;
  }
  return 0;
}

/* The true object's planar pose in a world, from its free joint. */
static void world_object(const nds_world *w, double xy[2], double *yaw) {
  const mjModel *m = nds_world_mj_model(w);
  const mjData *d = nds_world_mj_data(w);
  const int j = m->body_jntadr[mj_name2id(m, mjOBJ_BODY, "object")];
  const double *q = d->qpos + m->jnt_qposadr[j];
  xy[0] = q[0], xy[1] = q[1];
  *yaw = nd_quat_yaw(q + 3);
}

/* The segment duration, from T up in steps of 10 %, at which M chained segments from rest
 * at start through keys peak within v_max and a_max (the executor's rule). */
static double push_stretch(const double start[2], const double *keys, int M, double T,
                           double v_max, double a_max) {
  for (;; T *= 1.1) {
    nd_snap_seg seg[ND_MAX_KEYS];
    double sp[2][4] = {{start[0], 0, 0, 0}, {start[1], 0, 0, 0}}, v2 = 0, a2 = 0;
    for (int k = 0; k < M; k++) {
      nd_snap_seg_make(&seg[k], (const double(*)[4])sp, keys + 4 * k, keys + 4 * k + 2, T);
      for (double t = 0; t <= T; t += 1e-3) {
        nd_snap_seg_eval(&seg[k], t, sp);
        v2 = fmax(v2, sp[0][ND_V] * sp[0][ND_V] + sp[1][ND_V] * sp[1][ND_V]);
        a2 = fmax(a2, sp[0][ND_A] * sp[0][ND_A] + sp[1][ND_A] * sp[1][ND_A]);
      }
      nd_snap_seg_eval(&seg[k], T, sp);
    }
    if (sqrt(v2) <= v_max && sqrt(a2) <= a_max) return T;
  }
}

/* The pushes of section 2 in a world (ideal or lab, 1 ms) tracking the chained segments
 * (push i's segments last Ts[i]) as the executor sends them, then 0.2 s at rest: each
 * step's cost, the sphere's tracking error (true position less setpoint), reflex stops,
 * the object's pose at the horizon into obj[i] (x, y, yaw). Returns 0, or -1 with a
 * message. */
typedef struct {
  double *step_us, *track;  /* per step */
  int nstep, ntrack, stops;
} world_figs;

static int world_pushes(const nds_world_cfg *base, const double *keys, int n, int M,
                        const double *Ts, double (*obj)[3], world_figs *f, char *err,
                        int errlen) {
  for (int i = 0; i < n; i++) {
    const double T = Ts[i];
    nds_world_cfg c = *base;
    c.obj[0] = c.obj[1] = c.obj[2] = 0.0;
    c.ee[0] = push_ee[0], c.ee[1] = push_ee[1];
    nds_world *w = nds_world_create(&c, err, errlen);
    if (!w) return -1;
    nd_snap_seg seg[ND_MAX_KEYS];
    double sp[2][4] = {{c.ee[0], 0, 0, 0}, {c.ee[1], 0, 0, 0}};
    nd_snap_chain(seg, (const double(*)[4])sp, keys + 8 * i, M, T);
    const double dt = nds_world_mj_model(w)->opt.timestep;
    const int horizon = (int)lround(M * T / dt), hold = (int)lround(0.2 / dt);
    nds_world_out out;
    for (int s = 0; s < horizon + hold; s++) {
      const double t = s < horizon ? s * dt : M * T;
      int k = (int)(t / T);
      if (k > M - 1) k = M - 1;
      nd_snap_seg_eval(&seg[k], t - k * T, sp);
      const double t0 = now_s();
      nds_world_step(w, (const double(*)[4])sp, &out);
      f->step_us[f->nstep++] = 1e6 * (now_s() - t0);
      f->stops += out.stopped_now;
      double ee[2];
      nds_world_ee(w, ee);
      if (s < horizon) f->track[f->ntrack++] = hypot(ee[0] - sp[0][ND_P], ee[1] - sp[1][ND_P]);
      if (s == horizon - 1) world_object(w, obj[i], &obj[i][2]);
    }
    nds_world_free(w);
  }
  return 0;
}

/* The refit's cost and accuracy, CEM alone against a cheaper CEM refined by
 * Levenberg-Marquardt: at a 2 ms replay step with the adapter's window over recs,
 * from NSEED draws of the D = 1 prior. Prints a line per run and the figures. */
static int bench_refine(const nds_scene_cfg *wc, const nd_rollout *recs, int nrec,
                        nd_pool *pool) {
  enum { NSEED = 3, NCFG = 2 };
  static const int pop[NCFG] = {32, 4}, iters[NCFG] = {2, 1}, lm[NCFG] = {0, 3};
  static const char *const name[NCFG] = {"cem", "lm"};
  double reps[NCFG][NSEED], e_s[NCFG][NSEED], e_t[NCFG][NSEED];
  char err[256];
  nds_scene_cfg fc = *wc;
  fc.timestep = 0.002;
  nds_model fm = {0};
  if (nds_model_init(&fm, &fc, err, sizeof(err))) goto fail;
  for (int k = 0; k < NCFG; k++) {
    for (int sd = 0; sd < NSEED; sd++) {
      nds_fit_cfg cfg;
      nds_fit_cfg_default(&cfg);
      cfg.replay.window = NDS_FIT_WINDOW_MOCAP;
      cfg.pop = pop[k], cfg.iters = iters[k], cfg.lm_iters = lm[k];
      nd_rng rr;
      nd_rng_seed(&rr, 1 + sd, 7);
      nds_fit_paper_prior(nd_theta_true, 1.0, cfg.lower, &rr, cfg.mu0, cfg.sigma0);
      cfg.mu0[ND_TH_MASS] = nd_theta_true[ND_TH_MASS];
      nds_fit *fit = nds_fit_create(&fm, &cfg, pool, err, sizeof(err));
      nds_fit_out fo;
      if (!fit || nds_fit_run(fit, recs, nrec, &fo, err, sizeof(err))) {
        nds_fit_free(fit);
        goto fail;
      }
      nds_fit_free(fit);
      reps[k][sd] = fo.replays;
      e_s[k][sd] = fabs(fo.mean[ND_TH_SLIDE] / nd_theta_true[ND_TH_SLIDE] - 1.0);
      e_t[k][sd] = fabs(fo.mean[ND_TH_TORSION] / nd_theta_true[ND_TH_TORSION] - 1.0);
      printf("refit Q %d C %d + LM %d, prior draw %d: %d replays, sliding %.4f (from %.3f), "
             "torsional %.5f (from %.5f)", cfg.pop, cfg.iters, cfg.lm_iters, sd + 1,
             fo.replays, fo.mean[0], cfg.mu0[0], fo.mean[1], cfg.mu0[1]);
      if (fo.lm_run)
        printf(", its std %.4f / %.5f", fo.lm_std[ND_TH_SLIDE], fo.lm_std[ND_TH_TORSION]);
      printf("\n");
    }
  }
  nds_model_free(&fm);
  for (int k = 0; k < NCFG; k++) {
    printf("refit_replays_%s %.0f count\n", name[k], nd_quantile(reps[k], NSEED, 0.5));
    printf("refit_slide_err_%s %.4f ratio\n", name[k], nd_quantile(e_s[k], NSEED, 0.5));
    printf("refit_torsion_err_%s %.4f ratio\n", name[k], nd_quantile(e_t[k], NSEED, 0.5));
  }
  return 0;
fail:
  fprintf(stderr, "nudge-bench: %s\n", err);
  nds_model_free(&fm);
  return -1;
}

int main(int argc, char **argv) {
  char err[512];
  int sections = SEC_PLAN | SEC_PREDICT | SEC_LAB | SEC_FIT;
  double lab_theta[ND_NTHETA];
  memcpy(lab_theta, nd_theta_true, sizeof(lab_theta));
  int reps = 30;
  double plan_dt = 0.005, robust = NDS_FIT_ROBUST_SCALE;
  nd_opt opts[] = {
      {"reps", ND_OPT_INT, &reps, 3, 10000, .help = "plans per latency figure"},
      {"plan-dt", ND_OPT_DOUBLE, &plan_dt, 1e-4, 0.02, .arg = "S",
       .help = "planning model timestep, s"},
      {"robust", ND_OPT_DOUBLE, &robust, 1e-12, 1, .arg = "S",
       .help = "scale of the robust score timed as refit_s_10x5s_robust, m^2"},
      {"theta", ND_OPT_THETA, lab_theta, .arg = "S,T,R,M[,B,X,Y]",
       .def = "the model's own",
       .help = "theta of the planning model the lab section holds against the worlds, e.g. a "
               "fit's (nudge-adapter's PARAMS): does it predict the lab better than the "
               "model's own?"},
      {"sections", ND_OPT_CUSTOM, &sections, .parse = parse_sections, .arg = "LIST",
       .def = "plan,predict,lab,fit",
       .help = "what to measure: plan (mj_step rate, batches, plan latency with and without "
               "free flight), predict (the planning model against the 1 ms world), lab (the "
               "lab world: step cost, the arm's tracking, the planning model against it), "
               "fit (the adapter's refit)"},
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

  const int nbatch = 128;
  double *keys = malloc(sizeof(double) * nbatch * 8);
  nds_rollout_out *outs = malloc(sizeof(*outs) * nbatch);
  for (int i = 0; i < nbatch; i++) push_keys(i, keys + 8 * i);

  /* 2. Batched rollouts on 1 and 2 workers, against the raw rate. 3. Plan latency at the
   * paper's settings on every core, warm-started like the MPC, with and without free flight;
   * against brute force: N C rollouts of H / dt steps at the raw rate on every worker. */
  double rate[3] = {0}, eff2 = 0, med[5] = {0}, p90[5] = {0}, brute_ms = 0;
  double *lat = malloc(sizeof(double) * reps);
  nd_pool *pool = su.pool;
  if (sections & SEC_PLAN) {
    for (int w = 1; w <= 2; w++) {
      nd_pool *bp = nd_pool_create(w, err, sizeof(err));
      nds_batch *b = bp ? nds_batch_create(&nm, bp, err, sizeof(err)) : NULL;
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
      nd_pool_free(bp);
    }
    eff2 = rate[2] / (2.0 * raw_rate);
    printf("parallel efficiency on 2 workers: %.2f of 2 x raw mj_step, %.2f of 2 x 1-worker batch\n",
           eff2, rate[2] / (2.0 * rate[1]));

    /* N 128 C 4; N 50 C 2 without and with free flight; the live planner's N 20 C 2 with
     * draws beyond the limits drawn again (pop, iters, free flight, redraws); the same on
     * the lab world, as nudge-up sets it: the arm's reach ranked, its box and limits, 0.6 s
     * segments (processes/supervisor/nudge-up). */
    const int settings[5][4] = {{128, 4, 1, 0}, {50, 2, 0, 0}, {50, 2, 1, 0}, {20, 2, 1, 8},
                                {20, 2, 1, 8}};
    const double lab_lo[2] = {NDS_PANDA_WS_XMIN, NDS_PANDA_WS_YMIN},
                 lab_hi[2] = {NDS_PANDA_WS_XMAX, NDS_PANDA_WS_YMAX};
    nds_reach reach;
    if (nds_reach_build_ws(&reach, lab_lo, lab_hi, err, sizeof(err))) {
      fprintf(stderr, "nudge-bench: %s\n", err);
      return 1;
    }
    for (int k = 0; k < 5; k++) {
      nds_planner_cfg cfg;
      nds_planner_cfg_default(&cfg);
      cfg.pop = settings[k][0];
      cfg.iters = settings[k][1];
      cfg.free_flight = settings[k][2];
      cfg.redraws = settings[k][3];
      if (k == 4) {
        cfg.T = 0.6, cfg.v_max = 0.45, cfg.a_max = 1.8, cfg.reach = &reach;
        nds_planner_cfg_fit_limits(&cfg);
        for (int a = 0; a < 2; a++) cfg.ws_lo[a] = lab_lo[a], cfg.ws_hi[a] = lab_hi[a];
      }
      nds_planner *p = nds_planner_create(&nm, &cfg, pool, err, sizeof(err));
      if (!p) {
        fprintf(stderr, "nudge-bench: %s\n", err);
        return 1;
      }
      const nd_goal goal = k == 4 ? (nd_goal){.x = 0.1, .y = 0.1, .yaw = 0.3}
                                  : (nd_goal){.x = 0.2, .y = 0.05, .yaw = 0.3};
      nds_plan plan;
      for (int r = 0; r < reps; r++) {
        double t = now_s();
        nds_planner_plan(p, &s0, sp0, &goal, &plan, err, sizeof(err));
        lat[r] = 1e3 * (now_s() - t);
      }
      med[k] = nd_quantile(lat, reps, 0.5);
      p90[k] = nd_quantile(lat, reps, 0.9);
      printf("plan%s N %3d C %d, H %.1f s, M 2, %d workers, free flight %s, redraws %d: median "
             "%.1f ms, p90 %.1f ms (%d candidates, %d simulated: the others beyond the "
             "limits; %d redrawn)\n", k == 4 ? " (lab)" : "", cfg.pop, cfg.iters, 2 * cfg.T,
             nd_pool_size(pool), cfg.free_flight ? "on" : "off", cfg.redraws, med[k], p90[k],
             plan.evals, plan.rollouts, plan.redrawn);
      nds_planner_free(p);
    }
    nds_reach_free(&reach);
    brute_ms = 1e3 * 50.0 * 2.0 * nsteps / (raw_rate * nd_pool_size(pool));
    printf("brute force N 50 C 2 (%d steps each at the raw rate on %d workers): %.1f ms; plan "
           "with free flight %.2f of it\n", nsteps, nd_pool_size(pool), brute_ms, med[2] / brute_ms);
  }

  /* 4. What the coarse planning step costs: the same pushes in the planning model and in
   * the 1 ms world, final object position after the 0.6 s horizon, for several steps. */
  const nds_model world = su.world;
  const nds_scene_cfg wc = world.cfg;
  mjData *dw = su.d;
  nds_rollout_out *ref = malloc(sizeof(*ref) * nbatch);
  double *perr = malloc(sizeof(double) * nbatch);
  double pe_med = 0.0, pe_world10 = 0.0;
  if (sections & SEC_PREDICT) {
    double moved = 0.0;
    for (int i = 0; i < nbatch; i++) {
      nds_rollout(&world, dw, &ctrl, &s0, sp0, keys + 8 * i, M, T, &ref[i]);
      moved += hypot(ref[i].obj_xy[0] - s0.obj_pos[0], ref[i].obj_xy[1] - s0.obj_pos[1]) / nbatch;
    }
    /* Each step's planning model; at 10 ms also with the world's contact, for comparison. */
    const double dts[5] = {0.002, 0.005, 0.010, 0.010, plan_dt};
    const int world_contact[5] = {0, 0, 1, 0, 0};
    printf("planning step vs the 1 ms world, %d pushes over 0.6 s (object moved %.3f m on average):\n",
           nbatch, moved);
    for (int k = 0; k < 5; k++) {
      if (k == 4 && (plan_dt == 0.002 || plan_dt == 0.005 || plan_dt == 0.010)) break;
      nds_scene_cfg c;
      int cal = 0;
      if (world_contact[k]) {
        nds_scene_cfg_default(&c);
        c.timestep = dts[k];
      } else {
        cal = nds_scene_cfg_planning(&c, dts[k]);
      }
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
      printf("  dt %.3f s, %s contact: %.3f ms per rollout, object position error median %.4f m, "
             "max %.4f m\n", dts[k], cal ? "calibrated" : "the world's", ms, med_k,
             perr[nbatch - 1]);
      if (world_contact[k])
        pe_world10 = med_k;
      else if (dts[k] == plan_dt)
        pe_med = med_k;
      mj_deleteData(d2);
      nds_model_free(&m2);
    }
  }

  /* 6. The lab world: the same pushes (32 of them), slowed to what the arm takes in every
   * direction (0.45 m/s, 1.8 m/s^2; the live planner goes beyond where its arm map lets it,
   * doc/decisions.md#lab-caps), tracked by the arm in 1 ms steps, each
   * timed; the arm's tracking error and reflex stops; the planning model at 5 ms and at the
   * live planner's 10 ms (at --theta) against the lab world's outcome, next to the same
   * against the ideal world: the object's position and yaw at the horizon. */
  enum { NLAB = 32 };
  double lab_fig[14] = {0};
  if (sections & SEC_LAB) {
    static double step_us[2][NLAB * 4000], track[2][NLAB * 4000];
    static double truth[2][NLAB][3];
    double Ts[NLAB];
    for (int i = 0; i < NLAB; i++) Ts[i] = push_stretch(push_ee, keys + 8 * i, M, T, 0.45, 1.8);
    world_figs wf[2] = {{step_us[0], track[0], 0, 0, 0}, {step_us[1], track[1], 0, 0, 0}};
    nds_world_cfg wcfg[2];
    nds_world_cfg_default(&wcfg[0]);
    nds_world_cfg_lab(&wcfg[1]);
    for (int k = 0; k < 2; k++)
      if (world_pushes(&wcfg[k], keys, NLAB, M, Ts, truth[k], &wf[k], err, sizeof(err))) {
        fprintf(stderr, "nudge-bench: %s\n", err);
        return 1;
      }
    const double pdts[2] = {0.005, 0.010};
    double pe[2][2], ye[2][2], yerr[NLAB];
    for (int j = 0; j < 2; j++) {
      nds_scene_cfg c;
      nds_scene_cfg_planning(&c, pdts[j]);
      nds_model m2 = {0};
      if (nds_model_init(&m2, &c, err, sizeof(err)) ||
          nds_theta_apply(&m2, lab_theta, err, sizeof(err))) {
        fprintf(stderr, "nudge-bench: %s\n", err);
        nds_model_free(&m2);
        return 1;
      }
      mjData *d2 = mj_makeData(m2.m);
      nds_state s8;
      double sp8[2][4];
      push_start(&m2, &s8, sp8);
      for (int k = 0; k < 2; k++) {
        for (int i = 0; i < NLAB; i++) {
          nds_rollout_out o;
          nds_rollout(&m2, d2, &ctrl, &s8, sp8, keys + 8 * i, M, Ts[i], &o);
          perr[i] = hypot(o.obj_xy[0] - truth[k][i][0], o.obj_xy[1] - truth[k][i][1]);
          yerr[i] = 180.0 / ND_PI * fabs(nd_wrap_angle(o.obj_yaw - truth[k][i][2]));
        }
        pe[j][k] = nd_quantile(perr, NLAB, 0.5);
        ye[j][k] = nd_quantile(yerr, NLAB, 0.5);
      }
      mj_deleteData(d2);
      nds_model_free(&m2);
    }
    const double lab_mean = nd_stats_of(step_us[1], wf[1].nstep).mean;
    lab_fig[0] = nd_quantile(step_us[1], wf[1].nstep, 0.5);
    lab_fig[1] = nd_quantile(step_us[1], wf[1].nstep, 0.99);
    lab_fig[2] = lab_mean / 1000.0;
    lab_fig[3] = nd_quantile(step_us[0], wf[0].nstep, 0.5);
    lab_fig[4] = 1e3 * nd_quantile(track[1], wf[1].ntrack, 0.5);
    lab_fig[5] = 1e3 * nd_quantile(track[1], wf[1].ntrack, 0.99);
    lab_fig[6] = pe[0][1], lab_fig[7] = pe[0][0], lab_fig[8] = pe[1][1], lab_fig[9] = pe[1][0];
    lab_fig[10] = wf[1].stops;
    lab_fig[11] = nd_quantile(Ts, NLAB, 0.5);
    lab_fig[12] = ye[1][1], lab_fig[13] = ye[1][0];
    printf("lab world, %d pushes (segments of %.2f s median): %d reflex stops; step p50 %.1f us, p99 %.1f us, mean %.1f us (%.1f %% of a core "
           "at 1 kHz; the ideal world's p50 %.1f us); the arm's tracking error p50 %.2f mm, "
           "p99 %.2f mm\n", NLAB, lab_fig[11], wf[1].stops, lab_fig[0], lab_fig[1], lab_mean, 100 * lab_fig[2],
           lab_fig[3], lab_fig[4], lab_fig[5]);
    printf("planning model against the world's outcome at the pushes' end, object position error "
           "median: 5 ms model: lab %.4f m, ideal %.4f m; 10 ms model: lab %.4f m, ideal %.4f m\n",
           pe[0][1], pe[0][0], pe[1][1], pe[1][0]);
    printf("  its yaw error median: 5 ms model: lab %.2f deg, ideal %.2f deg; 10 ms model: lab "
           "%.2f deg, ideal %.2f deg (theta %s)\n", ye[0][1], ye[0][0], ye[1][1], ye[1][0],
           memcmp(lab_theta, nd_theta_true, sizeof(lab_theta)) ? "--theta" : "the model's own");
  }

  if (sections & SEC_FIT) {
    /* 5. The adapter's refit: CEM at the paper's Q 32, C 2 on 2 workers over a buffer of ten
     * 5 s pushes recorded in the 1 ms world, from a D = 1 prior; in the fit's default replay
     * mode at the adapter's step (the recorded 1 ms) and window, at 2 ms (the adapter's step
     * until it was found to bias the fit: its L(theta_true) says how far the coarse step
     * strays), in the other replay mode, ranked by the robust score (--robust), and with the
     * study's 5 ms window. */
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
    double refit_s[NFIT] = {0}, fit_dt[NFIT] = {0.001, 0.002, 0.001, 0.001, 0.001};
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
    if (bench_refine(&wc, recs, NREC, fpool)) return 1;
    refit_s[0] = nd_quantile(rep_s, REFIT_REPS, 0.5);  /* sorts rep_s */
    printf("refit in the adapter's configuration, %d times: median %.2f s (%.2f..%.2f)\n",
           REFIT_REPS, refit_s[0], rep_s[0], rep_s[REFIT_REPS - 1]);
    nd_pool_free(fpool);
    for (int i = 0; i < NREC; i++) nd_rollout_free(&recs[i]);
    printf("refit_s_10x5s %.2f s\n", refit_s[0]);
    printf("refit_s_10x5s_2ms %.2f s\n", refit_s[1]);
    /* The other replay mode at 1 ms, by name. */
    printf("refit_s_10x5s_1ms_%s %.2f s\n", nds_replay_mode_name(omode), refit_s[2]);
    printf("refit_s_10x5s_robust %.2f s\n", refit_s[3]);
    printf("refit_s_10x5s_window5ms %.2f s\n", refit_s[4]);
  }

  printf("mj_step_rate %.0f steps/s\n", raw_rate);
  if (sections & SEC_PLAN) {
    printf("rollout_ratio_1w %.3f ratio\n", rate[1] / raw_rate);
    printf("rollout_efficiency_2w %.3f ratio\n", eff2);
    printf("plan_ms_median_n128_c4 %.1f ms\n", med[0]);
    printf("plan_ms_median_n50_c2_no_ff %.1f ms\n", med[1]);
    printf("plan_ms_median_n50_c2 %.1f ms\n", med[2]);
    printf("plan_ms_p90_n50_c2 %.1f ms\n", p90[2]);
    printf("plan_ff_speedup_n50_c2 %.2f ratio\n", med[1] / med[2]);
    printf("plan_brute_ratio_n50_c2 %.3f ratio\n", med[2] / brute_ms);
    printf("plan_ms_median_n20_c2_redraws %.1f ms\n", med[3]);
    printf("plan_ms_median_lab_n20_c2 %.1f ms\n", med[4]);
  }
  printf("plan_dt %.4f s\n", plan_dt);
  if (sections & SEC_PREDICT) {
    printf("prediction_error_m %.4f m\n", pe_med);
    printf("prediction_error_10ms_world_contact %.4f m\n", pe_world10);
  }
  if (sections & SEC_LAB) {
    printf("lab_step_us_p50 %.1f us\nlab_step_us_p99 %.1f us\n", lab_fig[0], lab_fig[1]);
    printf("lab_step_core_share %.3f of_core\nideal_step_us_p50 %.1f us\n", lab_fig[2], lab_fig[3]);
    printf("lab_track_err_p50 %.2f mm\nlab_track_err_p99 %.2f mm\n", lab_fig[4], lab_fig[5]);
    printf("lab_reflex_stops %.0f count\n", lab_fig[10]);
    printf("prediction_error_lab_5ms %.4f m\nprediction_error_ideal_5ms %.4f m\n", lab_fig[6],
           lab_fig[7]);
    printf("prediction_error_lab_10ms %.4f m\nprediction_error_ideal_10ms %.4f m\n", lab_fig[8],
           lab_fig[9]);
    printf("prediction_yaw_error_lab_10ms %.2f deg\nprediction_yaw_error_ideal_10ms %.2f deg\n",
           lab_fig[12], lab_fig[13]);
  }

  free(perr);
  free(ref);
  free(lat);
  free(keys);
  free(outs);
  mj_deleteData(d);
  nds_setup_free(&su);
  return 0;
}
