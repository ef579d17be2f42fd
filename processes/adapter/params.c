/* params: what a finished fit becomes: a version, a history entry, PARAMS (adapter.h). */
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "adapter.h"
#include "nudge/nudge_params_t.h"

int adapter_publish(adapter *a) {
  const nd_history_entry *e = &a->latest;
  nudge_params_t m;
  memset(&m, 0, sizeof(m));
  m.utime = ndp_utime();
  m.version = e->version;
  memcpy(m.theta_mean, e->mean, sizeof(m.theta_mean));
  memcpy(m.theta_std, e->std, sizeof(m.theta_std));
  m.fit_mask = (int8_t)e->mask;
  m.loss = e->loss;
  m.buffer_size = e->buffer_size;
  if (nudge_params_t_publish(a->lcm, NDP_CH_PARAMS, &m) != 0) return -1;
  a->st.published++;
  a->next_params = ndp_mono() + 1.0;
  return 0;
}

void adapter_print_refit(int64_t version, int n, int total, double secs, const nds_fit_out *out) {
  char mean[200], std[200], of[48];
  nd_theta_str(out->mean, " ", mean, sizeof(mean));
  nd_theta_str(out->std, " ", std, sizeof(std));
  printf("refit version %lld: %d rollout(s)%s in %.2f s, loss %.4g%s%s%s, theta %s, std %s\n",
         (long long)version, n, adapter_window_note(n, total, of, sizeof(of)), secs, out->loss_mean,
         out->diverged_mean ? " (mean diverged on some)" : "",
         out->flat ? " (flat: the rollouts do not tell the candidates apart; theta kept)" : "",
         out->scan_moved ? " (moved by the scan)" : "", mean, std);
  fflush(stdout);
}

/* Take a finished fit: new version, history, PARAMS, a line on stdout. */
void adapter_collect(adapter *a, adapter_fitter *ft) {
  pthread_mutex_lock(&ft->mu);
  const int rc = ft->rc, n = ft->n;
  const nds_fit_out out = ft->out;
  const double secs = ft->secs;
  char err[256];
  memcpy(err, ft->err, sizeof(err));
  ft->state = FIT_IDLE;
  pthread_mutex_unlock(&ft->mu);

  if (rc) {
    fprintf(stderr, PROG ": refit on %d rollout(s) failed after %.2f s: %s; waiting for more\n",
            n, secs, err);
    a->failed_n = a->total;
    a->st.state = "error";
    return;
  }
  nd_history_entry e;
  memset(&e, 0, sizeof(e));
  e.version = a->version + 1;
  e.utime = ndp_utime();
  e.buffer_created = a->buffer_created;
  e.mask = a->o->fit;
  memcpy(e.mean, out.mean, sizeof(e.mean));
  memcpy(e.std, out.std, sizeof(e.std));
  e.loss = out.loss_mean;
  e.fit_time = secs;
  e.buffer_size = a->total;  /* nothing is read while a fit runs: the total it covers */
  unsigned char buf[ND_HISTORY_ENC_SIZE];
  char herr[400];
  if (nd_history_encode(&e, buf, herr, sizeof(herr)) ||
      nd_rfile_append(&a->hist, ND_RFILE_KIND_PARAMS, buf, sizeof(buf), herr, sizeof(herr))) {
    /* Still published: the planner should not wait for a disk. A restart would then
     * reuse this version number for another fit, which the planner takes as new too. */
    fprintf(stderr, PROG ": version %lld not kept in the history: %s\n",
            (long long)e.version, herr);
  }
  a->version = e.version;
  a->latest = e;
  a->have_latest = 1;
  a->covered = a->total;
  a->failed_n = 0;
  a->st.state = "idle";
  adapter_print_refit(e.version, n, a->total, secs, &out);
  if (adapter_publish(a))
    fprintf(stderr, PROG ": publishing on %s failed\n", NDP_CH_PARAMS);
}

/* Resume from the history: version, distribution, what the last fit covered. */
int adapter_resume(adapter *a, nds_fit *fit, const double sigma0[ND_NTHETA],
                        const nd_history_summary *hs, char *err, int errlen) {
  if (hs->bad)
    fprintf(stderr, PROG ": %s: skipped %lld bad entr%s, the first: %s\n", a->o->history,
            (long long)hs->bad, hs->bad == 1 ? "y" : "ies", hs->first_bad);
  if (!hs->have_last) return 0;
  const nd_history_entry *e = &hs->last;
  double mean[ND_NTHETA], std[ND_NTHETA];
  for (int i = 0; i < ND_NTHETA; i++) {
    /* A parameter fitted then and now goes on; one fitted only now starts from the
     * prior; a held one is held at --theta, as asked. */
    const int was = (e->mask >> i) & 1, now = (a->o->fit >> i) & 1;
    mean[i] = now && was ? e->mean[i] : a->o->theta[i];
    std[i] = now && was ? e->std[i] : sigma0[i];
  }
  if (nds_fit_set_dist(fit, mean, std, err, errlen)) return -1;
  a->version = e->version;
  a->latest = *e;
  a->have_latest = 1;
  return 0;
}

/* Quit while a refit runs: nds_fit_run cannot be interrupted and may take tens of
 * seconds, longer than a supervisor's grace. Its result is dropped (the history holds
 * only committed fits, so nothing is lost that a restart would not redo); the process
 * leaves without joining the fit thread. */
void adapter_quit_during_fit(adapter *a) {
  fprintf(stderr, PROG ": stopped during a refit; its result is dropped\n");
  a->st.state = "stopped";
  ndp_status_tick(a->lcm, &a->st, 1);
  nd_rfile_writer_close(&a->hist);
  fflush(stdout);
  fflush(stderr);
  _exit(0);
}


int adapter_open_history(adapter *a, nd_history_summary *hs, char *err, int errlen) {
  /* Lock the history first: a second adapter on it stops here. */
  nd_rfile_tail repair;
  if (nd_rfile_open_append(&a->hist, a->o->history, ND_RFILE_KIND_PARAMS, &repair, err,
                           errlen)) {
    if (strstr(err, "locked"))
      snprintf(err + strlen(err), errlen - strlen(err),
               " (is another nudge-adapter running on this history?)");
    return -1;
  }
  if (repair.status != ND_RFILE_END)
    fprintf(stderr, PROG ": %s: cut off a %s tail: %s\n", a->o->history,
            nd_rfile_status_name(repair.status), repair.why);
  return nd_history_scan(a->o->history, hs, err, errlen);
}

void adapter_banner(const adapter *a, const nds_fit *fit, const nds_fit_cfg *fc,
                    const nd_history_summary *hs) {
  const adapter_opts *o = a->o;
  double m0[ND_NTHETA], s0[ND_NTHETA];
  nds_fit_dist(fit, m0, s0);
  char fitted[80], rank[64] = "L", scanned[80] = "none", ref[200], mean[200], std[200];
  char window[32] = "all";
  if (o->max_rollouts > 0) snprintf(window, sizeof(window), "the newest %d", o->max_rollouts);
  nd_theta_str(o->ref, ", ", ref, sizeof(ref));
  nd_theta_str(m0, ", ", mean, sizeof(mean));
  nd_theta_str(s0, ", ", std, sizeof(std));
  nd_theta_mask_str(o->fit, fitted, sizeof(fitted));
  if (o->scan & o->fit) nd_theta_mask_str(o->scan & o->fit, scanned, sizeof(scanned));
  if (fc->robust > 0) snprintf(rank, sizeof(rank), "the robust score of scale %g m^2", fc->robust);
  fprintf(stderr,
          PROG ": buffer %s, history %s (%lld entries%s), fit %s, CEM Q %d C %d rho %.2g, "
          "prior D %g on (%s), %s (%s) std (%s), replay %s dt %g s window %g s x %d phase(s) "
          "skip clear %g m, scan %s (%d points), ranked by %s, "
          "LM %d iterations, fitting on %s rollouts, %d worker(s), nice %d, %s\n",
          o->buffer, o->history, (long long)hs->entries, hs->have_last ? ", resuming" : "",
          fitted, fc->pop, fc->iters, fc->elite_frac, o->D, ref,
          hs->have_last ? "from version" : "prior", mean, std,
          nds_replay_mode_name(fc->replay.mode), o->replay_dt,
          fc->replay.window, fc->phases, fc->replay.skip_clear, scanned, o->scan_points, rank,
          fc->lm_iters, window, o->threads, o->nice, ndp_url(o->url));
  if (hs->have_last)
    fprintf(stderr, PROG ": resuming after version %lld (fit up to rollout %d of the buffer "
            "created %lld us)\n", (long long)hs->last.version, (int)hs->last.buffer_size,
            (long long)hs->last.buffer_created);
}
