/* nds_replay: replay of a recorded rollout (forces, velocities or setpoints) and its loss
 * terms. */
#include "nds_replay.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_math.h"
#include "nd_release.h"
#include "nd_snap.h"

/* As in nds_rollout: every warning counter starts here, so any warning during the replay
 * (including the one MuJoCo counts again after resetting a bad state) leaves some counter
 * != WARN_START, and MuJoCo, which prints only at a zero count, stays quiet. */
#define WARN_START 2

/* A model step may be this far (relative) from k record steps and still count as k:
 * timesteps written as decimals do not divide exactly in binary. */
#define RATIO_TOL 1e-9

void nds_replay_cfg_default(nds_replay_cfg *cfg, int mode) {
  cfg->mode = mode;
  nds_ctrl_cfg_default(&cfg->ctrl);
  /* A velocity replay follows the robot's recorded velocity without lag: a servo that
   * lags under contact load lets the fit lower friction so the sphere keeps up
   * (doc/decisions.md#replay-kv). */
  cfg->ctrl.kv = 0;
  cfg->window = 0;
  cfg->smooth = 0;
  cfg->phase = 0;
  cfg->skip_clear = 0;
}

int nds_replay_cfg_check(const nds_replay_cfg *cfg, char *err, int errlen) {
  const int mode = cfg->mode;
  if (mode != NDS_REPLAY_FORCE && mode != NDS_REPLAY_VELOCITY && mode != NDS_REPLAY_SETPOINT)
    snprintf(err, errlen, "replay.mode: unknown replay mode %d", mode);
  else if (!(isfinite(cfg->window) && cfg->window >= 0))
    snprintf(err, errlen, "replay.window = %g s, must be finite and >= 0", cfg->window);
  else if (!(isfinite(cfg->smooth) && cfg->smooth >= 0 && cfg->smooth <= 1))
    snprintf(err, errlen, "replay.smooth = %g s, must be in [0, 1]", cfg->smooth);
  else if (!(cfg->phase == 0 || (cfg->phase > 0 && cfg->phase < cfg->window)))
    snprintf(err, errlen, "replay.phase = %g s, must be in [0, window = %g s)", cfg->phase,
             cfg->window);
  else if (!(isfinite(cfg->skip_clear) && cfg->skip_clear >= 0))
    snprintf(err, errlen, "replay.skip_clear = %g m, must be finite and >= 0", cfg->skip_clear);
  else
    return 0;
  return -1;
}

const char *nds_replay_mode_name(int mode) {
  switch (mode) {
    case NDS_REPLAY_FORCE: return "force";
    case NDS_REPLAY_VELOCITY: return "velocity";
    case NDS_REPLAY_SETPOINT: return "setpoint";
    default: return "?";
  }
}

void nds_replay_sp_put(double row[6], const double sp[2][4]) {
  for (int a = 0; a < 2; a++) {
    row[a] = sp[a][ND_P];
    row[2 + a] = sp[a][ND_V];
    row[4 + a] = sp[a][ND_A];
  }
}

void nds_replay_sp_get(const double row[6], double sp[2][4]) {
  for (int a = 0; a < 2; a++) {
    sp[a][ND_P] = row[a];
    sp[a][ND_V] = row[2 + a];
    sp[a][ND_A] = row[4 + a];
    sp[a][ND_J] = 0;
  }
}

int nds_replay_ratio(const nds_model *nm, const nd_rollout *r, char *err, int errlen) {
  if (r->control != ND_CTRL_FORCE && r->control != ND_CTRL_VELOCITY) {
    snprintf(err, errlen, "replay: unknown control mode %d", (int)r->control);
    return -1;
  }
  if (r->n < 1 || r->n > ND_ROLLOUT_MAX_STEPS) {
    snprintf(err, errlen, "replay: %d steps, must be in [1, %d]", (int)r->n,
             ND_ROLLOUT_MAX_STEPS);
    return -1;
  }
  if (!r->u || !r->obj || !r->ee || !r->sp) {
    snprintf(err, errlen, "replay: record of %d steps has no step arrays", (int)r->n);
    return -1;
  }
  double md = nm->m->opt.timestep;
  if (!(isfinite(r->dt) && r->dt > 0)) {
    snprintf(err, errlen, "replay: record dt = %g s, must be finite and > 0", r->dt);
    return -1;
  }
  double q = md / r->dt;
  long k = lround(q);
  /* Only whole coarsenings: a finer model would have to invent controls between the
   * recorded ones, a fractional ratio would have to resample them. */
  if (k < 1 || fabs(q - (double)k) > RATIO_TOL * q) {
    snprintf(err, errlen,
             "replay: model timestep %g s is not a whole multiple of the record's %g s "
             "(ratio %.6g)",
             md, r->dt, q);
    return -1;
  }
  if (k > r->n) {
    snprintf(err, errlen, "replay: record of %d steps is shorter than one model step (%ld)",
             (int)r->n, k);
    return -1;
  }
  return (int)k;
}

int nds_replay_check(const nds_model *nm, const nd_rollout *r, char *err, int errlen) {
  if (nds_replay_ratio(nm, r, err, errlen) < 0) return -1;
  struct {
    const char *name;
    const double *v;
    int n;
  } f[] = {{"obj_pos", r->obj_pos, 3}, {"obj_quat", r->obj_quat, 4},
           {"obj_vel", r->obj_vel, 6}, {"ee_pos", r->ee_pos, 2},
           {"ee_vel", r->ee_vel, 2},   {"u", r->u, 2 * r->n},
           {"obj", r->obj, ND_ROLLOUT_OBJ * r->n},  {"ee", r->ee, 2 * r->n},
           {"sp", r->sp, 6 * r->n}};
  for (size_t i = 0; i < sizeof(f) / sizeof(f[0]); i++) {
    for (int j = 0; j < f[i].n; j++) {
      if (!isfinite(f[i].v[j])) {
        snprintf(err, errlen, "replay: record %s[%d] = %g is not finite", f[i].name, j,
                 f[i].v[j]);
        return -1;
      }
    }
  }
  /* Re-anchoring normalises the quaternions; one of zero norm has no direction. */
  for (int i = -1; i < r->n; i++) {
    const double *qt = i < 0 ? r->obj_quat : nd_rollout_obj(r, i) + 3;
    if (!(qt[0] * qt[0] + qt[1] * qt[1] + qt[2] * qt[2] + qt[3] * qt[3] > 1e-24)) {
      if (i < 0) snprintf(err, errlen, "replay: record obj_quat has zero norm");
      else snprintf(err, errlen, "replay: record obj[%d] quaternion has zero norm", i);
      return -1;
    }
  }
  return 0;
}

void nds_replay_observe(const nds_model *nm, const mjData *d, double obj[ND_ROLLOUT_OBJ],
                        double ee[2]) {
  const mjModel *m = nm->m;
  memcpy(obj, d->qpos + nm->obj_qpos, ND_ROLLOUT_OBJ * sizeof(double));
  /* The slide joints move the sphere by (qpos - qpos0) from its body position; the same
   * offset nds_state_get applies. */
  for (int k = 0; k < 2; k++)
    ee[k] = d->qpos[nm->ee_qpos[k]] + m->body_pos[3 * nm->ee_body + k] -
            m->qpos0[nm->ee_qpos[k]];
}

void nds_replay_start_get(const nd_rollout *r, nds_state *s) {
  memcpy(s->obj_pos, r->obj_pos, sizeof(s->obj_pos));
  memcpy(s->obj_quat, r->obj_quat, sizeof(s->obj_quat));
  memcpy(s->obj_vel, r->obj_vel, sizeof(s->obj_vel));
  memcpy(s->ee_pos, r->ee_pos, sizeof(s->ee_pos));
  memcpy(s->ee_vel, r->ee_vel, sizeof(s->ee_vel));
}

void nds_replay_start_put(nd_rollout *r, const nds_state *s) {
  memcpy(r->obj_pos, s->obj_pos, sizeof(s->obj_pos));
  memcpy(r->obj_quat, s->obj_quat, sizeof(s->obj_quat));
  memcpy(r->obj_vel, s->obj_vel, sizeof(s->obj_vel));
  memcpy(r->ee_pos, s->ee_pos, sizeof(s->ee_pos));
  memcpy(r->ee_vel, s->ee_vel, sizeof(s->ee_vel));
}

/* Observation i of r (object pose, sphere x, y); i = -1: the initial state. */
static void rec_obs(const nd_rollout *r, int i, double obj[ND_ROLLOUT_OBJ], double ee[2]) {
  if (i < 0) {
    memcpy(obj, r->obj_pos, 3 * sizeof(double));
    memcpy(obj + 3, r->obj_quat, 4 * sizeof(double));
    memcpy(ee, r->ee_pos, 2 * sizeof(double));
    return;
  }
  memcpy(obj, nd_rollout_obj(r, i), ND_ROLLOUT_OBJ * sizeof(double));
  memcpy(ee, r->ee + 2 * i, 2 * sizeof(double));
}

/* A straight-line fit in time of the object's observations j0..j1 about observation i:
 * value y0 and slope v per axis (positions; orientations as rotation vectors from qi,
 * body frame, as mju_subQuat and a free joint's rates). Returns the mean squared residual
 * of x and y. */
static double line_fit(const nd_rollout *r, int i, int j0, int j1, const double qi[4],
                       double y0[6], double v[6]) {
  double st = 0, stt = 0, sy[6] = {0}, sty[6] = {0}, syy = 0;
  for (int j = j0; j <= j1; j++) {
    const double *o = nd_rollout_obj(r, j), t = (j - i) * r->dt;
    double y[6], qj[4];
    memcpy(y, o, 3 * sizeof(double));
    memcpy(qj, o + 3, sizeof(qj));
    mju_normalize4(qj);
    mju_subQuat(y + 3, qj, qi);
    st += t;
    stt += t * t;
    for (int a = 0; a < 6; a++) sy[a] += y[a], sty[a] += t * y[a];
    syy += y[0] * y[0] + y[1] * y[1];
  }
  const double n = j1 - j0 + 1, den = n * stt - st * st;
  double rss = syy;
  for (int a = 0; a < 6; a++) {
    v[a] = den > 0 ? (n * sty[a] - st * sy[a]) / den : 0;
    y0[a] = (sy[a] - v[a] * st) / n;
    if (a < 2) rss -= y0[a] * sy[a] + v[a] * sty[a];
  }
  return rss / n;
}

/* The object's pose q (7) and rates v (6) at observation i: of the line fits over the
 * observations within +-h, before i and after i, the one closest to its points. Near a
 * push's start or stop only one side is a line; elsewhere the centred fit is the least
 * noisy and the others differ from it by noise. */
static void anchor_fit(const nd_rollout *r, int i, int h, mjtNum q[7], mjtNum v[6]) {
  const int lo = i - h < 0 ? 0 : i - h, hi = i + h >= r->n ? r->n - 1 : i + h;
  const int span[3][2] = {{lo, hi}, {lo, i}, {i, hi}};
  double qi[4], y0[6], best = INFINITY;
  memcpy(qi, nd_rollout_obj(r, i) + 3, sizeof(qi));
  mju_normalize4(qi);
  for (int k = 0; k < 3; k++) {
    if (span[k][1] - span[k][0] < 2) continue;
    double y[6], w[6];
    const double e = line_fit(r, i, span[k][0], span[k][1], qi, y, w);
    if (e < best) {
      best = e;
      memcpy(y0, y, sizeof(y0));
      memcpy(v, w, sizeof(w));
    }
  }
  if (!(best < INFINITY)) {  /* fewer than three observations: the observation, at rest */
    memset(y0, 0, sizeof(y0));
    memcpy(y0, nd_rollout_obj(r, i), 3 * sizeof(double));
    memset(v, 0, 6 * sizeof(mjtNum));
  }
  mju_copy(q, y0, 3);
  mju_copy4(q + 3, qi);
  mju_quatIntegrate(q + 3, y0 + 3, 1);
}

/* Put observation i of r, and its rates from observation i - 1, into d: see re-anchoring
 * in nds_replay.h. MuJoCo's Euler step moves qpos by the new qvel times the step, so the
 * rates are the difference of two observations over the record's step: exact for a record
 * taken at the model's step, the mean rate over its last record step otherwise. With
 * cfg->smooth the object's come from anchor_fit instead. */
static void reanchor(const nds_model *nm, mjData *d, const nds_replay_cfg *cfg,
                     const nd_rollout *r, int i) {
  const mjModel *m = nm->m;
  double o1[ND_ROLLOUT_OBJ], e1[2], o0[ND_ROLLOUT_OBJ], e0[2];
  rec_obs(r, i, o1, e1);
  rec_obs(r, i - 1, o0, e0);
  const double rdt = 1 / r->dt;
  mjtNum *q = d->qpos + nm->obj_qpos, *v = d->qvel + nm->obj_dof;
  const int h = (int)lround(cfg->smooth / r->dt);
  if (h > 0) {
    anchor_fit(r, i, h, q, v);
  } else {
    mju_copy(q, o1, ND_ROLLOUT_OBJ);
    mju_normalize4(q + 3);
    mju_normalize4(o0 + 3);
    for (int a = 0; a < 3; a++) v[a] = (o1[a] - o0[a]) * rdt;
    /* A free joint's angular velocity is in the body frame, as mju_subQuat's difference. */
    mju_subQuat(v + 3, q + 3, o0 + 3);
    mju_scl3(v + 3, v + 3, rdt);
  }
  for (int a = 0; a < 2; a++) {
    d->qpos[nm->ee_qpos[a]] = e1[a] - m->body_pos[3 * nm->ee_body + a] + m->qpos0[nm->ee_qpos[a]];
    d->qvel[nm->ee_dof[a]] = (e1[a] - e0[a]) * rdt;
  }
}

/* Model steps per re-anchoring window at model step mdt (0: never re-anchor). */
static long window_steps(const nds_replay_cfg *cfg, double mdt) {
  return cfg->window > 0 ? lround(fmax(1, cfg->window / mdt)) : 0;
}

/* 1 if over record steps a..b the sphere stays clear or more from the model's box at its
 * pose at a, and the object still at that pose (see nds_replay.h). */
static int window_clear(const nds_model *nm, const nd_rollout *r, int a, int b, double clear) {
  const double *oa = nd_rollout_obj(r, a), yaw = nd_quat_yaw(oa + 3);
  const nd_release_box box = {oa[0], oa[1], yaw, {nm->cfg.obj_half[0], nm->cfg.obj_half[1]}};
  for (int i = a; i <= b; i++) {
    const double *o = nd_rollout_obj(r, i);
    double n[2];
    if (hypot(o[0] - oa[0], o[1] - oa[1]) > NDS_REPLAY_STILL_POS ||
        fabs(nd_wrap_angle(nd_quat_yaw(o + 3) - yaw)) > NDS_REPLAY_STILL_ROT ||
        nd_release_gap(&box, nm->cfg.ee_radius, r->ee + 2 * i, n) < clear)
      return 0;
  }
  return 1;
}

static void diverge(nds_replay_terms *out) {
  out->pos_o = out->pos_ee = out->rot_o = out->robust = NDS_REPLAY_DIVERGED;
  out->diverged = 1;
}

/* One model step of the replay from record step base (k record steps per model step):
 * the sphere driven as cfg->mode says. Return 1 if MuJoCo warned (diverged), else 0. */
static int sim_step(const nds_model *nm, mjData *d, const nds_replay_cfg *cfg,
                    const nds_ctrl_cfg *ctrl, nds_ctrl *pid, const nd_rollout *r, int base,
                    int k) {
  const mjModel *m = nm->m;
  const int dof0 = nm->ee_dof[0], dof1 = nm->ee_dof[1];
  const double vel[2] = {d->qvel[dof0], d->qvel[dof1]};
  double f[2];
  if (cfg->mode == NDS_REPLAY_SETPOINT) {
    /* Exactly the episode's controller call: raw slide qpos, the model's step. */
    double s[2][4];
    nds_replay_sp_get(r->sp + 6 * base, s);
    const double pos[2] = {d->qpos[nm->ee_qpos[0]], d->qpos[nm->ee_qpos[1]]};
    nds_ctrl_pid(ctrl, pid, (const double(*)[4])s, pos, vel, m->opt.timestep, f);
  } else {
    /* The mean of the k recorded controls: for k = 1 exactly the recorded one. */
    double u[2] = {0, 0};
    for (int i = 0; i < k; i++) {
      u[0] += r->u[2 * (base + i)];
      u[1] += r->u[2 * (base + i) + 1];
    }
    u[0] /= k;
    u[1] /= k;
    if (cfg->mode == NDS_REPLAY_FORCE) f[0] = u[0], f[1] = u[1];
    else nds_ctrl_vel(ctrl, pid, u, vel, f);
  }
  d->qfrc_applied[dof0] = f[0];
  d->qfrc_applied[dof1] = f[1];
  mj_step(m, d);
  for (int w = 0; w < mjNWARNING; w++)
    if (d->warning[w].number != WARN_START) return 1;
  return 0;
}

/* The replay; stops once sp + k1 se + k2 sr > bound T, or with robust > 0 once the
 * windows' score passes bound (never for bound = INFINITY). */
static int replay(const nds_model *nm, mjData *d, const nds_replay_cfg *cfg,
                  const nd_rollout *r, double k1, double k2, double robust, double bound,
                  nds_replay_terms *out, double *pred, char *err, int errlen) {
  memset(out, 0, sizeof(*out)); /* padding too, so terms compare bytewise */
  int k = nds_replay_ratio(nm, r, err, errlen);
  if (k < 0) return -1;
  const int mode = cfg->mode;
  if (nds_replay_cfg_check(cfg, err, errlen)) return -1;
  /* A force taken for a velocity (or back) would replay nonsense that still scores. */
  if ((mode == NDS_REPLAY_FORCE && r->control != ND_CTRL_FORCE) ||
      (mode == NDS_REPLAY_VELOCITY && r->control != ND_CTRL_VELOCITY)) {
    snprintf(err, errlen, "replay: %s mode cannot replay a %s record (control %d)",
             nds_replay_mode_name(mode), r->control == ND_CTRL_FORCE ? "force" : "velocity",
             (int)r->control);
    return -1;
  }
  const mjModel *m = nm->m;
  nds_ctrl_cfg vc = cfg->ctrl;
  if (!(vc.kv > 0)) vc.kv = NDS_CTRL_M_REF / m->opt.timestep;  /* kv dt / m = 1: one step */
  const nds_ctrl_cfg *ctrl = &vc;
  const int T = r->n / k; /* a trailing partial model step is not replayed */
  out->steps = T;

  nds_state s0;
  nds_replay_start_get(r, &s0);
  char serr[64];
  int j = 0, diverged = nds_state_set(nm, d, &s0, serr, sizeof(serr)) != 0;
  for (int w = 0; w < mjNWARNING; w++) d->warning[w].number = WARN_START;

  double sp = 0, se = 0, sr = 0;
  int cut = 0;
  nds_ctrl pid;
  nds_ctrl_reset(&pid, m->body_mass[nm->ee_body]);
  const double mdt = m->opt.timestep;
  const long W = window_steps(cfg, mdt);
  const long shift = W ? lround(cfg->phase / mdt) % W : 0;
  /* The robust score's windows are the re-anchoring ones (the whole replay is one when not
   * re-anchoring). rs sums the finished windows' log(1 + e_w / robust), ws the running
   * window's weighted errors. e_w divides by the window's full length wlen, known in
   * advance, so ws only grows toward its final value, and ws > wcap (the room left under
   * the bound) is as final a cut as one on L's sums. */
  const long span = W ? W : T;
  const long nwin = (T + span - 1) / span;
  const double limit = robust > 0 ? bound * nwin : bound * T;
  long wlen = span < T ? span : T, wend = wlen;
  double rs = 0, ws = 0, wcap = robust > 0 ? wlen * robust * expm1(limit) : 0;
  const int skip = mode == NDS_REPLAY_VELOCITY && W && cfg->skip_clear > 0;
  long still_end = 0;  /* steps before it are a clear window's: predicted, not simulated */
  const double *still_o = NULL;
  for (; j < T && !diverged && !cut; j++) {
    const int base = j * k;
    double obj[ND_ROLLOUT_OBJ], ee[2];
    const double *oo = r->obj + ND_ROLLOUT_OBJ * (base + k - 1), *oe = r->ee + 2 * (base + k - 1);
    const int anchor = W && j > 0 && (j + shift) % W == 0;
    if (skip && (j == 0 || anchor)) {
      long end = j + W - (j + shift) % W;  /* the next anchor */
      if (end > T) end = T;
      const int a = j > 0 ? base - 1 : 0;
      if (window_clear(nm, r, a, (int)(end * k - 1), cfg->skip_clear)) {
        still_end = end;
        still_o = nd_rollout_obj(r, a);
      }
    }
    if (j < still_end) {
      memcpy(obj, still_o, sizeof(obj));
      memcpy(ee, oe, sizeof(ee));
      out->skipped++;
    } else {
      if (anchor) reanchor(nm, d, cfg, r, base - 1);
      if ((diverged = sim_step(nm, d, cfg, ctrl, &pid, r, base, k))) break;
      nds_replay_observe(nm, d, obj, ee);
    }
    const double dx = obj[0] - oo[0], dy = obj[1] - oo[1];
    const double ex = ee[0] - oe[0], ey = ee[1] - oe[1];
    const double po = dx * dx + dy * dy, pe = ex * ex + ey * ey;
    /* The angle between the unit vectors v(phi) and v(phi~), i.e. arccos(v^T v~) in
     * [0, pi], taken as the wrapped difference: arccos near 1 loses half the digits
     * (its floor is ~1e-8 rad where the angles agree exactly). */
    const double yaw = nd_quat_yaw(obj + 3);
    const double ro = fabs(nd_wrap_angle(yaw - nd_quat_yaw(oo + 3)));
    sp += po;
    se += pe;
    sr += ro;
    if (robust > 0) {
      ws += po + k1 * pe + k2 * ro;
      if (ws > wcap) {
        cut = 1; /* with the finished windows, past the bound: so is the full score */
      } else if (j + 1 == wend) {
        rs += log1p(ws / wlen / robust);
        ws = 0;
        wlen = T - wend < span ? T - wend : span;
        wend += wlen;
        wcap = wlen * robust * expm1(limit - rs);
      }
    } else if (sp + k1 * se + k2 * sr > limit) {
      cut = 1; /* the sums only grow: past the limit the full L is past the bound too */
    }
    if (pred) {
      double *row = pred + (size_t)NDS_REPLAY_PRED_COLS * j;
      row[0] = obj[0], row[1] = obj[1], row[2] = yaw, row[3] = ee[0], row[4] = ee[1];
    }
  }
  if (!diverged && !(isfinite(sp) && isfinite(se) && isfinite(sr))) diverged = 1;
  if (diverged) {
    if (pred)
      for (size_t i = (size_t)NDS_REPLAY_PRED_COLS * j; i < (size_t)NDS_REPLAY_PRED_COLS * T;
           i++)
        pred[i] = NAN;
    diverge(out);
    return 0;
  }
  out->pos_o = sp / T;
  out->pos_ee = se / T;
  out->rot_o = sr / T;
  out->robust = robust > 0 ? (rs + (cut ? log1p(ws / wlen / robust) : 0)) / nwin : 0;
  out->cut = cut && j < T;
  return 0;
}

int nds_replay(const nds_model *nm, mjData *d, const nds_replay_cfg *cfg, const nd_rollout *r,
               nds_replay_terms *out, double *pred, char *err, int errlen) {
  return replay(nm, d, cfg, r, 0, 0, 0, INFINITY, out, pred, err, errlen);
}

int nds_replay_bounded(const nds_model *nm, mjData *d, const nds_replay_cfg *cfg,
                       const nd_rollout *r, double k1, double k2, double robust,
                       double bound, nds_replay_terms *out, char *err, int errlen) {
  return replay(nm, d, cfg, r, k1, k2, robust, bound, out, NULL, err, errlen);
}

double nds_replay_loss(const nds_replay_terms *t, double k1, double k2) {
  return t->pos_o + k1 * t->pos_ee + k2 * t->rot_o;
}
