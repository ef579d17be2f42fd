/* draw: the geoms nudge-view adds to MuJoCo's scene (view.h): what the model does not hold.
 * Everything is computed from the newest inputs alone, so a frame is a function of them. */
#include <math.h>
#include <string.h>

#include "nd_snap.h"
#include "view.h"

static const float rgba_goal[4] = {0.1f, 0.85f, 0.2f, 0.4f};
static const float rgba_pred[4] = {1.0f, 0.5f, 0.0f, 0.35f};
static const float rgba_key[4] = {1.0f, 0.85f, 0.05f, 1.0f};
static const float rgba_path[4] = {1.0f, 0.85f, 0.05f, 0.9f};
static const float rgba_trail[4] = {0.0f, 0.8f, 0.9f, 1.0f};

#define KEY_RADIUS 0.008     /* m */
#define PATH_WIDTH 3.0       /* pixels: path and trail are lines, cheap to draw in software */
#define TRAIL_WIDTH 4.0      /* pixels */
#define ARROW_WIDTH 0.003
#define ARROW_SCALE 0.2      /* m of arrow per m/s of keypoint velocity */
#define PATH_SAMPLES 12      /* per segment */
#define TRAIL_GAP 0.25       /* s: trail points farther apart in time are not joined */
#define GHOST_PAD 0.0015     /* m: ghosts enclose the box they overlap, so neither hides */

typedef struct {
  mjvScene *scn;
  int dropped;
} adder;

/* The next free geom, initialised as decor of type and rgba, or NULL (counted) if full. */
static mjvGeom *add(adder *a, int type, const float rgba[4]) {
  if (a->scn->ngeom >= a->scn->maxgeom) {
    a->dropped++;
    return NULL;
  }
  mjvGeom *g = &a->scn->geoms[a->scn->ngeom++];
  mjv_initGeom(g, type, NULL, NULL, NULL, rgba);
  return g;
}

static void connector(adder *a, int type, double width, const double p0[3], const double p1[3],
                      const float rgba[4]) {
  /* A connector's direction is undefined at zero length. */
  if (hypot(hypot(p1[0] - p0[0], p1[1] - p0[1]), p1[2] - p0[2]) < 1e-6) return;
  mjvGeom *g = add(a, type, rgba);
  if (g) mjv_makeConnector(g, type, width, p0[0], p0[1], p0[2], p1[0], p1[1], p1[2]);
}

/* A box of the object's size at (x, y, yaw), resting on the table. */
static void ghost(adder *a, const view_scene *s, double x, double y, double yaw,
                  const float rgba[4]) {
  const double c = cos(yaw), sn = sin(yaw);
  const mjtNum size[3] = {s->obj_half[0] + GHOST_PAD, s->obj_half[1] + GHOST_PAD,
                          s->obj_half[2] + GHOST_PAD};
  const mjtNum pos[3] = {x, y, s->obj_half[2]};
  const mjtNum mat[9] = {c, -sn, 0, sn, c, 0, 0, 0, 1};
  mjvGeom *g = add(a, mjGEOM_BOX, rgba);
  if (g) mjv_initGeom(g, mjGEOM_BOX, size, pos, mat, rgba);
}

/* The plan's keypoints, their velocities as arrows, and the minimum-snap path through
 * them from the start state the plan arrived to (view_inputs.plan_s0), segment by
 * segment as nd_snap builds them: each keypoint reached with its velocity, zero
 * acceleration and jerk, the next segment starting there. */
static void plan(adder *a, const view_scene *s, const view_inputs *in) {
  const nudge_plan_t *pl = &in->plan;
  const double z = s->ee_height;
  double s0[2][4];
  memcpy(s0, in->plan_s0, sizeof s0);
  double prev[3] = {s0[0][ND_P], s0[1][ND_P], z};
  for (int k = 0; k < pl->M; k++) {
    const double *key = pl->keypoints[k];
    const double T = k == 0 ? in->plan_seg0_T : pl->T;
    nd_snap_seg seg;
    nd_snap_seg_make(&seg, (const double(*)[4])s0, key, key + 2, T);
    for (int i = 1; i <= PATH_SAMPLES; i++) {
      double st[2][4];
      nd_snap_seg_eval(&seg, T * i / PATH_SAMPLES, st);
      const double p[3] = {st[0][ND_P], st[1][ND_P], z};
      connector(a, mjGEOM_LINE, PATH_WIDTH, prev, p, rgba_path);
      memcpy(prev, p, sizeof prev);
    }
    const mjtNum r[3] = {KEY_RADIUS, KEY_RADIUS, KEY_RADIUS};
    const mjtNum pos[3] = {key[0], key[1], z};
    mjvGeom *g = add(a, mjGEOM_SPHERE, rgba_key);
    if (g) {
      mjv_initGeom(g, mjGEOM_SPHERE, r, pos, NULL, rgba_key);
      g->emission = 0.3f;
    }
    if (hypot(key[2], key[3]) > 1e-3) {
      const double tip[3] = {key[0] + ARROW_SCALE * key[2], key[1] + ARROW_SCALE * key[3], z};
      connector(a, mjGEOM_ARROW, ARROW_WIDTH, pos, tip, rgba_key);
    }
    for (int ax = 0; ax < 2; ax++) {
      s0[ax][ND_P] = key[ax];
      s0[ax][ND_V] = key[2 + ax];
      s0[ax][ND_A] = s0[ax][ND_J] = 0.0;
    }
  }
}

/* The setpoints of the last trail_s of EE_CMD time, older ones fainter. */
static void trail(adder *a, const view_scene *s, const view_inputs *in) {
  const int64_t newest = in->cmd.utime;
  const int64_t span = (int64_t)(in->trail_s * 1e6);
  const double z = s->ee_height;
  const double *prev = NULL;
  int64_t t_prev = 0;
  for (int i = in->trail_n - 1; i >= -1; i--) {
    /* Oldest first; i == -1 is the newest setpoint itself, which the decimated ring may
     * not hold yet. */
    const view_trail_pt *q =
        i >= 0 ? &in->trail[(in->trail_head + VIEW_TRAIL_CAP - 1 - i) % VIEW_TRAIL_CAP] : NULL;
    const double *p = q ? q->p : in->cmd.p;
    const int64_t t = q ? q->utime : newest;
    if (newest - t > span) continue;
    if (prev && t - t_prev <= (int64_t)(TRAIL_GAP * 1e6)) {
      float rgba[4];
      memcpy(rgba, rgba_trail, sizeof rgba);
      rgba[3] = (float)(0.25 + 0.75 * (1.0 - (double)(newest - t) / (double)span));
      const double p0[3] = {prev[0], prev[1], z}, p1[3] = {p[0], p[1], z};
      connector(a, mjGEOM_LINE, TRAIL_WIDTH, p0, p1, rgba);
    }
    prev = p;
    t_prev = t;
  }
}

int view_draw(const view_scene *s, const view_inputs *in, mjvScene *scn) {
  adder a = {scn, 0};
  if (in->have_cmd && in->trail_s > 0.0) trail(&a, s, in);
  if (in->have_plan) plan(&a, s, in);
  /* Translucent geoms last: MuJoCo sorts them by depth anyway, but if the scene is full
   * the solid markers are the ones kept. */
  const double *pr = in->plan.predicted;
  if (in->have_plan) ghost(&a, s, pr[0], pr[1], pr[2], rgba_pred);
  if (in->have_task) ghost(&a, s, in->task.goal_x, in->task.goal_y, in->task.goal_yaw, rgba_goal);
  return a.dropped;
}
