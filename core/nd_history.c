/* nd_history: encoding and reading the adapter's parameter history. */
#include "nd_history.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

/* Where each version puts what follows the common first 32 bytes (nd_history.h). */
typedef struct {
  uint32_t version;
  int size, ntheta, mean, std, loss, fit_time, buffer_size, reserved;
} nd_history_layout;

static const nd_history_layout nd_history_v2 = {
    2, ND_HISTORY_ENC_SIZE, ND_NTHETA, 32, 88, 144, 152, 160, 164};
static const nd_history_layout nd_history_v1 = {
    1, ND_HISTORY_ENC_SIZE_V1, ND_NTHETA_PAPER, 32, 64, 96, 104, 112, 116};

/* Version 2 holds all of theta: a change of ND_NTHETA needs a new version. */
_Static_assert(ND_NTHETA == 7 && ND_HISTORY_ENC_SIZE == 32 + 16 * ND_NTHETA + 24,
               "the history encoding's layout does not match ND_NTHETA");
_Static_assert(ND_HISTORY_ENC_VERSION == 2, "nd_history_encode writes nd_history_v2");

int nd_history_check(const nd_history_entry *e, char *err, int errlen) {
  const unsigned all = (1u << ND_NTHETA) - 1;
  if (e->mask < 1 || e->mask > all) {
    snprintf(err, errlen, "fit mask %u: must be in [1, %u]", (unsigned)e->mask, all);
    return -1;
  }
  if (e->version < 1) {
    snprintf(err, errlen, "version %lld: must be >= 1", (long long)e->version);
    return -1;
  }
  if (e->utime <= 0) {
    snprintf(err, errlen, "utime %lld: not a time", (long long)e->utime);
    return -1;
  }
  if (e->buffer_created < 0) {
    snprintf(err, errlen, "buffer_created %lld: negative", (long long)e->buffer_created);
    return -1;
  }
  char why[200];
  if (nd_theta_check(e->mean, why, sizeof(why))) {
    snprintf(err, errlen, "mean: %s", why);
    return -1;
  }
  for (int i = 0; i < ND_NTHETA; i++) {
    const double s = e->std[i];
    const int held = !(e->mask & (1u << i));
    if (!isfinite(s) || s < 0.0 || (held && s != 0.0)) {
      snprintf(err, errlen, "std[%d] (%s) = %g: must be finite and >= 0, and 0 when held", i,
               nd_theta_name[i], s);
      return -1;
    }
  }
  if (!isfinite(e->loss) || e->loss < 0.0) {
    snprintf(err, errlen, "loss %g: must be finite and >= 0", e->loss);
    return -1;
  }
  if (!isfinite(e->fit_time) || e->fit_time < 0.0) {
    snprintf(err, errlen, "fit_time %g: must be finite and >= 0", e->fit_time);
    return -1;
  }
  if (e->buffer_size < 1) {
    snprintf(err, errlen, "buffer_size %d: must be >= 1", (int)e->buffer_size);
    return -1;
  }
  return 0;
}

/* Little-endian by shifts: the file must read the same on any host. */
static void put_u32(unsigned char *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (unsigned char)(v >> (8 * i));
}
static void put_u64(unsigned char *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (unsigned char)(v >> (8 * i));
}
static void put_f64(unsigned char *p, double d) {
  uint64_t v;
  memcpy(&v, &d, sizeof(v));
  put_u64(p, v);
}
static uint32_t get_u32(const unsigned char *p) {
  uint32_t v = 0;
  for (int i = 0; i < 4; i++) v |= (uint32_t)p[i] << (8 * i);
  return v;
}
static uint64_t get_u64(const unsigned char *p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; i++) v |= (uint64_t)p[i] << (8 * i);
  return v;
}
static double get_f64(const unsigned char *p) {
  uint64_t v = get_u64(p);
  double d;
  memcpy(&d, &v, sizeof(d));
  return d;
}

int nd_history_encode(const nd_history_entry *e, unsigned char buf[ND_HISTORY_ENC_SIZE],
                       char *err, int errlen) {
  char why[200];
  if (nd_history_check(e, why, sizeof(why))) {
    snprintf(err, errlen, "history entry not encoded: %s", why);
    return -1;
  }
  const nd_history_layout *l = &nd_history_v2;
  put_u32(buf + 0, l->version);
  put_u32(buf + 4, e->mask);
  put_u64(buf + 8, (uint64_t)e->version);
  put_u64(buf + 16, (uint64_t)e->utime);
  put_u64(buf + 24, (uint64_t)e->buffer_created);
  for (int i = 0; i < l->ntheta; i++) {
    put_f64(buf + l->mean + 8 * i, e->mean[i]);
    put_f64(buf + l->std + 8 * i, e->std[i]);
  }
  put_f64(buf + l->loss, e->loss);
  put_f64(buf + l->fit_time, e->fit_time);
  put_u32(buf + l->buffer_size, (uint32_t)e->buffer_size);
  put_u32(buf + l->reserved, 0);
  return 0;
}

int nd_history_decode(nd_history_entry *e, const unsigned char *buf, size_t len, char *err,
                       int errlen) {
  if (len != ND_HISTORY_ENC_SIZE && len != ND_HISTORY_ENC_SIZE_V1) {
    snprintf(err, errlen, "history entry of %zu bytes, expected %d (version 2) or %d "
             "(version 1)", len, ND_HISTORY_ENC_SIZE, ND_HISTORY_ENC_SIZE_V1);
    return -1;
  }
  const uint32_t ver = get_u32(buf);
  const nd_history_layout *l = ver == 2 ? &nd_history_v2 : ver == 1 ? &nd_history_v1 : NULL;
  if (!l) {
    snprintf(err, errlen, "history entry encoding version %u, expected 2 or 1", (unsigned)ver);
    return -1;
  }
  if (len != (size_t)l->size) {
    snprintf(err, errlen, "history entry encoding version %u in %zu bytes, expected %d",
             (unsigned)ver, len, l->size);
    return -1;
  }
  const uint32_t reserved = get_u32(buf + l->reserved);
  if (reserved != 0) {
    snprintf(err, errlen, "history entry reserved field is %08x, expected 0",
             (unsigned)reserved);
    return -1;
  }
  memset(e, 0, sizeof(*e));
  e->mask = get_u32(buf + 4);
  const unsigned mine = (1u << l->ntheta) - 1;
  if (e->mask > mine) {  /* a version-1 entry fitted none of the box's */
    snprintf(err, errlen, "history entry: fit mask %u: must be in [1, %u] in version %u",
             (unsigned)e->mask, mine, (unsigned)ver);
    return -1;
  }
  e->version = (int64_t)get_u64(buf + 8);
  e->utime = (int64_t)get_u64(buf + 16);
  e->buffer_created = (int64_t)get_u64(buf + 24);
  for (int i = 0; i < ND_NTHETA; i++) {
    e->mean[i] = i < l->ntheta ? get_f64(buf + l->mean + 8 * i) : nd_theta_true[i];
    e->std[i] = i < l->ntheta ? get_f64(buf + l->std + 8 * i) : 0.0;
  }
  e->loss = get_f64(buf + l->loss);
  e->fit_time = get_f64(buf + l->fit_time);
  e->buffer_size = (int32_t)get_u32(buf + l->buffer_size);
  char why[200];
  if (nd_history_check(e, why, sizeof(why))) {
    snprintf(err, errlen, "history entry: %s", why);
    return -1;
  }
  return 0;
}

int nd_history_scan(const char *path, nd_history_summary *s, char *err, int errlen) {
  memset(s, 0, sizeof(*s));
  struct stat st;
  if (stat(path, &st) != 0 && errno == ENOENT) return 0;
  nd_rfile_reader rd;
  if (nd_rfile_reader_open(&rd, path, ND_RFILE_KIND_PARAMS, err, errlen)) return -1;
  int rc = 0;
  for (;;) {
    nd_rfile_record rec;
    const int k = nd_rfile_next(&rd, &rec, &s->tail, err, errlen);
    if (k < 0) {
      rc = -1;
      break;
    }
    if (k == 0) break;
    nd_history_entry e;
    char why[200];
    if (rec.kind != ND_RFILE_KIND_PARAMS) {
      snprintf(why, sizeof(why), "record kind %u, expected %d", (unsigned)rec.kind,
               ND_RFILE_KIND_PARAMS);
    } else if (nd_history_decode(&e, rec.data, rec.len, why, sizeof(why)) == 0) {
      s->entries++;
      if (!s->have_last || e.version >= s->last.version) s->last = e;
      s->have_last = 1;
      continue;
    }
    if (s->bad++ == 0)
      snprintf(s->first_bad, sizeof(s->first_bad), "record at offset %lld: %s",
               (long long)rec.offset, why);
  }
  nd_rfile_reader_close(&rd);
  return rc;
}
