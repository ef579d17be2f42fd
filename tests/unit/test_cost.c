/* test_cost: plan cost terms, their symmetry, and the terminal condition's edges. */
#include "nd_test.h"

#include "nd_cost.h"
#include "nd_math.h"
#include "nd_rng.h"

static void test_known_values(void **state) {
  (void)state;
  const nd_goal g = {.x = 0.5, .y = -0.2, .yaw = 0.3};
  const double obj[2] = {0.8, 0.2}, ee[2] = {0.8, 0.25};
  assert_near(nd_cost_pos(obj, &g), 0.09 + 0.16, 1e-15);
  assert_near(nd_cost_prox(obj, ee), 0.0025, 1e-15);
  assert_near(nd_cost_rot(0.3, &g), 0.0, 0.0);
  assert_near(nd_cost_rot(0.3 + 3.14159265358979323846 / 2.0, &g), 1.0, 1e-15);
  assert_near(nd_cost_rot(0.3 + 3.14159265358979323846 / 6.0, &g), 0.25, 1e-15);

  const nd_cost_weights w = {.w_rot = 0.1, .w_prox = 0.01, .w_acc = 0.001};
  const double yaw = 0.3 + 3.14159265358979323846 / 6.0;
  const double obj_at[1][3] = {{obj[0], obj[1], yaw}}, ee_at[1][2] = {{ee[0], ee[1]}};
  const double task = nd_task_error(&w, &g, obj, yaw);
  assert_near(task, 0.25 + 0.1 * 0.25, 1e-15);
  assert_near(nd_cost_plan(&w, &g, task, obj_at, ee_at, 1, 40.0, NULL),
              0.25 + 0.1 * 0.25 + 0.01 * 0.0025 + 0.001 * 40.0, 1e-15);
  /* Each weight scales only its own term. */
  nd_cost_weights w2 = w;
  w2.w_acc = 0.0;
  assert_near(nd_cost_plan(&w, &g, task, obj_at, ee_at, 1, 40.0, NULL) -
                  nd_cost_plan(&w2, &g, task, obj_at, ee_at, 1, 40.0, NULL),
              0.04, 1e-15);
  w2 = w;
  w2.w_prox = 0.0;
  assert_near(nd_cost_plan(&w, &g, task, obj_at, ee_at, 1, 40.0, NULL) -
                  nd_cost_plan(&w2, &g, task, obj_at, ee_at, 1, 40.0, NULL),
              0.01 * 0.0025, 1e-15);
}

/* L_prox is the mean over the horizon's samples: of two approaches that end at the lead
 * point, the one there sooner costs less, by the mean of the squared distances it saved;
 * each sample's lead point follows the object's pose there. */
static void test_prox_over_horizon(void **state) {
  (void)state;
  const nd_goal g = {.x = 0.3, .y = 0.0, .yaw = 0.0};
  const nd_cost_weights w = {.w_prox = 1.0, .prox_lead = 0.08};
  const double obj_at[4][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  const double soon[4][2] = {{-0.12, 0}, {-0.08, 0}, {-0.08, 0}, {-0.08, 0}};
  const double late[4][2] = {{-0.20, 0}, {-0.16, 0}, {-0.12, 0}, {-0.08, 0}};
  const double c_soon = nd_cost_plan(&w, &g, 0.0, obj_at, soon, 4, 0.0, NULL);
  const double c_late = nd_cost_plan(&w, &g, 0.0, obj_at, late, 4, 0.0, NULL);
  assert_near(c_soon, 0.04 * 0.04 / 4, 1e-15);
  assert_near(c_late, (0.12 * 0.12 + 0.08 * 0.08 + 0.04 * 0.04) / 4, 1e-15);
  assert_true(c_soon < c_late);
  /* The object moved half way to the goal at the last sample: so did its lead point. */
  const double moving[4][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0.15, 0, 0}};
  const double behind[4][2] = {{-0.08, 0}, {-0.08, 0}, {-0.08, 0}, {0.07, 0}};
  assert_near(nd_cost_plan(&w, &g, 0.0, moving, behind, 4, 0.0, NULL), 0.0, 1e-15);
}

/* The lead point: behind the object on the goal's line, fading into it near the goal. */
static void test_lead_point(void **state) {
  (void)state;
  const nd_goal g = {.x = 0.5, .y = -0.2, .yaw = 0.0};
  double p[2];
  nd_cost_lead_point(0.08, &g, (const double[2]){0.8, 0.2}, p);
  assert_near(p[0], 0.8 + 0.08 * 0.6, 1e-15);
  assert_near(p[1], 0.2 + 0.08 * 0.8, 1e-15);
  /* 2 cm from the goal: 0.4 of the lead; at the goal: the object itself. */
  nd_cost_lead_point(0.08, &g, (const double[2]){0.52, -0.2}, p);
  assert_near(p[0], 0.52 + 0.08 * 0.4, 1e-15);
  assert_near(p[1], -0.2, 1e-15);
  nd_cost_lead_point(0.08, &g, (const double[2]){0.5, -0.2}, p);
  assert_near(p[0], 0.5, 0.0);
  assert_near(p[1], -0.2, 0.0);
  nd_cost_lead_point(0.0, &g, (const double[2]){0.8, 0.2}, p);
  assert_near(p[0], 0.8, 0.0);
  assert_near(p[1], 0.2, 0.0);
  /* The plan cost charges the sphere's distance to it: behind the object (seen from the
   * goal) costs nothing, the goal side twice the lead squared. */
  nd_cost_weights w = {.w_rot = 0.0, .w_prox = 1.0, .w_acc = 0.0, .prox_lead = 0.08};
  const double obj[1][3] = {{0.8, 0.2, 0.0}};
  const double behind[1][2] = {{0.848, 0.264}}, front[1][2] = {{0.752, 0.136}};
  const double task = nd_task_error(&w, &g, obj[0], 0.0);
  assert_near(nd_cost_plan(&w, &g, task, obj, behind, 1, 0.0, NULL), nd_cost_pos(obj[0], &g),
              1e-15);
  assert_near(nd_cost_plan(&w, &g, task, obj, front, 1, 0.0, NULL) - nd_cost_pos(obj[0], &g),
              4.0 * 0.08 * 0.08, 1e-15);
}

/* The task term by arrival: a plan that meets eps and stays scores by when it gets there
 * (eps (k + 1) / n on top of its largest error from then on), below every plan that does
 * not (its final error + eps); one that runs the object through the goal is not arriving;
 * a smaller eps moves arrival later; eps 0 is the final error alone. */
static void test_arrival(void **state) {
  (void)state;
  const nd_cost_weights w = {.w_rot = 0.02};
  nd_goal g = {.x = 0.1, .y = 0.0, .yaw = 0.0, .eps = 1e-3};
  enum { N = 4 };
  /* The object's x at each quarter of the horizon, y and yaw 0: errors (x - 0.1)^2. */
  const double early[N][3] = {{0.09, 0, 0}, {0.1, 0, 0}, {0.1, 0, 0}, {0.1, 0, 0}};
  const double late[N][3] = {{0.0, 0, 0}, {0.05, 0, 0}, {0.08, 0, 0}, {0.1, 0, 0}};
  const double through[N][3] = {{0.05, 0, 0}, {0.1, 0, 0}, {0.15, 0, 0}, {0.2, 0, 0}};
  const double short_of[N][3] = {{0.0, 0, 0}, {0.03, 0, 0}, {0.05, 0, 0}, {0.06, 0, 0}};
  /* early: within eps (1e-4) from the first sample on. */
  assert_near(nd_cost_arrival(&w, &g, g.eps, early, N), 1e-4 + 1e-3 * 0.25, 1e-15);
  /* late: 4e-4 at the third sample, 0 at the last: max 4e-4 from k = 2 (0.75 of the
   * horizon), 0 at k = 3. */
  assert_near(nd_cost_arrival(&w, &g, g.eps, late, N), fmin(4e-4 + 1e-3 * 0.75, 1e-3), 1e-15);
  assert_true(nd_cost_arrival(&w, &g, g.eps, early, N) < nd_cost_arrival(&w, &g, g.eps, late, N));
  /* through: at the goal mid-horizon, 0.1 beyond at the end: not arriving. */
  assert_near(nd_cost_arrival(&w, &g, g.eps, through, N), 0.01 + 1e-3, 1e-15);
  /* short of it: the final error + eps, above every arriving plan's 2 eps. */
  assert_near(nd_cost_arrival(&w, &g, g.eps, short_of, N), 0.0016 + 1e-3, 1e-15);
  assert_true(nd_cost_arrival(&w, &g, g.eps, late, N) < 2e-3);
  /* A yaw error counts as nd_task_error does: 90 degrees off at the end is not arriving. */
  const double turned[N][3] = {{0.1, 0, 0}, {0.1, 0, 0}, {0.1, 0, 0}, {0.1, 0, 1.5707963267948966}};
  assert_near(nd_cost_arrival(&w, &g, g.eps, turned, N), 0.02 + 1e-3, 1e-15);
  /* Aimed inside the goal's eps (the planner's --arrival share): early's 1e-4 at the first
   * sample no longer counts at 5e-5, its arrival is the second sample. */
  assert_near(nd_cost_arrival(&w, &g, 5e-5, early, N), 5e-5 * 0.5, 1e-18);
  /* Without eps, the final state's error: the paper's term. */
  g.eps = 0.0;
  assert_near(nd_cost_arrival(&w, &g, g.eps, late, N), 0.0, 0.0);
  assert_near(nd_cost_arrival(&w, &g, g.eps, through, N), 0.01, 1e-15);
  /* A NaN sample is never a good plan. */
  g.eps = 1e-3;
  const double bad[N][3] = {{0.1, 0, 0}, {NAN, 0, 0}, {0.1, 0, 0}, {0.1, 0, 0}};
  assert_true(isinf(nd_cost_arrival(&w, &g, g.eps, bad, N)));
}

/* L_edge on the lab's box [-0.15, 0.15] x [-0.30, 0.40] with the 8 cm lead: the object
 * may stand anywhere the sphere can get behind it, and up to a goal beyond that, no farther. */
static void test_edge(void **state) {
  (void)state;
  const nd_cost_weights w = nd_cost_weights_default();
  const double lo[2] = {-0.15, -0.30}, hi[2] = {0.15, 0.40};
  const nd_goal inner = {.x = 0.0, .y = 0.1}, near_edge = {.x = 0.14, .y = -0.04};
  assert_near(nd_cost_edge(&w, &inner, (const double[2]){0.069, -0.219}, lo, hi), 0.0, 0.0);
  assert_near(nd_cost_edge(&w, &inner, (const double[2]){-0.069, 0.319}, lo, hi), 0.0, 0.0);
  /* 2 cm beyond x = 0.07 and 1 cm beyond y = -0.22. */
  assert_near(nd_cost_edge(&w, &inner, (const double[2]){0.09, -0.23}, lo, hi), 4e-4 + 1e-4,
              1e-15);
  assert_near(nd_cost_edge(&w, &inner, (const double[2]){-0.10, 0.35}, lo, hi), 9e-4 + 9e-4,
              1e-15);
  /* A goal near the edge: free up to it, charged past it (the 2.5 cm overshoot that left
   * the lab's object where no push could reach it). */
  assert_near(nd_cost_edge(&w, &near_edge, (const double[2]){0.14, -0.04}, lo, hi), 0.0, 0.0);
  assert_near(nd_cost_edge(&w, &near_edge, (const double[2]){0.165, -0.04}, lo, hi),
              0.025 * 0.025, 1e-15);
  /* Past the goal it outweighs the position term it trades against. */
  const double past[2] = {0.15, -0.04}, short_[2] = {0.13, -0.04};
  assert_true(nd_cost_pos(past, &near_edge) + w.w_edge * nd_cost_edge(&w, &near_edge, past, lo, hi) >
              5.0 * (nd_cost_pos(short_, &near_edge) +
                     w.w_edge * nd_cost_edge(&w, &near_edge, short_, lo, hi)));
  /* No lead: the box itself. */
  nd_cost_weights w0 = w;
  w0.prox_lead = 0.0;
  assert_near(nd_cost_edge(&w0, &inner, (const double[2]){0.149, 0.399}, lo, hi), 0.0, 0.0);
  assert_near(nd_cost_edge(&w0, &inner, (const double[2]){0.16, 0.40}, lo, hi), 1e-4, 1e-15);
}

static void test_cuboid_symmetry(void **state) {
  (void)state;
  const double pi = 3.14159265358979323846;
  const double obj[2] = {0.1, 0.1};
  const nd_cost_weights w = nd_cost_weights_default();
  for (int gi = -6; gi <= 6; gi++) {
    const nd_goal g = {.x = 0.0, .y = 0.0, .yaw = gi * 0.5};
    for (int i = -20; i <= 20; i++) {
      const double yaw = i * 0.17;
      const double r = nd_cost_rot(yaw, &g);
      assert_true(r >= 0.0 && r <= 1.0);
      assert_near(nd_cost_rot(yaw + pi, &g), r, 1e-12);
      assert_near(nd_cost_rot(yaw - pi, &g), r, 1e-12);
      /* Mirror images about the goal yaw cost the same; so do whole turns. */
      assert_near(nd_cost_rot(2.0 * g.yaw - yaw, &g), r, 1e-12);
      assert_near(nd_cost_rot(yaw + 2.0 * pi, &g), r, 1e-12);
      assert_near(nd_task_error(&w, &g, obj, yaw + pi), nd_task_error(&w, &g, obj, yaw), 1e-12);
    }
    /* Zero at the goal and at its flip, maximal a quarter turn away. */
    assert_near(nd_cost_rot(g.yaw + pi, &g), 0.0, 1e-24);
    assert_near(nd_cost_rot(g.yaw + pi / 2.0, &g), 1.0, 1e-15);
  }
}

/* Moves along the way round from `from` to `to`, at most 8, their ends into pts and their
 * length into *len; -1 where a step finds no way. */
static int round_moves(const nd_cost_round *r, const double box[3], const double from[2],
                       const double to[2], double pts[8][2], double *len) {
  const double *at = from;
  int moves = 0;
  *len = 0.0;
  while (nd_dist2(at, to) > 0.0 && moves < 8) {
    if (nd_cost_round_next(r, box, at, to, pts[moves]) < 0.0) return -1;
    *len += nd_dist2(at, pts[moves]);
    at = pts[moves++];
  }
  return moves;
}

/* Going along the way round: each next point is a corner of the grown box, then the end;
 * the moves add up to the way's length; none where the end is in the object or out of
 * reach. */
static void test_round_next(void **state) {
  (void)state;
  const nd_cost_round w = {{0.05, 0.03}, 0.025, {-1, -1}, {1, 1}};
  const double b0[3] = {0, 0, 0}, to[2] = {-0.15, 0}, e = 1e-5;
  const double at[2] = {0.15, 0};
  double next[2], pts[8][2], len;
  const double way = nd_cost_round_next(&w, b0, at, to, next);
  assert_near(way, nd_cost_round_way(&w, b0, at, to), 1e-12);
  assert_int_equal(round_moves(&w, b0, at, to, pts, &len), 3);
  for (int k = 0; k < 2; k++) { /* (0.08, +-0.06), then (-0.08, the same side) */
    assert_near(fabs(pts[k][0]), 0.08, e);
    assert_near(fabs(pts[k][1]), 0.06, e);
  }
  assert_near(len, way, e);
  /* Clear: straight to the end. */
  assert_near(nd_cost_round_next(&w, b0, (double[]){0.1, 0.1}, (double[]){-0.1, 0.1}, next),
              0.2, e);
  assert_near(next[0], -0.1, 1e-12);
  assert_near(next[1], 0.1, 1e-12);
  /* 5 mm inside the grown box: out through the nearest side first. */
  assert_true(nd_cost_round_next(&w, b0, (double[]){0.075, 0}, to, next) > 0.0);
  assert_near(next[0], 0.08, e);
  assert_near(next[1], 0.0, e);
  /* From 2 mm inside a side (a sphere released clear of the object, but within the way's
   * margin) round a turned box: out, two corners, the end. */
  const double bt[3] = {0.001, -0.002, 0.03}, from_in[2] = {0.079, 0.004};
  assert_int_equal(round_moves(&w, bt, from_in, to, pts, &len), 4);
  assert_near(len, nd_cost_round_way(&w, bt, from_in, to), e);
  /* An end within the grown box but clear of the sphere's reach into the object: round the
   * two corners, then in along the side (this end once sent the way back out of the box). */
  const double near_end[2] = {-0.078, 0.0};
  assert_int_equal(round_moves(&w, b0, (double[]){0.15, 0}, near_end, pts, &len), 3);
  /* The way's length counts the step in along the side; the last move takes it diagonally. */
  const double near_way = nd_cost_round_way(&w, b0, (double[]){0.15, 0}, near_end);
  assert_true(len <= near_way && len > near_way - 0.002);
  /* An end in the object, or every corner beyond reach: none. */
  assert_true(nd_cost_round_next(&w, b0, at, (double[]){0.02, 0}, next) < 0.0);
  nd_cost_round r = w;
  r.hi[1] = 0.05;
  r.lo[1] = -0.05;
  assert_true(nd_cost_round_next(&r, b0, (double[]){0.15, 0}, to, next) < 0.0);
}

/* 1 if p lies in the box b (x, y, yaw) of half sides hx, hy. */
static int in_box(const double b[3], const double p[2], double hx, double hy) {
  double d[2] = {p[0] - b[0], p[1] - b[1]};
  nd_rot2(cos(b[2]), -sin(b[2]), d, d);
  return fabs(d[0]) < hx && fabs(d[1]) < hy;
}

/* Random boxes, starts and ends (the lab's keypoint box): every way found ends within 6
 * moves, each clear of the object grown by the radius. Many starts lie on a corner, the
 * point the last move went to: the next move must leave it. */
static void test_round_next_random(void **state) {
  (void)state;
  const nd_cost_round r = {{0.06, 0.04}, 0.025, {-0.15, -0.3}, {0.15, 0.4}};
  nd_rng g;
  nd_rng_seed(&g, 7, 0);
  int ways = 0;
  for (int t = 0; t < 20000; t++) {
    const double box[3] = {0.2 * nd_rng_uniform(&g) - 0.1, 0.2 * nd_rng_uniform(&g) - 0.1,
                           6.4 * nd_rng_uniform(&g) - 3.2};
    const double from[2] = {0.3 * nd_rng_uniform(&g) - 0.15, 0.7 * nd_rng_uniform(&g) - 0.3};
    const double to[2] = {0.3 * nd_rng_uniform(&g) - 0.15, 0.7 * nd_rng_uniform(&g) - 0.3};
    if (in_box(box, from, 0.085, 0.065) || in_box(box, to, 0.085, 0.065)) continue;
    double pts[8][2], len;
    if (nd_cost_round_next(&r, box, from, to, pts[0]) < 0.0) continue; /* none in reach */
    const int moves = round_moves(&r, box, from, to, pts, &len);
    assert_true(moves >= 1 && moves <= 6);
    assert_true(nd_dist2(pts[moves > 1 ? moves - 1 : 0], to) == 0.0);
    for (int k = 0; k < moves; k++) {
      const double *a = k ? pts[k - 1] : from, *b = pts[k];
      for (int q = 1; q < 20; q++) {
        const double m[2] = {a[0] + (b[0] - a[0]) * q / 20.0, a[1] + (b[1] - a[1]) * q / 20.0};
        assert_false(in_box(box, m, 0.075, 0.055));
      }
    }
    ways++;
  }
  assert_true(ways > 10000);
}

/* The way round the box: straight where the line is clear, round the grown box's corners
 * where it is not, only by corners within reach, and out of the grown box first. */
static void test_round_way(void **state) {
  (void)state;
  /* Box 10 x 6 cm, sphere radius 2.5 cm: grown by 3 cm, half sides 8 and 6 cm. */
  const nd_cost_round w = {{0.05, 0.03}, 0.025, {-1, -1}, {1, 1}};
  const double b0[3] = {0, 0, 0}, b90[3] = {0, 0, M_PI / 2};
  const double e = 1e-5;
  assert_near(nd_cost_round_way(&w, b0, (double[]){0.1, 0.1}, (double[]){-0.1, 0.1}), 0.2, e);
  const double round0 = 2 * hypot(0.07, 0.06) + 0.16, round90 = 2 * hypot(0.09, 0.08) + 0.12;
  assert_near(nd_cost_round_way(&w, b0, (double[]){0.15, 0}, (double[]){-0.15, 0}), round0, e);
  assert_near(nd_cost_round_way(&w, b90, (double[]){0.15, 0}, (double[]){-0.15, 0}), round90, e);
  /* The +y corners beyond reach: round the -y side, as long; both beyond: straight. */
  nd_cost_round r = w;
  r.hi[1] = 0.05;
  assert_near(nd_cost_round_way(&r, b0, (double[]){0.15, 0}, (double[]){-0.15, 0}), round0, e);
  r.lo[1] = -0.05;
  assert_near(nd_cost_round_way(&r, b0, (double[]){0.15, 0}, (double[]){-0.15, 0}), 0.3, e);
  /* A lead point where the sphere cannot be (faded into the object near the goal). */
  assert_near(nd_cost_round_way(&w, b0, (double[]){0.15, 0}, (double[]){0.0, 0.0}), 0.15, e);
  /* The sphere 5 mm inside the grown box: out to its side, then along it and round. */
  assert_near(nd_cost_round_way(&w, b0, (double[]){0.075, 0}, (double[]){-0.15, 0}),
              0.005 + 0.06 + 0.16 + hypot(0.07, 0.06), e);
  /* The lab's push from the box's +x edge back (decisions#prox-round): the box at x 0.098
   * turned 44 degrees, the goal at (0.09, 0.12), the sphere on the goal's side. Straight,
   * the lead point is nearer from the +x end, beyond which the arm cannot reach, than from
   * where the sphere hovers; round, it is further, and the way round the -x end nearer. */
  const nd_cost_round lab = {{0.05, 0.03}, 0.025, {-0.15, -0.30}, {0.15, 0.40}};
  const double box[3] = {0.098, -0.054, 44 * M_PI / 180};
  nd_goal g = {.x = 0.09, .y = 0.12, .yaw = 0.4};
  nd_cost_weights cw = nd_cost_weights_default();
  double lead[2];
  nd_cost_lead_point(cw.prox_lead, &g, box, lead);
  const double hover[2] = {0.14, 0.02}, plus_x[2] = {0.16, -0.02}, minus_x[2] = {0.03, 0.02};
  assert_true(nd_dist2(plus_x, lead) < nd_dist2(hover, lead));
  assert_true(nd_dist2(minus_x, lead) > nd_dist2(hover, lead));
  assert_true(nd_cost_round_way(&lab, box, plus_x, lead) >
              nd_cost_round_way(&lab, box, hover, lead) + 0.05);
  assert_true(nd_cost_round_way(&lab, box, minus_x, lead) <
              nd_cost_round_way(&lab, box, hover, lead) - 0.1);
  /* nd_cost_plan: L_prox the squared way round; straight where it is clear. */
  cw.w_acc = 0.0;
  const double obj[1][3] = {{0.098, -0.054, 44 * M_PI / 180}};
  const double at_hover[1][2] = {{0.14, 0.02}};
  const double d = nd_cost_round_way(&lab, box, hover, lead);
  assert_near(nd_cost_plan(&cw, &g, 0.0, obj, at_hover, 1, 0.0, &lab), cw.w_prox * d * d, 1e-12);
  const double at_lead[1][2] = {{lead[0], lead[1] - 0.03}};
  assert_near(nd_cost_plan(&cw, &g, 0.0, obj, at_lead, 1, 0.0, &lab),
              nd_cost_plan(&cw, &g, 0.0, obj, at_lead, 1, 0.0, NULL), 1e-15);
}

static void test_default_weights(void **state) {
  (void)state;
  const nd_cost_weights w = nd_cost_weights_default();
  assert_near(w.w_rot, 2e-2, 0.0);
  /* Proximity and acceleration must stay tie-breakers: a 10 cm position error
   * (L_pos = 1e-2) must outweigh a 30 cm EE distance and a mean |a|^2 of 130 together. */
  assert_true(w.w_prox > 0.0 && w.w_acc > 0.0);
  assert_true(w.w_prox * 0.09 + w.w_acc * 130.0 < 1e-2);
  /* The lead point sits about where a pushing sphere touches the 10 x 6 cm box. */
  assert_true(w.prox_lead > 0.03 && w.prox_lead < 0.1);
  /* ...yet a quarter-turn yaw error alone fails the task at eps = 1e-2. */
  assert_true(w.w_rot * 1.0 > 1e-2);
}

static void test_terminal_condition(void **state) {
  (void)state;
  const double eps = 1e-2, tau = 5.0;
  assert_int_equal(nd_task_check(0.5, 1.0, eps, tau), ND_TASK_RUNNING);
  assert_int_equal(nd_task_check(0.005, 1.0, eps, tau), ND_TASK_SUCCESS);
  /* Strict inequalities on both edges. */
  assert_int_equal(nd_task_check(eps, 1.0, eps, tau), ND_TASK_RUNNING);
  assert_int_equal(nd_task_check(nextafter(eps, 0.0), 1.0, eps, tau), ND_TASK_SUCCESS);
  assert_int_equal(nd_task_check(0.5, tau, eps, tau), ND_TASK_RUNNING);
  assert_int_equal(nd_task_check(0.5, nextafter(tau, 10.0), eps, tau), ND_TASK_TIMEOUT);
  /* Success wins over timeout. */
  assert_int_equal(nd_task_check(0.001, 7.0, eps, tau), ND_TASK_SUCCESS);
  /* A non-finite error never succeeds, whatever eps is. */
  assert_int_equal(nd_task_check(NAN, 1.0, eps, tau), ND_TASK_RUNNING);
  assert_int_equal(nd_task_check(NAN, 7.0, eps, tau), ND_TASK_TIMEOUT);
  assert_int_equal(nd_task_check(-INFINITY, 1.0, eps, tau), ND_TASK_RUNNING);
  assert_int_equal(nd_task_check(NAN, 1.0, INFINITY, tau), ND_TASK_RUNNING);
  assert_int_equal(nd_task_check(INFINITY, 1.0, INFINITY, tau), ND_TASK_RUNNING);
  /* A NaN pose propagates into the task error, which must then not count as success. */
  const nd_cost_weights w = nd_cost_weights_default();
  const nd_goal g = {.x = 0.0, .y = 0.0, .yaw = 0.0};
  const double obj[2] = {NAN, 0.0};
  assert_int_equal(nd_task_check(nd_task_error(&w, &g, obj, 0.0), 1.0, eps, tau),
                   ND_TASK_RUNNING);
  assert_int_equal(nd_task_check(nd_task_error(&w, &g, (const double[2]){0, 0}, NAN), 1.0,
                                 eps, tau),
                   ND_TASK_RUNNING);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_known_values),
      cmocka_unit_test(test_lead_point),
      cmocka_unit_test(test_prox_over_horizon),
      cmocka_unit_test(test_arrival),
      cmocka_unit_test(test_edge),
      cmocka_unit_test(test_round_way),
      cmocka_unit_test(test_round_next),
      cmocka_unit_test(test_round_next_random),
      cmocka_unit_test(test_cuboid_symmetry),
      cmocka_unit_test(test_default_weights),
      cmocka_unit_test(test_terminal_condition),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
