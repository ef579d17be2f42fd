/* adapter: what the files of nudge-adapter share.
 *
 *   main.c    wiring: the model, the fit, the history, the loop
 *   options.c the command line and the fit's configuration
 *   watch.c   the replay buffer: reading what was appended, skipping bad records
 *   fitter.c  the fit thread: one nds_fit_run per job
 *   params.c  a finished fit: the next version, the history, PARAMS
 *   batch.c   a whole buffer read at once, with the replays' model and a fit
 *   score.c   --score: one replay of the whole buffer at a given theta, no LCM
 *   offline.c --offline: the watching loop's refits on a recorded buffer, no LCM
 *
 * The adapter watches the replay buffer the task runner appends to. Whenever complete
 * rollouts beyond those of the last fit are there, it refits theta on all of them, or on
 * the newest --max-rollouts, the only ones it then keeps (sim/nds_fit.h), publishes the
 * result on PARAMS, appends it to the parameter history (core/nd_history.h) and
 * republishes it at 1 Hz, so a planner started later gets it too. A refit takes seconds,
 * so it runs in the fit thread; the main thread does not touch the rollout array while a
 * job runs (new records wait in the file, so one refit covers whatever arrived during the
 * last one). A restarted adapter reads its history: version numbering and the CEM
 * distribution go on from its last entry. */
#ifndef ADAPTER_H
#define ADAPTER_H

#include <pthread.h>
#include <sys/types.h>

#include "nd_history.h"
#include "nd_rbuf.h"
#include "nds_fit.h"
#include "ndp.h"

#define PROG "nudge-adapter"

typedef struct {
  const char *url;
  const char *buffer;
  char history[ND_RFILE_PATH_MAX];
  unsigned fit;               /* bit i: theta[i] fitted */
  unsigned logfit;            /* bit i: theta[i] searched as ln theta */
  unsigned scan;              /* bit i: theta[i] scanned over its prior's range (cfg.scan) */
  double theta[ND_NTHETA];    /* prior mean; value of held parameters */
  double ref[ND_NTHETA];      /* nominal theta the prior std is sized from */
  double D;                   /* prior uncertainty of the paper's formula */
  int scan_points;            /* grid points per scanned parameter */
  int threads;
  uint64_t seed;
  int nice;
  double replay_dt;           /* model timestep of the replays, s */
  int replay_mode;            /* NDS_REPLAY_* */
  double replay_window;       /* s */
  double replay_skip;         /* m */
  double anchor_fit;          /* s: half-width of the anchors' fit (nds_replay_cfg.smooth) */
  double robust;              /* m^2: CEM ranks by the robust score; 0: by L (nds_fit.h) */
  int max_rollouts;           /* refits use the newest this many rollouts; 0: all */
  double score[ND_NTHETA];    /* --score: theta to evaluate; NAN: watch and refit */
  int offline;                /* --offline: refit once per recorded rollout, then exit */
} adapter_opts;

/* The fit thread's job and result. Fields under mu. */
enum { FIT_IDLE = 0, FIT_QUEUED, FIT_RUNNING, FIT_DONE };

typedef struct {
  pthread_t th;
  pthread_mutex_t mu;
  pthread_cond_t cv;
  int started;
  int state;              /* FIT_*: main moves IDLE->QUEUED and DONE->IDLE, the thread the rest */
  int quit;
  nds_fit *fit;
  const nd_rollout *rs;   /* the job: rs[0, n), untouched by main while not IDLE */
  int n;
  int rc;                 /* result */
  nds_fit_out out;
  double secs;
  char err[256];
} adapter_fitter;

/* The process's state, owned by the main thread. */
typedef struct {
  const adapter_opts *o;
  lcm_t *lcm;
  ndp_status st;
  nds_model model;            /* the replays' model, for checking records before a fit */

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
  nd_rollout *rs;             /* good records, file order: the newest max_rollouts */
  int n, cap;
  int total;                  /* good records read from this buffer, dropped ones too */
  int64_t bad_logged;

  /* fits */
  int covered;                /* total when the latest fit (or the history's) ran; 0 none */
  int failed_n;               /* a fit at this total failed: wait for more */
  int64_t version;            /* latest version; 0: none yet */
  int have_latest;
  nd_history_entry latest;
  nd_rfile_writer hist;
  double next_params;
} adapter;

/* options.c: parse argv into o and the fit's configuration fc. ND_OPT_RUN, or the exit
 * status (usage or refusal printed). */
int adapter_options(int argc, char **argv, adapter_opts *o, nds_fit_cfg *fc);

/* batch.c: the replays' model, the default scene at o->replay_dt with theta. 0, or -1 and
 * a message. */
int adapter_model_init(const adapter_opts *o, const double theta[ND_NTHETA], nds_model *m,
                       char *err, int errlen);

/* A whole buffer for the modes that read it and exit: all of it is owned here. */
typedef struct {
  nd_rollout *rs;             /* o->buffer's complete records, file order */
  int n;
  nds_model model;            /* the replays' model at the theta given */
  int have_model;
  nd_pool *pool;
  nds_fit *fit;               /* on model and pool */
} adapter_batch;

/* Read o->buffer (at least one rollout, else a message naming it and what it was for),
 * build the model at theta and a fit of fc. 0, or -1 and a message; close b either way. */
int adapter_batch_open(adapter_batch *b, const adapter_opts *o, const nds_fit_cfg *fc,
                       const double theta[ND_NTHETA], const char *what, char *err, int errlen);
void adapter_batch_close(adapter_batch *b);

/* score.c: L(o->score) on every rollout of o->buffer, printed as 'name value unit'
 * lines; the exit status (0, 1 unreadable or failed). */
int adapter_score(const adapter_opts *o, const nds_fit_cfg *fc);

/* offline.c: the refits the watching adapter would make on o->buffer as it grew by one
 * rollout at a time, each line printed as it prints them, then the last fit as 'name
 * value unit' lines; the exit status (0, 1 unreadable or failed). */
int adapter_offline(const adapter_opts *o, const nds_fit_cfg *fc);

/* watch.c */
void adapter_poll(adapter *a);            /* read what was appended (no fit running) */
void adapter_close(adapter *a);           /* close the buffer, drop its records */
/* " (the newest of TOTAL)" into buf when a fit on n records left some of the total read
 * out (--max-rollouts), else "". */
const char *adapter_window_note(int n, int total, char *buf, int len);

/* fitter.c */
int adapter_fitter_start(adapter_fitter *ft, char *err, int errlen);
int adapter_fitter_state(adapter_fitter *ft);
void adapter_fitter_submit(adapter_fitter *ft, const nd_rollout *rs, int n);
void adapter_fitter_stop(adapter_fitter *ft);

/* params.c */
int adapter_open_history(adapter *a, nd_history_summary *hs, char *err, int errlen);
void adapter_banner(const adapter *a, const nds_fit *fit, const nds_fit_cfg *fc,
                    const nd_history_summary *hs);
int adapter_publish(adapter *a);          /* PARAMS of the latest fit; -1 on failure */
void adapter_collect(adapter *a, adapter_fitter *ft);  /* take a finished fit */
/* The refit line on stdout: version, rollouts fitted (n of the total read), time, out. */
void adapter_print_refit(int64_t version, int n, int total, double secs, const nds_fit_out *out);
int adapter_resume(adapter *a, nds_fit *fit, const double sigma0[ND_NTHETA],
                   const nd_history_summary *hs, char *err, int errlen);
void adapter_quit_during_fit(adapter *a);

#endif
