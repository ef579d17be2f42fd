/* nd_rbuf: rollouts over nd_rfile. */
#include "nd_rbuf.h"

#include <stdio.h>
#include <stdlib.h>

int nd_rbuf_open(nd_rfile_writer *w, const char *path, nd_rfile_tail *repair, char *err,
                 int errlen) {
  return nd_rfile_open_append(w, path, ND_RFILE_KIND_ROLLOUTS, repair, err, errlen);
}

int nd_rbuf_append(nd_rfile_writer *w, const nd_rollout *r, char *err, int errlen) {
  char why[200];
  if (nd_rollout_check(r, why, sizeof why)) {
    snprintf(err, (size_t)errlen, "%s: not appended: %s", w->path, why);
    return -1;
  }
  const size_t cap = nd_rollout_encoded_size(r->n);
  unsigned char *buf = malloc(cap);
  if (!buf) {
    snprintf(err, (size_t)errlen, "%s: out of memory encoding %zu bytes", w->path, cap);
    return -1;
  }
  size_t len;
  int rc = nd_rollout_encode(r, buf, cap, &len, err, errlen);
  if (rc == 0)
    rc = nd_rfile_append(w, ND_RFILE_KIND_ROLLOUTS, buf, (uint32_t)len, err, errlen);
  free(buf);
  return rc;
}

int nd_rbuf_reader_open(nd_rfile_reader *rd, const char *path, char *err, int errlen) {
  return nd_rfile_reader_open(rd, path, ND_RFILE_KIND_ROLLOUTS, err, errlen);
}

int nd_rbuf_next(nd_rfile_reader *rd, nd_rollout *r, nd_rfile_tail *tail, char *err,
                 int errlen) {
  nd_rfile_record rec;
  int k = nd_rfile_next(rd, &rec, tail, err, errlen);
  if (k <= 0) return k;
  if (rec.kind != ND_RFILE_KIND_ROLLOUTS) {
    snprintf(err, (size_t)errlen, "%s: record at offset %lld has kind %u, expected %d "
             "(rollout)", rd->path, (long long)rec.offset, (unsigned)rec.kind,
             ND_RFILE_KIND_ROLLOUTS);
    return -1;
  }
  char why[200];
  if (nd_rollout_decode(r, rec.data, rec.len, why, sizeof why)) {
    snprintf(err, (size_t)errlen, "%s: record at offset %lld: %s", rd->path,
             (long long)rec.offset, why);
    return -1;
  }
  return 1;
}

int nd_rbuf_read_all(const char *path, nd_rollout **out, int *n, nd_rfile_tail *tail,
                     char *err, int errlen) {
  *out = NULL;
  *n = 0;
  nd_rfile_reader rd;
  if (nd_rbuf_reader_open(&rd, path, err, errlen)) return -1;
  nd_rollout *rs = NULL;
  int count = 0, cap = 0, k;
  for (;;) {
    if (count == cap) {
      cap = cap ? 2 * cap : 16;
      nd_rollout *grown = realloc(rs, (size_t)cap * sizeof *rs);
      if (!grown) {
        snprintf(err, (size_t)errlen, "%s: out of memory for %d rollouts", path, cap);
        k = -1;
        break;
      }
      rs = grown;
    }
    k = nd_rbuf_next(&rd, &rs[count], tail, err, errlen);
    if (k <= 0) break;
    count++;
  }
  nd_rfile_reader_close(&rd);
  if (k < 0) {
    nd_rbuf_free_all(rs, count);
    return -1;
  }
  *out = rs;
  *n = count;
  return 0;
}

void nd_rbuf_free_all(nd_rollout *rs, int n) {
  for (int i = 0; i < n; i++) nd_rollout_free(&rs[i]);
  free(rs);
}
