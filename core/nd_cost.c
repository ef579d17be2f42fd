/* nd_cost: plan cost terms and terminal condition (doc/design.md#plan-cost). */
#include "nd_cost.h"

#include <math.h>

/* Default weights. Positions in metres: L_pos and L_prox in m^2 (a 10 cm error is 1e-2),
 * L_rot in [0, 1], L_acc in (m/s^2)^2 (a 10 cm rest-to-rest move in 0.3 s: mean |a|^2 31).
 * w_rot = 2e-2, the paper's lambda1: a 90 degree yaw error weighs like 14 cm of position.
 * w_prox = 5e-3 only breaks ties: it pulls the sphere to the object when no candidate
 *   touches it, yet the last centimetres of pushing outvote it.
 * w_acc = 2e-6: a smoothing preference, small next to a centimetre of progress and next
 *   to what L_prox gains when the sphere approaches at the limits (a 17 cm approach done
 *   in 0.3 s rather than 0.6 s: about 2.4e-5), so it does not slow the approach.
 * prox_lead = 8 cm, about the box's half length plus the sphere's radius: the tie-break
 *   then favours the side a push toward the goal starts from, so a sphere on the wrong side
 *   goes around instead of hovering (doc/decisions.md#prox-lead).
 * w_edge = 10: a centimetre past the goal toward the box's edge costs 1e-3, the demo's eps,
 *   where the same centimetre of L_pos costs 1e-4 (doc/decisions.md#edge-cost).
 * The arithmetic: doc/decisions.md#cost-weights. */
nd_cost_weights nd_cost_weights_default(void) {
  nd_cost_weights w = {.w_rot = 2e-2, .w_prox = 5e-3, .w_acc = 2e-6, .prox_lead = 0.08,
                       .w_edge = 10.0};
  return w;
}

double nd_cost_pos(const double obj_xy[2], const nd_goal *goal) {
  const double dx = obj_xy[0] - goal->x, dy = obj_xy[1] - goal->y;
  return dx * dx + dy * dy;
}

double nd_cost_rot(double obj_yaw, const nd_goal *goal) {
  const double s = sin(obj_yaw - goal->yaw);
  return s * s;
}

double nd_cost_prox(const double obj_xy[2], const double ee_xy[2]) {
  const double dx = obj_xy[0] - ee_xy[0], dy = obj_xy[1] - ee_xy[1];
  return dx * dx + dy * dy;
}

void nd_cost_lead_point(double lead, const nd_goal *goal, const double obj_xy[2], double p[2]) {
  const double gx = goal->x - obj_xy[0], gy = goal->y - obj_xy[1];
  const double r = fmax(hypot(gx, gy), ND_COST_LEAD_FADE);
  p[0] = obj_xy[0] - lead * gx / r;
  p[1] = obj_xy[1] - lead * gy / r;
}

double nd_cost_edge(const nd_cost_weights *w, const nd_goal *goal, const double obj_xy[2],
                    const double lo[2], const double hi[2]) {
  const double g[2] = {goal->x, goal->y};
  double e = 0.0;
  for (int i = 0; i < 2; i++) {
    const double a = fmin(lo[i] + w->prox_lead, g[i]), b = fmax(hi[i] - w->prox_lead, g[i]);
    const double d = fmax(0.0, a - obj_xy[i]) + fmax(0.0, obj_xy[i] - b);
    e += d * d;
  }
  return e;
}

/* L_prox over the horizon, not at its end: a candidate that reaches the lead point at the
 * horizon's end scores like one that gets there at once, and the receding horizon then
 * puts the sphere's arrival off at every re-plan (doc/decisions.md#prox-mean). */
double nd_cost_plan(const nd_cost_weights *w, const nd_goal *goal, double task,
                    const double (*obj_at)[3], const double (*ee_at)[2], int n,
                    double acc_sq_mean) {
  double prox = 0.0;
  for (int k = 0; k < n; k++) {
    double lead[2];
    nd_cost_lead_point(w->prox_lead, goal, obj_at[k], lead);
    prox += nd_cost_prox(lead, ee_at[k]);
  }
  return task + w->w_prox * prox / (n > 0 ? n : 1) + w->w_acc * acc_sq_mean;
}

/* The task ends the moment its error falls below eps, so a plan is worth when it gets
 * there; the final state alone rates a plan that arrives at once like one that arrives at
 * the horizon's end, and the receding horizon then puts arrival off at every re-plan
 * (doc/decisions.md#arrival). Counting only a stay below eps keeps a push that runs the
 * object through the goal from scoring as arriving. */
double nd_cost_arrival(const nd_cost_weights *w, const nd_goal *goal, double eps,
                       const double (*at)[3], int n) {
  if (!(eps > 0.0)) return nd_task_error(w, goal, at[n - 1], at[n - 1][2]);
  double stay = 0.0, best = INFINITY;
  for (int k = n - 1; k >= 0; k--) {
    const double e = nd_task_error(w, goal, at[k], at[k][2]);
    if (isnan(e)) return INFINITY;
    stay = fmax(stay, e);
    const double c = stay + eps * (stay < eps ? (double)(k + 1) / n : 1.0);
    if (c < best) best = c;
  }
  return best;
}

double nd_task_error(const nd_cost_weights *w, const nd_goal *goal, const double obj_xy[2],
                     double obj_yaw) {
  return nd_cost_pos(obj_xy, goal) + w->w_rot * nd_cost_rot(obj_yaw, goal);
}

nd_task_status nd_task_check(double task_error, double t, double eps, double tau) {
  /* isfinite first: a NaN error from a diverged simulation must never count as done. */
  if (isfinite(task_error) && task_error < eps) return ND_TASK_SUCCESS;
  if (t > tau) return ND_TASK_TIMEOUT;
  return ND_TASK_RUNNING;
}
