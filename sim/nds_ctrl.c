/* nds_ctrl: PID with acceleration feed-forward, and velocity tracking, per axis. */
#include "nds_ctrl.h"

#include "nd_snap.h"

/* The rollout's Euler step integrates these forces explicitly (semi-implicit Euler). The
 * gains scale with the sphere's mass (nds_ctrl_reset), so per unit mass they are those
 * of NDS_CTRL_M_REF = 1 kg whatever the mass, and the bounds are those of 1 kg at the
 * coarsest step, dt_max = 10 ms. With a = kp dt^2 / m and b = kd dt / m the discrete
 * error dynamics are stable iff b < 2 and a + 2 b < 4: kd = 20 gives b = 0.2, kp = 1000
 * a = 0.1, well inside; a 1 kg sphere sees a 5 Hz loop with damping ratio 0.32, the
 * feed-forward doing most of the tracking. ki is far below the continuous limit
 * kp kd / m (2e4) and, with i_max, adds at most 10 N to lean into a pushed object's
 * friction. Velocity mode: kv dt / m = 1 at 10 ms (stable below 2), a 10 ms time constant;
 * the replay sets kv for its own step instead (nds_replay_cfg_default). */
void nds_ctrl_cfg_default(nds_ctrl_cfg *cfg) {
  cfg->kp = 1000.0;
  cfg->kd = 20.0;
  cfg->ki = 2000.0;
  cfg->i_max = 0.005;
  cfg->m_ff = 1.0;
  cfg->f_max = 40.0;
  cfg->kv = 100.0;
}

void nds_ctrl_reset(nds_ctrl *c, double mass) {
  c->integ[0] = 0;
  c->integ[1] = 0;
  c->gain = mass / NDS_CTRL_M_REF;
}

/* Clamp that lets NaN through, so a bad input shows up as a bad force, not a saturated one. */
static double clampf(double x, double lo, double hi) { return x > hi ? hi : x < lo ? lo : x; }

void nds_ctrl_pid(const nds_ctrl_cfg *cfg, nds_ctrl *c, const double sp[2][4],
                  const double pos[2], const double vel[2], double dt, double f[2]) {
  for (int k = 0; k < 2; k++) {
    double e = sp[k][ND_P] - pos[k];
    c->integ[k] = clampf(c->integ[k] + e * dt, -cfg->i_max, cfg->i_max);
    double u = cfg->m_ff * sp[k][ND_A] + cfg->kp * e + cfg->kd * (sp[k][ND_V] - vel[k]) +
               cfg->ki * c->integ[k];
    f[k] = clampf(c->gain * u, -c->gain * cfg->f_max, c->gain * cfg->f_max);
  }
}

void nds_ctrl_vel(const nds_ctrl_cfg *cfg, const nds_ctrl *c, const double v_ref[2],
                  const double vel[2], double f[2]) {
  for (int k = 0; k < 2; k++)
    f[k] = clampf(c->gain * cfg->kv * (v_ref[k] - vel[k]), -c->gain * cfg->f_max,
                  c->gain * cfg->f_max);
}
