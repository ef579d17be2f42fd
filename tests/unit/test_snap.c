/* test_snap: minimum-snap segments meet their eight conditions, are optimal against
 * perturbations that keep those conditions, and splice seamlessly mid-segment. */
#include <string.h>

#include "nd_test.h"

#include "nd_rng.h"
#include "nd_snap.h"

#define MAXDEG 15
static const double Ts[] = {0.05, 0.1, 0.2, 0.3, 0.6, 1.0, 2.0};
#define NT ((int)(sizeof Ts / sizeof Ts[0]))

static double unif(nd_rng *r, double lo, double hi) { return lo + (hi - lo) * nd_rng_uniform(r); }

/* A random but physically plausible start state and target for one axis. */
static void random_axis(nd_rng *r, double s0[4], double *p1, double *v1) {
  s0[ND_P] = unif(r, -1.0, 1.0);
  s0[ND_V] = unif(r, -2.0, 2.0);
  s0[ND_A] = unif(r, -20.0, 20.0);
  s0[ND_J] = unif(r, -500.0, 500.0);
  *p1 = unif(r, -1.0, 1.0);
  *v1 = unif(r, -2.0, 2.0);
}

/* Magnitude of the k-th derivative the data of a segment implies, for relative errors. */
static double deriv_scale(const double s0[4], double p1, double v1, double T, int k) {
  double m = fabs(s0[ND_P]) + fabs(p1) + (fabs(s0[ND_V]) + fabs(v1)) * T +
             fabs(s0[ND_A]) * T * T + fabs(s0[ND_J]) * T * T * T;
  return m / pow(T, k);
}

/* m-th derivative at t of the general polynomial sum_k c[k] t^k, k <= deg. */
static double poly_deriv(const double *c, int deg, int m, double t) {
  double acc = 0.0;
  for (int k = deg; k >= m; k--) {
    double f = 1.0;
    for (int i = 0; i < m; i++) f *= (double)(k - i);
    acc = acc * t + f * c[k];
  }
  return acc;
}

/* Gauss-Legendre rule with n nodes on [-1, 1] by Newton iteration on P_n. */
#define GLN 10
static double gl_x[GLN], gl_w[GLN];
static void gl_init(void) {
  for (int i = 0; i < GLN; i++) {
    double x = cos(3.14159265358979323846 * (i + 0.75) / (GLN + 0.5)), dp = 0.0;
    for (int it = 0; it < 100; it++) {
      double p0 = 1.0, p1 = x;
      for (int k = 2; k <= GLN; k++) {
        double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = GLN * (x * p1 - p0) / (x * x - 1.0);
      double dx = p1 / dp;
      x -= dx;
      if (fabs(dx) < 1e-16) break;
    }
    gl_x[i] = x;
    gl_w[i] = 2.0 / ((1.0 - x * x) * dp * dp);
  }
}

/* Integral of the squared snap of a general polynomial over [0, T] by quadrature
 * (exact for deg <= 12 with 10 nodes, up to rounding). */
static double quad_snap_cost(const double *c, int deg, double T) {
  double sum = 0.0;
  for (int i = 0; i < GLN; i++) {
    double t = 0.5 * T * (gl_x[i] + 1.0);
    double s = poly_deriv(c, deg, 4, t);
    sum += gl_w[i] * s * s;
  }
  return 0.5 * T * sum;
}

/* Integral of snap_a * snap_b over [0, T] by the same rule. */
static double quad_snap_dot(const double *a, const double *b, int deg, double T) {
  double sum = 0.0;
  for (int i = 0; i < GLN; i++) {
    double t = 0.5 * T * (gl_x[i] + 1.0);
    sum += gl_w[i] * poly_deriv(a, deg, 4, t) * poly_deriv(b, deg, 4, t);
  }
  return 0.5 * T * sum;
}

/* h(t) = t^4 (t - T)^4 q(t) for q of degree <= 2: zero value, velocity, acceleration
 * and jerk at both ends, so p + eps h meets the same eight conditions as p. */
static int bump_poly(double T, const double q[3], double h[MAXDEG + 1]) {
  double b[MAXDEG + 1] = {0};
  /* (t - T)^4 by the binomial theorem, then shift by t^4. */
  const double binom[5] = {1.0, 4.0, 6.0, 4.0, 1.0};
  for (int k = 0; k <= 4; k++) b[4 + k] = binom[k] * pow(-T, 4 - k);
  for (int k = 0; k <= MAXDEG; k++) h[k] = 0.0;
  for (int i = 0; i <= 8; i++)
    for (int j = 0; j < 3; j++) h[i + j] += b[i] * q[j];
  return 10;
}

static void test_known_rest_to_rest(void **state) {
  (void)state;
  /* Rest to rest over distance D in time T: the classic 35 -84 70 -20 profile, whose
   * snap integral is 100800 D^2 / T^7. */
  const double s0[4] = {0.0, 0.0, 0.0, 0.0};
  double c[8];
  nd_snap_coeffs(s0, 1.0, 0.0, 1.0, c);
  const double want[8] = {0, 0, 0, 0, 35, -84, 70, -20};
  for (int k = 0; k < 8; k++) assert_near(c[k], want[k], 1e-12);
  assert_near(nd_snap_cost(c, 1.0), 100800.0, 1e-8);

  const double s1[4] = {0.2, 0.0, 0.0, 0.0};
  nd_snap_coeffs(s1, 0.5, 0.0, 0.3, c);
  const double J = nd_snap_cost(c, 0.3);
  assert_near(J / (100800.0 * 0.09 / pow(0.3, 7)), 1.0, 1e-12);
  double out[4];
  nd_snap_eval_poly(c, 0.15, out);
  assert_near(out[ND_P], 0.35, 1e-12); /* symmetric profile: halfway at half time */
  assert_near(out[ND_A], 0.0, 1e-9);
}

static void test_boundary_conditions(void **state) {
  (void)state;
  nd_rng r;
  nd_rng_seed(&r, 42, 1);
  double worst_abs[4] = {0}, worst_rel[4] = {0};
  for (int ti = 0; ti < NT; ti++) {
    const double T = Ts[ti];
    for (int n = 0; n < 300; n++) {
      double s0[4], p1, v1, c[8], a[4], b[4];
      random_axis(&r, s0, &p1, &v1);
      nd_snap_coeffs(s0, p1, v1, T, c);
      nd_snap_eval_poly(c, 0.0, a);
      nd_snap_eval_poly(c, T, b);
      const double end[4] = {p1, v1, 0.0, 0.0};
      for (int k = 0; k < 4; k++) {
        const double sc = deriv_scale(s0, p1, v1, T, k);
        const double e = fmax(fabs(a[k] - s0[k]), fabs(b[k] - end[k]));
        worst_abs[k] = fmax(worst_abs[k], e);
        worst_rel[k] = fmax(worst_rel[k], e / sc);
        /* The start is copied, not solved: it must match to rounding of /2 and /6. */
        assert_near(a[k], s0[k], 1e-15 * fabs(s0[k]));
        assert_true(e <= 1e-9 * fmax(1.0, sc));
      }
    }
  }
  print_message("bc worst abs  p %.2e v %.2e a %.2e j %.2e\n", worst_abs[0], worst_abs[1],
                worst_abs[2], worst_abs[3]);
  print_message("bc worst rel  p %.2e v %.2e a %.2e j %.2e\n", worst_rel[0], worst_rel[1],
                worst_rel[2], worst_rel[3]);
  /* Positions and velocities are O(1) here, so they also hold to 1e-9 absolutely. */
  assert_true(worst_abs[0] <= 1e-9 && worst_abs[1] <= 1e-9);
}

static void test_cost_exact_vs_quadrature(void **state) {
  (void)state;
  nd_rng r;
  nd_rng_seed(&r, 43, 1);
  double worst = 0.0;
  for (int ti = 0; ti < NT; ti++) {
    for (int n = 0; n < 50; n++) {
      double s0[4], p1, v1, c[MAXDEG + 1] = {0};
      random_axis(&r, s0, &p1, &v1);
      nd_snap_coeffs(s0, p1, v1, Ts[ti], c);
      const double J = nd_snap_cost(c, Ts[ti]), Jq = quad_snap_cost(c, 7, Ts[ti]);
      assert_true(J > 0.0);
      worst = fmax(worst, fabs(J - Jq) / Jq);
      assert_near(J / Jq, 1.0, 1e-10);
    }
  }
  print_message("cost exact vs quadrature: worst rel diff %.2e\n", worst);
}

static void test_perturbations_never_cheaper(void **state) {
  (void)state;
  nd_rng r;
  nd_rng_seed(&r, 44, 1);
  /* Sizes of eps^2 cost(h) relative to the optimum: from barely visible to dominant. */
  const double frac[] = {1e-6, 1e-3, 1e-1, 1.0, 10.0};
  const int nf = (int)(sizeof frac / sizeof frac[0]);
  double worst_gap_rel = INFINITY, worst_cos = 0.0, worst_quad_err = 0.0;
  int count = 0;
  for (int ti = 0; ti < NT; ti++) {
    const double T = Ts[ti];
    for (int n = 0; n < 40; n++) {
      double s0[4], p1, v1, c[MAXDEG + 1] = {0}, h[MAXDEG + 1], q[3];
      random_axis(&r, s0, &p1, &v1);
      nd_snap_coeffs(s0, p1, v1, T, c);
      for (int j = 0; j < 3; j++) q[j] = unif(&r, -1.0, 1.0) / pow(T, j);
      const int deg = bump_poly(T, q, h);
      const double J = nd_snap_cost(c, T), Jh = quad_snap_cost(h, deg, T);
      /* First-order optimality: the optimum's snap is orthogonal to every admissible
       * perturbation's snap, so the cost rises only by eps^2 cost(h). */
      const double cosang = quad_snap_dot(c, h, deg, T) / sqrt(J * Jh);
      worst_cos = fmax(worst_cos, fabs(cosang));
      assert_true(fabs(cosang) < 1e-9);
      for (int f = 0; f < nf; f++) {
        for (int sgn = -1; sgn <= 1; sgn += 2) {
          const double eps = sgn * sqrt(frac[f] * J / Jh);
          double pp[MAXDEG + 1];
          for (int k = 0; k <= MAXDEG; k++) pp[k] = c[k] + eps * h[k];
          /* The competitor meets the same eight conditions. */
          const double end[4] = {p1, v1, 0.0, 0.0};
          for (int k = 0; k < 4; k++) {
            const double sc = fmax(1.0, deriv_scale(s0, p1, v1, T, k));
            assert_true(fabs(poly_deriv(pp, deg, k, 0.0) - s0[k]) <= 1e-9 * sc);
            assert_true(fabs(poly_deriv(pp, deg, k, T) - end[k]) <= 1e-9 * sc);
          }
          const double Jp = quad_snap_cost(pp, deg, T);
          const double gap_rel = (Jp - J) / (eps * eps * Jh);
          worst_gap_rel = fmin(worst_gap_rel, gap_rel);
          worst_quad_err = fmax(worst_quad_err, fabs(gap_rel - 1.0));
          assert_true(Jp > J);
          count++;
        }
      }
    }
  }
  print_message("perturbations: %d, min (J_pert - J*) / (eps^2 J_h) = %.9f, "
                "max |that - 1| = %.2e, max |cos(snap*, snap_h)| = %.2e\n",
                count, worst_gap_rel, worst_quad_err, worst_cos);
  assert_true(worst_gap_rel > 0.99);
}

static void test_splice_mid_segment(void **state) {
  (void)state;
  nd_rng r;
  nd_rng_seed(&r, 45, 1);
  double worst_splice = 0.0, worst_replan = 0.0;
  for (int ti = 0; ti < NT; ti++) {
    const double T = Ts[ti];
    for (int n = 0; n < 50; n++) {
      double s0[2][4], p1[2], v1[2];
      for (int ax = 0; ax < 2; ax++) random_axis(&r, s0[ax], &p1[ax], &v1[ax]);
      nd_snap_seg a, b, c;
      nd_snap_seg_make(&a, s0, p1, v1, T);
      const double tm = T * unif(&r, 0.05, 0.95);
      double mid[2][4], out[2][4], out2[2][4];
      nd_snap_seg_eval(&a, tm, mid);

      /* A new plan to an unrelated keypoint starts exactly where the old one is. */
      double p2[2], v2[2], dummy[4];
      for (int ax = 0; ax < 2; ax++) random_axis(&r, dummy, &p2[ax], &v2[ax]);
      nd_snap_seg_make(&b, (const double(*)[4])mid, p2, v2, unif(&r, 0.05, 2.0));
      nd_snap_seg_eval(&b, 0.0, out);
      for (int ax = 0; ax < 2; ax++)
        for (int k = 0; k < 4; k++) {
          const double e = fabs(out[ax][k] - mid[ax][k]);
          worst_splice = fmax(worst_splice, e / fmax(fabs(mid[ax][k]), 1e-300));
          assert_true(e <= 1e-12 * fabs(mid[ax][k]));
        }

      /* Replanning to the same keypoint with the remaining time reproduces the rest of
       * the old segment: the eight conditions determine the polynomial uniquely. */
      nd_snap_seg_make(&c, (const double(*)[4])mid, p1, v1, T - tm);
      for (int i = 0; i <= 10; i++) {
        const double t = tm + (T - tm) * i / 10.0;
        nd_snap_seg_eval(&a, t, out);
        nd_snap_seg_eval(&c, t - tm, out2);
        for (int ax = 0; ax < 2; ax++)
          for (int k = 0; k < 4; k++) {
            /* Relative to the replanned segment's own data: a short remainder is a
             * stiff problem, and its jerk legitimately amplifies rounding by 1/T'^3. */
            const double sc = fmax(1.0, deriv_scale(mid[ax], p1[ax], v1[ax], T - tm, k));
            const double e = fabs(out[ax][k] - out2[ax][k]) / sc;
            worst_replan = fmax(worst_replan, e);
            assert_true(e <= 1e-9);
          }
      }
    }
  }
  print_message("splice worst rel %.2e, replan-same-target worst rel %.2e\n", worst_splice,
                worst_replan);
}

static void test_eval_outside_segment(void **state) {
  (void)state;
  const double s0[2][4] = {{0.1, 0.3, -2.0, 40.0}, {-0.2, -0.1, 5.0, -10.0}};
  const double p1[2] = {0.4, 0.05}, v1[2] = {0.25, -0.5};
  nd_snap_seg seg;
  nd_snap_seg_make(&seg, s0, p1, v1, 0.3);
  double out[2][4], at0[2][4], atT[2][4];
  nd_snap_seg_eval(&seg, 0.0, at0);
  nd_snap_seg_eval(&seg, -0.5, out);
  for (int ax = 0; ax < 2; ax++)
    for (int k = 0; k < 4; k++) assert_true(out[ax][k] == at0[ax][k]);

  nd_snap_seg_eval(&seg, 0.3, atT);
  for (int ax = 0; ax < 2; ax++) {
    assert_near(atT[ax][ND_P], p1[ax], 1e-12);
    assert_near(atT[ax][ND_V], v1[ax], 1e-12);
  }
  const double dts[] = {1e-9, 0.1, 0.7, 5.0};
  for (int i = 0; i < 4; i++) {
    nd_snap_seg_eval(&seg, 0.3 + dts[i], out);
    for (int ax = 0; ax < 2; ax++) {
      assert_near(out[ax][ND_P], p1[ax] + v1[ax] * dts[i], 1e-11);
      assert_near(out[ax][ND_V], v1[ax], 1e-11);
      assert_true(out[ax][ND_A] == 0.0 && out[ax][ND_J] == 0.0);
    }
  }
  /* Just inside the end the polynomial already has (numerically) zero a and j. */
  nd_snap_seg_eval(&seg, 0.3 - 1e-9, out);
  for (int ax = 0; ax < 2; ax++) {
    assert_near(out[ax][ND_P], p1[ax] - v1[ax] * 1e-9, 1e-11);
    assert_near(out[ax][ND_A], 0.0, 1e-6);
  }
}

/* A re-plan dt later, sampled along the chain, follows the same path: at dt = 0 it gives
 * the keypoints back, at dt = T each keypoint takes the next one's place, in between the
 * chain's own state, and past its end its last keypoint. */
static void test_retime(void **state) {
  (void)state;
  nd_rng r;
  nd_rng_seed(&r, 7, 1);
  enum { M = 3 };
  const double T = 0.3;
  for (int trial = 0; trial < 50; trial++) {
    double s0[2][4], keys[4 * M], out[4 * M];
    for (int ax = 0; ax < 2; ax++) {
      double p1, v1;
      random_axis(&r, s0[ax], &p1, &v1);
    }
    for (int i = 0; i < 4 * M; i++) keys[i] = unif(&r, -1.0, 1.0);
    nd_snap_retime((const double(*)[4])s0, keys, M, T, 0.0, out);
    for (int i = 0; i < 4 * M; i++) assert_near(out[i], keys[i], 1e-9);
    nd_snap_retime((const double(*)[4])s0, keys, M, T, T, out);
    for (int i = 0; i < 4 * (M - 1); i++) assert_near(out[i], keys[i + 4], 1e-9);
    for (int i = 0; i < 4; i++) assert_true(out[4 * (M - 1) + i] == keys[4 * (M - 1) + i]);

    /* dt = 0.4 T: keypoint 0 is the chain at 1.4 T, inside segment 1. */
    nd_snap_seg seg0, seg1;
    double end0[2][4], at[2][4];
    nd_snap_seg_make(&seg0, (const double(*)[4])s0, keys, keys + 2, T);
    nd_snap_seg_eval(&seg0, T, end0);
    nd_snap_seg_make(&seg1, (const double(*)[4])end0, keys + 4, keys + 6, T);
    nd_snap_seg_eval(&seg1, 0.4 * T, at);
    double in_place[4 * M];
    memcpy(in_place, keys, sizeof(in_place));
    nd_snap_retime((const double(*)[4])s0, in_place, M, T, 0.4 * T, in_place);
    nd_snap_retime((const double(*)[4])s0, keys, M, T, 0.4 * T, out);
    assert_memory_equal(in_place, out, sizeof(out));
    for (int ax = 0; ax < 2; ax++) {
      assert_near(out[ax], at[ax][ND_P], 1e-12);
      assert_near(out[2 + ax], at[ax][ND_V], 1e-12);
    }

    nd_snap_retime((const double(*)[4])s0, keys, M, T, 2.5 * T, out);
    for (int k = 0; k < M; k++)
      for (int i = 0; i < 4; i++) assert_true(out[4 * k + i] == keys[4 * (M - 1) + i]);
  }
}

int main(void) {
  gl_init();
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_known_rest_to_rest),
      cmocka_unit_test(test_boundary_conditions),
      cmocka_unit_test(test_cost_exact_vs_quadrature),
      cmocka_unit_test(test_perturbations_never_cheaper),
      cmocka_unit_test(test_splice_mid_segment),
      cmocka_unit_test(test_eval_outside_segment),
      cmocka_unit_test(test_retime),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
