/* nd_cost: the plan cost terms and the task's terminal condition (doc/design.md#plan-cost,
 * doc/design.md#terminal). */
#ifndef ND_COST_H
#define ND_COST_H

#include "nd_goal.h"


/* Weights of the plan cost E = L_pos + w_rot L_rot + w_prox L_prox + w_acc L_acc
 * + w_edge L_edge, and prox_lead (m): how far behind the object, seen from the goal, L_prox
 * wants the sphere (0: at the object, the paper's term). */
typedef struct {
  double w_rot, w_prox, w_acc, prox_lead, w_edge;
} nd_cost_weights;

/* Within this distance of the goal's position the lead point fades into the object: the
 * last pushes may come from any side, to turn it. */
#define ND_COST_LEAD_FADE 0.05

/* The project's default weights (nd_cost.c says why; the paper's l2, l3 are illegible). */
nd_cost_weights nd_cost_weights_default(void);

/* L_pos = |obj - goal|^2 over (x, y). */
double nd_cost_pos(const double obj_xy[2], const nd_goal *goal);

/* L_rot = sin^2(yaw - goal yaw): zero at the goal yaw and at goal yaw + pi (cuboid symmetry). */
double nd_cost_rot(double obj_yaw, const nd_goal *goal);

/* |obj - ee|^2 over (x, y); L_prox is its mean over the horizon, with the lead point for obj
 * (nd_cost_plan). */
double nd_cost_prox(const double obj_xy[2], const double ee_xy[2]);

/* The point L_prox draws the sphere to: obj - lead (goal - obj) / max(|goal - obj|,
 * ND_COST_LEAD_FADE), i.e. where a push toward the goal starts. */
void nd_cost_lead_point(double lead, const nd_goal *goal, const double obj_xy[2], double p[2]);

/* L_edge: how far (squared, m^2) the object is beyond where the sphere can still reach a
 * lead point (the sphere's box [lo, hi] shrunk by prox_lead), per axis not counting the
 * part up to the goal: a goal near the box's edge may be met, not overshot. */
double nd_cost_edge(const nd_cost_weights *w, const nd_goal *goal, const double obj_xy[2],
                    const double lo[2], const double hi[2]);

/* What L_prox needs to measure the way round the object: the box's half sides, the
 * sphere's radius and the box [lo, hi] the sphere's centre keeps to (its keypoints'). */
typedef struct {
  double half[2], radius, lo[2], hi[2];
} nd_cost_round;

/* Clearance (m) the way round keeps beyond the sphere's radius: an arm tracks its setpoint
 * some millimetres off, and a sphere grazing a side turns the box. */
#define ND_COST_ROUND_MARGIN 0.005

/* Length (m) of the shortest way for the sphere's centre from `from` to `to` round the
 * object at box = (x, y, yaw): outside the box grown by radius + ND_COST_ROUND_MARGIN,
 * turning only at the grown box's corners within [lo, hi]. An end within the grown box
 * leaves it through the nearest side, that part counted. Straight when the line is clear,
 * when `to` lies where the sphere cannot be (the box grown by the radius: near the goal the
 * lead point fades into the object) or when no way round keeps within [lo, hi]. */
double nd_cost_round_way(const nd_cost_round *r, const double box[3], const double from[2],
                         const double to[2]);

/* That way, to go along it: its length (m, straight when the line is clear) and its first
 * point after `from` into next (out of the grown box, a corner, or `to`; NULL: none), or -1
 * when there is none: `to` within the box grown by the radius, or no way within [lo, hi]. */
double nd_cost_round_next(const nd_cost_round *r, const double box[3], const double from[2],
                          const double to[2], double next[2]);

/* E of a rollout without L_edge: the task term `task` (the paper's nd_task_error of the
 * final state, or nd_cost_arrival), L_prox as the mean over the rollout's n samples of the
 * object obj_at[k] = (x, y, yaw) and the sphere ee_at[k] (each from its lead point; squared
 * straight, or with round the squared nd_cost_round_way), and L_acc = acc_sq_mean, the
 * mean of |a_ee|^2 over its steps. round NULL: straight, the paper's. */
double nd_cost_plan(const nd_cost_weights *w, const nd_goal *goal, double task,
                    const double (*obj_at)[3], const double (*ee_at)[2], int n,
                    double acc_sq_mean, const nd_cost_round *round);

/* The task term by arrival at eps (a threshold to aim at, e.g. a share of the goal's),
 * from the object's poses at[k] = (x, y, yaw) at (k + 1) / n of the horizon (at[n - 1] the
 * final): with S_k the largest task error from sample k on, the least of S_k + eps (k + 1)
 * / n where S_k < eps, else the final error + eps. A plan that meets eps and keeps it
 * scores by when (under 2 eps, every other one above); the final error alone if eps <= 0. */
double nd_cost_arrival(const nd_cost_weights *w, const nd_goal *goal, double eps,
                       const double (*at)[3], int n);

/* Task error L_pos + w_rot L_rot, the quantity the terminal condition compares to eps. */
double nd_task_error(const nd_cost_weights *w, const nd_goal *goal, const double obj_xy[2],
                     double obj_yaw);

typedef enum { ND_TASK_RUNNING = 0, ND_TASK_SUCCESS = 1, ND_TASK_TIMEOUT = 2 } nd_task_status;

/* Terminal condition: success when task_error < eps, timeout when t > tau, else running.
 * Success wins when both hold. A non-finite error counts as not reached. */
nd_task_status nd_task_check(double task_error, double t, double eps, double tau);

#endif
