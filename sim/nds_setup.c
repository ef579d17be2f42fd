/* nds_setup: models, pool and start of the in-process tools. */
#include "nds_setup.h"

#include <stdio.h>
#include <string.h>
#include <unistd.h>

const nd_goal nds_demo_goals[NDS_DEMO_GOALS] = {
    {.x = 0.20, .y = 0.00, .yaw = 0.0},   {.x = 0.15, .y = 0.12, .yaw = 0.6},
    {.x = 0.15, .y = -0.12, .yaw = -0.6}, {.x = 0.05, .y = 0.20, .yaw = 1.2},
    {.x = -0.10, .y = -0.15, .yaw = -0.5},
};

const double nds_start_ee[2] = {-0.10, 0.0};

int nds_setup_init(nds_setup *s, double plan_dt, int threads, char *err, int errlen) {
  memset(s, 0, sizeof(*s));
  nds_scene_cfg wc, pc;
  nds_scene_cfg_default(&wc);
  nds_scene_cfg_planning(&pc, plan_dt);
  if (nds_model_init(&s->world, &wc, err, errlen) || nds_model_init(&s->plan, &pc, err, errlen) ||
      !(s->pool = nd_pool_create(threads, err, errlen)))
    goto fail;
  if (!(s->d = mj_makeData(s->world.m))) {
    snprintf(err, errlen, "out of memory for the world's mjData");
    goto fail;
  }
  nds_state_rest(&s->world, 0.0, 0.0, 0.0, nds_start_ee, &s->start);
  return 0;
fail:
  nds_setup_free(s);
  return -1;
}

void nds_setup_free(nds_setup *s) {
  if (s->d) mj_deleteData(s->d);
  nd_pool_free(s->pool);
  nds_model_free(&s->plan);
  nds_model_free(&s->world);
  memset(s, 0, sizeof(*s));
}

int nds_setup_cores(int max) {
  const long n = sysconf(_SC_NPROCESSORS_ONLN);
  return n < 1 ? 1 : n > max ? max : (int)n;
}
