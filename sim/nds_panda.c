/* nds_panda: the emulated Panda's model, kinematics, control and reflexes. */
#include "nds_panda.h"

#include "nd_linalg.h"
#include "nd_math.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NJ NDS_PANDA_NJ
#define PI 3.14159265358979323846

/* ---- published data ---- */

/* Franka Emika, "Robot and interface specifications", Limits for Panda
 * (https://frankaemika.github.io/docs/control_parameters.html); the same values as
 * libfranka's include/franka/rate_limiting.h before its margins. */
const double nds_panda_q_min[NJ] = {-2.8973, -1.7628, -2.8973, -3.0718,
                                    -2.8973, -0.0175, -2.8973};
const double nds_panda_q_max[NJ] = {2.8973, 1.7628, 2.8973, -0.0698,
                                    2.8973, 3.7525, 2.8973};
const double nds_panda_dq_max[NJ] = {2.1750, 2.1750, 2.1750, 2.1750,
                                     2.6100, 2.6100, 2.6100};
const double nds_panda_ddq_max[NJ] = {15, 7.5, 10, 12.5, 15, 20, 20};
const double nds_panda_dddq_max[NJ] = {7500, 3750, 5000, 6250, 7500, 10000, 10000};
const double nds_panda_tau_max[NJ] = {87, 87, 87, 87, 12, 12, 12};

/* Same page, "Denavit-Hartenberg parameters" (Craig's convention). */
const double nds_panda_dh_a[NJ] = {0, 0, 0, 0.0825, -0.0825, 0, 0.088};
const double nds_panda_dh_d[NJ] = {0.333, 0, 0.316, 0, 0.384, 0, 0};
const double nds_panda_dh_alpha[NJ] = {0, -PI / 2, PI / 2, PI / 2, -PI / 2, PI / 2, PI / 2};

/* Link dynamics: C. Gaz, M. Cognetti, A. Oliva, P. Robuffo Giordano, A. De Luca, "Dynamic
 * Identification of the Franka Emika Panda Robot With Retrieval of Feasible Parameters
 * Using Penalty-Based Optimization", IEEE RA-L 4(4):4147-4154, 2019; the estimates p^ of
 * its supplementary material (revised 15 Oct 2019), Table VIII (mass, centre of mass) and
 * Table IX (inertia), as in github.com/marcocognetti/FrankaEmikaPandaDynModel,
 * matlab/ConvertDynPars2VREP/DynPars2VREP.m. All in DH frame i (the MuJoCo body frame);
 * the inertia is about the centre of mass with axes parallel to that frame, ordered
 * xx, xy, xz, yy, yz, zz. Table VIII marks c1z "don't care" (joint 1 turns link 1 about
 * z only, so it never enters the dynamics): 0, as in DynPars2VREP.m. */
static const double gaz_mass[NJ] = {4.970684, 0.646926, 3.228604, 3.587895,
                                    1.225946, 1.666555, 7.35522e-01};
static const double gaz_com[NJ][3] = {
    {3.875e-03, 2.081e-03, 0},          {-3.141e-03, -2.872e-02, 3.495e-03},
    {2.7518e-02, 3.9252e-02, -6.6502e-02}, {-5.317e-02, 1.04419e-01, 2.7454e-02},
    {-1.1953e-02, 4.1065e-02, -3.8437e-02}, {6.0149e-02, -1.4117e-02, -1.0517e-02},
    {1.0517e-02, -4.252e-03, 6.1597e-02}};
static const double gaz_inertia[NJ][6] = {
    {7.0337e-01, -1.3900e-04, 6.7720e-03, 7.0661e-01, 1.9169e-02, 9.1170e-03},
    {7.9620e-03, -3.9250e-03, 1.0254e-02, 2.8110e-02, 7.0400e-04, 2.5995e-02},
    {3.7242e-02, -4.7610e-03, -1.1396e-02, 3.6155e-02, -1.2805e-02, 1.0830e-02},
    {2.5853e-02, 7.7960e-03, -1.3320e-03, 1.9552e-02, 8.6410e-03, 2.8323e-02},
    {3.5549e-02, -2.1170e-03, -4.0370e-03, 2.9474e-02, 2.2900e-04, 8.6270e-03},
    {1.9640e-03, 1.0900e-04, -1.1580e-03, 4.3540e-03, 3.4100e-04, 5.4330e-03},
    {1.2516e-02, -4.2800e-04, -1.1960e-03, 1.0027e-02, -7.4100e-04, 4.8150e-03}};

/* ---- kinematics ---- */

typedef struct {
  double o[NJ][3], z[NJ][3]; /* joint i's frame origin and axis, world */
  double fpos[3], fR[9];     /* flange */
  double tool[3];            /* sphere centre */
} chain;

static void fk_chain(const nds_panda_cfg *cfg, const double q[NJ], chain *c) {
  double p[3] = {cfg->base_pos[0], cfg->base_pos[1], cfg->base_pos[2]};
  double cy = cos(cfg->base_yaw), sy = sin(cfg->base_yaw);
  double R[9] = {cy, -sy, 0, sy, cy, 0, 0, 0, 1};
  for (int i = 0; i < NJ; i++) {
    double ca = cos(nds_panda_dh_alpha[i]), sa = sin(nds_panda_dh_alpha[i]);
    double cq = cos(q[i]), sq = sin(q[i]);
    double a = nds_panda_dh_a[i], dd = nds_panda_dh_d[i];
    double t[3] = {a, -sa * dd, ca * dd};
    for (int r = 0; r < 3; r++)
      p[r] += R[3 * r] * t[0] + R[3 * r + 1] * t[1] + R[3 * r + 2] * t[2];
    /* RotX(alpha) RotZ(q) */
    double B[9] = {cq, -sq, 0, ca * sq, ca * cq, -sa, sa * sq, sa * cq, ca};
    double N[9];
    for (int r = 0; r < 3; r++)
      for (int k = 0; k < 3; k++)
        N[3 * r + k] = R[3 * r] * B[k] + R[3 * r + 1] * B[3 + k] + R[3 * r + 2] * B[6 + k];
    memcpy(R, N, sizeof(R));
    for (int r = 0; r < 3; r++) {
      c->o[i][r] = p[r];
      c->z[i][r] = R[3 * r + 2];
    }
  }
  for (int r = 0; r < 3; r++) {
    c->fpos[r] = p[r] + R[3 * r + 2] * NDS_PANDA_FLANGE_D;
    c->tool[r] = c->fpos[r] + R[3 * r + 2] * cfg->tool_length;
  }
  memcpy(c->fR, R, sizeof(R));
}

void nds_panda_fk(const nds_panda_cfg *cfg, const double q[NJ], double pos[3], double R[9],
                  double tool[3]) {
  chain c;
  fk_chain(cfg, q, &c);
  if (pos) memcpy(pos, c.fpos, sizeof(c.fpos));
  if (R) memcpy(R, c.fR, sizeof(c.fR));
  if (tool) memcpy(tool, c.tool, sizeof(c.tool));
}

static void jac_of(const chain *c, double J[35]) {
  for (int i = 0; i < NJ; i++) {
    const double *z = c->z[i];
    double r[3];
    for (int k = 0; k < 3; k++) r[k] = c->tool[k] - c->o[i][k];
    J[0 * NJ + i] = z[1] * r[2] - z[2] * r[1];
    J[1 * NJ + i] = z[2] * r[0] - z[0] * r[2];
    J[2 * NJ + i] = z[0] * r[1] - z[1] * r[0];
    J[3 * NJ + i] = z[0];
    J[4 * NJ + i] = z[1];
  }
}

void nds_panda_jac(const nds_panda_cfg *cfg, const double q[NJ], double J[35]) {
  chain c;
  fk_chain(cfg, q, &c);
  jac_of(&c, J);
}

/* The task error toward target with the tool down: position, then the rotation (world x,
 * y) that turns the tool axis z onto -z_world, z x (0, 0, -1) = (-z_y, z_x, 0), scaled
 * from its sine to the angle. */
void nds_panda_task_error(const double tool[3], const double fR[9], const double target[3],
                          double e[5]) {
  for (int k = 0; k < 3; k++) e[k] = target[k] - tool[k];
  double zx = fR[2], zy = fR[5], zz = fR[8];
  double s = sqrt(zx * zx + zy * zy), ang = atan2(s, -zz);
  double f = s > 1e-12 ? ang / s : 1.0;
  e[3] = -zy * f;
  e[4] = zx * f;
}

/* IK: damped least squares with a posture pull in the null space. LAMBDA keeps the step
 * finite through a singular pose without biasing the converged answer (the fixed point is
 * e = 0 whatever lambda); NS_GAIN moves the posture half-way toward rest per iteration;
 * MAX_STEP bounds the joint move per iteration so the linearisation holds. */
#define IK_LAMBDA 1e-3
#define IK_NS_GAIN 0.5
#define IK_MAX_STEP 0.2
#define IK_ITERS 500
#define IK_TOL 1e-9

int nds_panda_ik(const nds_panda_cfg *cfg, const double target[3], const double seed[NJ],
                 double q[NJ], char *err, int errlen) {
  const double *s = seed ? seed : cfg->q_rest;
  for (int i = 0; i < NJ; i++) q[i] = s[i];
  double e[5], enorm = INFINITY;
  for (int it = 0; it < IK_ITERS; it++) {
    chain c;
    fk_chain(cfg, q, &c);
    nds_panda_task_error(c.tool, c.fR, target, e);
    double J[35], A[25], A0[25], y[5], dq[NJ], g[NJ], jg[5];
    jac_of(&c, J);
    nd_aat(J, 5, NJ, IK_LAMBDA * IK_LAMBDA, A);
    if (nd_chol(A, 5)) break;
    nd_chol_solve(A, 5, e, y);
    /* Null-space posture step g - J' (J J')^-1 J g, undamped: a damped projector leaks
     * into the task and would hold the answer off the target. Skipped at a singularity. */
    for (int i = 0; i < NJ; i++) g[i] = IK_NS_GAIN * (cfg->q_rest[i] - q[i]);
    nd_aat(J, 5, NJ, 0, A0);
    if (nd_chol(A0, 5)) {
      memset(g, 0, sizeof(g));
      memset(jg, 0, sizeof(jg));
    } else {
      for (int r = 0; r < 5; r++) {
        jg[r] = 0;
        for (int k = 0; k < NJ; k++) jg[r] += J[r * NJ + k] * g[k];
      }
      nd_chol_solve(A0, 5, jg, jg);
    }
    double big = 0, ns = 0;
    for (int i = 0; i < NJ; i++) {
      double t = 0, u = 0;
      for (int r = 0; r < 5; r++) {
        t += J[r * NJ + i] * y[r];
        u += J[r * NJ + i] * jg[r];
      }
      dq[i] = t + g[i] - u;
      ns += (g[i] - u) * (g[i] - u);
      if (fabs(dq[i]) > big) big = fabs(dq[i]);
    }
    enorm = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3] + e[4] * e[4]);
    if (enorm < IK_TOL && sqrt(ns) < IK_TOL) {
      for (int i = 0; i < NJ; i++) {
        double lo = nds_panda_q_min[i] + NDS_PANDA_IK_MARGIN;
        double hi = nds_panda_q_max[i] - NDS_PANDA_IK_MARGIN;
        if (!(q[i] >= lo && q[i] <= hi)) {
          snprintf(err, errlen,
                   "IK: (%.3f, %.3f, %.3f): joint %d at %.3f rad, within %.2f rad of its "
                   "limits [%.4f, %.4f]",
                   target[0], target[1], target[2], i + 1, q[i], NDS_PANDA_IK_MARGIN,
                   nds_panda_q_min[i], nds_panda_q_max[i]);
          return -1;
        }
      }
      return 0;
    }
    double sc = big > IK_MAX_STEP ? IK_MAX_STEP / big : 1.0;
    for (int i = 0; i < NJ; i++) {
      q[i] += sc * dq[i];
      /* Stay inside the hard limits; the margin is checked on the answer. */
      if (q[i] < nds_panda_q_min[i]) q[i] = nds_panda_q_min[i];
      if (q[i] > nds_panda_q_max[i]) q[i] = nds_panda_q_max[i];
    }
  }
  snprintf(err, errlen,
           "IK: (%.3f, %.3f, %.3f) unreachable with the tool down: residual %.3g",
           target[0], target[1], target[2], enorm);
  return -1;
}

int nds_panda_rate_map(const nds_panda_cfg *cfg, const double q[NJ], double rates[NJ][2]) {
  double J[35], A[25];
  nds_panda_jac(cfg, q, J);
  nd_aat(J, 5, NJ, 0, A);
  if (nd_chol(A, 5)) return -1;
  /* Columns 0 and 1 of J' (J J')^-1: the joint rates of a unit sphere rate along world x
   * and along y, no tilt. */
  double ex[5] = {1, 0, 0, 0, 0}, ey[5] = {0, 1, 0, 0, 0};
  nd_chol_solve(A, 5, ex, ex);
  nd_chol_solve(A, 5, ey, ey);
  for (int i = 0; i < NJ; i++) {
    rates[i][0] = rates[i][1] = 0;
    for (int k = 0; k < 5; k++) {
      rates[i][0] += J[k * NJ + i] * ex[k];
      rates[i][1] += J[k * NJ + i] * ey[k];
    }
  }
  return 0;
}

/* max_i r |u_i| / lim_i over horizontal unit directions u of the sphere: a direction phi
 * needs cos phi of one rate plus sin phi of the other, whose largest size over phi is
 * their Euclidean norm. */
static double rate_ratio(const nds_panda_cfg *cfg, const double q[NJ], double r,
                         const double lim[NJ]) {
  double m[NJ][2];
  if (nds_panda_rate_map(cfg, q, m)) return INFINITY;
  double worst = 0;
  for (int i = 0; i < NJ; i++) {
    const double ratio = r * sqrt(m[i][0] * m[i][0] + m[i][1] * m[i][1]) / lim[i];
    if (ratio > worst) worst = ratio;
  }
  return worst;
}

double nds_panda_speed_ratio(const nds_panda_cfg *cfg, const double q[NJ], double v) {
  return rate_ratio(cfg, q, v, nds_panda_dq_max);
}

double nds_panda_accel_ratio(const nds_panda_cfg *cfg, const double q[NJ], double a) {
  return rate_ratio(cfg, q, a, nds_panda_ddq_max);
}

/* ---- configuration ---- */

/* The lab world's arm (doc/lab-world.md#reach has the search behind it). */
void nds_panda_cfg_default(nds_panda_cfg *cfg) {
  /* IK of the sphere start (-0.10, 0, 0.026) from Franka's "ready" posture (0, -pi/4, 0,
   * -3 pi/4, 0, pi/2, pi/4): elbow up over the table edge, wrist flipped down. */
  static const double q_rest[NJ] = {-0.10858, -1.18472, -0.07779, -2.69523,
                                    -0.07218, 1.51173,  0.78540};
  memset(cfg, 0, sizeof(*cfg));
  /* Behind the workspace, 0.30 m below the table top: the shoulder (0.333 above the base)
   * then sits at table height, which gives the widest band of sphere positions reachable
   * at 0.5 m/s (doc/lab-world.md#reach). */
  cfg->base_pos[0] = -0.30;
  cfg->base_pos[1] = 0.05;
  cfg->base_pos[2] = -0.30;
  cfg->base_yaw = 0;
  /* A 0.2 m rod keeps the wrist (~0.33 m up) and link 7's housing clear of the 5 cm box;
   * longer rods reach no further and load the 12 N m wrist joints more. */
  cfg->tool_length = 0.20;
  cfg->ee_radius = 0.025;
  /* A light sphere and rod with their adapter: the Panda's payload is 3 kg. */
  cfg->tool_mass = 0.25;
  memcpy(cfg->q_rest, q_rest, sizeof(q_rest));
}

double nds_panda_push_height(const nds_panda_cfg *cfg) {
  return cfg->ee_radius + NDS_EE_GAP;
}

int nds_panda_cfg_check(const nds_panda_cfg *cfg, char *err, int errlen) {
  if (!nd_all_finite(cfg->base_pos, 3) || !isfinite(cfg->base_yaw)) {
    snprintf(err, errlen, "panda: base pose not finite");
    return -1;
  }
  if (!(isfinite(cfg->ee_radius) && cfg->ee_radius > 0)) {
    snprintf(err, errlen, "panda: ee_radius = %g: must be finite and > 0", cfg->ee_radius);
    return -1;
  }
  /* The rod must be longer than the sphere is wide, or the sphere swallows the flange. */
  if (!(isfinite(cfg->tool_length) && cfg->tool_length > 2 * cfg->ee_radius)) {
    snprintf(err, errlen, "panda: tool_length = %g: must be finite and > 2 ee_radius (%g)",
             cfg->tool_length, 2 * cfg->ee_radius);
    return -1;
  }
  if (!(isfinite(cfg->tool_mass) && cfg->tool_mass > 0)) {
    snprintf(err, errlen, "panda: tool_mass = %g: must be finite and > 0", cfg->tool_mass);
    return -1;
  }
  for (int i = 0; i < NJ; i++) {
    double v = cfg->q_rest[i];
    if (!(v >= nds_panda_q_min[i] && v <= nds_panda_q_max[i])) {
      snprintf(err, errlen, "panda: q_rest[%d] = %g: outside joint %d's limits [%g, %g]", i,
               v, i + 1, nds_panda_q_min[i], nds_panda_q_max[i]);
      return -1;
    }
  }
  return 0;
}

/* ---- MJCF ---- */

/* Joint properties, the same for the seven joints. The torque loop of the real arm closes
 * on link-side torque sensors and hides most of the motors' reflected inertia and friction
 * (Gaz et al. fit link-side torques with no rotor term); what is left is modelled small:
 * ARMATURE keeps the brake law's explicit 1 ms damping stable with room on the lightest
 * joint (joint 7: ~0.005 kg m^2 of link and tool, d 15 N m s/rad: d dt / I = 0.6 with it,
 * 3 > 2 without); DAMPING (0.1 N m s/rad, integrated implicitly by MuJoCo's Euler) and
 * FRICTIONLOSS (0.1 N m) are small against Gaz et al.'s Coulomb-like friction levels
 * (0.3-1.3 N m, supplementary Table I), which the real arm's torque loop compensates. */
#define JNT_ARMATURE 0.02
#define JNT_DAMPING 0.1
#define JNT_FRICTIONLOSS 0.1

/* Drawing radii (m) of the links' capsules and the tool rod: the Panda's housings are
 * ~6 cm in radius; nothing of the arm but the sphere collides. */
#define LINK_RADIUS 0.055
#define ROD_RADIUS 0.008

/* Tool mass split: 60% in the sphere (a solid ball at the rod's end), 40% in the rod and
 * flange adapter (a uniform thin rod from the flange to the sphere). */
#define TOOL_SPHERE_SHARE 0.6

typedef struct {
  char *buf;
  int len, pos;
} writer;

static void put(writer *w, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void put(writer *w, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  int room = w->pos < w->len ? w->len - w->pos : 0;
  int n = vsnprintf(room ? w->buf + w->pos : NULL, room, fmt, ap);
  va_end(ap);
  if (n > 0) w->pos += n;
}

static int done(const writer *w, const char *what, char *err, int errlen) {
  if (w->pos >= w->len) {
    snprintf(err, errlen, "panda: %s needs %d bytes, buffer has %d", what, w->pos + 1,
             w->len);
    return -1;
  }
  return 0;
}

/* Child frame i's position in its parent (DH frame i-1): RotX(alpha) (a, 0, d). */
static void dh_pos(int i, double p[3]) {
  double ca = cos(nds_panda_dh_alpha[i]), sa = sin(nds_panda_dh_alpha[i]);
  p[0] = nds_panda_dh_a[i];
  p[1] = -sa * nds_panda_dh_d[i];
  p[2] = ca * nds_panda_dh_d[i];
}

static void put_arm(writer *w, const nds_panda_cfg *cfg) {
  const char *grey = "0.85 0.85 0.85 1", *dark = "0.25 0.25 0.25 1";
  double hy = 0.5 * cfg->base_yaw;
  put(w,
      "<body name=\"panda_link0\" pos=\"%.17g %.17g %.17g\" quat=\"%.17g 0 0 %.17g\">\n",
      cfg->base_pos[0], cfg->base_pos[1], cfg->base_pos[2], cos(hy), sin(hy));
  /* Link 0 is fixed: drawn only (its tower up to joint 2, which link 1 turns about). */
  put(w,
      "  <geom name=\"panda_link0\" type=\"cylinder\" fromto=\"0 0 0 0 0 %.17g\" "
      "size=\"%g\" contype=\"0\" conaffinity=\"0\" rgba=\"%s\"/>\n",
      nds_panda_dh_d[0] - LINK_RADIUS, 1.2 * LINK_RADIUS, grey);
  for (int i = 0; i < NJ; i++) {
    double p[3], ha = 0.5 * nds_panda_dh_alpha[i];
    const double *I = gaz_inertia[i], *c = gaz_com[i];
    dh_pos(i, p);
    int ind = 2 * (i + 1);
    put(w,
        "%*s<body name=\"panda_link%d\" pos=\"%.17g %.17g %.17g\" "
        "quat=\"%.17g %.17g 0 0\">\n",
        ind, "", i + 1, p[0], p[1], p[2], cos(ha), sin(ha));
    /* MuJoCo's fullinertia order is xx, yy, zz, xy, xz, yz. */
    put(w,
        "%*s  <inertial pos=\"%.17g %.17g %.17g\" mass=\"%.17g\" "
        "fullinertia=\"%.17g %.17g %.17g %.17g %.17g %.17g\"/>\n",
        ind, "", c[0], c[1], c[2], gaz_mass[i], I[0], I[3], I[5], I[1], I[2], I[4]);
    put(w,
        "%*s  <joint name=\"panda_joint%d\" type=\"hinge\" axis=\"0 0 1\" limited=\"true\" "
        "range=\"%.17g %.17g\" armature=\"%g\" damping=\"%g\" frictionloss=\"%g\"/>\n",
        ind, "", i + 1, nds_panda_q_min[i], nds_panda_q_max[i], JNT_ARMATURE, JNT_DAMPING,
        JNT_FRICTIONLOSS);
    /* A housing around the joint axis, and a capsule to the next frame's origin. */
    put(w,
        "%*s  <geom type=\"cylinder\" fromto=\"0 0 %g 0 0 %g\" size=\"%g\" contype=\"0\" "
        "conaffinity=\"0\" group=\"1\" rgba=\"%s\"/>\n",
        ind, "", -LINK_RADIUS, LINK_RADIUS, LINK_RADIUS, i % 2 ? grey : dark);
    double n[3] = {0, 0, NDS_PANDA_FLANGE_D};
    if (i + 1 < NJ) dh_pos(i + 1, n);
    if (n[0] * n[0] + n[1] * n[1] + n[2] * n[2] > 1e-6)
      put(w,
          "%*s  <geom type=\"capsule\" fromto=\"0 0 0 %.17g %.17g %.17g\" size=\"%g\" "
          "contype=\"0\" conaffinity=\"0\" group=\"1\" rgba=\"%s\"/>\n",
          ind, "", n[0], n[1], n[2], 0.8 * LINK_RADIUS, grey);
  }
  /* The tool on the flange (frame 7 moved along z; same axes). */
  double L = cfg->tool_length, r = cfg->ee_radius, m = cfg->tool_mass;
  double ms = TOOL_SPHERE_SHARE * m, mr = m - ms;
  double zc = (ms * L + mr * 0.5 * L) / m;
  /* Thin rod about its centre m L^2/12, sphere 2/5 m r^2; parallel axes to zc. */
  double ixx = mr * L * L / 12 + mr * (0.5 * L - zc) * (0.5 * L - zc) + 0.4 * ms * r * r +
               ms * (L - zc) * (L - zc);
  double izz = 0.4 * ms * r * r + 0.5 * mr * ROD_RADIUS * ROD_RADIUS;
  int ind = 2 * (NJ + 1);
  put(w, "%*s<site name=\"panda_flange\" pos=\"0 0 %.17g\" size=\"0.01\"/>\n", ind, "",
      NDS_PANDA_FLANGE_D);
  put(w, "%*s<body name=\"panda_tool\" pos=\"0 0 %.17g\">\n", ind, "", NDS_PANDA_FLANGE_D);
  put(w,
      "%*s  <inertial pos=\"0 0 %.17g\" mass=\"%.17g\" "
      "diaginertia=\"%.17g %.17g %.17g\"/>\n",
      ind, "", zc, m, ixx, ixx, izz);
  put(w,
      "%*s  <geom name=\"panda_rod\" type=\"cylinder\" fromto=\"0 0 0 0 0 %.17g\" "
      "size=\"%g\" contype=\"0\" conaffinity=\"0\" group=\"1\" rgba=\"%s\"/>\n",
      ind, "", L - r, ROD_RADIUS, dark);
  put(w,
      "%*s  <geom name=\"panda_sphere\" type=\"sphere\" pos=\"0 0 %.17g\" size=\"%.17g\" "
      "contype=\"1\" conaffinity=\"1\" rgba=\"0.9 0.3 0.2 1\"/>\n",
      ind, "", L, r);
  put(w, "%*s  <site name=\"tool\" pos=\"0 0 %.17g\" size=\"0.005\"/>\n", ind, "", L);
  put(w, "%*s</body>\n", ind, "");
  for (int i = NJ; i >= 0; i--) put(w, "%*s</body>\n", 2 * i, "");
}

int nds_panda_xml_body(const nds_panda_cfg *cfg, char *buf, int len, char *err,
                       int errlen) {
  if (nds_panda_cfg_check(cfg, err, errlen)) return -1;
  writer w = {buf, len, 0};
  put_arm(&w, cfg);
  return done(&w, "arm MJCF", err, errlen);
}

/* The sphere's body against the world body: every world geom (the table plane) is left
 * out, the pushed object kept. Contype bits cannot do this without changing the table's
 * or the object's bits, since both use MuJoCo's default 1/1. */
static void put_contact(writer *w) {
  put(w, "<exclude name=\"panda_sphere_world\" body1=\"world\" body2=\"panda_tool\"/>\n");
}

static void put_actuator(writer *w) {
  for (int i = 0; i < NJ; i++)
    put(w,
        "<motor name=\"panda_motor%d\" joint=\"panda_joint%d\" gear=\"1\" "
        "ctrllimited=\"true\" ctrlrange=\"%g %g\"/>\n",
        i + 1, i + 1, -nds_panda_tau_max[i], nds_panda_tau_max[i]);
}

int nds_panda_xml_contact(char *buf, int len, char *err, int errlen) {
  writer w = {buf, len, 0};
  put_contact(&w);
  return done(&w, "contact MJCF", err, errlen);
}

int nds_panda_xml_actuator(char *buf, int len, char *err, int errlen) {
  writer w = {buf, len, 0};
  put_actuator(&w);
  return done(&w, "actuator MJCF", err, errlen);
}

int nds_panda_scene_xml(const nds_panda_cfg *cfg, const nds_scene_cfg *scene, int with_box,
                        char *buf, int len, char *err, int errlen) {
  if (nds_panda_cfg_check(cfg, err, errlen)) return -1;
  nds_scene_cfg def;
  if (!scene) {
    nds_scene_cfg_default(&def);
    scene = &def;
  }
  if (nds_scene_cfg_check(scene, err, errlen)) return -1;
  writer w = {buf, len, 0};
  if (nds_scene_xml_head(scene, "nudge_lab", buf, len, &w.pos) ||
      (with_box && nds_scene_xml_object(scene, buf, len, &w.pos))) {
    snprintf(err, errlen, "panda: scene MJCF does not fit, buffer has %d bytes", len);
    return -1;
  }
  put_arm(&w, cfg);
  put(&w, "</worldbody>\n<contact>\n");
  put_contact(&w);
  put(&w, "</contact>\n<actuator>\n");
  put_actuator(&w);
  put(&w, "</actuator>\n</mujoco>\n");
  return done(&w, "scene MJCF", err, errlen);
}

mjModel *nds_panda_scene_load(const nds_panda_cfg *cfg, const nds_scene_cfg *scene,
                              int with_box, char *err, int errlen) {
  enum { XML_LEN = 16384 };
  char *xml = malloc(XML_LEN);
  /* The VFS holds mjMAXVFS file names inline (~2 MB): too big for the stack. */
  mjVFS *vfs = malloc(sizeof(mjVFS));
  mjModel *m = NULL;
  if (!xml || !vfs) {
    snprintf(err, errlen, "panda: out of memory");
    goto out;
  }
  if (nds_panda_scene_xml(cfg, scene, with_box, xml, XML_LEN, err, errlen)) goto out;
  mj_defaultVFS(vfs);
  static const char fname[] = "nudge_panda.xml";
  int n = (int)strlen(xml);
  if (mj_makeEmptyFileVFS(vfs, fname, n)) {
    snprintf(err, errlen, "panda: cannot add %s to the VFS", fname);
    goto out;
  }
  memcpy(vfs->filedata[mj_findFileVFS(vfs, fname)], xml, n);
  char lerr[512] = "";
  m = mj_loadXML(fname, vfs, lerr, sizeof(lerr));
  mj_deleteVFS(vfs);
  if (!m) snprintf(err, errlen, "panda: MuJoCo rejected the generated MJCF: %s", lerr);
out:
  free(vfs);
  free(xml);
  return m;
}

/* ---- the arm in a model ---- */

int nds_panda_resolve(nds_panda *p, const mjModel *m, const nds_panda_cfg *cfg, char *err,
                      int errlen) {
  memset(p, 0, sizeof(*p));
  if (nds_panda_cfg_check(cfg, err, errlen)) return -1;
  p->cfg = *cfg;
  char name[32];
  for (int i = 0; i <= NJ; i++) {
    snprintf(name, sizeof(name), "panda_link%d", i);
    if ((p->body[i] = mj_name2id(m, mjOBJ_BODY, name)) < 0) {
      snprintf(err, errlen, "panda: no body named \"%s\"", name);
      return -1;
    }
  }
  for (int i = 0; i < NJ; i++) {
    snprintf(name, sizeof(name), "panda_joint%d", i + 1);
    int j = mj_name2id(m, mjOBJ_JOINT, name);
    if (j < 0 || m->jnt_type[j] != mjJNT_HINGE || m->jnt_bodyid[j] != p->body[i + 1]) {
      snprintf(err, errlen, "panda: joint \"%s\" must be a hinge of body panda_link%d",
               name, i + 1);
      return -1;
    }
    p->qpos[i] = m->jnt_qposadr[j];
    p->dof[i] = m->jnt_dofadr[j];
    snprintf(name, sizeof(name), "panda_motor%d", i + 1);
    int a = p->act[i] = mj_name2id(m, mjOBJ_ACTUATOR, name);
    if (a < 0 || m->actuator_trntype[a] != mjTRN_JOINT || m->actuator_trnid[2 * a] != j ||
        m->actuator_gear[6 * a] != 1 || m->actuator_dyntype[a] != mjDYN_NONE ||
        m->actuator_gaintype[a] != mjGAIN_FIXED || m->actuator_gainprm[mjNGAIN * a] != 1 ||
        m->actuator_biastype[a] != mjBIAS_NONE) {
      snprintf(err, errlen, "panda: actuator \"%s\" must be a motor of gear 1 on %s", name,
               name);
      return -1;
    }
  }
  p->body_tool = mj_name2id(m, mjOBJ_BODY, "panda_tool");
  p->geom_sphere = mj_name2id(m, mjOBJ_GEOM, "panda_sphere");
  p->site_tool = mj_name2id(m, mjOBJ_SITE, "tool");
  p->site_flange = mj_name2id(m, mjOBJ_SITE, "panda_flange");
  if (p->body_tool < 0 || p->geom_sphere < 0 || p->site_tool < 0 || p->site_flange < 0) {
    snprintf(err, errlen, "panda: no %s",
             p->body_tool < 0     ? "body \"panda_tool\""
             : p->geom_sphere < 0 ? "geom \"panda_sphere\""
             : p->site_tool < 0   ? "site \"tool\""
                                  : "site \"panda_flange\"");
    return -1;
  }
  /* The sphere must not touch the table: its body excluded against the world body. */
  /* A signature is (body1 + 1) << 16 + body2 + 1, in either order of the pair. */
  int tb = p->body_tool + 1, found = 0;
  for (int k = 0; k < m->nexclude; k++) {
    int sig = m->exclude_signature[k];
    found |= sig == (1 << 16) + tb || sig == (tb << 16) + 1;
  }
  if (!found) {
    snprintf(err, errlen, "panda: no <exclude body1=\"world\" body2=\"panda_tool\"/>");
    return -1;
  }
  /* The controller's dJ dq comes from cfg's DH kinematics: the model must be cfg's arm. */
  mjData *d = mj_makeData(m);
  if (!d) {
    snprintf(err, errlen, "panda: out of memory for an mjData");
    return -1;
  }
  for (int i = 0; i < NJ; i++) d->qpos[p->qpos[i]] = cfg->q_rest[i];
  mj_kinematics(m, d);
  double fpos[3], tool[3], off = 0;
  nds_panda_fk(cfg, cfg->q_rest, fpos, NULL, tool);
  for (int k = 0; k < 3; k++) {
    off = fmax(off, fabs(fpos[k] - d->site_xpos[3 * p->site_flange + k]));
    off = fmax(off, fabs(tool[k] - d->site_xpos[3 * p->site_tool + k]));
  }
  mj_deleteData(d);
  if (!(off < 1e-9)) {
    snprintf(err, errlen, "panda: the model's arm is %.3g m away from cfg's (base, tool)",
             off);
    return -1;
  }
  return 0;
}

void nds_panda_set_q(const nds_panda *p, const mjModel *m, mjData *d, const double q[NJ]) {
  for (int i = 0; i < NJ; i++) {
    d->qpos[p->qpos[i]] = q[i];
    d->qvel[p->dof[i]] = 0;
    d->ctrl[p->act[i]] = 0;
    d->qacc_warmstart[p->dof[i]] = 0;
  }
  mj_forward(m, d);
}

void nds_panda_get_q(const nds_panda *p, const mjData *d, double q[NJ], double dq[NJ]) {
  for (int i = 0; i < NJ; i++) {
    if (q) q[i] = d->qpos[p->qpos[i]];
    if (dq) dq[i] = d->qvel[p->dof[i]];
  }
}

void nds_panda_apply(const nds_panda *p, mjData *d, const double tau[NJ]) {
  for (int i = 0; i < NJ; i++) d->ctrl[p->act[i]] = tau[i];
}

