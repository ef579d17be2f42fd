/* nd_cost: plan cost terms and terminal condition (doc/design.md#plan-cost). */
#include "nd_cost.h"

#include <math.h>
#include <string.h>

#include "nd_math.h"

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

/* Whether the segment p-q (box frame) passes through the open rectangle |x| < h[0],
 * |y| < h[1]: Liang-Barsky clipping to both slabs, a touch along a side not counted. */
static int round_blocked(const double p[2], const double q[2], const double h[2]) {
  double t0 = 0.0, t1 = 1.0;
  for (int k = 0; k < 2; k++) {
    const double d = q[k] - p[k];
    if (fabs(d) < 1e-12) {
      if (!(fabs(p[k]) < h[k])) return 0;
      continue;
    }
    double a = (-h[k] - p[k]) / d, b = (h[k] - p[k]) / d;
    if (a > b) {
      const double t = a;
      a = b;
      b = t;
    }
    t0 = fmax(t0, a);
    t1 = fmin(t1, b);
    if (t1 - t0 <= 1e-9) return 0;
  }
  return 1;
}

double nd_cost_round_next(const nd_cost_round *r, const double box[3], const double from[2],
                          const double to[2], double next[2]) {
  enum { FROM, TO, NV = 6 };
  const double c = cos(box[2]), s = sin(box[2]), grow = r->radius + ND_COST_ROUND_MARGIN;
  const double h[2] = {r->half[0] + grow, r->half[1] + grow};
  /* Vertices: the two ends and the grown box's corners, in the box's frame (p) and the
   * world's (w). They sit a hair outside it, so a way along a side is not blocked. */
  const double hair = 1.0 + 1e-6;
  double p[NV][2], w[NV][2];
  int usable[NV], prev[NV];
  const double *end[2] = {from, to};
  double out = 0.0;
  int from_out = 0; /* `from` within the grown box: the way's first point is out of it */
  for (int i = FROM; i <= TO; i++) {
    const double d[2] = {end[i][0] - box[0], end[i][1] - box[1]};
    nd_rot2(c, -s, d, p[i]);
    if (i == TO && fabs(p[i][0]) < r->half[0] + r->radius &&
        fabs(p[i][1]) < r->half[1] + r->radius)
      return -1.0;
    const double in0 = h[0] - fabs(p[i][0]), in1 = h[1] - fabs(p[i][1]);
    if (in0 > 0.0 && in1 > 0.0) {
      const int ax = in0 <= in1 ? 0 : 1;
      out += ax == 0 ? in0 : in1;
      p[i][ax] = copysign(h[ax] * hair, p[i][ax]);
      from_out |= i == FROM;
    }
    usable[i] = 1;
  }
  if (!round_blocked(p[FROM], p[TO], h)) {
    if (next && from_out) {
      nd_rot2(c, s, p[FROM], next);
      next[0] += box[0];
      next[1] += box[1];
    } else if (next) {
      memcpy(next, to, 2 * sizeof(double));
    }
    return nd_dist2(from, to);
  }
  for (int k = 0; k < 4; k++) {
    p[2 + k][0] = (k & 1 ? 1.0 : -1.0) * h[0] * hair;
    p[2 + k][1] = (k & 2 ? 1.0 : -1.0) * h[1] * hair;
  }
  for (int i = 0; i < NV; i++) {
    nd_rot2(c, s, p[i], w[i]);
    w[i][0] += box[0];
    w[i][1] += box[1];
    if (i > TO)
      usable[i] = w[i][0] >= r->lo[0] && w[i][0] <= r->hi[0] && w[i][1] >= r->lo[1] &&
                  w[i][1] <= r->hi[1];
  }
  /* Dijkstra on the six vertices, an edge wherever the grown box does not block it. */
  double dist[NV];
  int done[NV] = {0};
  for (int i = 0; i < NV; i++) {
    dist[i] = INFINITY;
    prev[i] = -1;
  }
  dist[FROM] = 0.0;
  for (;;) {
    int u = -1;
    for (int i = 0; i < NV; i++)
      if (usable[i] && !done[i] && isfinite(dist[i]) && (u < 0 || dist[i] < dist[u])) u = i;
    if (u < 0 || u == TO) break;
    done[u] = 1;
    for (int v = 0; v < NV; v++) {
      if (!usable[v] || done[v] || round_blocked(p[u], p[v], h)) continue;
      const double d = dist[u] + nd_dist2(w[u], w[v]);
      if (d < dist[v]) {
        dist[v] = d;
        prev[v] = u;
      }
    }
  }
  if (!isfinite(dist[TO])) return -1.0;
  if (next) {
    /* The way's first point that is not where it starts: a start on a corner (the point
     * the last move went to) reaches that corner first, a hop of length 0. */
    int first = TO;
    for (int v = TO; v != FROM; v = prev[v])
      if (nd_dist2(w[v], w[FROM]) > 1e-9) first = v;
    memcpy(next, from_out ? w[FROM] : w[first], 2 * sizeof(double));
  }
  return dist[TO] + out;
}

double nd_cost_round_way(const nd_cost_round *r, const double box[3], const double from[2],
                         const double to[2]) {
  const double d = nd_cost_round_next(r, box, from, to, NULL);
  return d < 0.0 ? nd_dist2(from, to) : d;
}

/* L_prox over the horizon, not at its end: a candidate that reaches the lead point at the
 * horizon's end scores like one that gets there at once, and the receding horizon then
 * puts the sphere's arrival off at every re-plan (doc/decisions.md#prox-mean). */
double nd_cost_plan(const nd_cost_weights *w, const nd_goal *goal, double task,
                    const double (*obj_at)[3], const double (*ee_at)[2], int n,
                    double acc_sq_mean, const nd_cost_round *round) {
  double prox = 0.0;
  for (int k = 0; k < n; k++) {
    double lead[2];
    nd_cost_lead_point(w->prox_lead, goal, obj_at[k], lead);
    if (round) {
      const double d = nd_cost_round_way(round, obj_at[k], ee_at[k], lead);
      prox += d * d;
    } else {
      prox += nd_cost_prox(lead, ee_at[k]);
    }
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
