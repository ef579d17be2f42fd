/* batch: a whole recorded buffer at once, for the modes that read it and exit (--score,
 * --offline): its rollouts, the replays' model at a theta, a fit on a worker pool
 * (adapter.h). */
#include <stdio.h>
#include <string.h>

#include "adapter.h"

int adapter_model_init(const adapter_opts *o, const double theta[ND_NTHETA], nds_model *m,
                       char *err, int errlen) {
  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  sc.timestep = o->replay_dt;
  memcpy(sc.theta, theta, sizeof(sc.theta));
  return nds_model_init(m, &sc, err, errlen);
}

int adapter_batch_open(adapter_batch *b, const adapter_opts *o, const nds_fit_cfg *fc,
                       const double theta[ND_NTHETA], const char *what, char *err, int errlen) {
  memset(b, 0, sizeof(*b));
  if (nd_rbuf_read_all(o->buffer, &b->rs, &b->n, NULL, err, errlen)) return -1;
  if (b->n == 0) {
    snprintf(err, errlen, "%s holds no complete rollout to %s", o->buffer, what);
    return -1;
  }
  if (adapter_model_init(o, theta, &b->model, err, errlen)) return -1;
  b->have_model = 1;
  if (!(b->pool = nd_pool_create(o->threads, err, errlen)) ||
      !(b->fit = nds_fit_create(&b->model, fc, b->pool, err, errlen)))
    return -1;
  return 0;
}

void adapter_batch_close(adapter_batch *b) {
  nds_fit_free(b->fit);
  nd_pool_free(b->pool);
  if (b->have_model) nds_model_free(&b->model);
  nd_rbuf_free_all(b->rs, b->n);
  memset(b, 0, sizeof(*b));
}
