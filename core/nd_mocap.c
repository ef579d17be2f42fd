/* nd_mocap: noise, latency and drops of an emulated motion capture (nd_mocap.h). */
#include "nd_mocap.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

void nd_mocap_cfg_lab(nd_mocap_cfg *cfg) {
  cfg->rate = 240.0;
  cfg->sigma_pos = 1e-4;
  cfg->sigma_rot = 2e-3;
  cfg->latency = 6e-3;
  cfg->latency_jitter = 5e-4;
  cfg->drop_prob = 0.01 / 3.0;  /* bursts of 3 frames on average: 1 % of frames lost */
  cfg->drop_burst = 3.0;
  cfg->seed = 1;
}

void nd_mocap_cfg_exact(nd_mocap_cfg *cfg) {
  memset(cfg, 0, sizeof(*cfg));
  cfg->rate = 240.0;
  cfg->drop_burst = 1.0;
  cfg->seed = 1;
}

int nd_mocap_cfg_check(const nd_mocap_cfg *c, char *err, int errlen) {
  const char *bad = NULL;
  if (!(c->rate > 0 && c->rate <= 10000)) bad = "rate";
  else if (!(c->sigma_pos >= 0 && c->sigma_pos <= 0.1)) bad = "sigma_pos";
  else if (!(c->sigma_rot >= 0 && c->sigma_rot <= 1)) bad = "sigma_rot";
  else if (!(c->latency >= 0 && c->latency <= 1)) bad = "latency";
  else if (!(c->latency_jitter >= 0 && c->latency_jitter <= c->latency)) bad = "latency_jitter";
  else if (!(c->drop_prob >= 0 && c->drop_prob < 1)) bad = "drop_prob";
  else if (!(c->drop_burst >= 1 && c->drop_burst <= 1e4)) bad = "drop_burst";
  else if (c->latency * c->rate + 2 > ND_MOCAP_QUEUE) bad = "latency x rate (frames in flight)";
  if (!bad) return 0;
  snprintf(err, errlen, "motion capture: %s out of range", bad);
  return -1;
}

void nd_mocap_init(nd_mocap *m, const nd_mocap_cfg *cfg, double t0) {
  memset(m, 0, sizeof(*m));
  m->cfg = *cfg;
  nd_rng_seed(&m->rng, cfg->seed, 0x6d6f636170ULL);  /* "mocap" */
  m->next = t0;
}

/* q = q * exp(w / 2) for a small rotation vector w (body frame), renormalised. */
static void rotate(double q[4], const double w[3]) {
  const double a = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
  double d[4] = {1, 0, 0, 0};
  if (a > 0) {
    const double s = sin(0.5 * a) / a;
    d[0] = cos(0.5 * a), d[1] = w[0] * s, d[2] = w[1] * s, d[3] = w[2] * s;
  }
  const double r[4] = {q[0] * d[0] - q[1] * d[1] - q[2] * d[2] - q[3] * d[3],
                       q[0] * d[1] + q[1] * d[0] + q[2] * d[3] - q[3] * d[2],
                       q[0] * d[2] - q[1] * d[3] + q[2] * d[0] + q[3] * d[1],
                       q[0] * d[3] + q[1] * d[2] - q[2] * d[1] + q[3] * d[0]};
  const double n = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]);
  for (int k = 0; k < 4; k++) q[k] = r[k] / n;
}

int nd_mocap_capture(nd_mocap *m, double t, const double obj_pos[3], const double obj_quat[4],
                     const double ee_pos[3]) {
  if (t < m->next) return 0;
  /* One frame per due time; a caller that skipped time catches up without a burst. */
  const double period = 1.0 / m->cfg.rate;
  m->next += period * (1.0 + floor((t - m->next) / period));
  const nd_mocap_cfg *c = &m->cfg;
  if (m->burst == 0 && c->drop_prob > 0 && nd_rng_uniform(&m->rng) < c->drop_prob) {
    /* Geometric burst length with the configured mean. */
    m->burst = 1;
    while (nd_rng_uniform(&m->rng) < 1.0 - 1.0 / c->drop_burst) m->burst++;
  }
  if (m->burst > 0) {
    m->burst--;
    m->dropped++;
    return 0;
  }
  if (m->n == ND_MOCAP_QUEUE) {
    m->overflow++;  /* a release that never came: the oldest frame goes */
    m->head = (m->head + 1) % ND_MOCAP_QUEUE;
    m->n--;
  }
  nd_mocap_frame *f = &m->q[(m->head + m->n) % ND_MOCAP_QUEUE];
  f->index = m->captured + m->dropped;
  f->t_capture = t;
  f->t_release = t + c->latency + c->latency_jitter * (2.0 * nd_rng_uniform(&m->rng) - 1.0);
  memcpy(f->obj_quat, obj_quat, sizeof(f->obj_quat));
  for (int k = 0; k < 3; k++) {
    f->obj_pos[k] = obj_pos[k] + c->sigma_pos * nd_rng_normal(&m->rng);
    f->ee_pos[k] = ee_pos[k] + c->sigma_pos * nd_rng_normal(&m->rng);
  }
  if (c->sigma_rot > 0) {
    const double w[3] = {c->sigma_rot * nd_rng_normal(&m->rng),
                         c->sigma_rot * nd_rng_normal(&m->rng),
                         c->sigma_rot * nd_rng_normal(&m->rng)};
    rotate(f->obj_quat, w);
  }
  /* Frames leave in capture order: jitter never lets one overtake the one before it. */
  if (m->n > 0) {
    const nd_mocap_frame *prev = &m->q[(m->head + m->n - 1) % ND_MOCAP_QUEUE];
    if (f->t_release < prev->t_release) f->t_release = prev->t_release;
  }
  m->n++;
  m->captured++;
  return 1;
}

int nd_mocap_release(nd_mocap *m, double t, nd_mocap_frame *out, int max) {
  int k = 0;
  while (k < max && m->n > 0 && m->q[m->head].t_release <= t) {
    out[k++] = m->q[m->head];
    m->head = (m->head + 1) % ND_MOCAP_QUEUE;
    m->n--;
  }
  return k;
}
