/* nudge-adapter: the incremental adaptation of theta (DESIGN.md sec. 3-4).
 *
 * Watches the replay buffer file the task runner appends to. Whenever complete rollouts
 * beyond those of the last fit are there, it refits theta with CEM on ALL of them
 * (nds_fit: replays of the recorded setpoints / controls in the model), publishes the
 * result on PARAMS, appends it to the parameter history and republishes it at 1 Hz, so a
 * planner started later gets it too.
 *
 * Threads. The main thread owns LCM, the files and every counter: it polls the buffer
 * every 100 ms, publishes, keeps the heartbeat. A refit takes seconds to tens of seconds,
 * so it runs in a fit thread (with the pool's workers); the main thread hands it a job
 * and collects the result, and does not touch the rollout array while a job runs (new
 * records wait in the file until then, so one refit covers whatever arrived during the
 * last one).
 *
 * Restart. The history (an nd_rfile of kind 2, entries in nd_history.h) is read at
 * start: the version numbering and the CEM distribution go on from its last entry, and
 * the buffer is refitted only if it holds rollouts that entry did not use. */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "nd_parse.h"
#include "nd_rbuf.h"
#include "nds_fit.h"
#include "ndp.h"
#include "nd_history.h"
#include "nudge/nudge_params_t.h"

#define PROG "nudge-adapter"
#define POLL_S 0.1            /* buffer poll period */
#define TORN_REPORT_S 2.0     /* an append takes milliseconds: a tail torn this long is a crash */
#define REJECT_LOG_FIRST 5    /* bad records described on stderr; then only counted */

/* ---------------------------------------------------------------------------------- */
/* Options: constant once parsed. */

typedef struct {
  const char *url;
  const char *buffer;
  char history[ND_RFILE_PATH_MAX];
  int fit[ND_NTHETA];
  double theta[ND_NTHETA];   /* prior mean; value of held parameters */
  double ref[ND_NTHETA];     /* nominal theta the prior std is sized from */
  double D;                   /* prior uncertainty of the paper's formula */
  int threads;
  uint64_t seed;
  int nice;
  double replay_dt;           /* model timestep of the replays, s */
  int replay_mode;            /* NDS_REPLAY_*, -1: the fit configuration's default */
  double replay_window;       /* s, < 0: NDS_FIT_WINDOW_MOCAP */
  double robust;              /* m^2: CEM ranks by the robust score; 0: by L (nds_fit.h) */
} opts;

static const char *theta_names[ND_NTHETA] = {"slide", "torsion", "roll", "mass"};

static void usage(FILE *f) {
  fprintf(f,
          "usage: " PROG " --buffer FILE [options]\n"
          "Incremental adaptation: watches the replay buffer FILE (appended to by\n"
          "nudge-tasks --record); whenever it holds rollouts the last fit did not use, refits\n"
          "theta with CEM on all of them (Q 32, C 2, elite fraction 0.2), publishes PARAMS\n"
          "(mean, std, loss, buffer size, version) and appends the fit to the parameter\n"
          "history. PARAMS is republished at 1 Hz. A restarted adapter goes on from its\n"
          "history: version numbers and the CEM distribution continue.\n\n"
          "  --buffer FILE      replay buffer to watch (need not exist yet)\n"
          "  --history FILE     parameter history (default: <buffer>.history)\n"
          "  --fit LIST         fitted parameters, comma-separated from slide, torsion, roll,\n"
          "                     mass (default slide,torsion,roll; the others are held at\n"
          "                     --theta)\n"
          "  --theta S,T,R,M    prior mean: sliding, torsional, rolling friction, sphere mass\n"
          "                     in kg (default: the simulation's ground truth; give the\n"
          "                     planner's --theta to start the loop from a wrong model)\n"
          "  --prior-d D        prior std per parameter (r + D r - max(1e-7, r - D r)) / 16,\n"
          "                     the paper's formula, with r the nominal theta of --prior-ref;\n"
          "                     0.01..10 (default 1.0)\n"
          "  --prior-ref S,T,R,M  nominal theta that sizes the prior std (default: the\n"
          "                     simulation's ground truth, MuJoCo's default frictions and a\n"
          "                     1 kg sphere, as in the paper). Not --theta: a wrong mean\n"
          "                     must not also shrink the std (0.3 instead of 1 would give\n"
          "                     the truth a 19-std distance instead of 5.6)\n"
          "  --threads N        replay workers, 1..256 (default: cores - 1 up to 4 cores,\n"
          "                     cores - 2 above, at least 1)\n"
          "  --nice N           scheduling niceness of the whole process, 0..19 (default 10:\n"
          "                     on a small machine refits must not slow the planner)\n"
          "  --replay-dt S      model timestep of the replays, a whole multiple of the\n"
          "                     recorded dt, 0.0001..0.01 s (default 0.002: twice the\n"
          "                     bridge's, 3.5x faster than 0.001 at the same fit)\n"
          "  --replay-mode M    force, velocity or setpoint: how rollouts are replayed\n"
          "                     (default: nds_fit's default; see sim/nds_replay.h)\n"
          "  --replay-window S  re-anchor each replay on the observed pose every S s,\n"
          "                     0..60 (default 0.1, for poses interpolated from 240 Hz\n"
          "                     MOCAP; 0.005 for poses observed every step, as the study's;\n"
          "                     0: one shot, the paper's; sim/nds_fit.h)\n"
          "  --robust S         rank candidates by the replay windows' robust score of scale\n"
          "                     S m^2, 0..1 (default 0: by L, the paper's; sim/nds_fit.c)\n"
          "  --seed N           CEM seed (default 1; a restart adds the history's version)\n"
          "  --lcm-url URL      LCM URL (default: $LCM_DEFAULT_URL, else %s)\n"
          "  -h, --help         this text\n\n"
          "stdout: one line per refit. Exit status: 0 after SIGINT/SIGTERM, 1 on a runtime\n"
          "failure (history locked by another adapter, unreadable), 2 on bad arguments.\n",
          NDP_DEFAULT_URL);
}

static int parse_fit(const char *s, int fit[ND_NTHETA], char *err, int errlen) {
  char buf[128];
  if (strlen(s) >= sizeof(buf)) {
    snprintf(err, errlen, "--fit: value too long");
    return -1;
  }
  strcpy(buf, s);
  memset(fit, 0, sizeof(int) * ND_NTHETA);
  char *save = NULL;
  int any = 0;
  for (char *t = strtok_r(buf, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
    int i = 0;
    while (i < ND_NTHETA && strcmp(t, theta_names[i])) i++;
    if (i == ND_NTHETA) {
      snprintf(err, errlen, "--fit: unknown parameter '%s' (slide, torsion, roll, mass)", t);
      return -1;
    }
    if (fit[i]) {
      snprintf(err, errlen, "--fit: '%s' given twice", t);
      return -1;
    }
    fit[i] = 1;
    any = 1;
  }
  if (!any) {
    snprintf(err, errlen, "--fit: no parameter named");
    return -1;
  }
  return 0;
}

/* Return 0, 1 for --help, or 2 after printing what is wrong. */
static int parse_opts(int argc, char **argv, opts *o) {
  char err[256] = "";
  memset(o, 0, sizeof(*o));
  o->threads = ndp_default_threads();
  o->fit[ND_TH_SLIDE] = o->fit[ND_TH_TORSION] = o->fit[ND_TH_ROLL] = 1;
  memcpy(o->theta, nd_theta_true, sizeof(o->theta));
  memcpy(o->ref, nd_theta_true, sizeof(o->ref));
  o->D = 1.0;
  o->seed = 1;
  o->nice = 10;
  /* Two record steps per model step: 3.5x faster than 1 ms on the bench's ten 5 s pushes
   * (refit_s_10x5s), and re-anchoring keeps the coarse step's error from compounding, so
   * the fit lands where the 1 ms one does (sliding 1.007 at both). */
  o->replay_dt = 0.002;
  o->replay_mode = -1;
  o->replay_window = -1;
  const char *history = NULL;

  int rc = 0;
  for (int i = 1; i < argc && !rc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 1;
    }
    int known = !strcmp(a, "--lcm-url") || !strcmp(a, "--buffer") || !strcmp(a, "--history") ||
                !strcmp(a, "--fit") || !strcmp(a, "--theta") || !strcmp(a, "--prior-d") ||
                !strcmp(a, "--prior-ref") ||
                !strcmp(a, "--threads") || !strcmp(a, "--nice") ||
                !strcmp(a, "--replay-dt") || !strcmp(a, "--seed") ||
                !strcmp(a, "--replay-mode") || !strcmp(a, "--replay-window") ||
                !strcmp(a, "--robust");
    if (!known) {
      snprintf(err, sizeof(err), "unknown option: %s", a);
      rc = -1;
      break;
    }
    if (i + 1 >= argc) {
      snprintf(err, sizeof(err), "%s needs a value", a);
      rc = -1;
      break;
    }
    const char *v = argv[++i];
    if (!strcmp(a, "--lcm-url")) o->url = v;
    else if (!strcmp(a, "--buffer")) o->buffer = v;
    else if (!strcmp(a, "--history")) history = v;
    else if (!strcmp(a, "--fit")) rc = parse_fit(v, o->fit, err, sizeof(err));
    else if (!strcmp(a, "--theta")) rc = nd_theta_parse(v, a, o->theta, err, sizeof(err));
    else if (!strcmp(a, "--prior-ref")) rc = nd_theta_parse(v, a, o->ref, err, sizeof(err));
    else if (!strcmp(a, "--prior-d")) rc = nd_parse_double(v, a, 0.01, 10.0, &o->D, err, sizeof(err));
    else if (!strcmp(a, "--threads")) rc = nd_parse_int(v, a, 1, 256, &o->threads, err, sizeof(err));
    else if (!strcmp(a, "--nice")) rc = nd_parse_int(v, a, 0, 19, &o->nice, err, sizeof(err));
    else if (!strcmp(a, "--replay-dt")) rc = nd_parse_double(v, a, 1e-4, 0.01, &o->replay_dt, err, sizeof(err));
    else if (!strcmp(a, "--replay-window")) rc = nd_parse_double(v, a, 0, 60, &o->replay_window, err, sizeof(err));
    else if (!strcmp(a, "--robust")) rc = nd_parse_double(v, a, 0, 1, &o->robust, err, sizeof(err));
    else if (!strcmp(a, "--replay-mode")) {
      const int modes[] = {NDS_REPLAY_FORCE, NDS_REPLAY_VELOCITY, NDS_REPLAY_SETPOINT};
      o->replay_mode = -1;
      for (int k = 0; k < 3; k++)
        if (!strcmp(v, nds_replay_mode_name(modes[k]))) o->replay_mode = modes[k];
      if (o->replay_mode < 0) {
        snprintf(err, sizeof(err), "--replay-mode: '%s' is not force, velocity or setpoint", v);
        rc = -1;
      }
    }
    else rc = nd_parse_u64(v, a, &o->seed, err, sizeof(err));
  }
  if (!rc && (!o->buffer || !*o->buffer)) {
    snprintf(err, sizeof(err), "--buffer FILE is required");
    rc = -1;
  }
  if (!rc && history && !*history) {
    snprintf(err, sizeof(err), "--history: empty file name");
    rc = -1;
  }
  if (!rc) {
    int n = history ? snprintf(o->history, sizeof(o->history), "%s", history)
                    : snprintf(o->history, sizeof(o->history), "%s.history", o->buffer);
    if (n < 0 || n >= (int)sizeof(o->history) || strlen(o->buffer) >= ND_RFILE_PATH_MAX) {
      snprintf(err, sizeof(err), "--buffer / --history: path too long");
      rc = -1;
    }
  }
  /* The paper's width vanishes for a nominal value of 0. */
  for (int i = 0; i < ND_NTHETA && !rc; i++)
    if (o->fit[i] && !(o->ref[i] > 0.0)) {
      snprintf(err, sizeof(err), "--prior-ref: %s is fitted, so its nominal value must be > 0",
               theta_names[i]);
      rc = -1;
    }
  if (rc) {
    fprintf(stderr, PROG ": %s\n", err);
    usage(stderr);
    return 2;
  }
  return 0;
}

/* ---------------------------------------------------------------------------------- */
/* The fit thread: runs one nds_fit_run per job. Fields under mu. */

enum { FIT_IDLE = 0, FIT_QUEUED, FIT_RUNNING, FIT_DONE };

typedef struct {
  pthread_t th;
  pthread_mutex_t mu;
  pthread_cond_t cv;
  int state;              /* FIT_*: main moves IDLE->QUEUED and DONE->IDLE, the thread the rest */
  int quit;
  nds_fit *fit;
  const nd_rollout *rs;   /* the job: rs[0, n), untouched by main while not IDLE */
  int n;
  int rc;                 /* result */
  nds_fit_out out;
  double secs;
  char err[256];
} fitter;

static void *fit_main(void *arg) {
  fitter *ft = arg;
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

static int fitter_state(fitter *ft) {
  pthread_mutex_lock(&ft->mu);
  int s = ft->state;
  pthread_mutex_unlock(&ft->mu);
  return s;
}

/* ---------------------------------------------------------------------------------- */
/* The process's state, owned by the main thread. */

typedef struct {
  const opts *o;
  lcm_t *lcm;
  ndp_status st;
  nds_model model;            /* the replays' model, for checking records before a fit */
  uint32_t mask;

  /* buffer */
  nd_rfile_reader rd;
  int rd_open;
  int64_t resume;             /* offset to reopen at after an I/O error; 0: from the start */
  dev_t dev;
  ino_t ino;
  int64_t buffer_created;     /* header creation time of the open buffer */
  char open_err[256];         /* last reason the buffer could not be opened (said once) */
  int64_t stop_offset;        /* where the valid records stop, as last reported; -1 none */
  int64_t torn_offset;        /* torn tail seen here since torn_t; -1 none */
  double torn_t;
  nd_rollout *rs;             /* good records, file order */
  int n, cap;
  int64_t bad_logged;

  /* fits */
  int covered;                /* records the latest fit (or the history's) used; 0 none */
  int failed_n;               /* a fit of this many records failed: wait for more */
  int64_t version;            /* latest version; 0: none yet */
  int have_latest;
  nd_history_entry latest;
  nd_rfile_writer hist;
  double next_params;
} adapter;

static void say_bad_record(adapter *a, const char *why) {
  a->st.rejected++;
  if (a->bad_logged++ < REJECT_LOG_FIRST)
    fprintf(stderr, PROG ": skipped a record (%lld so far): %s\n", (long long)a->st.rejected,
            why);
  else if (a->bad_logged == REJECT_LOG_FIRST + 1)
    fprintf(stderr, PROG ": more bad records follow; counted in status.rejected only\n");
}

static void drop_records(adapter *a) {
  for (int i = 0; i < a->n; i++) nd_rollout_free(&a->rs[i]);
  a->n = 0;
}

static void close_buffer(adapter *a) {
  if (a->rd_open) nd_rfile_reader_close(&a->rd);
  a->rd_open = 0;
}

/* Open the buffer if it is not open. 1 when open, 0 when not (yet). */
static int open_buffer(adapter *a) {
  if (a->rd_open) return 1;
  char err[256];
  struct stat st;
  if (stat(a->o->buffer, &st) != 0) {
    snprintf(err, sizeof(err), "%s: %s", a->o->buffer, strerror(errno));
    if (errno == ENOENT) snprintf(err, sizeof(err), "waiting for %s to appear", a->o->buffer);
  } else if (nd_rbuf_reader_open(&a->rd, a->o->buffer, err, sizeof(err)) == 0) {
    struct stat fs;
    if (fstat(a->rd.fd, &fs) == 0 && a->resume > 0 &&
        (fs.st_dev != a->dev || fs.st_ino != a->ino)) {
      a->resume = 0;  /* another file under the name since the I/O error */
      drop_records(a);
    }
    if (a->resume > 0 && nd_rfile_reader_seek(&a->rd, a->resume, err, sizeof(err))) {
      nd_rfile_reader_close(&a->rd);
      return 0;
    }
    a->rd_open = 1;
    a->dev = fs.st_dev;
    a->ino = fs.st_ino;
    a->buffer_created = a->rd.created_us;
    a->open_err[0] = '\0';
    a->stop_offset = a->torn_offset = -1;
    if (a->resume == 0)
      fprintf(stderr, PROG ": reading %s (created %lld us)\n", a->o->buffer,
              (long long)a->buffer_created);
    return 1;
  }
  if (strcmp(err, a->open_err)) {
    fprintf(stderr, PROG ": %s\n", err);
    snprintf(a->open_err, sizeof(a->open_err), "%s", err);
  }
  return 0;
}

/* The file under the buffer's name is not the one open (deleted, replaced): start over. */
static void check_replaced(adapter *a) {
  struct stat st;
  int gone = stat(a->o->buffer, &st) != 0;
  if (!gone && st.st_dev == a->dev && st.st_ino == a->ino) return;
  fprintf(stderr,
          PROG ": %s was %s: dropping its %d rollout(s) and reading the new file when it "
          "appears (theta and versions go on)\n",
          a->o->buffer, gone ? "removed" : "replaced", a->n);
  close_buffer(a);
  drop_records(a);
  a->resume = 0;
  a->covered = 0;
  a->failed_n = 0;
}

/* Append rollout r (taken over) to the good records, after checking it replays. */
static void keep_record(adapter *a, nd_rollout *r, int64_t offset) {
  char why[256];
  if (nds_replay_check(&a->model, r, why, sizeof(why))) {
    char msg[400];
    snprintf(msg, sizeof(msg), "record at offset %lld cannot be replayed: %s", (long long)offset,
             why);
    say_bad_record(a, msg);
    nd_rollout_free(r);
    return;
  }
  if (a->n == a->cap) {
    int cap = a->cap ? 2 * a->cap : 16;
    nd_rollout *g = realloc(a->rs, sizeof(*g) * cap);
    if (!g) {
      say_bad_record(a, "out of memory for the rollout array");
      nd_rollout_free(r);
      return;
    }
    a->rs = g;
    a->cap = cap;
  }
  a->rs[a->n++] = *r;
}

/* Read what was appended since the last poll. Only while no fit holds the array. */
static void poll_buffer(adapter *a) {
  if (a->rd_open) check_replaced(a);
  if (!open_buffer(a)) return;
  for (;;) {
    nd_rollout r;
    nd_rfile_tail tail;
    char err[400];
    const int64_t at = a->rd.offset;
    const int k = nd_rbuf_next(&a->rd, &r, &tail, err, sizeof(err));
    if (k == 1) {
      a->st.received++;
      keep_record(a, &r, at);
      continue;
    }
    if (k < 0) {
      if (a->rd.offset > at) {  /* a sound frame holding no usable rollout: skip it */
        say_bad_record(a, err);
        continue;
      }
      fprintf(stderr, PROG ": %s; reopening\n", err);
      a->resume = at;
      close_buffer(a);
      return;
    }
    /* No complete valid record at the offset now. A torn tail normally is an append in
     * progress and completes within milliseconds; a corrupt record never heals. Either
     * way the fit goes on with the records before it; say where they stop, once. */
    const double now = ndp_mono();
    if (tail.status == ND_RFILE_END) {
      a->torn_offset = -1;
      if (a->stop_offset >= 0 && tail.offset > a->stop_offset) a->stop_offset = -1;
    } else if (tail.offset != a->stop_offset) {
      int report = tail.status == ND_RFILE_CORRUPT;
      if (tail.status == ND_RFILE_TORN) {
        if (a->torn_offset != tail.offset) {
          a->torn_offset = tail.offset;
          a->torn_t = now;
        }
        report = now - a->torn_t >= TORN_REPORT_S;
      }
      if (report) {
        fprintf(stderr,
                PROG ": %s: valid records stop at offset %lld (%s: %s); fitting the %d "
                "before it, still polling\n",
                a->o->buffer, (long long)tail.offset, nd_rfile_status_name(tail.status),
                tail.why, a->n);
        a->stop_offset = tail.offset;
      }
    }
    return;
  }
}

/* ---------------------------------------------------------------------------------- */

static int publish_params(adapter *a) {
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

/* Take a finished fit: new version, history, PARAMS, a line on stdout. */
static void collect(adapter *a, fitter *ft) {
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
    a->failed_n = n;
    a->st.state = "error";
    return;
  }
  nd_history_entry e;
  memset(&e, 0, sizeof(e));
  e.version = a->version + 1;
  e.utime = ndp_utime();
  e.buffer_created = a->buffer_created;
  e.mask = a->mask;
  memcpy(e.mean, out.mean, sizeof(e.mean));
  memcpy(e.std, out.std, sizeof(e.std));
  e.loss = out.loss_mean;
  e.fit_time = secs;
  e.buffer_size = n;
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
  a->covered = n;
  a->failed_n = 0;
  a->st.state = "idle";
  printf("refit version %lld: %d rollout(s) in %.2f s, loss %.4g%s%s, theta %.6g %.6g %.6g "
         "%.6g, std %.3g %.3g %.3g %.3g\n",
         (long long)e.version, n, secs, e.loss,
         out.diverged_mean ? " (mean diverged on some)" : "",
         out.flat ? " (flat: the rollouts do not tell the candidates apart; theta kept)" : "",
         e.mean[0], e.mean[1], e.mean[2],
         e.mean[3], e.std[0], e.std[1], e.std[2], e.std[3]);
  fflush(stdout);
  if (publish_params(a))
    fprintf(stderr, PROG ": publishing on %s failed\n", NDP_CH_PARAMS);
}

/* Resume from the history: version, distribution, what the last fit covered. */
static int load_history(adapter *a, nds_fit *fit, const double sigma0[ND_NTHETA],
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
    const int was = (e->mask >> i) & 1;
    mean[i] = a->o->fit[i] && was ? e->mean[i] : a->o->theta[i];
    std[i] = a->o->fit[i] && was ? e->std[i] : sigma0[i];
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
static void quit_during_fit(adapter *a) {
  fprintf(stderr, PROG ": stopped during a refit; its result is dropped\n");
  a->st.state = "stopped";
  ndp_status_tick(a->lcm, &a->st, 1);
  nd_rfile_writer_close(&a->hist);
  fflush(stdout);
  fflush(stderr);
  _exit(0);
}

int main(int argc, char **argv) {
  opts o;
  int rc = parse_opts(argc, argv, &o);
  if (rc == 1) return 0;
  if (rc) return 2;

  ndp_signals();
  ndp_mujoco_handlers(PROG);
  /* Before any thread exists: the pool's workers inherit it. */
  errno = 0;
  if (o.nice > 0 && nice(o.nice) == -1 && errno)
    fprintf(stderr, PROG ": nice(%d) refused (%s); running at normal priority\n", o.nice,
            strerror(errno));

  char err[512] = "";
  int status = 1;
  adapter a;
  memset(&a, 0, sizeof(a));
  a.o = &o;
  a.hist.fd = -1;
  a.rd.fd = -1;
  a.stop_offset = a.torn_offset = -1;
  ndp_status_init(&a.st, PROG);
  a.st.state = "starting";
  for (int i = 0; i < ND_NTHETA; i++) a.mask |= (uint32_t)o.fit[i] << i;
  fitter ft;
  memset(&ft, 0, sizeof(ft));
  int ft_started = 0, ft_sync = 0;
  nd_pool *pool = NULL;
  nd_history_summary hs;
  memset(&hs, 0, sizeof(hs));

  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  sc.timestep = o.replay_dt;
  memcpy(sc.theta, o.theta, sizeof(sc.theta));
  nds_fit_cfg fc;
  nds_fit_cfg_default(&fc);
  if (o.replay_mode >= 0) fc.replay.mode = o.replay_mode;
  fc.replay.window = o.replay_window >= 0 ? o.replay_window : NDS_FIT_WINDOW_MOCAP;
  fc.robust = o.robust;
  fc.pop = 32;
  fc.iters = 2;
  fc.elite_frac = 0.2;
  for (int i = 0; i < ND_NTHETA; i++) {
    /* The paper sizes the std from the true theta and draws the mean around it; here the
     * mean is given (--theta) and the nominal theta stands in for the truth. */
    const double r = o.ref[i], D = o.D;
    fc.fit[i] = o.fit[i];
    fc.mu0[i] = o.theta[i];
    fc.sigma0[i] = (r + D * r - fmax(fc.lower, r - D * r)) / 16;
  }

  if (nds_model_init(&a.model, &sc, err, sizeof(err))) goto done;
  /* Lock the history first: a second adapter on it stops here. */
  nd_rfile_tail repair;
  if (nd_rfile_open_append(&a.hist, o.history, ND_RFILE_KIND_PARAMS, &repair, err,
                           sizeof(err))) {
    if (strstr(err, "locked"))
      snprintf(err + strlen(err), sizeof(err) - strlen(err),
               " (is another nudge-adapter running on this history?)");
    goto done;
  }
  if (repair.status != ND_RFILE_END)
    fprintf(stderr, PROG ": %s: cut off a %s tail: %s\n", o.history,
            nd_rfile_status_name(repair.status), repair.why);
  /* Before the fit exists: its generator is seeded from the version reached, so a restart
   * does not redraw the samples of the first run. */
  if (nd_history_scan(o.history, &hs, err, sizeof(err))) goto done;
  fc.seed = o.seed + (uint64_t)(hs.have_last ? hs.last.version : 0);
  if (!(pool = nd_pool_create(o.threads, err, sizeof(err)))) goto done;
  if (!(ft.fit = nds_fit_create(&a.model, &fc, pool, err, sizeof(err)))) goto done;
  if (load_history(&a, ft.fit, fc.sigma0, &hs, err, sizeof(err))) goto done;
  if (!(a.lcm = ndp_lcm_create(o.url, err, sizeof(err)))) goto done;
  if (pthread_mutex_init(&ft.mu, NULL) || pthread_cond_init(&ft.cv, NULL)) {
    snprintf(err, sizeof(err), "cannot create the fit thread's lock");
    goto done;
  }
  ft_sync = 1;
  if (pthread_create(&ft.th, NULL, fit_main, &ft)) {
    snprintf(err, sizeof(err), "cannot start the fit thread");
    goto done;
  }
  ft_started = 1;

  double m0[ND_NTHETA], s0[ND_NTHETA];
  nds_fit_dist(ft.fit, m0, s0);
  char fitted[64] = "";
  for (int i = 0; i < ND_NTHETA; i++)
    if (o.fit[i])
      snprintf(fitted + strlen(fitted), sizeof(fitted) - strlen(fitted), "%s%s",
               fitted[0] ? "," : "", theta_names[i]);
  char rank[64] = "L";
  if (fc.robust > 0) snprintf(rank, sizeof(rank), "the robust score of scale %g m^2", fc.robust);
  fprintf(stderr,
          PROG ": buffer %s, history %s (%lld entries%s), fit %s, CEM Q %d C %d rho %.2g, "
          "prior D %g on (%g, %g, %g, %g), %s (%.4g, %.4g, %.4g, %.4g) std (%.3g, %.3g, %.3g, "
          "%.3g), replay %s dt %g s window %g s, ranked by %s, "
          "%d worker(s), nice %d, %s\n",
          o.buffer, o.history, (long long)hs.entries, hs.have_last ? ", resuming" : "", fitted,
          fc.pop, fc.iters, fc.elite_frac, o.D, o.ref[0], o.ref[1], o.ref[2], o.ref[3],
          hs.have_last ? "from version" : "prior", m0[0], m0[1], m0[2], m0[3], s0[0], s0[1],
          s0[2], s0[3], nds_replay_mode_name(fc.replay.mode), o.replay_dt, fc.replay.window,
          rank, o.threads, o.nice,
          ndp_url(o.url));
  if (hs.have_last)
    fprintf(stderr, PROG ": resuming after version %lld (fit on %d rollout(s) of the buffer "
            "created %lld us)\n", (long long)hs.last.version, (int)hs.last.buffer_size,
            (long long)hs.last.buffer_created);

  int covered_checked = 0;
  a.st.state = "waiting";
  while (!ndp_quit) {
    const int fs = fitter_state(&ft);
    if (fs == FIT_DONE) collect(&a, &ft);
    if (fs == FIT_DONE || fs == FIT_IDLE) {
      poll_buffer(&a);
      /* The history covers this buffer only if it was fitted on this very file. */
      if (a.rd_open && !covered_checked) {
        covered_checked = 1;
        if (hs.have_last && hs.last.buffer_created == a.buffer_created) {
          a.covered = hs.last.buffer_size;
        } else if (hs.have_last) {
          fprintf(stderr, PROG ": the history's last fit was on another buffer (created "
                  "%lld us): refitting on this one\n", (long long)hs.last.buffer_created);
        }
      }
      if (!a.rd_open) {
        covered_checked = 0;
        a.st.state = "waiting";
      } else if (a.n > a.covered && a.n != a.failed_n) {
        pthread_mutex_lock(&ft.mu);
        ft.rs = a.rs;
        ft.n = a.n;
        ft.state = FIT_QUEUED;
        pthread_cond_signal(&ft.cv);
        pthread_mutex_unlock(&ft.mu);
        a.st.state = "fitting";
        fprintf(stderr, PROG ": refitting on %d rollout(s) (%d new)\n", a.n, a.n - a.covered);
      } else if (strcmp(a.st.state, "error")) {
        a.st.state = "idle";
      }
    }
    if (a.have_latest && ndp_mono() >= a.next_params && publish_params(&a)) {
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
  {
    const int fs = fitter_state(&ft);
    if (fs == FIT_DONE) collect(&a, &ft);  /* finished: worth keeping */
    else if (fs != FIT_IDLE) quit_during_fit(&a);
  }
  a.st.state = "stopped";
  ndp_status_tick(a.lcm, &a.st, 1);
  status = 0;

done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  if (ft_started) {
    pthread_mutex_lock(&ft.mu);
    ft.quit = 1;
    pthread_cond_signal(&ft.cv);
    pthread_mutex_unlock(&ft.mu);
    pthread_join(ft.th, NULL);
  }
  if (ft_sync) {
    pthread_cond_destroy(&ft.cv);
    pthread_mutex_destroy(&ft.mu);
  }
  nds_fit_free(ft.fit);
  nd_pool_free(pool);
  close_buffer(&a);
  drop_records(&a);
  free(a.rs);
  nd_rfile_writer_close(&a.hist);
  nds_model_free(&a.model);
  if (a.lcm) lcm_destroy(a.lcm);
  return status;
}
