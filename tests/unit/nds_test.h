/* nds_test: what the cmocka tests of sim/ share: building a scene and catching MuJoCo's
 * warnings (a warning during a test is a finding, so the tests count them instead of
 * letting MuJoCo print). Include after nd_test.h. */
#ifndef NDS_TEST_H
#define NDS_TEST_H

#include <string.h>

#include "nds_model.h"

/* Warnings MuJoCo reported since nds_test_catch_warnings(). */
static int nds_test_warnings;

static void nds_test_count_warning(const char *msg) {
  (void)msg;
  nds_test_warnings++;
}

/* Route MuJoCo's warnings to nds_test_warnings. */
static inline void nds_test_catch_warnings(void) { mju_user_warning = nds_test_count_warning; }

/* The default scene at timestep (s) with theta (NULL: the true one); fails the test if it
 * does not build. */
static inline void nds_test_build(nds_model *nm, double timestep, const double *theta) {
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  cfg.timestep = timestep;
  if (theta) memcpy(cfg.theta, theta, sizeof(cfg.theta));
  char err[256] = "";
  if (nds_model_init(nm, &cfg, err, sizeof(err))) fail_msg("nds_model_init: %s", err);
}

#endif
