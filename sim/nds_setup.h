/* nds_setup: the standard pushing set-up the in-process tools share (nudge-demo,
 * nudge-experiment, nudge-bench): the 1 ms world with the true theta, a planning model at a
 * coarser step, the worker pool, the start pose and the five demo goals. */
#ifndef NDS_SETUP_H
#define NDS_SETUP_H

#include "nd_goal.h"
#include "nd_pool.h"
#include "nds_model.h"
#include "nds_state.h"

/* Five goals around the start pose (object at the origin, yaw 0): straight, sideways both
 * ways, with turns, and one behind the start that needs the sphere to go around. The demo's
 * goals, the study's evaluation tasks and its validation rollouts. */
#define NDS_DEMO_GOALS 5
extern const nd_goal nds_demo_goals[NDS_DEMO_GOALS];

/* Where the sphere starts: 10 cm behind the object at the origin. */
extern const double nds_start_ee[2];

typedef struct {
  nds_model world;   /* default scene at 1 ms, true theta */
  nds_model plan;    /* the same scene at the planning step */
  nd_pool *pool;
  mjData *d;         /* the world's data */
  nds_state start;   /* object at rest at the origin, sphere at nds_start_ee */
} nds_setup;

/* Build the set-up with a planning model at plan_dt and a pool of threads workers.
 * Return 0, or -1 with a message (s then holds nothing to free). */
int nds_setup_init(nds_setup *s, double plan_dt, int threads, char *err, int errlen);

/* Free what s holds; safe on a zeroed set-up. */
void nds_setup_free(nds_setup *s);

/* Online cores, at least 1 and at most max: the in-process tools' default worker count. */
int nds_setup_cores(int max);

#endif
