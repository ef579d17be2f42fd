/* landscape: nudge-experiment --landscape, the loss along each friction around the truth
 * for the FORCE and SETPOINT replay modes, and how far pushing lifts the box (the
 * diagnostic behind the default replay: doc/decisions.md). */
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "experiment.h"
#include "nd_math.h"

/* Curve shape on a grid x[0, n) holding the truth at x[it]. roughness = total variation /
 * (descent into the minimum + ascent out of it): 1 for a curve that falls to one minimum
 * and rises, more for every extra wiggle. monotone = fraction of grid steps that go the way
 * a curve with its one minimum at the truth goes (down before it, up after it). */
static void curve_shape(const double *x, const double *L, int n, int it, double *argmin,
                        double *rough, double *monotone, int *nmin) {
  int im = 0, good = 0;
  double tv = 0;
  for (int i = 0; i < n; i++) {
    if (L[i] < L[im]) im = i;
    if (i) {
      tv += fabs(L[i] - L[i - 1]);
      good += i <= it ? L[i] < L[i - 1] : L[i] > L[i - 1];
    }
  }
  *argmin = x[im];
  double need = (L[0] - L[im]) + (L[n - 1] - L[im]);
  *rough = need > 0 ? tv / need : INFINITY;
  *monotone = (double)good / (n - 1);
  *nmin = 0;
  for (int i = 0; i < n; i++) {
    int lo = i == 0 || L[i] < L[i - 1], hi = i == n - 1 || L[i] < L[i + 1];
    *nmin += lo && hi;
  }
}

/* A scripted push recorded in the world with the true theta (no planner): the sphere's
 * setpoint follows a smooth (quintic time-scaled) path for T s, then holds 0.3 s.
 * kind 0: straight through the box's centre along x, 20 cm (no rotation, the control);
 * kind 1, 2: the sphere pushes the long face near one end and follows a circle of 6.8 cm
 * around the box's centre, 2 rad counter-clockwise / clockwise: the box spins about its
 * centre, the motion torsional friction resists. */
static int scripted_push(exp_study *s, int kind, nd_rollout *out, char *err, int errlen) {
  const double T = 4.0, hold = 0.3, dt = s->su.world.m->opt.timestep;
  const double r = 0.068, dphi = kind == 1 ? 2.0 : -2.0;
  const double phi0 = kind == 1 ? atan2(-0.055, 0.04) - 0.08 : atan2(-0.055, -0.04) + 0.08;
  double ee0[2];
  if (kind == 0) ee0[0] = -0.10, ee0[1] = 0.0;
  else ee0[0] = r * cos(phi0), ee0[1] = r * sin(phi0);
  nds_state st;
  nds_state_rest(&s->su.world, 0.0, 0.0, 0.0, ee0, &st);
  const nd_goal g = {.x = 0, .y = 0, .yaw = 0};
  if (nds_record_begin(&s->rec, &s->su.world, &st, 100 + kind, 0, &g, nd_theta_true, err, errlen) ||
      nds_state_set(&s->su.world, s->su.d, &st, err, errlen))
    return -1;
  nds_ctrl_cfg cc;
  nds_ctrl_cfg_default(&cc);
  nds_ctrl pid;
  nds_ctrl_reset(&pid, s->su.world.m->body_mass[s->su.world.ee_body]);
  const int n = (int)lround((T + hold) / dt);
  for (int k = 0; k < n && k < s->rec.cap; k++) {
    double t = fmin(k * dt / T, 1.0);
    /* quintic s(t) = 10 t^3 - 15 t^4 + 6 t^5 and its time derivatives */
    double q = ((6 * t - 15) * t + 10) * t * t * t;
    double qd = k * dt < T ? 30 * t * t * (t - 1) * (t - 1) / T : 0;
    double qdd = k * dt < T ? 60 * t * (2 * t * t - 3 * t + 1) / (T * T) : 0;
    double sp[2][4] = {{0}};
    if (kind == 0) {
      sp[0][0] = ee0[0] + 0.2 * q, sp[0][1] = 0.2 * qd, sp[0][2] = 0.2 * qdd;
      sp[1][0] = 0;
    } else {
      double ph = phi0 + dphi * q, w = dphi * qd, al = dphi * qdd, c = cos(ph), sn = sin(ph);
      sp[0][0] = r * c, sp[1][0] = r * sn;
      sp[0][1] = -r * w * sn, sp[1][1] = r * w * c;
      sp[0][2] = -r * al * sn - r * w * w * c, sp[1][2] = r * al * c - r * w * w * sn;
    }
    const double pos[2] = {s->su.d->qpos[s->su.world.ee_qpos[0]], s->su.d->qpos[s->su.world.ee_qpos[1]]};
    const double vel[2] = {s->su.d->qvel[s->su.world.ee_dof[0]], s->su.d->qvel[s->su.world.ee_dof[1]]};
    double f[2];
    nds_ctrl_pid(&cc, &pid, (const double(*)[4])sp, pos, vel, dt, f);
    s->su.d->qfrc_applied[s->su.world.ee_dof[0]] = f[0];
    s->su.d->qfrc_applied[s->su.world.ee_dof[1]] = f[1];
    mj_step(s->su.world.m, s->su.d);
    nds_record_hook(&s->rec, &s->su.world, s->su.d, (const double(*)[4])sp, f);
  }
  if (nds_record_finish(&s->rec, ND_OUTCOME_TIMEOUT, err, errlen) ||
      nd_rollout_copy(out, &s->rec.r)) {
    if (!err[0]) snprintf(err, errlen, "out of memory");
    return -1;
  }
  return 0;
}

/* Rollout classes of the landscape: the planned training tasks, then the scripted ones. */
enum { NSCRIPT = 3, NLAND = NTRAIN + NSCRIPT };
static int land_class(int i) { return i < NTRAIN ? 0 : i == NTRAIN ? 1 : 2; }
static const char *land_cname[3] = {"planned", "straight", "spin"};

/* Grids in units of the truth, each holding it: sliding 0.5..1.5 in steps of 0.025,
 * torsional and rolling 0..3 in steps of 0.05 (0 as the fit's lower bound). */
enum { NG_MAX = 61 };
static const double land_hi[NFIT] = {1.5, 3.0, 3.0}, land_lo[NFIT] = {0.5, 0.0, 0.0};
static const int land_ng[NFIT] = {41, 61, 61};

/* The index of the truth in parameter p's landscape grid, and grid point g. */
static int land_it(int p) {
  return (int)lround((1.0 - land_lo[p]) / (land_hi[p] - land_lo[p]) * (land_ng[p] - 1));
}
static double land_x(int p, int g) {
  if (g == land_it(p)) return nd_theta_true[p];
  const double u = land_lo[p] + (land_hi[p] - land_lo[p]) * g / (land_ng[p] - 1);
  return fmax(1e-7, nd_theta_true[p] * u);
}

/* How pushing lifts the box, why re-anchoring puts back its full pose (nds_fit.c). MuJoCo's
 * soft contact lets a box that slides rise off the table (a sliding contact separates at a
 * rate that grows with its slip), so while pushed it hops on fewer than its four corners
 * and each landing's timing moves with theta. Each rollout is replayed once under the
 * true theta in the world (force replay from its start: bit for bit the recording),
 * counting the steps the sphere touches the box and, of those, the steps the box stands
 * on fewer than 3 table contacts, and its highest rise above its settled rest height. */
static void lift_replay(exp_study *s, const nd_rollout *r, double z_rest, int *touch, int *lifted,
                        double *rise) {
  const nds_model *w = &s->su.world;
  nds_state st;
  char err[64];
  nds_replay_start_get(r, &st);
  *touch = *lifted = 0;
  *rise = 0;
  if (nds_state_set(w, s->su.d, &st, err, sizeof(err))) return;
  for (int k = 0; k < r->n; k++) {
    s->su.d->qfrc_applied[w->ee_dof[0]] = r->u[2 * k];
    s->su.d->qfrc_applied[w->ee_dof[1]] = r->u[2 * k + 1];
    mj_step(w->m, s->su.d);
    int nt, ne;
    nds_contacts(w, s->su.d, &nt, &ne);
    if (!ne) continue;
    (*touch)++;
    *lifted += nt < 3;
    *rise = fmax(*rise, s->su.d->qpos[w->obj_qpos + 2] - z_rest);
  }
}

/* The lift report: the rollouts by class, then a push with no sphere at all, F along x
 * at the box's centre for 0.3 s after 0.3 s of settling (the settled height is z_rest). */
static void lift_report(exp_study *s, const nd_rollout *rs, int nr) {
  const nds_model *w = &s->su.world;
  mjData *d = s->su.d;
  nds_state st;
  char err[64];
  const double ee_far[2] = {-0.3, 0.0}, F = 8.0, dt = w->m->opt.timestep;
  nds_state_rest(w, 0.0, 0.0, 0.0, ee_far, &st);
  if (nds_state_set(w, d, &st, err, sizeof(err))) return;
  const int nset = (int)lround(0.3 / dt), npush = (int)lround(0.3 / dt);
  for (int k = 0; k < nset; k++) mj_step(w->m, d);
  const double z_rest = d->qpos[w->obj_qpos + 2];
  double *xf = d->xfrc_applied + 6 * w->obj_body;
  int lifted = 0;
  double rise = 0;
  for (int k = 0; k < npush; k++) {
    xf[0] = F;
    mj_step(w->m, d);
    int nt, ne;
    nds_contacts(w, d, &nt, &ne);
    lifted += nt < 3;
    rise = fmax(rise, d->qpos[w->obj_qpos + 2] - z_rest);
  }
  const double v = d->qvel[w->obj_dof];
  xf[0] = 0;  /* d is the study's world: leave no force behind */
  for (int c = 0; c < 3; c++) {
    int touch = 0, lift = 0, n = 0;
    double top = 0;
    for (int i = 0; i < nr; i++) {
      if (land_class(i) != c) continue;
      int t, l;
      double h;
      lift_replay(s, &rs[i], z_rest, &t, &l, &h);
      touch += t, lift += l, n++;
      top = fmax(top, h);
    }
    printf("lift %-8s %d rollouts: the sphere touches the box in %d steps; in %.0f%% of "
           "them the box stands on < 3 table contacts; it rises up to %.0f um above rest\n",
           land_cname[c], n, touch, touch ? 100.0 * lift / touch : 0.0, 1e6 * top);
  }
  printf("lift free-push  %.0f N along x at the box's centre for %.1f s, no sphere: < 3 table "
         "contacts in %.0f%% of the steps, rise up to %.0f um, speed %.2f m/s at the end\n",
         F, npush * dt, 100.0 * lifted / npush, 1e6 * rise, v);
  fflush(stdout);
}

int exp_landscape_run(const exp_opts *o) {
  char err[512] = "";
  exp_study s;
  int status = 1;
  nd_rollout rs[NLAND] = {{0}};
  int nr = 0;
  nds_fit *fits[2] = {NULL, NULL}, *rfit = NULL;
  FILE *f = NULL;
  double *Lb = NULL, *per = NULL;
  if (exp_study_init(&s, o, err, sizeof(err))) goto done;
  char path[1200];
  exp_path(path, sizeof(path), o->out, "landscape.nbuf");
  fprintf(stderr, PROG ": recording the %d training tasks with the true theta\n", NTRAIN);
  if (exp_record_truth(&s, exp_train_goals, NTRAIN, 5, rs, path, err, sizeof(err))) goto done;
  nr = NTRAIN;
  for (int k = 0; k < NSCRIPT; k++) {
    if (scripted_push(&s, k, &rs[nr], err, sizeof(err))) goto done;
    nr++;
  }
  for (int i = 0; i < nr; i++) {
    const double *e = nd_rollout_obj(&rs[i], rs[i].n - 1);
    fprintf(stderr, "  rollout %2d (%s): goal (%+.2f, %+.2f, %+.2f), %.2f s, object moved "
            "%.3f m, turned %+.3f rad\n", i, land_cname[land_class(i)], rs[i].goal[0],
            rs[i].goal[1], rs[i].goal[2], rs[i].n * rs[i].dt, hypot(e[0], e[1]),
            nd_quat_yaw(e + 3));
  }
  lift_report(&s, rs, nr);
  const int modes[2] = {NDS_REPLAY_FORCE, NDS_REPLAY_SETPOINT};
  for (int k = 0; k < 2; k++) {
    nds_fit_cfg fc;
    exp_fit_cfg(o, modes[k], &fc);
    if (!(fits[k] = nds_fit_create(&s.fitm, &fc, s.su.pool, err, sizeof(err)))) goto done;
  }
  {
    /* The study's robust score (--robust, or nds_fit.h's scale), in the study's mode. */
    nds_fit_cfg fc;
    exp_fit_cfg(o, o->mode, &fc);
    if (!(fc.robust > 0)) fc.robust = NDS_FIT_ROBUST_SCALE;
    if (!(rfit = nds_fit_create(&s.fitm, &fc, s.su.pool, err, sizeof(err)))) goto done;
  }
  exp_path(path, sizeof(path), o->out, "landscape.csv");
  if (!(f = fopen(path, "w"))) {
    snprintf(err, sizeof(err), "%.300s: %s", path, strerror(errno));
    goto done;
  }
  fputs("mode,param,value,rollout,class,turn_rad,L,pos_o,pos_ee,rot_o,diverged\n", f);
  Lb = malloc(sizeof(double) * NG_MAX * 6);   /* L per grid point and class; then S */
  per = malloc(sizeof(double) * NG_MAX * 2);
  if (!Lb || !per) {
    snprintf(err, sizeof(err), "out of memory");
    goto done;
  }
  nds_replay_terms terms[NLAND];
  double x[NG_MAX];
  nds_fit_cfg wcfg;
  exp_fit_cfg(o, o->mode, &wcfg);
  for (int p = 0; p < NFIT; p++) {
    const int NG = land_ng[p], it = land_it(p);
    for (int k = 0; k < 2; k++) {
      /* L of each class of rollouts. */
      for (int g = 0; g < NG; g++) {
        double th[ND_NTHETA];
        memcpy(th, nd_theta_true, sizeof(th));
        th[p] = x[g] = land_x(p, g);
        double L;
        if (nds_fit_loss(fits[k], th, rs, nr, &L, terms, err, sizeof(err))) goto done;
        Lb[3 * g] = Lb[3 * g + 1] = Lb[3 * g + 2] = 0;
        for (int i = 0; i < nr; i++) {
          double Li = nds_replay_loss(&terms[i], wcfg.k1, wcfg.k2);
          const double turn = nd_quat_yaw(nd_rollout_obj(&rs[i], rs[i].n - 1) + 3);
          fprintf(f, "%s,%s,%.9g,%d,%s,%.4f,%.9g,%.9g,%.9g,%.9g,%d\n",
                  nds_replay_mode_name(modes[k]), nd_theta_key[p], x[g], i, land_cname[land_class(i)],
                  turn, Li, terms[i].pos_o, terms[i].pos_ee, terms[i].rot_o, terms[i].diverged);
          Lb[3 * g + land_class(i)] += Li;
        }
      }
      for (int q = 0; q < 3; q++) {
        for (int g = 0; g < NG; g++) per[g] = Lb[3 * g + q];
        double am, rough, mono;
        int nmin;
        curve_shape(x, per, NG, it, &am, &rough, &mono, &nmin);
        /* Depth 20% and 50% either side of the truth (nearest grid points), and the plateau
         * a 0.1% offset already reaches (the chaos floor, below). */
        int d20 = (int)lround(0.2 / (land_hi[p] - land_lo[p]) * (NG - 1));
        int d50 = (int)lround(0.5 / (land_hi[p] - land_lo[p]) * (NG - 1));
        printf("landscape %-8s %-7s %-8s argmin %.4g (truth %.4g), monotone %.2f, roughness "
               "%.2f, local minima %d, L(-50%%) %.2e, L(-20%%) %.2e, L(+20%%) %.2e, "
               "L(+50%%) %.2e\n",
               nds_replay_mode_name(modes[k]), nd_theta_key[p], land_cname[q], am, nd_theta_true[p],
               mono, rough, nmin, per[it - d50], per[it - d20], per[it + d20], per[it + d50]);
      }
    }
  }
  /* The robust score along sliding friction beside L, from the same replays: how each
   * ranks candidates near the truth (nds_fit.c). Per class: both curves' shape, and both at
   * -10, -5, -2.5, +2.5, +5 and +10 % of the truth. */
  {
    const int p = ND_TH_SLIDE, NG = land_ng[p], it = land_it(p);
    double *Sb = Lb + 3 * NG_MAX, *Sper = per + NG_MAX;
    for (int g = 0; g < NG; g++) {
      double th[ND_NTHETA], S;
      memcpy(th, nd_theta_true, sizeof(th));
      th[p] = x[g] = land_x(p, g);
      if (nds_fit_score(rfit, th, rs, nr, &S, terms, err, sizeof(err))) goto done;
      for (int q = 0; q < 3; q++) Lb[3 * g + q] = Sb[3 * g + q] = 0;
      for (int i = 0; i < nr; i++) {
        Lb[3 * g + land_class(i)] += nds_replay_loss(&terms[i], wcfg.k1, wcfg.k2);
        Sb[3 * g + land_class(i)] += terms[i].robust;
      }
    }
    static const int off[6] = {-4, -2, -1, 1, 2, 4};
    for (int q = 0; q < 3; q++) {
      double am[2], rough[2], mono[2];
      int nmin[2];
      for (int g = 0; g < NG; g++) per[g] = Lb[3 * g + q], Sper[g] = Sb[3 * g + q];
      curve_shape(x, per, NG, it, &am[0], &rough[0], &mono[0], &nmin[0]);
      curve_shape(x, Sper, NG, it, &am[1], &rough[1], &mono[1], &nmin[1]);
      printf("robust-vs-L %-8s slide %-8s L: argmin %.4g, monotone %.2f, local minima %d; "
             "S: argmin %.4g, monotone %.2f, local minima %d; -10..+10%%: L",
             nds_replay_mode_name(o->mode), land_cname[q], am[0], mono[0], nmin[0], am[1],
             mono[1], nmin[1]);
      for (int i = 0; i < 6; i++) printf(" %.2e", per[it + off[i]]);
      printf(", S");
      for (int i = 0; i < 6; i++) printf(" %.3f", Sper[it + off[i]]);
      printf("\n");
    }
    fflush(stdout);
  }
  /* How fast L leaves 0 around the truth: relative offsets from 1e-9 up. An L that jumps
   * to its plateau at tiny offsets is chaos in the contacts, not information. */
  {
    static const double rel[] = {1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 0.05, 0.2, 0.5};
    enum { NREL = sizeof(rel) / sizeof(rel[0]) };
    for (int p = 0; p < NFIT; p++) {
      for (int k = 0; k < 2; k++) {
        for (int c = 0; c < 3; c++) {
          printf("near-truth %-8s %-7s %-8s", nds_replay_mode_name(modes[k]), nd_theta_key[p],
                 land_cname[c]);
          for (int q = 0; q < NREL; q++) {
            double Lpm = 0;
            for (int sg = 0; sg < 2; sg++) {
              double th[ND_NTHETA];
              memcpy(th, nd_theta_true, sizeof(th));
              th[p] *= 1 + (sg ? -rel[q] : rel[q]);
              double L;
              if (nds_fit_loss(fits[k], th, rs, nr, &L, terms, err, sizeof(err))) goto done;
              for (int i = 0; i < nr; i++)
                if (land_class(i) == c) Lpm += 0.5 * nds_replay_loss(&terms[i], wcfg.k1, wcfg.k2);
            }
            printf(" %g:%.1e", rel[q], Lpm);
          }
          printf("\n");
        }
      }
    }
  }
  /* What the refit makes of it: torsional friction alone fitted (the others held at the
   * truth), D = 1 prior, 10 refits on the planned or on the spin rollouts, 3 seeds. */
  for (int c = 0; c < 3; c += 2) {
    const nd_rollout *sub = c == 0 ? rs : rs + NTRAIN + 1;
    const int nsub = c == 0 ? NTRAIN : 2;
    for (int k = 0; k < 2; k++) {
      double e0 = 0, e1 = 0;
      printf("torsion-fit %-8s %-8s", nds_replay_mode_name(modes[k]), land_cname[c]);
      for (int seed = 1; seed <= 3; seed++) {
        nds_fit_cfg fc;
        exp_fit_cfg(o, modes[k], &fc);
        fc.fit[ND_TH_SLIDE] = fc.fit[ND_TH_ROLL] = 0;
        fc.seed = (uint64_t)seed;
        nd_rng rr;
        nd_rng_seed(&rr, (uint64_t)seed, 77);
        double mu0[ND_NTHETA], sg0[ND_NTHETA];
        nds_fit_paper_prior(nd_theta_true, 1.0, fc.lower, &rr, mu0, sg0);
        memcpy(fc.mu0, nd_theta_true, sizeof(fc.mu0));
        fc.mu0[ND_TH_TORSION] = mu0[ND_TH_TORSION];
        fc.sigma0[ND_TH_TORSION] = sg0[ND_TH_TORSION];
        nds_fit *ft = nds_fit_create(&s.fitm, &fc, s.su.pool, err, sizeof(err));
        if (!ft) goto done;
        nds_fit_out fo;
        for (int e = 0; e < 10; e++)
          if (nds_fit_run(ft, sub, nsub, &fo, err, sizeof(err))) {
            nds_fit_free(ft);
            goto done;
          }
        nds_fit_free(ft);
        double a = 100 * fabs(fc.mu0[1] / nd_theta_true[1] - 1),
               b = 100 * fabs(fo.mean[1] / nd_theta_true[1] - 1);
        printf("  seed %d: %.1f%% -> %.1f%%", seed, a, b);
        e0 += a / 3, e1 += b / 3;
      }
      printf("  | mean %.1f%% -> %.1f%%\n", e0, e1);
      fflush(stdout);
    }
  }
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  if (f) fclose(f);
  free(Lb);
  free(per);
  for (int k = 0; k < 2; k++) nds_fit_free(fits[k]);
  nds_fit_free(rfit);
  for (int i = 0; i < nr; i++) nd_rollout_free(&rs[i]);
  exp_study_free(&s);
  return status;
}