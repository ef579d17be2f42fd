/* score: nudge-adapter --score, the loss of one theta on a whole buffer (adapter.h). */
#include <stdio.h>
#include <stdlib.h>

#include "adapter.h"

int adapter_score(const adapter_opts *o, const nds_fit_cfg *fc) {
  char err[512] = "";
  int status = 1;
  adapter_batch b;
  double L = 0;
  nds_replay_terms *per = NULL;
  if (adapter_batch_open(&b, o, fc, o->score, "score", err, sizeof(err))) goto done;
  if (!(per = calloc((size_t)b.n, sizeof(*per)))) {
    snprintf(err, sizeof(err), "out of memory for %d rollouts' terms", b.n);
    goto done;
  }
  if (nds_fit_loss(b.fit, o->score, b.rs, b.n, &L, per, err, sizeof(err))) goto done;
  /* The terms summed over the rollouts: which of them the loss is made of. */
  double po = 0, pe = 0, ro = 0;
  long steps = 0, skipped = 0;
  for (int i = 0; i < b.n; i++) {
    po += per[i].pos_o, pe += per[i].pos_ee, ro += per[i].rot_o;
    steps += per[i].steps, skipped += per[i].skipped;
  }
  printf("rollouts %d count\nloss_obj_pos %.6g m^2\nloss_ee_pos %.6g m^2\nloss_obj_rot %.6g rad\n"
         "loss %.6g m^2\nreplay_steps %ld count\nreplay_steps_clear %ld count\n", b.n, po, pe,
         ro, L, steps, skipped);
  /* The fitted parameters' standard errors at this theta (nds_fit_cov). */
  double sd[ND_NTHETA];
  if (nds_fit_cov(b.fit, o->score, b.rs, b.n, sd, err, sizeof(err))) goto done;
  for (int i = 0; i < ND_NTHETA; i++)
    if (o->fit >> i & 1) printf("std_%s %.6g %s\n", nd_theta_key[i], sd[i], nd_theta_unit[i]);
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": --score: %s\n", err);
  free(per);
  adapter_batch_close(&b);
  return status;
}
