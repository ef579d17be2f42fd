/* fitter: the fit thread, one nds_fit_run per job (adapter.h). */
#include <stdio.h>
#include <string.h>

#include "adapter.h"

static void *fit_main(void *arg) {
  adapter_fitter *ft = arg;
  pthread_mutex_lock(&ft->mu);
  for (;;) {
    while (ft->state != FIT_QUEUED && !ft->quit) pthread_cond_wait(&ft->cv, &ft->mu);
    if (ft->quit) break;
    ft->state = FIT_RUNNING;
    const nd_rollout *rs = ft->rs;
    const int n = ft->n;
    pthread_mutex_unlock(&ft->mu);

    nds_fit_out out;
    char err[256] = "";
    const double t0 = ndp_mono();
    const int rc = nds_fit_run(ft->fit, rs, n, &out, err, sizeof(err));
    const double secs = ndp_mono() - t0;

    pthread_mutex_lock(&ft->mu);
    ft->rc = rc;
    ft->out = out;
    ft->secs = secs;
    memcpy(ft->err, err, sizeof(err));
    ft->state = FIT_DONE;
  }
  pthread_mutex_unlock(&ft->mu);
  return NULL;
}

int adapter_fitter_state(adapter_fitter *ft) {
  pthread_mutex_lock(&ft->mu);
  int s = ft->state;
  pthread_mutex_unlock(&ft->mu);
  return s;
}


int adapter_fitter_start(adapter_fitter *ft, char *err, int errlen) {
  if (pthread_mutex_init(&ft->mu, NULL) || pthread_cond_init(&ft->cv, NULL)) {
    snprintf(err, errlen, "cannot create the fit thread's lock");
    return -1;
  }
  if (pthread_create(&ft->th, NULL, fit_main, ft)) {
    pthread_cond_destroy(&ft->cv);
    pthread_mutex_destroy(&ft->mu);
    snprintf(err, errlen, "cannot start the fit thread");
    return -1;
  }
  ft->started = 1;
  return 0;
}

void adapter_fitter_submit(adapter_fitter *ft, const nd_rollout *rs, int n) {
  pthread_mutex_lock(&ft->mu);
  ft->rs = rs;
  ft->n = n;
  ft->state = FIT_QUEUED;
  pthread_cond_signal(&ft->cv);
  pthread_mutex_unlock(&ft->mu);
}

void adapter_fitter_stop(adapter_fitter *ft) {
  if (!ft->started) return;
  pthread_mutex_lock(&ft->mu);
  ft->quit = 1;
  pthread_cond_signal(&ft->cv);
  pthread_mutex_unlock(&ft->mu);
  pthread_join(ft->th, NULL);
  pthread_cond_destroy(&ft->cv);
  pthread_mutex_destroy(&ft->mu);
  ft->started = 0;
}
