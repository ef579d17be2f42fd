/* nudge-calibrate: fit the planning model's contact softness to the 1 ms world.
 *
 * A coarse step changes what MuJoCo's soft contacts do: stepped at 10 ms with the world's
 * own solref, solimp and tilt damping, the box slides ~2.4 cm too far over a 0.6 s push.
 * This program draws pushes from random starts around a yawed box, rolls each out in the
 * 1 ms world (the truth) and in the planning model at --plan-dt, and searches the planning
 * model's contact values with the project's CEM for the least prediction error. It checks
 * the result on pushes it was not fitted on, a second friction included, and prints the
 * values sim/nds_model.c tabulates, from this program's defaults
 * (doc/decisions.md#plan-contact). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_cem.h"
#include "nd_math.h"
#include "nd_opt.h"
#include "nd_rfile.h"
#include "nd_rng.h"
#include "nd_stats.h"
#include "nds_rollout.h"

#define PROG "nudge-calibrate"
#define NDIM 6 /* log solref0, log solref1, solimp0, solimp1 - solimp0, log width, log tilt */

/* A 0.6 s push (M 2, T 0.3) and the world's outcome. */
typedef struct {
  nds_state s0;
  double sp0[2][4];
  double keys[8];
  nds_rollout_out truth;
} push;

typedef struct {
  const nds_scene_cfg *world;  /* what the search varies the contact of */
  nds_ctrl_cfg ctrl;
  push *train;
  int n;
  double dt;
} fit_ctx;

/* Pushes from rest: the box at the origin at a random yaw, the sphere 7-11 cm from it at a
 * random bearing, driven through the box's side (up to 3 cm off its centre) 5-17 cm on. */
static void draw_pushes(const nds_model *world, mjData *d, const nds_ctrl_cfg *ctrl,
                        uint64_t seed, push *p, int n) {
  nd_rng r;
  nd_rng_seed(&r, seed, 7);
  for (int i = 0; i < n; i++) {
    const double yaw = 2.0 * (nd_rng_uniform(&r) - 0.5), a = 2.0 * M_PI * nd_rng_uniform(&r);
    const double dist = 0.07 + 0.04 * nd_rng_uniform(&r);
    const double ee[2] = {dist * cos(a), dist * sin(a)};
    nds_state_rest(world, 0.0, 0.0, yaw, ee, &p[i].s0);
    memset(p[i].sp0, 0, sizeof(p[i].sp0));
    p[i].sp0[0][0] = ee[0], p[i].sp0[1][0] = ee[1];
    const double dir = a + M_PI + 0.8 * (nd_rng_uniform(&r) - 0.5);
    const double lat = 0.06 * (nd_rng_uniform(&r) - 0.5), reach = 0.05 + 0.12 * nd_rng_uniform(&r);
    const double px = -lat * sin(dir), py = lat * cos(dir), c = cos(dir), s = sin(dir);
    const double k[8] = {px - 0.04 * c, py - 0.04 * s, 0.3 * c, 0.3 * s,
                         px + reach * c, py + reach * s, 0.0, 0.0};
    memcpy(p[i].keys, k, sizeof(k));
    nds_rollout(world, d, ctrl, &p[i].s0, (const double(*)[4])p[i].sp0, k, 2, 0.3, &p[i].truth);
  }
}

/* The scene cfg a search vector stands for. */
static void cfg_of(const double *x, double dt, nds_scene_cfg *c) {
  c->timestep = dt;
  c->solref[0] = exp(x[0]);
  c->solref[1] = exp(x[1]);
  c->solimp[0] = x[2];
  c->solimp[1] = fmin(x[2] + x[3], 0.995);
  c->solimp[2] = exp(x[4]);
  c->tilt_damping = fmax(exp(x[5]) - 0.01, 0.0);
}

typedef struct {
  double pos_med, pos_p90, yaw_med, yaw_p90, score;
} pred_err;

/* Prediction error of the model built from c on n pushes. The score the search minimises
 * caps each push's error (a push that tips chaotically must not decide) and counts a
 * radian of yaw like 3 cm. Return -1 if c builds no model. */
static int pred_error(const nds_scene_cfg *c, const nds_ctrl_cfg *ctrl, const push *p, int n,
                      pred_err *e) {
  char err[256];
  nds_model m = {0};
  if (nds_model_init(&m, c, err, sizeof(err))) return -1;
  mjData *d = mj_makeData(m.m);
  double *pe = malloc(2 * sizeof(double) * n), *ye = pe + n;
  if (!d || !pe) {
    mj_deleteData(d);
    free(pe);
    nds_model_free(&m);
    return -1;
  }
  e->score = 0.0;
  for (int i = 0; i < n; i++) {
    nds_rollout_out o;
    nds_rollout(&m, d, ctrl, &p[i].s0, (const double(*)[4])p[i].sp0, p[i].keys, 2, 0.3, &o);
    if (o.diverged) {
      pe[i] = ye[i] = INFINITY;
    } else {
      pe[i] = hypot(o.obj_xy[0] - p[i].truth.obj_xy[0], o.obj_xy[1] - p[i].truth.obj_xy[1]);
      ye[i] = fabs(nd_wrap_angle(o.obj_yaw - p[i].truth.obj_yaw));
    }
    e->score += (fmin(pe[i], 0.05) + 0.03 * fmin(ye[i], 0.5)) / n;
  }
  e->pos_med = nd_quantile(pe, n, 0.5), e->pos_p90 = nd_quantile(pe, n, 0.9);
  e->yaw_med = nd_quantile(ye, n, 0.5), e->yaw_p90 = nd_quantile(ye, n, 0.9);
  free(pe);
  mj_deleteData(d);
  nds_model_free(&m);
  return 0;
}

static int fit_cost(void *ctx, const double *x, int n, double *cost) {
  const fit_ctx *f = ctx;
  for (int i = 0; i < n; i++) {
    nds_scene_cfg c = *f->world;
    cfg_of(x + NDIM * i, f->dt, &c);
    pred_err e;
    cost[i] = pred_error(&c, &f->ctrl, f->train, f->n, &e) ? INFINITY : e.score;
  }
  return 0;
}

static void report(const char *what, const pred_err *e) {
  printf("  %-34s position median %5.1f mm, p90 %5.1f mm; yaw median %.3f rad, p90 %.3f rad\n",
         what, 1e3 * e->pos_med, 1e3 * e->pos_p90, e->yaw_med, e->yaw_p90);
}

int main(int argc, char **argv) {
  double dt = 0.01;
  int npush = 256, pop = 48, iters = 10;
  uint64_t seed = 1;
  nd_opt opts[] = {
      {"plan-dt", ND_OPT_DOUBLE, &dt, 0.002, 0.01, .arg = "S", .help = "planning model timestep"},
      {"pushes", ND_OPT_INT, &npush, 8, 4096, .help = "pushes fitted on (as many checked)"},
      {"pop", ND_OPT_INT, &pop, 8, 1000, .help = "CEM population"},
      {"iters", ND_OPT_INT, &iters, 1, 100, .help = "CEM iterations"},
      {"seed", ND_OPT_U64, &seed, .help = "seed of the pushes and the search"},
  };
  nd_opt_spec spec = {PROG, "[options]",
                      "Fit the planning model's contact softness (solref, solimp) and tilt "
                      "damping at --plan-dt to the 1 ms world's pushes, and check the fit on "
                      "pushes it was not fitted on.",
                      "Ends with `name value unit` lines: the fitted values and the "
                      "prediction error before and after.",
                      opts, sizeof(opts) / sizeof(opts[0])};
  const int rc = nd_opt_parse(&spec, argc, argv);
  if (rc != ND_OPT_RUN) return rc;
  nd_rfile_umask_no_world_write();

  char err[512];
  int status = 1;
  nds_scene_cfg wc; /* the 1 ms world */
  nds_scene_cfg_default(&wc);
  fit_ctx f = {.world = &wc, .n = npush, .dt = dt};
  nds_ctrl_cfg_default(&f.ctrl);
  push *p = calloc(3 * (size_t)npush, sizeof(*p));
  nds_model world = {0}, slow = {0};
  mjData *d = NULL, *ds = NULL;
  nd_cem *cem = NULL;
  if (!p) {
    fprintf(stderr, PROG ": out of memory for %d pushes\n", npush);
    goto done;
  }
  f.train = p;
  /* Fitted on, checked on (same friction), checked on at half the sliding friction. */
  push *check = p + npush, *half = p + 2 * npush;
  nds_scene_cfg sc = wc;
  sc.theta[ND_TH_SLIDE] *= 0.5;
  if (nds_model_init(&world, &wc, err, sizeof(err)) ||
      nds_model_init(&slow, &sc, err, sizeof(err))) {
    fprintf(stderr, PROG ": %s\n", err);
    goto done;
  }
  if (!(d = mj_makeData(world.m)) || !(ds = mj_makeData(slow.m))) goto done;
  draw_pushes(&world, d, &f.ctrl, seed, f.train, npush);
  draw_pushes(&world, d, &f.ctrl, seed + 1000, check, npush);
  draw_pushes(&slow, ds, &f.ctrl, seed + 2000, half, npush);

  nds_scene_cfg def = wc; /* the world's contact at the planning step */
  def.timestep = dt;
  const double lo[NDIM] = {log(2.0 * dt), log(0.2), 0.5, 0.0, log(1e-4), log(0.01)};
  const double hi[NDIM] = {log(0.2), log(5.0), 0.99, 0.2, log(0.05), log(5.0)};
  const double mean[NDIM] = {log(fmax(def.solref[0], 2.0 * dt)), log(def.solref[1]),
                             def.solimp[0], def.solimp[1] - def.solimp[0],
                             log(def.solimp[2]), log(def.tilt_damping + 0.01)};
  const double std[NDIM] = {0.4, 0.5, 0.05, 0.03, 1.0, 1.0};
  nd_cem_cfg cc;
  nd_cem_cfg_default(&cc, 1, NDIM, pop, iters);
  cc.lower = lo, cc.upper = hi, cc.elite_frac = 0.2, cc.std_min = 0.01, cc.inject_mean = 1;
  if (!(cem = nd_cem_create(&cc, err, sizeof(err)))) {
    fprintf(stderr, PROG ": %s\n", err);
    goto done;
  }
  nd_cem_set_dist(cem, mean, std);
  nd_rng r;
  nd_rng_seed(&r, seed, 11);
  printf(PROG ": plan dt %.3f s, %d pushes of 0.6 s, CEM %d x %d\n", dt, npush, pop, iters);
  if (nd_cem_run(cem, &r, fit_cost, &f)) goto done;

  nds_scene_cfg fit = def;
  cfg_of(nd_cem_best(cem), dt, &fit);
  pred_err e[6];
  nds_scene_cfg def_half = def, fit_half = fit;
  def_half.theta[ND_TH_SLIDE] = fit_half.theta[ND_TH_SLIDE] = sc.theta[ND_TH_SLIDE];
  if (pred_error(&def, &f.ctrl, f.train, npush, &e[0]) ||
      pred_error(&fit, &f.ctrl, f.train, npush, &e[1]) ||
      pred_error(&def, &f.ctrl, check, npush, &e[2]) ||
      pred_error(&fit, &f.ctrl, check, npush, &e[3]) ||
      pred_error(&def_half, &f.ctrl, half, npush, &e[4]) ||
      pred_error(&fit_half, &f.ctrl, half, npush, &e[5])) {
    fprintf(stderr, PROG ": a model did not build\n");
    goto done;
  }
  printf("fitted: solref %.4g %.4g, solimp %.4g %.4g %.4g, tilt damping %.4g\n", fit.solref[0],
         fit.solref[1], fit.solimp[0], fit.solimp[1], fit.solimp[2], fit.tilt_damping);
  report("fitted pushes, world's contact:", &e[0]);
  report("fitted pushes, fitted contact:", &e[1]);
  report("other pushes, world's contact:", &e[2]);
  report("other pushes, fitted contact:", &e[3]);
  report("half friction, world's contact:", &e[4]);
  report("half friction, fitted contact:", &e[5]);
  printf("contact_solref_timeconst %.4g s\ncontact_solref_dampratio %.4g ratio\n",
         fit.solref[0], fit.solref[1]);
  printf("contact_solimp_d0 %.4g ratio\ncontact_solimp_dwidth %.4g ratio\n"
         "contact_solimp_width %.4g m\n", fit.solimp[0], fit.solimp[1], fit.solimp[2]);
  printf("contact_tilt_damping %.4g N_m_s/rad\n", fit.tilt_damping);
  printf("pred_err_check_default_mm %.1f mm\n", 1e3 * e[2].pos_med);
  printf("pred_err_check_fitted_mm %.1f mm\n", 1e3 * e[3].pos_med);
  printf("pred_err_half_default_mm %.1f mm\n", 1e3 * e[4].pos_med);
  printf("pred_err_half_fitted_mm %.1f mm\n", 1e3 * e[5].pos_med);
  status = 0;
done:
  nd_cem_free(cem);
  mj_deleteData(d);
  mj_deleteData(ds);
  nds_model_free(&slow);
  nds_model_free(&world);
  free(p);
  return status;
}
