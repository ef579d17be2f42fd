/* offline: nudge-adapter --offline, the watching loop's refits on a recorded buffer
 * (adapter.h). One fit object serves every refit, so each starts from the last one's
 * distribution, as the watching adapter's do: the same options and records give the same
 * thetas, and a buffer a study or a robot recorded can be refitted with other options. */
#include <stdio.h>
#include <string.h>

#include "adapter.h"

int adapter_offline(const adapter_opts *o, const nds_fit_cfg *fc) {
  char err[512] = "";
  int status = 1, fits = 0;
  adapter_batch b;
  nds_fit_cfg cfg = *fc;
  cfg.seed = o->seed;  /* a fresh history's: version 0 */
  nds_fit_out out;
  memset(&out, 0, sizeof(out));
  if (adapter_batch_open(&b, o, &cfg, o->theta, "fit", err, sizeof(err))) goto done;
  /* A record the model cannot replay is skipped, as the watching adapter skips it. */
  int kept = 0;
  for (int i = 0; i < b.n; i++) {
    char why[256];
    if (nds_replay_check(&b.model, &b.rs[i], why, sizeof(why))) {
      fprintf(stderr, PROG ": %s: skipped rollout %d: %s\n", o->buffer, i + 1, why);
      nd_rollout_free(&b.rs[i]);
    } else {
      b.rs[kept++] = b.rs[i];
    }
  }
  b.n = kept;
  for (int total = 1; total <= b.n; total++) {
    const int first = o->max_rollouts > 0 && total > o->max_rollouts ? total - o->max_rollouts : 0;
    const double t0 = ndp_mono();
    if (nds_fit_run(b.fit, b.rs + first, total - first, &out, err, sizeof(err))) {
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
  adapter_batch_close(&b);
  return status;
}
