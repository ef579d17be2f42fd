/* nds_planner: iCEM over keypoint sequences with batched MuJoCo rollouts. */
#include "nds_planner.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_exec.h"
#include "nd_math.h"

struct nds_planner {
  nds_planner_cfg cfg;       /* as it runs: v_max and the sampler as nds_planner_set_v_max left */
  nds_planner_cfg base;      /* as created */
  nds_batch *batch;
  nd_cem *cem;
  nd_rng rng;
  int dim;
  int cap;                   /* capacity of outs: nd_cem_max_batch */
  nds_rollout_out *outs;
  double *lower, *upper, *std0;
  int warm;                  /* the cem holds the previous plan's distribution */
  double last_sp0[2][4];     /* the last plan's start setpoint, for nds_planner_retime */
  /* inputs of the plan in progress, read by the cost callback */
  const nds_state *s;
  const double (*sp0)[4];
  const nd_goal *goal;
  int over_limits, over_arm; /* candidates beyond the limits in the plan in progress */
  int rollouts;              /* candidates simulated in it */
  double *feas;              /* cap x dim: the candidates within the limits, simulated */
  int *feas_idx;             /* their index in the batch */
  /* the limit checks on the pool: their candidates, and per candidate the answers */
  const double *chk_x;
  int *chk_ok, *chk_cart, *chk_arm;
  double *chk_ex;
  /* the cheapest candidate simulated in the plan in progress, and its rollout */
  double seen_cost;
  double seen_x[4 * ND_MAX_KEYS];
  nds_rollout_out seen_out;
  nd_cost_round round;       /* L_prox's way round the object (cfg.prox_round) */
};

void nds_planner_cfg_default(nds_planner_cfg *cfg) {
  memset(cfg, 0, sizeof(*cfg));
  cfg->pop = 128;
  cfg->iters = 4;
  cfg->M = 2;
  cfg->T = 0.3;
  cfg->elite_frac = 0.2;
  /* iCEM's recommended settings; with M = 2 the horizon is too short for colored noise
   * to mean anything, so it stays white. */
  cfg->keep_frac = 0.3;
  cfg->pop_decay = 1.25;
  cfg->momentum = 0.1;
  cfg->noise_beta = 0.0;
  cfg->std_init[0] = cfg->std_init[1] = 0.08;
  cfg->std_init[2] = cfg->std_init[3] = 0.25;
  cfg->std_min = 1e-3;
  cfg->ws_lo[0] = cfg->ws_lo[1] = ND_EXEC_WS_LO;  /* the executor's box: one default */
  cfg->ws_hi[0] = cfg->ws_hi[1] = ND_EXEC_WS_HI;
  cfg->key_v_max = 1.0;
  /* The Panda's Cartesian limits (1.7 m/s, 13 m/s^2: nd_exec_cfg_default) with margin, so
   * the executor never has to stretch what was planned (doc/decisions.md#planner-limits). */
  cfg->v_max = 1.5;
  cfg->a_max = 10.0;
  cfg->limit_penalty = 10.0;
  cfg->w = nd_cost_weights_default();
  nds_ctrl_cfg_default(&cfg->ctrl);
  cfg->free_flight = 1;
  /* At the limit itself: the lab's box and Cartesian limits already keep to 0.87 of the
   * joint velocity and 0.9 of the acceleration limits from rest; a margin below that
   * slowed the lab pushes (doc/decisions.md#arm-aware, #velocity-product). */
  cfg->reach_max = 1.0;
  cfg->seed = 1;
}

/* What a candidate asks of the robot (setpoint_peaks). */
typedef struct {
  double v, a;     /* peak speed (m/s) and acceleration (m/s^2) */
  double load;     /* the arm's peak load (nds_reach_load); 0 without an arm */
  double outside;  /* m beyond the workspace plus what the executor allows (<= 0: inside) */
} nds_peaks;

/* The executor refuses a segment, or the brake after it, that leaves its box plus
 * ND_EXEC_WS_MARGIN (nd_exec.h). The planner keeps this much further inside: its samples
 * are a rollout step apart (the position between them moves by up to h^2 a / 8). */
#define NDS_PLANNER_WS_SLACK 0.002

/* How far (m) position pos, and a brake from it at velocity vel (NULL: none), get beyond the
 * box plus the executor's margin less the slack. A brake from (v, 0, 0) travels 15/16 |v|
 * v / a_max (nd_exec.c), here with the planner's a_max, below the executor's. */
static double ws_outside(const nds_planner_cfg *c, const double pos[2], const double vel[2]) {
  const double m = ND_EXEC_WS_MARGIN - NDS_PLANNER_WS_SLACK;
  const double speed = vel ? hypot(vel[0], vel[1]) : 0.0;
  double worst = -INFINITY;
  for (int ax = 0; ax < 2; ax++) {
    const double brake = vel ? 15.0 / 16.0 * speed * vel[ax] / c->a_max : 0.0;
    const double lo = fmin(pos[ax], pos[ax] + brake), hi = fmax(pos[ax], pos[ax] + brake);
    worst = fmax(worst, fmax((c->ws_lo[ax] - m) - lo, hi - (c->ws_hi[ax] + m)));
  }
  return worst;
}

/* Accumulate into pk (squared v and a while accumulating) the peaks of segment seg's
 * setpoints, n samples over its duration; with early set, stop at the first beyond a
 * limit and return 1. */
static int seg_peaks(const nds_planner_cfg *c, const nd_snap_seg *seg, int n, int early,
                     nds_peaks *pk) {
  const double v2_max = c->v_max * c->v_max, a2_max = c->a_max * c->a_max;
  double sp[2][4];
  for (int j = 0; j < n; j++) {
    nd_snap_seg_eval(seg, j * seg->T / n, sp);
    const double sv = sp[0][ND_V] * sp[0][ND_V] + sp[1][ND_V] * sp[1][ND_V];
    const double sa = sp[0][ND_A] * sp[0][ND_A] + sp[1][ND_A] * sp[1][ND_A];
    const double pos[2] = {sp[0][ND_P], sp[1][ND_P]};
    if (!(sv <= pk->v)) pk->v = sv;
    if (!(sa <= pk->a)) pk->a = sa;
    const double o = ws_outside(c, pos, NULL);
    if (!(o <= pk->outside)) pk->outside = o;
    if (c->reach) {
      const double vel[2] = {sp[0][ND_V], sp[1][ND_V]}, acc[2] = {sp[0][ND_A], sp[1][ND_A]};
      const double l = nds_reach_load(c->reach, pos, vel, acc);
      if (!(l <= pk->load)) pk->load = l;
    }
    if (early && !(pk->v <= v2_max && pk->a <= a2_max && pk->load <= c->reach_max &&
                   pk->outside <= 0.0))
      return 1;
  }
  return 0;
}

/* Peaks over the setpoints of keys from sp0, sampled at the rollouts' step: speed,
 * acceleration, with an arm its load (nds_reach_load), and how far the segments, or the
 * executor's brake after the first, leave the workspace. The setpoints alone decide them:
 * no physics needed. With early set it stops at the first sample beyond a limit, its
 * peaks then only a lower bound. */
static void setpoint_peaks(const nds_planner *p, const double *keys, int early, nds_peaks *pk) {
  const nds_planner_cfg *c = &p->cfg;
  nd_snap_seg seg;
  double s[2][4];
  memcpy(s, p->sp0, sizeof(s));
  const int n = (int)ceil(c->T / nds_batch_model(p->batch, 0)->m->opt.timestep - 1e-9);
  *pk = (nds_peaks){.outside = ws_outside(c, keys, keys + 2)};
  for (int i = 0; i < c->M; i++) {
    const double *k = keys + 4 * i;
    nd_snap_seg_make(&seg, (const double(*)[4])s, k, k + 2, c->T);
    if (seg_peaks(c, &seg, n, early, pk)) break;
    nd_snap_seg_eval(&seg, c->T, s);
  }
  pk->v = sqrt(pk->v);
  pk->a = sqrt(pk->a);
}

double nds_planner_rest_time(const nds_planner *p, const double sp0[2][4], const double key[2],
                             double T) {
  const nds_planner_cfg *c = &p->cfg;
  const double h = nds_batch_model(p->batch, 0)->m->opt.timestep, zero[2] = {0.0, 0.0};
  if (!(T > 0.0)) T = h;
  for (; T <= NDS_PLANNER_REST_T_MAX; T *= 1.1) {
    nd_snap_seg seg;
    nd_snap_seg_make(&seg, sp0, key, zero, T);
    nds_peaks pk = {0};
    if (!seg_peaks(c, &seg, (int)ceil(T / h - 1e-9), 1, &pk)) return T;
  }
  return -1.0;
}

/* A candidate beyond the limits costs a step penalty plus its relative excess, which ranks
 * it behind every candidate the robot could execute (task costs are far below
 * limit_penalty; doc/decisions.md#planner-limits); as nothing can change that, it is not
 * simulated (doc/decisions.md#skip-infeasible). The others are rolled out. */
void nds_planner_cfg_fit_limits(nds_planner_cfg *cfg) {
  cfg->key_v_max = fmin(cfg->key_v_max, cfg->v_max / sqrt(2.0));
  cfg->std_init[2] = fmin(cfg->std_init[2], 0.25 * cfg->v_max);
  cfg->std_init[3] = fmin(cfg->std_init[3], 0.25 * cfg->v_max);
  cfg->T = fmax(cfg->T, fmin(NDS_PLANNER_REACH / cfg->v_max, NDS_PLANNER_T_MAX));
}

/* A candidate's relative excess over the limits, 0 within them; *cart and *arm say which
 * were broken. With early set, any positive excess only says "beyond" (setpoint_peaks). */
static double limit_excess(const nds_planner *p, const double *keys, int early, int *cart,
                           int *arm) {
  const nds_planner_cfg *c = &p->cfg;
  nds_peaks pk;
  setpoint_peaks(p, keys, early, &pk);
  double ex = fmax(0.0, pk.v / c->v_max - 1.0) + fmax(0.0, pk.a / c->a_max - 1.0) +
              fmax(0.0, pk.outside / ND_EXEC_WS_MARGIN);
  *cart = ex > 0.0;
  *arm = 0;
  if (c->reach) {
    /* The arm's joints count as its Cartesian limits; no IK counts as twice the limit. */
    const double ea = fmin(2.0, fmax(0.0, pk.load / c->reach_max - 1.0));
    *arm = ea > 0.0;
    ex += ea;
  }
  return ex;
}

/* The limit checks run on the rollouts' pool: with an arm and redraws they are about a
 * fifth of a plan's work (doc/decisions.md#plan-parallel). */
static void accept_task(void *ctx, int task, int worker) {
  (void)worker;
  nds_planner *p = ctx;
  int cart, arm;
  p->chk_ok[task] = limit_excess(p, p->chk_x + (size_t)task * p->dim, 1, &cart, &arm) <= 0.0;
}

static void excess_task(void *ctx, int task, int worker) {
  (void)worker;
  nds_planner *p = ctx;
  p->chk_ex[task] = limit_excess(p, p->chk_x + (size_t)task * p->dim, 0, &p->chk_cart[task],
                                 &p->chk_arm[task]);
}

/* Sampling keeps to what the robot can do (nd_cem's redraws): a draw beyond the limits is
 * drawn again. */
static void plan_accept(void *ctx, const double *x, int n, int *ok) {
  nds_planner *p = ctx;
  p->chk_x = x;
  p->chk_ok = ok;
  nd_pool_run(nds_batch_pool(p->batch), n, accept_task, p);
}

static int plan_cost(void *ctx, const double *x, int n, double *cost) {
  nds_planner *p = ctx;
  const nds_planner_cfg *c = &p->cfg;
  if (n > p->cap) return -1;
  p->chk_x = x;
  nd_pool_run(nds_batch_pool(p->batch), n, excess_task, p);
  int m = 0;
  for (int i = 0; i < n; i++) {
    const double ex = p->chk_ex[i];
    p->over_limits += p->chk_cart[i];
    p->over_arm += p->chk_arm[i];
    if (!(ex <= 0.0)) {
      cost[i] = c->limit_penalty * (1.0 + (isfinite(ex) ? ex : 1e3));
      continue;
    }
    memcpy(p->feas + m * p->dim, x + i * p->dim, sizeof(double) * p->dim);
    p->feas_idx[m++] = i;
  }
  if (m > 0) nds_batch_rollouts(p->batch, &c->ctrl, p->s, p->sp0, p->feas, m, c->M, c->T, p->outs);
  for (int k = 0; k < m; k++) {
    const nds_rollout_out *o = &p->outs[k];
    const int i = p->feas_idx[k];
    if (o->diverged) {
      cost[i] = INFINITY;
    } else {
      const double task =
          c->arrival > 0.0
              ? nd_cost_arrival(&c->w, p->goal, c->arrival * p->goal->eps, o->obj_at, NDS_ROLLOUT_NS)
              : nd_task_error(&c->w, p->goal, o->obj_xy, o->obj_yaw);
      cost[i] = nd_cost_plan(&c->w, p->goal, task, o->obj_at, o->ee_at, NDS_ROLLOUT_NS,
                             o->acc_sq_mean, c->prox_round ? &p->round : NULL) +
                c->w.w_edge * nd_cost_edge(&c->w, p->goal, o->obj_xy, c->ws_lo, c->ws_hi);
    }
    /* The best rollout so far, so the plan's prediction needs no rollout of its own. */
    if (cost[i] < p->seen_cost) {
      p->seen_cost = cost[i];
      p->seen_out = *o;
      memcpy(p->seen_x, x + i * p->dim, sizeof(double) * p->dim);
    }
  }
  p->rollouts += m;
  return 0;
}

/* The sampler's bounds and initial spread from cfg: keypoint positions within the
 * workspace, velocities within key_v_max. */
static void sampler_bounds(nds_planner *p) {
  const nds_planner_cfg *c = &p->cfg;
  for (int k = 0; k < c->M; k++) {
    double *lo = p->lower + 4 * k, *hi = p->upper + 4 * k;
    lo[0] = c->ws_lo[0], hi[0] = c->ws_hi[0];
    lo[1] = c->ws_lo[1], hi[1] = c->ws_hi[1];
    lo[2] = lo[3] = -c->key_v_max;
    hi[2] = hi[3] = c->key_v_max;
    memcpy(p->std0 + 4 * k, c->std_init, 4 * sizeof(double));
  }
}

nds_planner *nds_planner_create(const nds_model *model, const nds_planner_cfg *cfg,
                                nd_pool *pool, char *err, int errlen) {
  if (cfg->M < 1 || cfg->M > ND_MAX_KEYS || !(cfg->T > 0.0) || cfg->pop < 2 || cfg->iters < 1) {
    snprintf(err, errlen, "planner: need 1 <= M <= %d, T > 0, pop >= 2, iters >= 1 (got M %d, "
             "T %g, pop %d, iters %d)", ND_MAX_KEYS, cfg->M, cfg->T, cfg->pop, cfg->iters);
    return NULL;
  }
  if (!(cfg->v_max > 0.0) || !(cfg->a_max > 0.0)) {
    snprintf(err, errlen, "planner: limits must be positive (v_max %g, a_max %g)", cfg->v_max,
             cfg->a_max);
    return NULL;
  }
  nds_planner *p = calloc(1, sizeof(*p));
  if (!p) {
    snprintf(err, errlen, "planner: out of memory");
    return NULL;
  }
  p->cfg = p->base = *cfg;
  p->dim = cfg->M * 4;
  p->lower = calloc(3 * p->dim, sizeof(double));
  if (!p->lower) {
    snprintf(err, errlen, "planner: out of memory");
    nds_planner_free(p);
    return NULL;
  }
  p->upper = p->lower + p->dim;
  p->std0 = p->upper + p->dim;
  sampler_bounds(p);
  nd_cem_cfg cc;
  nd_cem_cfg_default(&cc, cfg->M, 4, cfg->pop, cfg->iters);
  cc.elite_frac = cfg->elite_frac;
  cc.keep_frac = cfg->keep_frac;
  cc.pop_decay = cfg->pop_decay;
  cc.momentum = cfg->momentum;
  cc.noise_beta = cfg->noise_beta;
  cc.std_min = cfg->std_min;
  cc.lower = p->lower;
  cc.upper = p->upper;
  cc.inject_mean = 1;
  cc.redraws = cfg->redraws;
  p->cem = nd_cem_create(&cc, err, errlen);
  if (!p->cem) {
    nds_planner_free(p);
    return NULL;
  }
  nd_cem_set_accept(p->cem, plan_accept, p);
  p->cap = nd_cem_max_batch(p->cem);
  if (!(p->outs = calloc(p->cap, sizeof(*p->outs))) ||
      !(p->feas = calloc((size_t)p->cap * p->dim, sizeof(double))) ||
      !(p->feas_idx = calloc(p->cap, sizeof(int))) ||
      !(p->chk_cart = calloc(2 * (size_t)p->cap, sizeof(int))) ||
      !(p->chk_ex = calloc(p->cap, sizeof(double)))) {
    snprintf(err, errlen, "planner: out of memory");
    nds_planner_free(p);
    return NULL;
  }
  p->chk_arm = p->chk_cart + p->cap;
  p->batch = nds_batch_create(model, pool, err, errlen);
  if (!p->batch) {
    nds_planner_free(p);
    return NULL;
  }
  nds_batch_set_free_flight(p->batch, cfg->free_flight);
  for (int k = 0; k < 2; k++) {
    p->round.half[k] = model->cfg.obj_half[k];
    p->round.lo[k] = cfg->ws_lo[k];
    p->round.hi[k] = cfg->ws_hi[k];
  }
  p->round.radius = model->cfg.ee_radius;
  nd_rng_seed(&p->rng, cfg->seed, 0);
  return p;
}

void nds_planner_free(nds_planner *p) {
  if (!p) return;
  nds_batch_free(p->batch);
  nd_cem_free(p->cem);
  free(p->outs);
  free(p->feas);
  free(p->feas_idx);
  free(p->chk_cart);
  free(p->chk_ex);
  free(p->lower);
  free(p);
}

int nds_planner_set_theta(nds_planner *p, const double theta[ND_NTHETA], char *err,
                          int errlen) {
  return nds_batch_set_theta(p->batch, theta, err, errlen);
}

const nds_planner_cfg *nds_planner_config(const nds_planner *p) { return &p->cfg; }

void nds_planner_reset(nds_planner *p) { p->warm = 0; }

int nds_planner_set_v_max(nds_planner *p, double v_max, char *err, int errlen) {
  if (!(v_max >= 0.0) || !isfinite(v_max)) {
    snprintf(err, errlen, "planner: speed limit %g m/s is not a speed (0 for the planner's own)",
             v_max);
    return -1;
  }
  nds_planner_cfg c = p->base;
  if (v_max > 0.0 && v_max < c.v_max) {
    c.v_max = v_max;
    nds_planner_cfg_fit_limits(&c);
  }
  p->cfg.v_max = c.v_max;
  p->cfg.T = c.T;
  p->cfg.key_v_max = c.key_v_max;
  memcpy(p->cfg.std_init, c.std_init, sizeof(c.std_init));
  sampler_bounds(p);
  p->warm = 0;
  return nd_cem_set_bounds(p->cem, p->lower, p->upper, err, errlen);
}

typedef struct {
  const nds_planner *p;
  double dt;
} retime_ctx;

/* The warm start's keypoints, from the last plan's start, moved dt along their path. */
static void retime_keys(void *ctx, double *x) {
  const retime_ctx *r = ctx;
  const nds_planner *p = r->p;
  nd_snap_retime((const double(*)[4])p->last_sp0, x, p->cfg.M, p->cfg.T, r->dt, x);
}

void nds_planner_retime(nds_planner *p, double dt) {
  if (!p->warm || !(dt > 0.0) || !isfinite(dt)) return;
  retime_ctx r = {p, dt};
  nd_cem_map(p->cem, retime_keys, &r);
}

int nds_planner_predict(nds_planner *p, const nds_state *s, const double (*sp)[2][4], int n,
                        nds_state *s1, char *err, int errlen) {
  return nds_predict(nds_batch_model(p->batch, 0), nds_batch_data(p->batch, 0), &p->cfg.ctrl,
                     s, sp, n, s1, err, errlen);
}

int nds_planner_plan(nds_planner *p, const nds_state *s, const double sp0[2][4],
                     const nd_goal *goal, nds_plan *out, char *err, int errlen) {
  const nds_planner_cfg *c = &p->cfg;
  const double g[3] = {goal->x, goal->y, goal->yaw};
  if (!nd_all_finite(&sp0[0][0], 8) || !nd_all_finite(g, 3) ||
      !nd_all_finite(s->obj_pos, 3) || !nd_all_finite(s->obj_quat, 4) ||
      !nd_all_finite(s->obj_vel, 6) || !nd_all_finite(s->ee_pos, 2) ||
      !nd_all_finite(s->ee_vel, 2)) {
    snprintf(err, errlen, "planner: state, setpoint or goal is not finite");
    return -1;
  }
  if (!p->warm) {
    /* Cold start: every keypoint at the current setpoint, at rest. The proximity term
     * draws the samples toward the object from there. */
    double mean[4 * ND_MAX_KEYS];
    for (int k = 0; k < c->M; k++) {
      mean[4 * k + 0] = sp0[0][0];
      mean[4 * k + 1] = sp0[1][0];
      mean[4 * k + 2] = mean[4 * k + 3] = 0.0;
    }
    nd_cem_set_dist(p->cem, mean, p->std0);
    p->warm = 1;
  } else {
    /* Re-plans come every 25-100 ms while a segment lasts 0.3-0.6 s: the previous plan's
     * keypoints are still ahead, so the mean keeps them (moved along their path by
     * nds_planner_retime where the caller knows when plans start) and only the std is
     * widened again. */
    nd_cem_shift(p->cem, 0, p->std0);
  }
  memcpy(p->last_sp0, sp0, sizeof(p->last_sp0));
  p->s = s;
  p->sp0 = sp0;
  p->goal = goal;
  p->over_limits = p->over_arm = p->rollouts = 0;
  p->seen_cost = INFINITY;
  int rc = nd_cem_run(p->cem, &p->rng, plan_cost, p);
  if (rc) {
    snprintf(err, errlen, "planner: rollout batch larger than %d", p->cap);
    return -1;
  }
  const double *best = nd_cem_best(p->cem);
  out->M = c->M;
  out->T = c->T;
  for (int k = 0; k < c->M; k++) memcpy(out->keys[k], best + 4 * k, 4 * sizeof(double));
  out->cost = nd_cem_best_cost(p->cem);
  out->evals = nd_cem_evals(p->cem);
  out->rollouts = p->rollouts;
  out->over_limits = p->over_limits;
  out->over_arm = p->over_arm;
  out->redrawn = nd_cem_redrawn(p->cem);
  /* What the best plan predicts, for logging, drawing and the plan message: the rollout
   * that ranked it, or (when the best was never simulated) its own; a diverged rollout
   * predicts the object stays where it is. */
  nds_rollout_out o;
  if (p->seen_cost == out->cost && !memcmp(p->seen_x, best, sizeof(double) * p->dim))
    o = p->seen_out;
  else
    nds_rollout(nds_batch_model(p->batch, 0), nds_batch_data(p->batch, 0), &c->ctrl, s, sp0,
                best, c->M, c->T, &o);
  out->task_error = o.diverged ? INFINITY : nd_task_error(&c->w, goal, o.obj_xy, o.obj_yaw);
  out->predicted[0] = o.diverged ? s->obj_pos[0] : o.obj_xy[0];
  out->predicted[1] = o.diverged ? s->obj_pos[1] : o.obj_xy[1];
  out->predicted[2] = o.diverged ? nds_state_yaw(s) : o.obj_yaw;
  return 0;
}
