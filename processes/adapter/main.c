/* nudge-adapter: the incremental adaptation of theta (adapter.h says what each file does). */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "adapter.h"
#include "nd_opt.h"

#define POLL_S 0.1  /* buffer poll period */

/* One pass of the main loop: take a finished fit, read the buffer, start the next fit. */
static void step(adapter *a, adapter_fitter *ft, const nd_history_summary *hs, int *checked) {
  const int fs = adapter_fitter_state(ft);
  if (fs == FIT_DONE) adapter_collect(a, ft);
  if (fs != FIT_DONE && fs != FIT_IDLE) return;
  adapter_poll(a);
  /* The history covers this buffer only if it was fitted on this very file. */
  if (a->rd_open && !*checked) {
    *checked = 1;
    if (hs->have_last && hs->last.buffer_created == a->buffer_created)
      a->covered = hs->last.buffer_size;
    else if (hs->have_last)
      fprintf(stderr, PROG ": the history's last fit was on another buffer (created %lld us): "
              "refitting on this one\n", (long long)hs->last.buffer_created);
  }
  if (!a->rd_open) {
    *checked = 0;
    a->st.state = "waiting";
  } else if (a->total > a->covered && a->total != a->failed_n) {
    adapter_fitter_submit(ft, a->rs, a->n);
    a->st.state = "fitting";
    char of[48];
    fprintf(stderr, PROG ": refitting on %d rollout(s)%s (%d new)\n", a->n,
            adapter_window_note(a->n, a->total, of, sizeof(of)), a->total - a->covered);
  } else if (strcmp(a->st.state, "error")) {
    a->st.state = "idle";
  }
}

int main(int argc, char **argv) {
  static adapter_opts o;
  static adapter a;
  static adapter_fitter ft;
  nds_fit_cfg fc;
  const int rc = adapter_options(argc, argv, &o, &fc);
  if (rc != ND_OPT_RUN) return rc;
  if (!isnan(o.score[0])) return adapter_score(&o, &fc);
  if (o.offline) return adapter_offline(&o, &fc);

  ndp_signals();
  ndp_mujoco_handlers(PROG);
  /* Before any thread exists: the pool's workers inherit it. */
  if (o.nice > 0) ndp_nice(PROG, o.nice);
  char err[512] = "";
  int status = 1;
  a.o = &o;
  a.hist.fd = a.rd.fd = -1;
  a.stop_offset = a.torn_offset = -1;
  ndp_status_init(&a.st, PROG);
  a.st.state = "starting";
  nd_pool *pool = NULL;
  static nd_history_summary hs;
  if (adapter_model_init(&o, o.theta, &a.model, err, sizeof(err)) ||
      adapter_open_history(&a, &hs, err, sizeof(err)))
    goto done;
  /* Seeded from the version reached, so a restart does not redraw the first run's samples. */
  fc.seed = o.seed + (uint64_t)(hs.have_last ? hs.last.version : 0);
  if (!(pool = nd_pool_create(o.threads, err, sizeof(err))) ||
      !(ft.fit = nds_fit_create(&a.model, &fc, pool, err, sizeof(err))) ||
      adapter_resume(&a, ft.fit, fc.sigma0, &hs, err, sizeof(err)) ||
      !(a.lcm = ndp_lcm_create(o.url, err, sizeof(err))) ||
      adapter_fitter_start(&ft, err, sizeof(err)))
    goto done;
  adapter_banner(&a, ft.fit, &fc, &hs);

  int checked = 0;
  a.st.state = "waiting";
  while (!ndp_quit) {
    step(&a, &ft, &hs, &checked);
    if (a.have_latest && ndp_mono() >= a.next_params && adapter_publish(&a)) {
      snprintf(err, sizeof(err), "publishing on %s failed", NDP_CH_PARAMS);
      goto done;
    }
    if (ndp_status_tick(a.lcm, &a.st, 0) < 0) {
      snprintf(err, sizeof(err), "publishing on %s failed", NDP_CH_STATUS);
      goto done;
    }
    struct timespec ts = {0, (long)(POLL_S * 1e9)};
    nanosleep(&ts, NULL);  /* a signal cuts it short */
  }
  const int fs = adapter_fitter_state(&ft);
  if (fs == FIT_DONE) adapter_collect(&a, &ft);  /* finished: worth keeping */
  else if (fs != FIT_IDLE) adapter_quit_during_fit(&a);
  a.st.state = "stopped";
  ndp_status_tick(a.lcm, &a.st, 1);
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  adapter_fitter_stop(&ft);
  nds_fit_free(ft.fit);
  nd_pool_free(pool);
  adapter_close(&a);
  nd_rfile_writer_close(&a.hist);
  nds_model_free(&a.model);
  if (a.lcm) lcm_destroy(a.lcm);
  return status;
}
