/* offline: nudge-adapter --offline, the watching loop's refits on a recorded buffer
 * (adapter.h). One fit object serves every refit, so each starts from the last one's
 * distribution, as the watching adapter's do: the same options and records give the same
 * thetas, and a buffer a study or a robot recorded can be refitted with other options. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "adapter.h"

int adapter_offline(const adapter_opts *o, const nds_fit_cfg *fc) {
  char err[512] = "";
  int status = 1, n = 0, fits = 0;
  nd_rollout *rs = NULL;
  nd_pool *pool = NULL;
  nds_fit *fit = NULL;
  nds_model model;
  int have_model = 0;
  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  sc.timestep = o->replay_dt;
  memcpy(sc.theta, o->theta, sizeof(sc.theta));
  nds_fit_cfg cfg = *fc;
  cfg.seed = o->seed;  /* a fresh history's: version 0 */
  nds_fit_out out;
  memset(&out, 0, sizeof(out));
  if (nd_rbuf_read_all(o->buffer, &rs, &n, NULL, err, sizeof(err))) goto done;
  if (nds_model_init(&model, &sc, err, sizeof(err))) goto done;
  have_model = 1;
  /* A record the model cannot replay is skipped, as the watching adapter skips it. */
  int kept = 0;
  for (int i = 0; i < n; i++) {
    char why[256];
    if (nds_replay_check(&model, &rs[i], why, sizeof(why))) {
      fprintf(stderr, PROG ": %s: skipped rollout %d: %s\n", o->buffer, i + 1, why);
      nd_rollout_free(&rs[i]);
    } else {
      rs[kept++] = rs[i];
    }
  }
  n = kept;
  if (n == 0) {
    snprintf(err, sizeof(err), "%s holds no complete rollout to fit", o->buffer);
    goto done;
  }
  if (!(pool = nd_pool_create(o->threads, err, sizeof(err))) ||
      !(fit = nds_fit_create(&model, &cfg, pool, err, sizeof(err))))
    goto done;
  for (int total = 1; total <= n; total++) {
    const int first = o->max_rollouts > 0 && total > o->max_rollouts ? total - o->max_rollouts : 0;
    const double t0 = ndp_mono();
    if (nds_fit_run(fit, rs + first, total - first, &out, err, sizeof(err))) {
      /* The watching adapter waits for more rollouts after a failed refit: so here. */
      fprintf(stderr, PROG ": refit on %d rollout(s) failed: %s\n", total - first, err);
      continue;
    }
    adapter_print_refit(++fits, total - first, total, ndp_mono() - t0, &out);
  }
  if (fits == 0) {
    snprintf(err, sizeof(err), "no refit of %s succeeded", o->buffer);
    goto done;
  }
  printf("refits %d count\nloss %.6g m^2\n", fits, out.loss_mean);
  for (int i = 0; i < ND_NTHETA; i++)
    printf("theta_%s %.9g %s\n", nd_theta_key[i], out.mean[i], nd_theta_unit[i]);
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": --offline: %s\n", err);
  nds_fit_free(fit);
  nd_pool_free(pool);
  if (have_model) nds_model_free(&model);
  nd_rbuf_free_all(rs, n);
  return status;
}
