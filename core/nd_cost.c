/* nd_cost: plan cost terms and terminal condition (DESIGN.md sec. 4). */
#include "nd_cost.h"

#include <math.h>

/* Default weights. Units: positions in metres, so L_pos and L_prox are in m^2 (a 10 cm
 * error is 1e-2); L_rot is dimensionless in [0, 1]; L_acc in (m/s^2)^2: a rest-to-rest
 * minimum-snap move of 10 (20) cm in 0.3 s peaks at 8 (17) m/s^2 with mean |a|^2 31 (126),
 * 30 cm in 0.6 s has mean |a|^2 18.
 *
 * w_rot = 2e-2: the paper's lambda1 (its OCR reads "2*10^-2"). A 90 degree yaw error
 *   then weighs like a 14 cm position error, and with eps = 1e-2 it admits up to 45
 *   degrees at an exact position; tighten it here if orientation matters more.
 * w_prox = 5e-3: the proximity term must only break ties. When no candidate touches
 *   the object, L_pos is the same for all and any positive weight pulls the EE in:
 *   0.3 m -> contact gains ~0.09 m^2 * 5e-3 = 4.4e-4, 2.5x the 1.8e-4 that w_acc
 *   charges for that approach in 0.6 s. When candidates do push, a 5 mm push at 5 cm
 *   from the goal gains 2 * 0.05 * 0.005 = 5e-4 in L_pos, while EE placements around
 *   the object differ by ~0.02 m^2 of L_prox -> 1e-4: pushing still wins. 5e-2 would
 *   let proximity outvote the last centimetres of pushing.
 * w_acc = 1e-5: mean |a|^2 of 20..130 costs 2e-4..1.3e-3, a smoothing preference that
 *   is small next to a centimetre of progress 20 cm from the goal (4e-3) and does not
 *   forbid the accelerations a push needs. */
nd_cost_weights nd_cost_weights_default(void) {
  nd_cost_weights w = {.w_rot = 2e-2, .w_prox = 5e-3, .w_acc = 1e-5};
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

double nd_cost_plan(const nd_cost_weights *w, const nd_goal *goal, const double obj_xy[2],
                    double obj_yaw, const double ee_xy[2], double acc_sq_mean) {
  return nd_task_error(w, goal, obj_xy, obj_yaw) + w->w_prox * nd_cost_prox(obj_xy, ee_xy) +
         w->w_acc * acc_sq_mean;
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
