/* nds_panda_ctrl: the emulated Panda's controllers and reflexes (nds_panda.h). */
#include "nds_panda.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_linalg.h"
#include "nd_math.h"

#define NJ NDS_PANDA_NJ

/* ---- control ---- */

/* Gains. Over the workspace the sphere's task inertia (the position rows of (J M^-1 J')^-1
 * with the tilt rows held) is 4-13 kg (doc/lab-world.md#controller). K_T 2000 N/m makes the arm yield
 * ~2.5 mm to the ~5 N of a 0.5 kg box sliding at friction 1, as a compliant arm should;
 * D_T = 2 sqrt(K_T m) with m = 8 kg damps it about critically (libfranka's example's
 * rule, 2 sqrt(K), with the unit mass it assumes replaced by the arm's). K_R 150 N m/rad
 * keeps the tool within ~0.25 degrees of vertical on the scripted pushes. D_R is critical
 * for 0.1 kg m^2, below the tilt rows' 0.3-1.3: the critical ~25 N m s/rad puts joint 6 at
 * its 12 N m limit when the sphere strikes the box. The null-space pull (k 10 N m/rad, d 1
 * N m s/rad) brings the elbow's and wrist's self-motion back to within ~0.005 rad of rest
 * after the scripted run, where without it joint 1 ends 0.3 rad away; franka_ros's
 * 2 sqrt(k) = 6.3 N m s/rad tracks as well but is slower back (0.018 rad). */
#define GAIN_K_T 2000.0
#define GAIN_M_T 8.0
#define GAIN_K_R 150.0
#define GAIN_I_R 0.1
#define GAIN_K_NS 10.0
#define GAIN_D_NS 1.0

void nds_panda_gains_default(nds_panda_gains *g) {
  g->k_t = GAIN_K_T;
  g->d_t = 2 * sqrt(GAIN_K_T * GAIN_M_T);
  g->k_r = GAIN_K_R;
  g->d_r = 2 * sqrt(GAIN_K_R * GAIN_I_R);
  g->k_ns = GAIN_K_NS;
  g->d_ns = GAIN_D_NS;
  g->accel_ff = 1;
}

int nds_panda_ctrl_init(nds_panda_ctrl *c, const mjModel *m, const nds_panda_gains *g,
                        char *err, int errlen) {
  memset(c, 0, sizeof(*c));
  const double v[6] = {g->k_t, g->d_t, g->k_r, g->d_r, g->k_ns, g->d_ns};
  static const char *name[6] = {"k_t", "d_t", "k_r", "d_r", "k_ns", "d_ns"};
  for (int i = 0; i < 6; i++) {
    if (!(isfinite(v[i]) && v[i] >= 0)) {
      snprintf(err, errlen, "panda: gain %s = %g: must be finite and >= 0", name[i], v[i]);
      return -1;
    }
  }
  c->g = *g;
  c->nv = m->nv;
  size_t n = (size_t)m->nv;
  c->jacp = calloc(3 * n, sizeof(mjtNum));
  c->jacr = calloc(3 * n, sizeof(mjtNum));
  c->rows = calloc(5 * n, sizeof(mjtNum));
  c->minv = calloc(5 * n, sizeof(mjtNum));
  if (!c->jacp || !c->jacr || !c->rows || !c->minv) {
    nds_panda_ctrl_free(c);
    snprintf(err, errlen, "panda: out of memory for the controller");
    return -1;
  }
  return 0;
}

void nds_panda_ctrl_free(nds_panda_ctrl *c) {
  free(c->jacp);
  free(c->jacr);
  free(c->rows);
  free(c->minv);
  c->jacp = c->jacr = c->rows = c->minv = NULL;
}

/* dJ(q) dq / dt along dq, the task acceleration at zero joint acceleration, by a central
 * difference of the DH Jacobian over a step of JDOT_STEP rad in the direction of dq:
 * truncation ~step^2, rounding ~1e-16 / step, both far below a micrometre per second^2. */
#define JDOT_STEP 1e-5

static void jdot_qdot(const nds_panda_cfg *cfg, const double q[NJ], const double dq[NJ],
                      double b[5]) {
  double n = 0;
  for (int i = 0; i < NJ; i++) n = fmax(n, fabs(dq[i]));
  for (int k = 0; k < 5; k++) b[k] = 0;
  if (!(n > 1e-12) || !isfinite(n)) return;
  double h = JDOT_STEP / n, qp[NJ], qm[NJ], Jp[35], Jm[35];
  for (int i = 0; i < NJ; i++) {
    qp[i] = q[i] + h * dq[i];
    qm[i] = q[i] - h * dq[i];
  }
  nds_panda_jac(cfg, qp, Jp);
  nds_panda_jac(cfg, qm, Jm);
  for (int k = 0; k < 5; k++)
    for (int i = 0; i < NJ; i++)
      b[k] += (Jp[k * NJ + i] - Jm[k * NJ + i]) * dq[i] / (2 * h);
}

/* Clamp tau to the torque limits; return the mask of clamped joints. NaN passes through,
 * so a bad input shows as a bad torque rather than a saturated one. */
static int saturate(double tau[NJ]) {
  int mask = 0;
  for (int i = 0; i < NJ; i++) {
    double t = nds_panda_tau_max[i];
    if (tau[i] > t) tau[i] = t, mask |= 1 << i;
    if (tau[i] < -t) tau[i] = -t, mask |= 1 << i;
  }
  return mask;
}

/* Damping of J J' in the null-space projector: negligible against its ~0.01-1 entries
 * away from singularities, it keeps the factorisation defined at one. */
#define NS_LAMBDA2 1e-6

int nds_panda_ctrl_impedance(nds_panda_ctrl *c, const nds_panda *p, const mjModel *m,
                             mjData *d, const double p_des[3], const double v_des[3],
                             const double a_des[3], double tau[NJ]) {
  const int nv = m->nv;
  const nds_panda_gains *g = &c->g;
  double q[NJ], dq[NJ], J[35], e[5], v[5], F[5];
  if (nv != c->nv) {
    for (int i = 0; i < NJ; i++) tau[i] = d->qfrc_bias[p->dof[i]];
    return -1;
  }
  nds_panda_get_q(p, d, q, dq);
  mj_jacSite(m, d, c->jacp, c->jacr, p->site_tool);
  for (int i = 0; i < NJ; i++) {
    int k = p->dof[i];
    J[0 * NJ + i] = c->jacp[0 * nv + k];
    J[1 * NJ + i] = c->jacp[1 * nv + k];
    J[2 * NJ + i] = c->jacp[2 * nv + k];
    J[3 * NJ + i] = c->jacr[0 * nv + k];
    J[4 * NJ + i] = c->jacr[1 * nv + k];
  }
  nds_panda_task_error(d->site_xpos + 3 * p->site_tool, d->site_xmat + 9 * p->site_tool, p_des, e);
  for (int r = 0; r < 5; r++) {
    v[r] = 0;
    for (int i = 0; i < NJ; i++) v[r] += J[r * NJ + i] * dq[i];
  }
  for (int k = 0; k < 3; k++) F[k] = g->k_t * e[k] + g->d_t * (v_des[k] - v[k]);
  for (int k = 3; k < 5; k++) F[k] = g->k_r * e[k] - g->d_r * v[k];

  /* Feed-forward Lambda ((a_des, 0, 0) - dJ dq), Lambda = (J M^-1 J')^-1 the task inertia:
   * with qfrc_bias cancelling the joint-space Coriolis and gravity, the force that gives
   * the sphere a_des and the tilt no acceleration. dJ dq, the task acceleration the joint
   * velocities make by themselves (~v^2 / 0.3 m: ~3 mm of lag at 0.5 m/s uncompensated),
   * comes from the DH kinematics. The arm's dofs are a tree of their own, so M^-1 J' has
   * no entries outside them. */
  if (g->accel_ff) {
    double L[25], f[5] = {0, 0, 0, 0, 0}, b[5];
    if (a_des)
      for (int k = 0; k < 3; k++) f[k] = a_des[k];
    jdot_qdot(&p->cfg, q, dq, b);
    for (int k = 0; k < 5; k++) f[k] -= b[k];
    mju_zero(c->rows, 5 * nv);
    for (int r = 0; r < 5; r++)
      for (int i = 0; i < NJ; i++) c->rows[r * nv + p->dof[i]] = J[r * NJ + i];
    mj_solveM(m, d, c->minv, c->rows, 5);
    for (int r = 0; r < 5; r++)
      for (int s = 0; s <= r; s++) {
        double t = 0;
        for (int i = 0; i < NJ; i++) t += J[r * NJ + i] * c->minv[s * nv + p->dof[i]];
        L[r * 5 + s] = L[s * 5 + r] = t;
      }
    if (!nd_chol(L, 5)) {
      nd_chol_solve(L, 5, f, f);
      for (int k = 0; k < 5; k++) F[k] += f[k];
    }
  }

  /* tau = J' F + (I - J' (J J')^-1 J) tau_ns + bias: libfranka's Cartesian impedance
   * example with franka_ros's null-space term (cartesian_impedance_example_controller.cpp),
   * whose pseudo-inverse of J' is (J J')^-1 J. */
  double A[25], gns[NJ], jg[5] = {0, 0, 0, 0, 0};
  for (int i = 0; i < NJ; i++)
    gns[i] = g->k_ns * (p->cfg.q_rest[i] - q[i]) - g->d_ns * dq[i];
  nd_aat(J, 5, NJ, NS_LAMBDA2, A);
  int ns_ok = !nd_chol(A, 5);
  if (ns_ok) {
    for (int r = 0; r < 5; r++) {
      jg[r] = 0;
      for (int i = 0; i < NJ; i++) jg[r] += J[r * NJ + i] * gns[i];
    }
    nd_chol_solve(A, 5, jg, jg);
  }
  for (int i = 0; i < NJ; i++) {
    double t = 0, u = 0;
    for (int r = 0; r < 5; r++) {
      t += J[r * NJ + i] * F[r];
      u += J[r * NJ + i] * jg[r];
    }
    tau[i] = t + (ns_ok ? gns[i] - u : 0) + d->qfrc_bias[p->dof[i]];
  }
  return saturate(tau);
}

/* libfranka's examples/joint_impedance_control.cpp gains (k_gains, d_gains). */
const double nds_panda_brake_kp[NJ] = {600, 600, 600, 600, 250, 150, 50};
const double nds_panda_brake_kd[NJ] = {50, 50, 50, 50, 30, 25, 15};

int nds_panda_ctrl_brake(const nds_panda *p, const mjData *d, const double q_hold[NJ],
                         double tau[NJ]) {
  for (int i = 0; i < NJ; i++) {
    int k = p->dof[i];
    tau[i] = nds_panda_brake_kp[i] * (q_hold[i] - d->qpos[p->qpos[i]]) -
             nds_panda_brake_kd[i] * d->qvel[k] + d->qfrc_bias[k];
  }
  return saturate(tau);
}

/* ---- reflexes ---- */

/* libfranka include/franka/rate_limiting.h: every limit is checked kLimitEps inside the
 * published one, and velocities a further kTolNumberPacketsLost cycles of the maximum
 * acceleration inside (the robot assumes constant acceleration over lost packets). */
#define LIMIT_EPS 1e-3
#define PACKETS_LOST 3.0

void nds_panda_monitor_reset(nds_panda_monitor *mo, double dt, int accel_window) {
  memset(mo, 0, sizeof(*mo));
  mo->dt = dt;
  int w = accel_window < 0 ? 0 : accel_window;
  mo->accel_window = w > NDS_PANDA_ACCEL_WINDOW_MAX ? NDS_PANDA_ACCEL_WINDOW_MAX : w;
}

void nds_panda_monitor_new_motion(nds_panda_monitor *mo) { mo->n_p = 0; }

static void set_reflex(nds_panda_reflex *r, nds_panda_reflex_kind kind, int joint,
                       double value, double limit) {
  if (r->kind != NDS_PANDA_REFLEX_NONE) return;
  r->kind = kind;
  r->joint = joint;
  r->value = value;
  r->limit = limit;
}

int nds_panda_monitor_check(nds_panda_monitor *mo, const double q[NJ], const double dq[NJ],
                            const double p_cmd[3], nds_panda_reflex *r) {
  const double dt = mo->dt, eps = LIMIT_EPS;
  r->kind = NDS_PANDA_REFLEX_NONE;
  r->joint = -1;
  r->value = r->limit = 0;
  if (!nd_all_finite(q, NJ) || !nd_all_finite(dq, NJ) || !nd_all_finite(p_cmd, 3)) {
    set_reflex(r, NDS_PANDA_REFLEX_NONFINITE, -1, NAN, 0);
    return 1;
  }
  for (int i = 0; i < NJ; i++) {
    double lo = nds_panda_q_min[i] + eps, hi = nds_panda_q_max[i] - eps;
    if (q[i] < lo) set_reflex(r, NDS_PANDA_REFLEX_JOINT_POSITION, i, q[i], lo);
    if (q[i] > hi) set_reflex(r, NDS_PANDA_REFLEX_JOINT_POSITION, i, q[i], hi);
  }
  for (int i = 0; i < NJ; i++) {
    double a_max = nds_panda_ddq_max[i] - eps;
    double v_max = nds_panda_dq_max[i] - eps - PACKETS_LOST * dt * a_max;
    if (fabs(dq[i]) > v_max)
      set_reflex(r, NDS_PANDA_REFLEX_JOINT_VELOCITY, i, dq[i], copysign(v_max, dq[i]));
  }
  /* The last window + 1 velocities in a ring: once full, the slot after the newest holds
   * the one `window` cycles back. */
  const int w = mo->accel_window, slots = w + 1;
  if (w > 0) {
    memcpy(mo->dq_hist[mo->head], dq, NJ * sizeof(double));
    if (mo->n_dq >= w) {
      const double *old = mo->dq_hist[(mo->head + 1) % slots];
      for (int i = 0; i < NJ; i++) {
        double a = (dq[i] - old[i]) / (w * dt), a_max = nds_panda_ddq_max[i] - eps;
        if (fabs(a) > a_max)
          set_reflex(r, NDS_PANDA_REFLEX_JOINT_ACCELERATION, i, a, copysign(a_max, a));
      }
    }
    mo->head = (mo->head + 1) % slots;
    if (mo->n_dq < w) mo->n_dq++;
  }

  /* Commanded position history, newest first: its 1st, 2nd and 3rd backward differences
   * are the setpoint's velocity, acceleration and jerk, as the robot sees a command. */
  memmove(mo->p_hist[1], mo->p_hist[0], 3 * sizeof(mo->p_hist[0]));
  memcpy(mo->p_hist[0], p_cmd, sizeof(mo->p_hist[0]));
  if (mo->n_p < 4) mo->n_p++;
  const double(*h)[3] = (const double(*)[3])mo->p_hist;
  double nv = 0, na = 0, nj = 0;
  for (int k = 0; k < 3; k++) {
    if (mo->n_p >= 2) nv += pow((h[0][k] - h[1][k]) / dt, 2);
    if (mo->n_p >= 3) na += pow((h[0][k] - 2 * h[1][k] + h[2][k]) / (dt * dt), 2);
    if (mo->n_p >= 4)
      nj += pow((h[0][k] - 3 * h[1][k] + 3 * h[2][k] - h[3][k]) / (dt * dt * dt), 2);
  }
  double a_max = NDS_PANDA_CART_A_MAX - eps;
  double v_max = NDS_PANDA_CART_V_MAX - eps - PACKETS_LOST * dt * a_max;
  double j_max = NDS_PANDA_CART_J_MAX - eps;
  if (sqrt(nv) > v_max) set_reflex(r, NDS_PANDA_REFLEX_CART_VELOCITY, -1, sqrt(nv), v_max);
  if (sqrt(na) > a_max)
    set_reflex(r, NDS_PANDA_REFLEX_CART_ACCELERATION, -1, sqrt(na), a_max);
  if (sqrt(nj) > j_max) set_reflex(r, NDS_PANDA_REFLEX_CART_JERK, -1, sqrt(nj), j_max);
  return r->kind != NDS_PANDA_REFLEX_NONE;
}

const char *nds_panda_reflex_name(const nds_panda_reflex *r, char *buf, int len) {
  const char *what = "none";
  switch (r->kind) {
    case NDS_PANDA_REFLEX_NONE: break;
    case NDS_PANDA_REFLEX_JOINT_POSITION: what = "position"; break;
    case NDS_PANDA_REFLEX_JOINT_VELOCITY: what = "velocity"; break;
    case NDS_PANDA_REFLEX_JOINT_ACCELERATION: what = "acceleration"; break;
    case NDS_PANDA_REFLEX_CART_VELOCITY: what = "Cartesian velocity"; break;
    case NDS_PANDA_REFLEX_CART_ACCELERATION: what = "Cartesian acceleration"; break;
    case NDS_PANDA_REFLEX_CART_JERK: what = "Cartesian jerk"; break;
    case NDS_PANDA_REFLEX_NONFINITE: what = "non-finite input"; break;
    default: what = "unknown reflex"; break;
  }
  int joint_kind = r->kind == NDS_PANDA_REFLEX_JOINT_POSITION ||
                   r->kind == NDS_PANDA_REFLEX_JOINT_VELOCITY ||
                   r->kind == NDS_PANDA_REFLEX_JOINT_ACCELERATION;
  if (joint_kind)
    snprintf(buf, len, "joint %d %s", r->joint + 1, what);
  else
    snprintf(buf, len, "%s", what);
  return buf;
}
