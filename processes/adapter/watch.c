/* watch: reading the replay buffer as it grows (adapter.h). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "adapter.h"

#define TORN_REPORT_S 2.0     /* an append takes milliseconds: a tail torn this long is a crash */
#define REJECT_LOG_FIRST 5    /* bad records described on stderr; then only counted */

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
  a->n = a->total = 0;
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
  /* Past the window the oldest goes: a refit's time and the memory stay bounded. */
  if (a->o->max_rollouts > 0 && a->n == a->o->max_rollouts) {
    nd_rollout_free(&a->rs[0]);
    memmove(a->rs, a->rs + 1, sizeof(*a->rs) * (size_t)(a->n - 1));
    a->n--;
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
  a->total++;
}

/* Read what was appended since the last poll. Only while no fit holds the array. */
void adapter_poll(adapter *a) {
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


const char *adapter_window_note(int n, int total, char *buf, int len) {
  buf[0] = '\0';
  if (n < total) snprintf(buf, len, " (the newest of %d)", total);
  return buf;
}

void adapter_close(adapter *a) {
  close_buffer(a);
  drop_records(a);
  free(a->rs);
  a->rs = NULL;
  a->cap = 0;
}
