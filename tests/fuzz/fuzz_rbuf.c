/* Fuzz target: the replay buffer on disk (core/nd_rfile.h, nd_rbuf.h, nd_rollout.h) and
 * the parameter history that shares its framing (core/nd_history.h).
 *
 * The input is the whole content of a record file. It is written to a scratch file and
 * read through every reader (raw records, rollouts one by one, all rollouts at once, the
 * history scan); a copy is opened for append, which must repair a torn tail exactly, refuse
 * damage followed by valid records without touching the file, and then accept one more
 * record. A reference model written from nd_rfile.h's format text predicts each outcome:
 * which records are valid, where and why reading stops, what the writer keeps. Every
 * decoded rollout or history entry must re-encode to the very bytes it came from (a
 * version-1 history entry: to version 2 with the same fields). The raw input is also fed
 * to nd_rollout_decode directly.
 *
 * Random bytes never carry a valid crc32, so the fuzzer alone would almost never get past
 * the frame checks to the decoders. Each input therefore runs a second time with the
 * header and record checksums recomputed (when that changes anything): the first run
 * covers checksum failures, the second everything behind them. */
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "fuzz.h"
#include "nd_rbuf.h"
#include "fuzz_history.h"

/* ---- scratch files: one private directory per process, on tmpfs when there is one, so
 * that the writer's fdatasync costs nothing. The code under test opens them by name, as
 * it opens a replay buffer; the target itself keeps a descriptor on each and refills it
 * in place (ftruncate, pwrite) and reads it back with pread, so an input costs no opens
 * beyond those of the readers and the writer under test. ---- */

static char fz_dir[512], fz_in[600], fz_copy[600];
static int fz_in_fd = -1, fz_copy_fd = -1;

static void fz_cleanup(void) {
  if (fz_in_fd >= 0) close(fz_in_fd);
  if (fz_copy_fd >= 0) close(fz_copy_fd);
  fz_in_fd = fz_copy_fd = -1;
  DIR *d = opendir(fz_dir);
  if (d) {
    for (struct dirent *e; (e = readdir(d));) {
      if (e->d_name[0] == '.') continue;
      char p[1024];
      snprintf(p, sizeof p, "%s/%s", fz_dir, e->d_name);
      unlink(p);
    }
    closedir(d);
  }
  rmdir(fz_dir);
}

static void fz_setup(void) {
  if (fz_dir[0]) return;
  const char *base = getenv("TMPDIR");
  if (access("/dev/shm", W_OK) == 0)
    base = "/dev/shm";
  else if (!base)
    base = "/tmp";
  snprintf(fz_dir, sizeof fz_dir, "%s/nudge-fuzz-rbuf-XXXXXX", base);
  FZ_CHECK(mkdtemp(fz_dir) != NULL, "cannot create a scratch directory in %s: %s", base,
           strerror(errno));
  snprintf(fz_in, sizeof fz_in, "%s/in.buf", fz_dir);
  snprintf(fz_copy, sizeof fz_copy, "%s/copy.buf", fz_dir);
  atexit(fz_cleanup);
  fz_on_abort = fz_cleanup;
  fz_in_fd = open(fz_in, O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  FZ_CHECK(fz_in_fd >= 0, "%s: %s", fz_in, strerror(errno));
  fz_copy_fd = open(fz_copy, O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  FZ_CHECK(fz_copy_fd >= 0, "%s: %s", fz_copy, strerror(errno));
}

/* Make the scratch file behind fd hold exactly d[0, n): overwrite in place, then cut what
 * the previous input left beyond n (the pages of [0, n) are reused, not freed and
 * allocated again as after a truncation to 0). */
static void fz_put(int fd, const char *path, const uint8_t *d, size_t n) {
  for (size_t done = 0; done < n;) {
    ssize_t k = pwrite(fd, d + done, n - done, (off_t)done);
    FZ_CHECK(k > 0, "%s: %s", path, strerror(errno));
    done += (size_t)k;
  }
  FZ_CHECK(ftruncate(fd, (off_t)n) == 0, "%s: %s", path, strerror(errno));
}

/* Whole file behind fd into a fresh buffer (caller frees). */
static uint8_t *fz_get(int fd, const char *path, size_t *n) {
  struct stat st;
  FZ_CHECK(fstat(fd, &st) == 0, "%s: %s", path, strerror(errno));
  uint8_t *b = malloc((size_t)st.st_size + 1);
  FZ_CHECK(b != NULL, "out of memory");
  size_t got = 0;
  while (got < (size_t)st.st_size) {
    ssize_t k = pread(fd, b + got, (size_t)st.st_size - got, (off_t)got);
    FZ_CHECK(k > 0, "%s: %s", path, strerror(errno));
    got += (size_t)k;
  }
  *n = got;
  return b;
}

/* ---- reference model of the format ---- */

enum { FZ_VALID = 3 };  /* beside ND_RFILE_END / _TORN / _CORRUPT */

FZ_ORACLE
static uint32_t fz_le32(const uint8_t *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

FZ_ORACLE
static void fz_put32(uint8_t *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

FZ_ORACLE
static uint32_t fz_crc(const uint8_t *frame, const uint8_t *payload, uint32_t len) {
  uLong c = crc32(0L, frame, 8);
  if (len) c = crc32(c, payload, (uInt)len);
  return (uint32_t)c;
}

/* What lies at off: FZ_VALID (a complete record with a matching crc; *kind, *len set) or
 * the status reading stops with. Kind and length limits come first: zero-filled or absurd
 * frames are corrupt even when the file also ends too early. */
FZ_ORACLE
static int fz_frame(const uint8_t *d, size_t size, size_t off, uint32_t *kind,
                    uint32_t *len) {
  const size_t avail = size - off;
  if (avail == 0) return ND_RFILE_END;
  if (avail < ND_RFILE_FRAME) return ND_RFILE_TORN;
  *len = fz_le32(d + off);
  *kind = fz_le32(d + off + 4);
  if (*kind == 0 || *kind > ND_RFILE_KIND_MAX || *len > ND_RFILE_MAX_PAYLOAD)
    return ND_RFILE_CORRUPT;
  if (avail - ND_RFILE_FRAME < *len) return ND_RFILE_TORN;
  if (fz_crc(d + off, d + off + ND_RFILE_FRAME, *len) != fz_le32(d + off + 8))
    return ND_RFILE_CORRUPT;
  return FZ_VALID;
}

typedef struct {
  size_t off;
  uint32_t kind, len;
} fz_rec;

typedef struct {
  int header_ok;
  uint32_t kind;  /* file kind, when header_ok */
  int status;     /* where the valid records end (header_ok), and why */
  size_t end;
  int64_t count;
  fz_rec *recs;   /* count of them */
  int tail_valid; /* a valid record starts somewhere after end: damage, not a torn tail */
} fz_model;

FZ_ORACLE
static void fz_model_run(fz_model *m, const uint8_t *d, size_t size) {
  memset(m, 0, sizeof *m);
  m->header_ok = size >= ND_RFILE_HEADER && memcmp(d, ND_RFILE_MAGIC, 8) == 0 &&
                 fz_le32(d + 8) == ND_RFILE_VERSION && fz_le32(d + 12) == ND_RFILE_HEADER &&
                 fz_le32(d + 20) == 0 && (uint32_t)crc32(0L, d, 36) == fz_le32(d + 36);
  if (!m->header_ok) return;
  m->kind = fz_le32(d + 16);
  m->recs = malloc((size / ND_RFILE_FRAME + 1) * sizeof *m->recs);
  FZ_CHECK(m->recs != NULL, "out of memory");
  size_t off = ND_RFILE_HEADER;
  for (;;) {
    uint32_t kind, len;
    const int s = fz_frame(d, size, off, &kind, &len);
    if (s != FZ_VALID) {
      m->status = s;
      break;
    }
    m->recs[m->count++] = (fz_rec){off, kind, len};
    off += ND_RFILE_FRAME + len;
  }
  m->end = off;
  for (size_t p = off + 1; m->status != ND_RFILE_END && p + ND_RFILE_FRAME <= size; p++) {
    uint32_t kind, len;
    /* The cheap test first: kind outside [1, ND_RFILE_KIND_MAX] (fz_frame would agree). */
    if ((d[p + 6] | d[p + 7]) || !(d[p + 4] | d[p + 5])) continue;
    if (fz_frame(d, size, p, &kind, &len) == FZ_VALID) {
      m->tail_valid = 1;
      break;
    }
  }
}

/* ---- decoders ---- */

/* Decode a rollout; if it decodes, it must be valid and re-encode to the same bytes.
 * Return 1 if it decoded. */
static int fz_rollout(const uint8_t *d, size_t len) {
  nd_rollout r;
  char why[256];
  if (nd_rollout_decode(&r, d, len, why, sizeof why)) {
    FZ_CHECK(!r.u && !r.obj && !r.ee && !r.sp && r.n == 0, "refused rollout holds arrays");
    FZ_CHECK(why[0] != 0, "refused without a reason");
    return 0;
  }
  FZ_CHECK(nd_rollout_check(&r, why, sizeof why) == 0, "decoded rollout invalid: %s", why);
  FZ_CHECK(len == nd_rollout_encoded_size(r.n), "%zu bytes decoded as %d steps", len, r.n);
  uint8_t *out = malloc(len);
  size_t olen = 0;
  FZ_CHECK(out != NULL, "out of memory");
  FZ_CHECK(nd_rollout_encode(&r, out, len, &olen, why, sizeof why) == 0, "%s", why);
  FZ_CHECK(olen == len && memcmp(out, d, len) == 0, "rollout re-encodes differently");
  free(out);
  nd_rollout_free(&r);
  return 1;
}

static int fz_history(const uint8_t *d, size_t len) {
  nd_history_entry e;
  char why[256];
  if (nd_history_decode(&e, d, len, why, sizeof why)) return 0;
  fz_history_reencodes(d, len, &e, "history entry");
  return 1;
}

/* A valid rollout encoding for the writer to append. */
static uint8_t fz_one[ND_ROLLOUT_ENC_FIXED + ND_ROLLOUT_ENC_STEP];

static void fz_make_one(void) {
  nd_rollout r;
  memset(&r, 0, sizeof r);
  FZ_CHECK(nd_rollout_alloc(&r, 1) == 0, "alloc");
  r.outcome = ND_OUTCOME_SUCCESS;
  r.control = ND_CTRL_FORCE;
  r.dt = 1e-3;
  r.obj_quat[0] = 1.0;
  r.obj[3] = 1.0; /* the pose after the step: a unit quaternion */
  size_t len;
  char why[256];
  FZ_CHECK(nd_rollout_encode(&r, fz_one, sizeof fz_one, &len, why, sizeof why) == 0 &&
           len == sizeof fz_one, "%s", why);
  nd_rollout_free(&r);
}

/* ---- one file through every reader and the writer ---- */

static void fz_readers(const uint8_t *d, size_t size, const fz_model *m) {
  char err[512];
  nd_rfile_reader rd;
  const int ro = nd_rfile_reader_open(&rd, fz_in, 0, err, sizeof err);
  FZ_CHECK((ro == 0) == m->header_ok, "reader open %d, model says header %s: %s", ro,
           m->header_ok ? "good" : "bad", ro ? err : "");
  int64_t rollouts = 0, entries = 0;
  if (ro == 0) {
    FZ_CHECK(rd.kind == m->kind, "kind %u, header says %u", rd.kind, m->kind);
    for (int64_t i = 0;; i++) {
      nd_rfile_record rec;
      nd_rfile_tail t;
      const int k = nd_rfile_next(&rd, &rec, &t, err, sizeof err);
      FZ_CHECK(k >= 0, "reader I/O error: %s", err);
      if (k == 0) {
        FZ_CHECK(i == m->count, "%lld records read, model has %lld", (long long)i,
                 (long long)m->count);
        FZ_CHECK(t.status == m->status && t.offset == (int64_t)m->end &&
                 t.size == (int64_t)size && t.records == m->count,
                 "tail %s at %lld of %lld (%lld records), model %s at %zu: %s",
                 nd_rfile_status_name(t.status), (long long)t.offset, (long long)t.size,
                 (long long)t.records, nd_rfile_status_name(m->status), m->end, t.why);
        FZ_CHECK(t.status == ND_RFILE_END || t.why[0] != 0, "stopped without a reason");
        /* Polling again finds the same place. */
        FZ_CHECK(nd_rfile_next(&rd, &rec, &t, err, sizeof err) == 0 &&
                 t.offset == (int64_t)m->end, "second poll moved");
        break;
      }
      FZ_CHECK(i < m->count, "record %lld beyond the model's %lld", (long long)i,
               (long long)m->count);
      const fz_rec *x = &m->recs[i];
      FZ_CHECK(rec.offset == (int64_t)x->off && rec.kind == x->kind && rec.len == x->len &&
               (x->len == 0 || memcmp(rec.data, d + x->off + ND_RFILE_FRAME, x->len) == 0),
               "record %lld differs from the file", (long long)i);
      if (rec.kind == ND_RFILE_KIND_ROLLOUTS)
        rollouts += fz_rollout(rec.data, rec.len);
      else if (rec.kind == ND_RFILE_KIND_PARAMS)
        entries += fz_history(rec.data, rec.len);
    }
    nd_rfile_reader_close(&rd);
  }

  /* Rollouts one by one: an undecodable sound record is an error the reader steps over. */
  const int is_rollouts = m->kind == ND_RFILE_KIND_ROLLOUTS;
  const int rb = nd_rbuf_reader_open(&rd, fz_in, err, sizeof err);
  FZ_CHECK((rb == 0) == is_rollouts, "rbuf open %d for file kind %u", rb, m->kind);
  if (rb == 0) {
    int64_t ok = 0, bad = 0;
    for (;;) {
      nd_rollout r;
      const int k = nd_rbuf_next(&rd, &r, NULL, err, sizeof err);
      if (k == 0) break;
      if (k > 0) {
        ok++;
        nd_rollout_free(&r);
      } else {
        bad++;
        FZ_CHECK(ok + bad <= m->count, "reader loops on a bad record: %s", err);
      }
    }
    FZ_CHECK(ok == rollouts && ok + bad == m->count, "rbuf_next: %lld good, %lld bad of "
             "%lld records, %lld rollouts", (long long)ok, (long long)bad,
             (long long)m->count, (long long)rollouts);
    nd_rfile_reader_close(&rd);
  }

  /* All rollouts at once: all or nothing. */
  nd_rollout *rs = NULL;
  int n = -1;
  nd_rfile_tail t;
  const int ra = nd_rbuf_read_all(fz_in, &rs, &n, &t, err, sizeof err);
  if (is_rollouts && rollouts == m->count) {
    FZ_CHECK(ra == 0 && n == m->count && t.status == m->status &&
             t.offset == (int64_t)m->end, "read_all %d, %d rollouts: %s", ra, n, err);
    for (int i = 0; i < n; i++) {
      const fz_rec *x = &m->recs[i];
      uint8_t *out = malloc(x->len);
      size_t olen = 0;
      FZ_CHECK(out && nd_rollout_encode(&rs[i], out, x->len, &olen, err, sizeof err) == 0 &&
               olen == x->len && memcmp(out, d + x->off + ND_RFILE_FRAME, olen) == 0,
               "read_all rollout %d differs from its record", i);
      free(out);
    }
    nd_rbuf_free_all(rs, n);
  } else {
    FZ_CHECK(ra == -1 && rs == NULL && n == 0, "read_all accepted a file with %lld of %lld "
             "records undecodable", (long long)(m->count - rollouts), (long long)m->count);
  }

  /* The history scan: bad records are counted, not fatal. */
  nd_history_summary s;
  const int hs = nd_history_scan(fz_in, &s, err, sizeof err);
  FZ_CHECK((hs == 0) == (m->kind == ND_RFILE_KIND_PARAMS), "history scan %d of kind %u: %s",
           hs, m->kind, err);
  if (hs == 0) {
    FZ_CHECK(s.entries == entries && s.entries + s.bad == m->count &&
             s.have_last == (entries > 0) && s.tail.status == m->status &&
             s.tail.offset == (int64_t)m->end, "history scan: %lld entries + %lld bad, "
             "model %lld of %lld", (long long)s.entries, (long long)s.bad,
             (long long)entries, (long long)m->count);
    FZ_CHECK(!s.have_last || nd_history_check(&s.last, err, sizeof err) == 0, "%s", err);
    FZ_CHECK((s.bad == 0) == (s.first_bad[0] == 0), "first_bad inconsistent");
  }
}

static void fz_writer(const uint8_t *d, size_t size, const fz_model *m) {
  fz_put(fz_copy_fd, fz_copy, d, size);
  const uint32_t want = m->header_ok && m->kind >= 1 && m->kind <= ND_RFILE_KIND_MAX
                            ? m->kind
                            : ND_RFILE_KIND_ROLLOUTS;
  /* An empty file is a fresh one (created by touch); otherwise the header must be sound
   * and of the kind asked for, and only a tail without valid records after it is cut. */
  const int fresh = size == 0;
  const int expect = fresh || (m->header_ok && m->kind == want && !m->tail_valid);
  char err[1024];
  /* A reader that has read everything valid and polls on while the writer repairs the
   * tail and appends: it must get exactly the appended record next. */
  nd_rfile_reader rd;
  const int polling = expect && !fresh;
  if (polling) {
    FZ_CHECK(nd_rfile_reader_open(&rd, fz_copy, 0, err, sizeof err) == 0, "%s", err);
    nd_rfile_record rec;
    while (nd_rfile_next(&rd, &rec, NULL, err, sizeof err) == 1) {}
    FZ_CHECK(rd.offset == (int64_t)m->end && rd.records == m->count, "poller at %lld",
             (long long)rd.offset);
  }
  nd_rfile_writer w;
  nd_rfile_tail rep;
  const int rc = nd_rfile_open_append(&w, fz_copy, want, &rep, err, sizeof err);
  size_t after_len;
  uint8_t *after = fz_get(fz_copy_fd, fz_copy, &after_len);
  if (!expect) {
    FZ_CHECK(rc == -1 && err[0], "writer accepted: model says refuse (header %d, kind %u, "
             "valid record after the damage %d)", m->header_ok, m->kind, m->tail_valid);
    FZ_CHECK(after_len == size && memcmp(after, d, size) == 0,
             "refused file was modified");
    free(after);
    return;
  }
  FZ_CHECK(rc == 0, "writer refused: %s", err);
  const size_t keep = fresh ? ND_RFILE_HEADER : m->end;
  const int64_t count = fresh ? 0 : m->count;
  FZ_CHECK(w.end == (int64_t)keep && w.records == count && after_len == keep,
           "writer keeps %lld bytes, %lld records; file %zu; model %zu, %lld",
           (long long)w.end, (long long)w.records, after_len, keep, (long long)count);
  FZ_CHECK(fresh || memcmp(after, d, keep) == 0, "writer changed the valid records");
  FZ_CHECK(fresh || (rep.status == m->status && rep.offset == (int64_t)m->end &&
                     rep.records == m->count),
           "repair report %s at %lld, model %s at %zu",
           nd_rfile_status_name(rep.status), (long long)rep.offset,
           nd_rfile_status_name(m->status), m->end);
  free(after);

  const uint8_t abc[3] = {'a', 'b', 'c'};
  const uint8_t *payload = want == ND_RFILE_KIND_ROLLOUTS ? fz_one : abc;
  const uint32_t plen = want == ND_RFILE_KIND_ROLLOUTS ? sizeof fz_one : sizeof abc;
  FZ_CHECK(nd_rfile_append(&w, want, payload, plen, err, sizeof err) == 0, "%s", err);
  nd_rfile_writer_close(&w);

  after = fz_get(fz_copy_fd, fz_copy, &after_len);
  fz_model m2;
  fz_model_run(&m2, after, after_len);
  FZ_CHECK(m2.header_ok && m2.kind == want && m2.status == ND_RFILE_END &&
               m2.count == count + 1 && after_len == keep + ND_RFILE_FRAME + plen,
           "after append: status %d, %lld records, %zu bytes", m2.status,
           (long long)m2.count, after_len);
  const fz_rec *x = &m2.recs[m2.count - 1];
  FZ_CHECK(x->kind == want && x->len == plen &&
           memcmp(after + x->off + ND_RFILE_FRAME, payload, plen) == 0,
           "appended record differs");
  if (polling) {
    nd_rfile_record rec;
    nd_rfile_tail t;
    FZ_CHECK(nd_rfile_next(&rd, &rec, &t, err, sizeof err) == 1 &&
             rec.offset == (int64_t)keep && rec.len == plen &&
             memcmp(rec.data, payload, plen) == 0, "poller missed the appended record");
    FZ_CHECK(nd_rfile_next(&rd, &rec, &t, err, sizeof err) == 0 && t.status == ND_RFILE_END,
             "poller after the append: %s", t.why);
    nd_rfile_reader_close(&rd);
  }
  free(m2.recs);
  free(after);
}

static void fz_file(const uint8_t *d, size_t size) {
  fz_model m;
  fz_model_run(&m, d, size);
  fz_put(fz_in_fd, fz_in, d, size);
  fz_readers(d, size, &m);
  fz_writer(d, size, &m);
  free(m.recs);
}

/* Recompute the header crc and the crc of every record whose frame fits in the file.
 * Return 1 if that changed a byte. */
FZ_ORACLE
static int fz_fix(uint8_t *d, size_t size) {
  int changed = 0;
  if (size < ND_RFILE_HEADER) return 0;
  uint8_t c[4];
  fz_put32(c, (uint32_t)crc32(0L, d, 36));
  if (memcmp(d + 36, c, 4)) changed = 1;
  memcpy(d + 36, c, 4);
  for (size_t off = ND_RFILE_HEADER; size - off >= ND_RFILE_FRAME;) {
    const uint32_t len = fz_le32(d + off);
    if (len > size - off - ND_RFILE_FRAME) break;
    fz_put32(c, fz_crc(d + off, d + off + ND_RFILE_FRAME, len));
    if (memcmp(d + off + 8, c, 4)) changed = 1;
    memcpy(d + off + 8, c, 4);
    off += ND_RFILE_FRAME + len;
  }
  return changed;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fz_setup();
  if (!fz_one[0]) fz_make_one();
  fz_rollout(data, size);
  fz_file(data, size);
  if (size >= ND_RFILE_HEADER) {
    uint8_t *fixed = malloc(size);
    FZ_CHECK(fixed != NULL, "out of memory");
    memcpy(fixed, data, size);
    if (fz_fix(fixed, size)) fz_file(fixed, size);
    free(fixed);
  }
  return 0;
}
