/* nds_planner: one MPC planning step. (state, setpoint, goal, theta, previous plan) ->
 * best keypoint sequence, by iCEM over M keypoints (x, y, vx, vy) with MuJoCo rollouts
 * on the pool. Candidates whose segments exceed the end-effector speed or acceleration
 * limits (or, with an arm's reach map, its joints'), or that the executor would refuse for
 * leaving its workspace box plus margin (a segment's overshoot, the brake after the first),
 * are penalised and not simulated, so what is planned is what the robot can execute and no
 * time goes to what it cannot. */
#ifndef NDS_PLANNER_H
#define NDS_PLANNER_H

#include <stdint.h>

#include "nd_cem.h"
#include "nd_cost.h"
#include "nds_reach.h"
#include "nds_rollout.h"

typedef struct {
  int pop, iters;           /* iCEM N and C */
  int M;                    /* keypoints per plan */
  double T;                 /* duration of each segment, s */
  double elite_frac, keep_frac, pop_decay, momentum, noise_beta;
  double std_init[4];       /* initial std of (x, y, vx, vy) */
  double std_min;
  double ws_lo[2], ws_hi[2];/* workspace bounds of keypoint positions */
  double key_v_max;         /* bound of keypoint velocities, m/s */
  double v_max, a_max;      /* end-effector limits the segments must respect */
  double limit_penalty;     /* added cost per unit of relative excess over a limit */
  nd_cost_weights w;
  double arrival;           /* > 0: the task term by arrival (nd_cost_arrival) at this share
                             * of the goal's eps; 0, the default: the final state's error,
                             * the paper's */
  int prox_round;           /* L_prox measured round the object, clear of its sides
                             * (nd_cost_round_way); 0, the default: straight, as the paper
                             * measures */
  nds_ctrl_cfg ctrl;
  int free_flight;          /* rollouts skip MuJoCo while the sphere is far from the object
                             * (nds_rollout_ff); 1 by default */
  const nds_reach *reach;   /* the arm's joint-limit map (not owned; NULL: no arm, the
                             * default): candidates loading a joint beyond reach_max are
                             * penalised as limit breakers */
  double reach_max;         /* load allowed (nds_reach_load), 1 by default */
  int redraws;              /* a fresh candidate beyond the limits is drawn again up to this
                             * many times (nd_cem_cfg.redraws); 0 by default */
  uint64_t seed;
} nds_planner_cfg;

/* Paper's simulation settings (N 128, C 4, M 2, T 0.3 s) with the project's limits
 * (doc/design.md#icem). */
void nds_planner_cfg_default(nds_planner_cfg *cfg);

typedef struct {
  double keys[ND_MAX_KEYS][4]; /* best keypoint sequence */
  int M;
  double T;
  double cost;              /* E of the best candidate (penalties included) */
  double task_error;        /* predicted L_pos + w_rot L_rot at the horizon */
  double predicted[3];      /* the object's pose (x, y, yaw) the best rollout ends at */
  int evals;                /* candidates scored */
  int rollouts;             /* of them simulated: those within the limits */
  int over_limits, over_arm; /* of them: beyond the Cartesian limits, beyond the arm's */
  int redrawn;              /* fresh candidates drawn again for being beyond the limits */
} nds_plan;

typedef struct nds_planner nds_planner;

/* Build a planner over model (copied per worker) on pool. NULL and a message on error. */
nds_planner *nds_planner_create(const nds_model *model, const nds_planner_cfg *cfg,
                                nd_pool *pool, char *err, int errlen);
void nds_planner_free(nds_planner *p);

/* Use theta for every following plan. Return 0, or -1 with a message. */
int nds_planner_set_theta(nds_planner *p, const double theta[ND_NTHETA], char *err,
                          int errlen);

/* Fit the sampler to cfg's v_max: keypoint velocities within v_max / sqrt 2 per axis (so
 * within v_max together) and a velocity spread of at most v_max / 4. Unchanged at the
 * default limits; at the lab's 0.45 m/s most candidates were beyond them otherwise
 * (doc/decisions.md#skip-infeasible). Segments last at least NDS_PLANNER_REACH / v_max
 * (at most NDS_PLANNER_T_MAX). */
void nds_planner_cfg_fit_limits(nds_planner_cfg *cfg);

/* A horizon must see the sphere round the object to where a push starts: at a slow task's
 * limit a segment lasts long enough to move it NDS_PLANNER_REACH, about the way round the
 * box's corner; a 0.3 s segment at 0.15 m/s spans 4.5 cm (doc/decisions.md#slow-reach). */
#define NDS_PLANNER_REACH 0.15  /* m */
#define NDS_PLANNER_T_MAX 1.0   /* s */

/* The configuration the planner runs with. */
const nds_planner_cfg *nds_planner_config(const nds_planner *p);

/* The next plan starts dt s after the last one: its warm start becomes the keypoints T
 * apart from dt on along the paths the last plan's distribution described, so a re-plan
 * goes on along the plan the executor follows instead of putting its keypoints off again.
 * Without a warm start (the first plan, after nds_planner_reset) it does nothing. */
void nds_planner_retime(nds_planner *p, double dt);

/* Forget the warm start (call at the start of a task). */
void nds_planner_reset(nds_planner *p);

/* Plan within end-effector speed v_max (m/s) from now on, the sampler fitted to it as
 * nds_planner_cfg_fit_limits does; 0, or a limit above the created one, restores the
 * created limit and sampler. Forgets the warm start. Return 0, or -1 with a message. */
int nds_planner_set_v_max(nds_planner *p, double v_max, char *err, int errlen);

/* The shortest duration from T on (stretched by 1.1) of a segment from setpoint sp0 to
 * rest at key whose setpoints keep to the planner's speed, acceleration, arm load and
 * workspace, as a candidate's must; -1 if none up to NDS_PLANNER_REST_T_MAX s. For a move
 * the planner does not search, as the release after a task. */
double nds_planner_rest_time(const nds_planner *p, const double sp0[2][4], const double key[2],
                             double T);
#define NDS_PLANNER_REST_T_MAX 2.0

/* Plan from state s with the executor at setpoint sp0 toward goal. Return 0, or -1 with a
 * message when the input is not finite (out untouched). */
int nds_planner_plan(nds_planner *p, const nds_state *s, const double sp0[2][4],
                     const nd_goal *goal, nds_plan *out, char *err, int errlen);

/* The state n model steps after s while the sphere tracks setpoints sp[0..n-1], one per
 * step (nds_predict with the planner's model and theta): where a plan that starts then
 * starts. Not concurrent with nds_planner_plan. Return 0, or -1 with a message. */
int nds_planner_predict(nds_planner *p, const nds_state *s, const double (*sp)[2][4], int n,
                        nds_state *s1, char *err, int errlen);

#endif
