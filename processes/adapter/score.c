/* score: nudge-adapter --score, the loss of one theta on a whole buffer (adapter.h). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "adapter.h"

int adapter_score(const adapter_opts *o, const nds_fit_cfg *fc) {
  char err[512] = "";
  int status = 1, n = 0;
  nd_rollout *rs = NULL;
  nd_pool *pool = NULL;
  nds_fit *fit = NULL;
  nds_model model;
  int have_model = 0;
  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  sc.timestep = o->replay_dt;
  memcpy(sc.theta, o->score, sizeof(sc.theta));
  double L = 0;
  nds_replay_terms *per = NULL;
  if (nd_rbuf_read_all(o->buffer, &rs, &n, NULL, err, sizeof(err))) goto done;
  if (n == 0) {
    snprintf(err, sizeof(err), "%s holds no complete rollout to score", o->buffer);
    goto done;
  }
  if (nds_model_init(&model, &sc, err, sizeof(err))) goto done;
  have_model = 1;
  if (!(per = calloc((size_t)n, sizeof(*per)))) {
    snprintf(err, sizeof(err), "out of memory for %d rollouts' terms", n);
    goto done;
  }
  if (!(pool = nd_pool_create(o->threads, err, sizeof(err))) ||
      !(fit = nds_fit_create(&model, fc, pool, err, sizeof(err))) ||
      nds_fit_loss(fit, o->score, rs, n, &L, per, err, sizeof(err)))
    goto done;
  /* The terms summed over the rollouts: which of them the loss is made of. */
  double po = 0, pe = 0, ro = 0;
  long steps = 0, skipped = 0;
  for (int i = 0; i < n; i++) {
    po += per[i].pos_o, pe += per[i].pos_ee, ro += per[i].rot_o;
    steps += per[i].steps, skipped += per[i].skipped;
  }
  printf("rollouts %d count\nloss_obj_pos %.6g m^2\nloss_ee_pos %.6g m^2\nloss_obj_rot %.6g rad\n"
         "loss %.6g m^2\nreplay_steps %ld count\nreplay_steps_clear %ld count\n", n, po, pe, ro,
         L, steps, skipped);
  /* The fitted parameters' standard errors at this theta (nds_fit_cov). */
  double sd[ND_NTHETA];
  if (nds_fit_cov(fit, o->score, rs, n, sd, err, sizeof(err))) goto done;
  for (int i = 0; i < ND_NTHETA; i++)
    if (o->fit >> i & 1) printf("std_%s %.6g %s\n", nd_theta_key[i], sd[i], nd_theta_unit[i]);
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": --score: %s\n", err);
  free(per);
  nds_fit_free(fit);
  nd_pool_free(pool);
  if (have_model) nds_model_free(&model);
  nd_rbuf_free_all(rs, n);
  return status;
}
