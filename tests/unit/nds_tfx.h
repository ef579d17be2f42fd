/* nds_tfx: the fixture of the tests that run planned episodes: the world model, a 5 ms
 * planning model, a 2-worker pool, a quick planner (N 32, C 2) and world data. Include
 * after nd_test.h. */
#ifndef NDS_TFX_H
#define NDS_TFX_H

#include "nds_planner.h"

typedef struct {
  nds_model world, plan;
  nd_pool *pool;
  nds_planner *planner;
  mjData *d;
} nds_tfx;

/* Build everything into *f (failing the test on an error); release with nds_tfx_free. */
static void nds_tfx_init(nds_tfx *f, uint64_t planner_seed) {
  char err[256];
  nds_scene_cfg wc, pc;
  nds_scene_cfg_default(&wc);
  pc = wc;
  pc.timestep = 0.005;
  assert_int_equal(nds_model_init(&f->world, &wc, err, sizeof(err)), 0);
  assert_int_equal(nds_model_init(&f->plan, &pc, err, sizeof(err)), 0);
  f->pool = nd_pool_create(2, err, sizeof(err));
  assert_non_null(f->pool);
  nds_planner_cfg cfg;
  nds_planner_cfg_default(&cfg);
  cfg.pop = 32;
  cfg.iters = 2;
  cfg.seed = planner_seed;
  f->planner = nds_planner_create(&f->plan, &cfg, f->pool, err, sizeof(err));
  assert_non_null(f->planner);
  f->d = mj_makeData(f->world.m);
  assert_non_null(f->d);
}

static void nds_tfx_free(nds_tfx *f) {
  mj_deleteData(f->d);
  nds_planner_free(f->planner);
  nd_pool_free(f->pool);
  nds_model_free(&f->plan);
  nds_model_free(&f->world);
}

#endif
