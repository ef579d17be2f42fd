/* nds_ctrl: the end-effector's low-level tracking controller (the robot's, not the model's).
 *
 * In simulation the sphere is driven by a force on its two slide joints: a PID toward the
 * min-snap setpoint with acceleration feed-forward. The velocity mode tracks a recorded
 * end-effector velocity, for replaying a real robot's rollouts. Gains are the robot's,
 * given for a sphere of NDS_CTRL_M_REF; a model whose sphere mass differs (a fitted mass
 * standing for a stiff arm, as the paper's real-robot fit) scales them with it, so the
 * sphere tracks its setpoint alike and only what it meets feels the mass. */
#ifndef NDS_CTRL_H
#define NDS_CTRL_H

typedef struct {
  double kp, kd, ki;  /* N/m, N s/m, N/(m s) */
  double i_max;       /* anti-windup bound on the integral, m s */
  double m_ff;        /* acceleration feed-forward mass, kg */
  double f_max;       /* force saturation per axis, N */
  double kv;          /* velocity mode gain, N s/m */
} nds_ctrl_cfg;

/* kp 1000, kd 20, ki 2000, i_max 5 mm s, m_ff 1 kg, f_max 40 N, kv 100 (for
 * NDS_CTRL_M_REF): stable at timesteps up to 10 ms (the bound is explained in nds_ctrl.c). */
void nds_ctrl_cfg_default(nds_ctrl_cfg *cfg);

#define NDS_CTRL_M_REF 1.0  /* kg: the sphere mass the gains are for */

typedef struct {
  double integ[2];
  double gain;        /* sphere mass / NDS_CTRL_M_REF: every gain and the force bound */
} nds_ctrl;

/* Zero the controller's memory and make it the controller of a sphere of mass kg (> 0):
 * gains and force bound scaled by mass / NDS_CTRL_M_REF. */
void nds_ctrl_reset(nds_ctrl *c, double mass);

/* PID force f[2] toward setpoint sp[axis][p, v, a, j] from sphere position and velocity,
 * advancing the integral by dt. */
void nds_ctrl_pid(const nds_ctrl_cfg *cfg, nds_ctrl *c, const double sp[2][4],
                  const double pos[2], const double vel[2], double dt, double f[2]);

/* Velocity-tracking force toward v_ref[2]. */
void nds_ctrl_vel(const nds_ctrl_cfg *cfg, const nds_ctrl *c, const double v_ref[2],
                  const double vel[2], double f[2]);

#endif
