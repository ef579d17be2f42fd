/* nds_ctrl: PID with acceleration feed-forward, and velocity tracking, per axis. */
#include "nds_ctrl.h"

#include "nd_snap.h"

/* The rollout's Euler step integrates these forces explicitly (semi-implicit Euler), so
 * the gains are bounded by the lightest sphere and coarsest step they must serve:
 * m_min = 0.2 kg, dt_max = 10 ms. With a = kp dt^2 / m and b = kd dt / m the discrete
 * error dynamics are stable iff b < 2 and a + 2 b < 4. kd = 20 gives b = 1 there (the
 * velocity error dies in one step), kp = 1000 gives a = 0.5: eigenvalues {0, 0.5}, real
 * and well inside the unit circle. The bounds only loosen for heavier spheres and finer
 * steps (the pair stays stable down to ~0.13 kg at 10 ms); a 1 kg sphere sees a
 * 5 Hz loop with damping ratio 0.32, the feed-forward doing most of the tracking.
 * ki is far below the continuous limit kp kd / m (2e4 for 1 kg) and, with i_max,
 * adds at most 10 N to lean into a pushed object's friction. */
void nds_ctrl_cfg_default(nds_ctrl_cfg *cfg) {
  cfg->kp = 1000.0;
  cfg->kd = 20.0;
  cfg->ki = 2000.0;
  cfg->i_max = 0.005;
  cfg->m_ff = 1.0;
  cfg->f_max = 40.0;
  cfg->kv = 20.0;
}

void nds_ctrl_reset(nds_ctrl *c) {
  c->integ[0] = 0;
  c->integ[1] = 0;
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
    f[k] = clampf(u, -cfg->f_max, cfg->f_max);
  }
}

void nds_ctrl_vel(const nds_ctrl_cfg *cfg, const double v_ref[2], const double vel[2],
                  double f[2]) {
  for (int k = 0; k < 2; k++)
    f[k] = clampf(cfg->kv * (v_ref[k] - vel[k]), -cfg->f_max, cfg->f_max);
}
