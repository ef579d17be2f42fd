/* test_rfile: the rollout encoding, the append-only record file and the replay buffer.
 * Round trips are bitwise; every torn prefix and every sampled bit flip of a record is
 * caught and never returned; a reader running beside a writer sees only whole records;
 * a writer killed with SIGKILL at random loses nothing it reported committed; a second
 * writer, a read-only file, an unwritable directory, a full disk and a file-size limit
 * all fail with a clear message and leave the earlier records readable. */
#define _GNU_SOURCE
#include "nd_test.h"

#include <errno.h>
#include <math.h>
#include <fcntl.h>
#include <ftw.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <zlib.h>

#include "nd_rbuf.h"
#include "nd_rfile.h"
#include "nd_rollout.h"

static char g_dir[64];  /* mkdtemp directory of this run, removed at the end */

static void path_of(char *out, size_t cap, const char *name) {
  snprintf(out, cap, "%s/%s", g_dir, name);
}

/* ---- deterministic data ---- */

static uint64_t rnd_next(uint64_t *s) {
  *s ^= *s >> 12;
  *s ^= *s << 25;
  *s ^= *s >> 27;
  return *s * 2685821657736338717ULL;
}

static double rnd_unit(uint64_t *s) { return (double)(rnd_next(s) >> 11) * 0x1p-53 * 2 - 1; }

/* A random unit quaternion (a rollout refuses others). */
static void unit_quat(double q[4], uint64_t *s) {
  double n = 0;
  for (int i = 0; i < 4; i++) q[i] = rnd_unit(s) + (i == 0 ? 2 : 0), n += q[i] * q[i];
  for (int i = 0; i < 4; i++) q[i] /= sqrt(n);
}

/* A valid rollout of n steps; includes -0.0 and a subnormal so "bitwise" means bitwise. */
static void make_rollout(nd_rollout *r, int n, uint64_t seed) {
  uint64_t s = seed * 0x9E3779B97F4A7C15ULL + 1;
  memset(r, 0, sizeof *r);
  assert_int_equal(nd_rollout_alloc(r, n), 0);
  r->task_id = (int64_t)seed * 1000 - 7;
  r->utime = 1700000000000000LL + (int64_t)seed;
  r->outcome = 1 + (int)(seed % 3);
  r->control = (int)(seed % 2);
  r->dt = 1e-3;
  for (int i = 0; i < 3; i++) r->goal[i] = rnd_unit(&s);
  const double theta[4] = {1, 0.005, 1e-4, 0.5};
  memcpy(r->theta, theta, sizeof theta);
  for (int i = 0; i < 3; i++) r->obj_pos[i] = rnd_unit(&s);
  unit_quat(r->obj_quat, &s);
  for (int i = 0; i < 6; i++) r->obj_vel[i] = rnd_unit(&s);
  for (int i = 0; i < 2; i++) r->ee_pos[i] = rnd_unit(&s), r->ee_vel[i] = rnd_unit(&s);
  for (int i = 0; i < 2 * n; i++) r->u[i] = rnd_unit(&s) * 20;
  for (int k = 0; k < n; k++) {
    double *o = nd_rollout_obj(r, k);
    for (int i = 0; i < 3; i++) o[i] = rnd_unit(&s);
    unit_quat(o + 3, &s);
  }
  for (int i = 0; i < 2 * n; i++) r->ee[i] = rnd_unit(&s);
  for (int i = 0; i < 6 * n; i++) r->sp[i] = rnd_unit(&s);
  r->u[0] = -0.0;
  r->ee[1] = 4.9e-324;
  r->sp[6 * n - 1] = -0.0;
}

static int same_bits(const void *a, const void *b, size_t n) { return memcmp(a, b, n) == 0; }

static void assert_rollout_equal(const nd_rollout *a, const nd_rollout *b) {
  assert_int_equal(a->task_id, b->task_id);
  assert_int_equal(a->utime, b->utime);
  assert_int_equal(a->outcome, b->outcome);
  assert_int_equal(a->control, b->control);
  assert_int_equal(a->n, b->n);
  assert_true(same_bits(&a->dt, &b->dt, 8));
  assert_true(same_bits(a->goal, b->goal, sizeof a->goal));
  assert_true(same_bits(a->theta, b->theta, sizeof a->theta));
  assert_true(same_bits(a->obj_pos, b->obj_pos, sizeof a->obj_pos));
  assert_true(same_bits(a->obj_quat, b->obj_quat, sizeof a->obj_quat));
  assert_true(same_bits(a->obj_vel, b->obj_vel, sizeof a->obj_vel));
  assert_true(same_bits(a->ee_pos, b->ee_pos, sizeof a->ee_pos));
  assert_true(same_bits(a->ee_vel, b->ee_vel, sizeof a->ee_vel));
  assert_true(same_bits(a->u, b->u, (size_t)a->n * 2 * 8));
  assert_true(same_bits(a->obj, b->obj, (size_t)a->n * ND_ROLLOUT_OBJ * 8));
  assert_true(same_bits(a->ee, b->ee, (size_t)a->n * 2 * 8));
  assert_true(same_bits(a->sp, b->sp, (size_t)a->n * 6 * 8));
}

/* Generic payload of record seq: its seq, its length, then bytes derived from both. */
static uint32_t payload_len(uint32_t seq) {
  uint64_t s = seq + 12345;
  rnd_next(&s);
  const uint64_t x = rnd_next(&s);
  return (x % 8 == 0) ? 65536 + (uint32_t)(x >> 8) % 200000 : 8 + (uint32_t)(x >> 8) % 6000;
}

/* Larger records for the kill test, so that a kill often lands inside the write. */
static uint32_t big_len(uint32_t seq) {
  uint64_t s = seq + 777;
  rnd_next(&s);
  return 65536 + (uint32_t)(rnd_next(&s) >> 8) % 512000;
}

#define MAX_PAYLOAD (65536 + 512000)

static void fill_payload(unsigned char *p, uint32_t seq, uint32_t len) {
  memcpy(p, &seq, 4);
  memcpy(p + 4, &len, 4);
  for (uint32_t i = 8; i < len; i++) p[i] = (unsigned char)(seq * 131u + i * 7u + (i >> 9));
}

static int payload_ok(const nd_rfile_record *rec, uint32_t seq, uint32_t (*size)(uint32_t),
                      unsigned char *scratch) {
  const uint32_t len = size(seq);
  if (rec->len != len || rec->kind != 7) return 0;
  fill_payload(scratch, seq, len);
  return memcmp(rec->data, scratch, len) == 0;
}

/* ---- files ---- */

static unsigned char *slurp(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  assert_non_null(f);
  fseek(f, 0, SEEK_END);
  *len = (size_t)ftell(f);
  fseek(f, 0, SEEK_SET);
  unsigned char *b = malloc(*len + 1);
  assert_non_null(b);
  assert_int_equal(fread(b, 1, *len, f), *len);
  fclose(f);
  return b;
}

static void spit(const char *path, const unsigned char *b, size_t len) {
  int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0640);
  assert_true(fd >= 0);
  assert_int_equal(write(fd, b, len), (ssize_t)len);
  close(fd);
}

static int64_t file_size(const char *path) {
  struct stat st;
  return stat(path, &st) ? -1 : (int64_t)st.st_size;
}

/* Write rollouts of the given step counts to path (fresh); their record offsets into
 * starts[count + 1] (the last entry is the end of the file). */
static void write_rollouts(const char *path, const int *steps, int count, nd_rollout *rs,
                           int64_t *starts) {
  char err[512];
  unlink(path);
  nd_rfile_writer w;
  nd_rfile_tail t;
  assert_int_equal(nd_rbuf_open(&w, path, &t, err, sizeof err), 0);
  assert_int_equal(t.status, ND_RFILE_END);
  assert_int_equal(t.records, 0);
  int64_t at = ND_RFILE_HEADER;
  for (int i = 0; i < count; i++) {
    make_rollout(&rs[i], steps[i], (uint64_t)i + 1);
    starts[i] = at;
    if (nd_rbuf_append(&w, &rs[i], err, sizeof err)) fail_msg("%s", err);
    at += ND_RFILE_FRAME + (int64_t)nd_rollout_encoded_size(steps[i]);
    assert_int_equal(w.end, at);
  }
  starts[count] = at;
  nd_rfile_writer_close(&w);
  assert_int_equal(file_size(path), at);
}

/* Records the generic reader returns from path: their count, each checked to be the
 * byte-identical record of orig at starts[i]. */
static int read_checked(const char *path, const unsigned char *orig, const int64_t *starts,
                        nd_rfile_tail *t) {
  char err[512];
  nd_rfile_reader rd;
  assert_int_equal(nd_rfile_reader_open(&rd, path, ND_RFILE_KIND_ROLLOUTS, err, sizeof err), 0);
  nd_rfile_record rec;
  int n = 0, k;
  while ((k = nd_rfile_next(&rd, &rec, t, err, sizeof err)) == 1) {
    assert_int_equal(rec.offset, starts[n]);
    assert_int_equal(rec.offset + ND_RFILE_FRAME + rec.len, starts[n + 1]);
    assert_true(memcmp(rec.data, orig + starts[n] + ND_RFILE_FRAME, rec.len) == 0);
    n++;
  }
  assert_int_equal(k, 0);
  nd_rfile_reader_close(&rd);
  return n;
}

/* ---- the encoding ---- */

static void put_f64(unsigned char *p, double v) {
  uint64_t b;
  memcpy(&b, &v, 8);
  for (int i = 0; i < 8; i++) p[i] = (unsigned char)(b >> (8 * i));
}

static void put_u32(unsigned char *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (unsigned char)(v >> (8 * i));
}

static void test_encoding_round_trip_and_layout(void **state) {
  (void)state;
  char err[256];
  nd_rollout r, d;
  make_rollout(&r, 37, 5);
  const size_t size = nd_rollout_encoded_size(37);
  assert_int_equal(size, 232 + 136 * 37);
  unsigned char *buf = malloc(size);
  size_t len = 0;
  assert_int_equal(nd_rollout_encode(&r, buf, size - 1, &len, err, sizeof err), -1);
  assert_non_null(strstr(err, "needs"));
  assert_int_equal(nd_rollout_encode(&r, buf, size, &len, err, sizeof err), 0);
  assert_int_equal(len, size);
  /* Little-endian at the documented offsets, whatever the host. */
  const unsigned char head[8] = {3, 0, 0, 0, 37, 0, 0, 0};
  assert_memory_equal(buf, head, 8);
  unsigned char want[8];
  put_f64(want, r.dt);
  assert_memory_equal(buf + 32, want, 8);
  put_f64(want, r.ee_vel[1]);
  assert_memory_equal(buf + 224, want, 8);
  put_f64(want, r.u[1]);
  assert_memory_equal(buf + 240, want, 8);
  put_f64(want, r.obj[7 * 36 + 6]); /* the last step's quaternion z */
  assert_memory_equal(buf + 232 + 72 * 37 - 8, want, 8);
  put_f64(want, r.ee[2 * 37 - 1]);
  assert_memory_equal(buf + 232 + 88 * 37 - 8, want, 8);
  put_f64(want, r.sp[0]);
  assert_memory_equal(buf + 232 + 88 * 37, want, 8);
  put_f64(want, r.sp[6 * 37 - 1]);
  assert_memory_equal(buf + size - 8, want, 8);
  assert_int_equal(nd_rollout_decode(&d, buf, len, err, sizeof err), 0);
  assert_rollout_equal(&r, &d);
  assert_near(nd_rollout_duration(&d), 0.037, 1e-15);
  nd_rollout_free(&d);
  assert_null(d.u);
  assert_int_equal(d.n, 0);
  nd_rollout_free(&r);
  free(buf);
}

/* Decode of buf patched by fn must fail, the message naming `field`, r left empty. */
static void expect_reject(const unsigned char *good, size_t len, size_t cut,
                          void (*patch)(unsigned char *, int), int arg, const char *field) {
  char err[256] = "";
  unsigned char *b = malloc(len);
  memcpy(b, good, len);
  if (patch) patch(b, arg);
  nd_rollout d;
  memset(&d, 0xAB, sizeof d);  /* garbage in: decode must not trust it */
  if (nd_rollout_decode(&d, b, len - cut, err, sizeof err) != -1)
    fail_msg("decode accepted a rollout with a bad %s", field);
  if (!strstr(err, field)) fail_msg("message '%s' does not name '%s'", err, field);
  assert_null(d.u);
  assert_int_equal(d.n, 0);
  free(b);
}

enum { STEPS = 9 };
static void p_nan_at(unsigned char *b, int off) { put_f64(b + off, NAN); }
static void p_inf_at(unsigned char *b, int off) { put_f64(b + off, -INFINITY); }
static void p_f64_zero(unsigned char *b, int off) { put_f64(b + off, 0.0); }
static void p_f64_neg(unsigned char *b, int off) { put_f64(b + off, -1e-3); }
static void p_u32(unsigned char *b, int v) { put_u32(b + (v >> 24), (uint32_t)(v & 0xFFFFFF)); }
static void p_n(unsigned char *b, int n) { put_u32(b + 4, (uint32_t)n); }

static void test_decode_rejects(void **state) {
  (void)state;
  char err[256];
  nd_rollout r;
  make_rollout(&r, STEPS, 9);
  unsigned char good[232 + 136 * STEPS];
  size_t len;
  assert_int_equal(nd_rollout_encode(&r, good, sizeof good, &len, err, sizeof err), 0);
  const int u0 = 232, obj0 = 232 + 16 * STEPS, ee0 = 232 + 72 * STEPS, sp0 = 232 + 88 * STEPS;
  /* not finite, named by field and index */
  expect_reject(good, len, 0, p_nan_at, 32, "dt");
  expect_reject(good, len, 0, p_nan_at, 48, "goal[1]");
  expect_reject(good, len, 0, p_inf_at, 64 + 24, "theta[3]");
  expect_reject(good, len, 0, p_nan_at, 120 + 24, "obj_quat[3]");
  expect_reject(good, len, 0, p_nan_at, 152 + 40, "obj_vel[5]");
  expect_reject(good, len, 0, p_nan_at, 216, "ee_vel[0]");
  expect_reject(good, len, 0, p_nan_at, u0 + (2 * 4 + 1) * 8, "u[4][1]");
  expect_reject(good, len, 0, p_inf_at, obj0 + (7 * (STEPS - 1) + 2) * 8, "obj[8][2]");
  expect_reject(good, len, 0, p_nan_at, obj0 + (7 * 4 + 6) * 8, "obj[4][6]");
  /* quaternions must be unit ones (within 1e-2: what MOCAP accepts) */
  expect_reject(good, len, 0, p_f64_zero, obj0 + (7 * 2 + 3) * 8, "obj quaternion[2]");
  expect_reject(good, len, 0, p_f64_neg, 120, "obj_quat = ");
  expect_reject(good, len, 0, p_nan_at, ee0, "ee[0][0]");
  expect_reject(good, len, 0, p_inf_at, sp0 + (6 * 3 + 4) * 8, "sp[3][4]");
  /* dt must be a positive step */
  expect_reject(good, len, 0, p_f64_zero, 32, "dt");
  expect_reject(good, len, 0, p_f64_neg, 32, "dt");
  /* absurd n, before anything is sized from it */
  expect_reject(good, len, 0, p_n, 0, "n = 0");
  expect_reject(good, len, 0, p_n, -1, "n = -1");
  expect_reject(good, len, 0, p_n, ND_ROLLOUT_MAX_STEPS + 1, "n = 480001");
  expect_reject(good, len, 0, p_n, 0x7fffffff, "n = 2147483647");
  /* n and the length disagree */
  expect_reject(good, len, 0, p_n, STEPS + 1, "needs exactly");
  expect_reject(good, len, 0, p_n, STEPS - 1, "needs exactly");
  expect_reject(good, len, 8, NULL, 0, "needs exactly");
  expect_reject(good, len, len - 100, NULL, 0, "shorter than");
  /* unknown enums and version */
  expect_reject(good, len, 0, p_u32, 24 << 24 | 7, "outcome = 7");
  expect_reject(good, len, 0, p_u32, 24 << 24 | 0, "outcome = 0");
  expect_reject(good, len, 0, p_u32, 28 << 24 | 2, "control = 2");
  expect_reject(good, len, 0, p_u32, 0 << 24 | 1, "version 1");
  expect_reject(good, len, 0, p_u32, 0 << 24 | 4, "version 4");
  /* the previous layout, named: its records lack the pose the replay needs */
  expect_reject(good, len, 0, p_u32, 0 << 24 | 2, "version 2 (object x, y, yaw only)");
  /* the encoder refuses what the decoder would */
  r.u[5] = NAN;
  assert_int_equal(nd_rollout_encode(&r, good, sizeof good, &len, err, sizeof err), -1);
  assert_non_null(strstr(err, "u[2][1]"));
  r.u[5] = 0;
  r.outcome = 9;
  assert_int_equal(nd_rollout_encode(&r, good, sizeof good, &len, err, sizeof err), -1);
  assert_non_null(strstr(err, "outcome"));
  nd_rollout_free(&r);
  assert_int_equal(nd_rollout_alloc(&r, -1), -1);
  assert_int_equal(nd_rollout_alloc(&r, ND_ROLLOUT_MAX_STEPS + 1), -1);
}

/* ---- the file ---- */

static void test_file_round_trip(void **state) {
  (void)state;
  char path[128], err[512];
  path_of(path, sizeof path, "round.nbuf");
  const int steps[6] = {1, 7, 100, 1000, 3, 5000};
  nd_rollout rs[6];
  int64_t starts[7];
  write_rollouts(path, steps, 6, rs, starts);
  struct stat st;
  assert_int_equal(stat(path, &st), 0);
  assert_int_equal(st.st_mode & 0027, 0);  /* created 0640 (less umask): no world access */

  nd_rollout *got;
  int n;
  nd_rfile_tail t;
  assert_int_equal(nd_rbuf_read_all(path, &got, &n, &t, err, sizeof err), 0);
  assert_int_equal(n, 6);
  for (int i = 0; i < 6; i++) assert_rollout_equal(&rs[i], &got[i]);
  assert_int_equal(t.status, ND_RFILE_END);
  assert_int_equal(t.offset, starts[6]);
  assert_int_equal(t.size, starts[6]);
  nd_rbuf_free_all(got, n);

  /* Reopening finds them all and appends after them; nothing to repair. */
  nd_rfile_writer w;
  assert_int_equal(nd_rbuf_open(&w, path, &t, err, sizeof err), 0);
  assert_int_equal(t.status, ND_RFILE_END);
  assert_int_equal(t.records, 6);
  assert_int_equal(w.end, starts[6]);
  assert_int_equal(nd_rbuf_append(&w, &rs[2], err, sizeof err), 0);
  nd_rfile_writer_close(&w);

  /* Polling reader: resumes from where it stopped, sees the new record only. */
  nd_rfile_reader rd;
  nd_rollout one;
  assert_int_equal(nd_rbuf_reader_open(&rd, path, err, sizeof err), 0);
  assert_int_equal(nd_rfile_reader_seek(&rd, starts[6], err, sizeof err), 0);
  assert_int_equal(nd_rbuf_next(&rd, &one, &t, err, sizeof err), 1);
  assert_rollout_equal(&rs[2], &one);
  nd_rollout_free(&one);
  assert_int_equal(nd_rbuf_next(&rd, &one, &t, err, sizeof err), 0);
  assert_int_equal(t.status, ND_RFILE_END);
  assert_int_equal(nd_rfile_reader_seek(&rd, 10, err, sizeof err), -1);
  nd_rfile_reader_close(&rd);

  /* A rollout the decoder would reject is never appended. */
  assert_int_equal(nd_rbuf_open(&w, path, NULL, err, sizeof err), 0);
  const int64_t end = w.end;
  rs[1].obj[8] = NAN;
  assert_int_equal(nd_rbuf_append(&w, &rs[1], err, sizeof err), -1);
  assert_non_null(strstr(err, "obj[1][1]"));
  assert_non_null(strstr(err, path));
  assert_int_equal(file_size(path), end);
  nd_rfile_writer_close(&w);
  for (int i = 0; i < 6; i++) nd_rollout_free(&rs[i]);
}

/* A sound record (crc fine) holding a bad rollout: the layer above reports it, by offset. */
static void test_undecodable_record(void **state) {
  (void)state;
  char path[128], err[512];
  path_of(path, sizeof path, "undecodable.nbuf");
  unlink(path);
  nd_rollout r;
  make_rollout(&r, 4, 3);
  unsigned char b[232 + 136 * 4];
  size_t len;
  assert_int_equal(nd_rollout_encode(&r, b, sizeof b, &len, err, sizeof err), 0);
  nd_rfile_writer w;
  assert_int_equal(nd_rbuf_open(&w, path, NULL, err, sizeof err), 0);
  assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_ROLLOUTS, b, (uint32_t)len, err, sizeof err), 0);
  put_f64(b + 232 + 8, NAN);  /* u[0][1] */
  const int64_t bad = w.end;
  assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_ROLLOUTS, b, (uint32_t)len, err, sizeof err), 0);
  nd_rfile_writer_close(&w);
  nd_rollout *got;
  int n;
  assert_int_equal(nd_rbuf_read_all(path, &got, &n, NULL, err, sizeof err), -1);
  assert_null(got);
  char want[64];
  snprintf(want, sizeof want, "offset %lld", (long long)bad);
  assert_non_null(strstr(err, want));
  assert_non_null(strstr(err, "u[0][1]"));
  nd_rollout_free(&r);
}

static void test_cut_at_every_offset(void **state) {
  (void)state;
  char path[128], orig_path[128], err[512];
  path_of(orig_path, sizeof orig_path, "cut-orig.nbuf");
  path_of(path, sizeof path, "cut.nbuf");
  const int steps[4] = {50, 2, 300, 10};
  nd_rollout rs[4], extra;
  int64_t starts[5];
  write_rollouts(orig_path, steps, 4, rs, starts);
  size_t size;
  unsigned char *orig = slurp(orig_path, &size);
  make_rollout(&extra, 6, 99);
  const int64_t last = starts[3];
  int tested = 0;
  for (int64_t cut = last; cut < (int64_t)size; cut++) {
    spit(path, orig, (size_t)cut);
    nd_rfile_tail t;
    assert_int_equal(read_checked(path, orig, starts, &t), 3);
    assert_int_equal(t.offset, last);
    assert_int_equal(t.size, cut);
    assert_int_equal(t.status, cut == last ? ND_RFILE_END : ND_RFILE_TORN);
    if (cut > last) {
      char where[64];
      snprintf(where, sizeof where, "offset %lld", (long long)last);
      assert_non_null(strstr(t.why, where));
    }
    /* The writer cuts the torn tail, says so, and its next record is readable. */
    nd_rfile_writer w;
    memset(&t, 0x5a, sizeof t);
    if (nd_rbuf_open(&w, path, &t, err, sizeof err)) fail_msg("cut %lld: %s", (long long)cut, err);
    assert_int_equal(t.status, cut == last ? ND_RFILE_END : ND_RFILE_TORN);
    assert_int_equal(t.offset, last);
    assert_int_equal(t.size, cut);
    assert_int_equal(t.records, 3);
    assert_int_equal(w.end, last);
    assert_int_equal(nd_rbuf_append(&w, &extra, err, sizeof err), 0);
    nd_rfile_writer_close(&w);
    nd_rollout *got;
    int n;
    assert_int_equal(nd_rbuf_read_all(path, &got, &n, &t, err, sizeof err), 0);
    assert_int_equal(n, 4);
    assert_int_equal(t.status, ND_RFILE_END);
    for (int i = 0; i < 3; i++) assert_rollout_equal(&rs[i], &got[i]);
    assert_rollout_equal(&extra, &got[3]);
    nd_rbuf_free_all(got, n);
    tested++;
  }
  printf("cut_offsets_tested %d count\n", tested);
  assert_int_equal(tested, (int)(size - (size_t)last));
  free(orig);
  nd_rollout_free(&extra);
  for (int i = 0; i < 4; i++) nd_rollout_free(&rs[i]);
}

/* Generic records: empty payloads, the kind range, the size limit, kind-0 files. */
static void test_generic_records(void **state) {
  (void)state;
  char path[128], err[512];
  path_of(path, sizeof path, "generic.nbuf");
  unlink(path);
  nd_rfile_writer w;
  assert_int_equal(nd_rfile_open_append(&w, path, 0, NULL, err, sizeof err), -1);
  assert_int_equal(nd_rfile_open_append(&w, path, ND_RFILE_KIND_PARAMS, NULL, err, sizeof err), 0);
  const unsigned char one = 0x42;
  assert_int_equal(nd_rfile_append(&w, 5, NULL, 0, err, sizeof err), 0);
  assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_MAX, &one, 1, err, sizeof err), 0);
  assert_int_equal(nd_rfile_append(&w, 0, &one, 1, err, sizeof err), -1);
  assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_MAX + 1, &one, 1, err, sizeof err), -1);
  assert_int_equal(nd_rfile_append(&w, 5, &one, ND_RFILE_MAX_PAYLOAD + 1, err, sizeof err), -1);
  assert_non_null(strstr(err, "out of range"));
  assert_int_equal(w.records, 2);
  assert_int_equal(w.end, ND_RFILE_HEADER + 2 * ND_RFILE_FRAME + 1);
  nd_rfile_writer_close(&w);
  /* the writer's scan agrees with the appends: nothing to cut */
  nd_rfile_tail t;
  assert_int_equal(nd_rfile_open_append(&w, path, ND_RFILE_KIND_PARAMS, &t, err, sizeof err), 0);
  assert_int_equal(t.status, ND_RFILE_END);
  assert_int_equal(t.records, 2);
  assert_int_equal(nd_rfile_append(&w, 6, &one, 0, err, sizeof err), 0);
  nd_rfile_writer_close(&w);
  nd_rfile_reader rd;
  nd_rfile_record rec;
  assert_int_equal(nd_rfile_reader_open(&rd, path, 0, err, sizeof err), 0);
  assert_int_equal(rd.kind, ND_RFILE_KIND_PARAMS);
  assert_int_equal(nd_rfile_next(&rd, &rec, &t, err, sizeof err), 1);
  assert_int_equal(rec.kind, 5);
  assert_int_equal(rec.len, 0);
  assert_int_equal(nd_rfile_next(&rd, &rec, &t, err, sizeof err), 1);
  assert_int_equal(rec.kind, ND_RFILE_KIND_MAX);
  assert_int_equal(rec.len, 1);
  assert_int_equal(rec.data[0], 0x42);
  assert_int_equal(nd_rfile_next(&rd, &rec, &t, err, sizeof err), 1);
  assert_int_equal(rec.kind, 6);
  assert_int_equal(rec.len, 0);
  assert_int_equal(nd_rfile_next(&rd, &rec, &t, err, sizeof err), 0);
  assert_int_equal(t.status, ND_RFILE_END);
  assert_int_equal(t.records, 3);
  nd_rfile_reader_close(&rd);
  /* the rollout layer names a foreign record by its offset */
  nd_rollout *got;
  int n;
  assert_int_equal(nd_rbuf_read_all(path, &got, &n, NULL, err, sizeof err), -1);
  assert_non_null(strstr(err, "expected kind 1"));
}

/* Flip bit `bit` of the file and check the record holding it is never returned. */
static void flip_case(const char *path, const unsigned char *orig, size_t size,
                      const int64_t *starts, int target, int nrec, int64_t bit, int repair,
                      int *refused, int *cut) {
  char err[512];
  unsigned char *b = malloc(size);
  memcpy(b, orig, size);
  b[bit / 8] ^= (unsigned char)(1u << (bit % 8));
  spit(path, b, size);
  nd_rfile_tail t;
  const int n = read_checked(path, orig, starts, &t);
  if (n != target)
    fail_msg("bit %lld of record %d: %d records returned, expected %d", (long long)bit,
             target, n, target);
  assert_int_equal(t.offset, starts[target]);
  assert_int_not_equal(t.status, ND_RFILE_END);
  if (repair) {
    nd_rfile_writer w;
    const int rc = nd_rbuf_open(&w, path, &t, err, sizeof err);
    if (target < nrec - 1) {
      /* damage inside the file: refused, nothing cut */
      assert_int_equal(rc, -1);
      assert_non_null(strstr(err, "refusing to cut"));
      assert_int_equal(file_size(path), (int64_t)size);
      (*refused)++;
    } else {
      assert_int_equal(rc, 0);
      assert_int_equal(w.end, starts[target]);
      assert_int_equal(file_size(path), starts[target]);
      nd_rfile_writer_close(&w);
      (*cut)++;
    }
  }
  free(b);
}

static void test_bit_flips_caught(void **state) {
  (void)state;
  char path[128], orig_path[128];
  path_of(orig_path, sizeof orig_path, "flip-orig.nbuf");
  path_of(path, sizeof path, "flip.nbuf");
  const int steps[5] = {20, 20, 20, 20, 20};
  nd_rollout rs[5];
  int64_t starts[6];
  write_rollouts(orig_path, steps, 5, rs, starts);
  size_t size;
  unsigned char *orig = slurp(orig_path, &size);
  int tried = 0, refused = 0, cut = 0;
  const int targets[2] = {2, 4};
  for (int k = 0; k < 2; k++) {
    const int target = targets[k];
    const int64_t b0 = starts[target] * 8, b1 = starts[target + 1] * 8;
    /* every bit of length, kind and crc, then payload bits at a stride coprime to 8 */
    for (int64_t bit = b0; bit < b1; bit += (bit < b0 + 96 ? 1 : 29)) {
      flip_case(path, orig, size, starts, target, 5, bit, tried % 4 == 0, &refused, &cut);
      tried++;
    }
    flip_case(path, orig, size, starts, target, 5, b1 - 1, 1, &refused, &cut);
    tried++;
  }
  printf("bit_flips_tested %d count\nflips_refused_mid_file %d count\nflips_cut_at_tail %d count\n",
         tried, refused, cut);
  assert_true(refused > 20 && cut > 20);
  free(orig);
  for (int i = 0; i < 5; i++) nd_rollout_free(&rs[i]);
}

static void test_bad_header(void **state) {
  (void)state;
  char path[128], err[512];
  path_of(path, sizeof path, "header.nbuf");
  const int steps[1] = {3};
  nd_rollout rs[1];
  int64_t starts[2];
  write_rollouts(path, steps, 1, rs, starts);
  size_t size;
  unsigned char *orig = slurp(path, &size);
  unsigned char *b = malloc(size);
  nd_rfile_reader rd;
  nd_rfile_writer w;
  /* A genuine header of a kind-2 file, to swap in whole. */
  char p2[128];
  path_of(p2, sizeof p2, "params.nbuf");
  unlink(p2);
  assert_int_equal(nd_rfile_open_append(&w, p2, ND_RFILE_KIND_PARAMS, NULL, err, sizeof err), 0);
  nd_rfile_writer_close(&w);
  size_t l2;
  unsigned char *params = slurp(p2, &l2);
  assert_int_equal(l2, ND_RFILE_HEADER);
  struct {
    int at;               /* -1: take the kind-2 header */
    unsigned char set, flip;
    const char *msg;
  } cases[] = {
      {7, 'X', 0, "starts with \"NUDGEBUX\", expected magic \"NUDGEBUF\""},
      {0, 0x7f, 0, "starts with \"\\x7fUDGEBUF\""},
      {8, 2, 0, "format version 2, this build reads version 1"},
      {12, 41, 0, "header size 41"},
      {20, 1, 0, "unknown header flags 0x1"},
      {26, 0, 0x10, "header checksum mismatch"},
      {37, 0, 0x01, "header checksum mismatch"},
      {-1, 0, 0, "holds kind 2 (parameter history), expected kind 1 (rollouts)"},
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    memcpy(b, orig, size);
    if (cases[i].at < 0)
      memcpy(b, params, ND_RFILE_HEADER);
    else if (cases[i].flip)
      b[cases[i].at] ^= cases[i].flip;
    else
      b[cases[i].at] = cases[i].set;
    if (cases[i].at == 20) put_u32(b + 36, (uint32_t)crc32(0, b, 36));  /* well-formed */
    spit(path, b, size);
    assert_int_equal(nd_rbuf_reader_open(&rd, path, err, sizeof err), -1);
    if (!strstr(err, cases[i].msg) || !strstr(err, path))
      fail_msg("reader: '%s' lacks '%s' or the path", err, cases[i].msg);
    assert_int_equal(nd_rbuf_open(&w, path, NULL, err, sizeof err), -1);
    if (!strstr(err, cases[i].msg) || !strstr(err, path))
      fail_msg("writer: '%s' lacks '%s' or the path", err, cases[i].msg);
    /* refused means untouched */
    size_t l;
    unsigned char *now = slurp(path, &l);
    assert_int_equal(l, size);
    assert_memory_equal(now, b, size);
    free(now);
  }
  /* a text file, a short one, a missing one */
  spit(path, (const unsigned char *)"x,y\n1,2\n", 8);
  assert_int_equal(nd_rbuf_reader_open(&rd, path, err, sizeof err), -1);
  assert_non_null(strstr(err, "not a nudge record file"));
  spit(path, orig, 20);
  assert_int_equal(nd_rbuf_open(&w, path, NULL, err, sizeof err), -1);
  assert_non_null(strstr(err, "header truncated: 20 of 40"));
  assert_int_equal(w.sys_errno, 0);  /* not a storage error: not a record file */
  unlink(path);
  assert_int_equal(nd_rbuf_reader_open(&rd, path, err, sizeof err), -1);
  assert_non_null(strstr(err, "No such file"));
  /* an empty file (made by touch) is the writer's to initialise */
  spit(path, orig, 0);
  assert_int_equal(nd_rbuf_open(&w, path, NULL, err, sizeof err), 0);
  assert_int_equal(nd_rbuf_append(&w, &rs[0], err, sizeof err), 0);
  nd_rfile_writer_close(&w);
  assert_int_equal(file_size(path), (int64_t)size);
  free(b);
  free(orig);
  free(params);
  nd_rollout_free(&rs[0]);
}

/* ---- processes ---- */

/* Append records seq = first, first + 1, ... of kind 7 (count of them, or forever if
 * count < 0), writing each seq to report_fd after its append returned. */
static int append_loop(const char *path, uint32_t (*size)(uint32_t), uint32_t first,
                       int count, int report_fd) {
  char err[512];
  nd_rfile_writer w;
  if (nd_rfile_open_append(&w, path, ND_RFILE_KIND_ROLLOUTS, NULL, err, sizeof err)) {
    fprintf(stderr, "child: %s\n", err);
    return 1;
  }
  unsigned char *p = malloc(MAX_PAYLOAD);
  for (uint32_t seq = first; count < 0 || seq < first + (uint32_t)count; seq++) {
    const uint32_t len = size(seq);
    fill_payload(p, seq, len);
    if (nd_rfile_append(&w, 7, p, len, err, sizeof err)) {
      fprintf(stderr, "child: %s\n", err);
      return 1;
    }
    if (report_fd >= 0 && write(report_fd, &seq, 4) != 4) return 1;
  }
  nd_rfile_writer_close(&w);
  free(p);
  return 0;
}

static void test_concurrent_reader(void **state) {
  (void)state;
  char path[128], err[512];
  path_of(path, sizeof path, "concurrent.nbuf");
  unlink(path);
  nd_rfile_writer w;  /* create it first so the reader can open it at once */
  assert_int_equal(nd_rfile_open_append(&w, path, ND_RFILE_KIND_ROLLOUTS, NULL, err, sizeof err), 0);
  nd_rfile_writer_close(&w);
  enum { COUNT = 400 };
  pid_t pid = fork();
  assert_true(pid >= 0);
  if (pid == 0) _exit(append_loop(path, payload_len, 0, COUNT, -1));
  nd_rfile_reader rd;
  assert_int_equal(nd_rfile_reader_open(&rd, path, ND_RFILE_KIND_ROLLOUTS, err, sizeof err), 0);
  unsigned char *scratch = malloc(MAX_PAYLOAD);
  uint32_t seen = 0;
  int torn = 0, corrupt = 0, empty = 0, exited = 0, status = 0;
  for (;;) {
    nd_rfile_record rec;
    nd_rfile_tail t;
    int k = nd_rfile_next(&rd, &rec, &t, err, sizeof err);
    assert_int_not_equal(k, -1);
    if (k == 1) {
      if (!payload_ok(&rec, seen, payload_len, scratch)) fail_msg("record %u wrong or out of order", seen);
      seen++;
      continue;
    }
    torn += t.status == ND_RFILE_TORN;
    corrupt += t.status == ND_RFILE_CORRUPT;
    empty += t.status == ND_RFILE_END;
    if (seen == COUNT || exited) break;  /* after exit: one more full pass was made */
    exited = waitpid(pid, &status, WNOHANG) == pid;
    struct timespec nap = {0, 20000};
    if (!exited) nanosleep(&nap, NULL);
  }
  if (!exited) assert_int_equal(waitpid(pid, &status, 0), pid);
  assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  assert_int_equal(seen, COUNT);
  printf("concurrent_records %u count\nconcurrent_polls_torn %d count\n"
         "concurrent_polls_corrupt %d count\nconcurrent_polls_at_end %d count\n",
         seen, torn, corrupt, empty);
  nd_rfile_reader_close(&rd);
  free(scratch);
}

static void test_sigkill_mid_append(void **state) {
  (void)state;
  char path[128], err[512];
  path_of(path, sizeof path, "killed.nbuf");
  unlink(path);
  unsigned char *scratch = malloc(MAX_PAYLOAD);
  uint64_t s = 2024;
  enum { ROUNDS = 20 };
  int torn_seen = 0, reported_total = 0, extra_total = 0;
  uint32_t count = 0;
  for (int round = 0; round < ROUNDS; round++) {
    int fds[2];
    assert_int_equal(pipe(fds), 0);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
      close(fds[0]);
      _exit(append_loop(path, big_len, count, -1, fds[1]));
    }
    close(fds[1]);
    uint32_t seq, reported = 0, last = count;
    int nrep = 0;
    if (round % 2 == 0) {  /* any time at all: mostly lands in fdatasync */
      struct timespec nap = {0, (long)(1000000 + rnd_next(&s) % 15000000)};
      nanosleep(&nap, NULL);
    } else {  /* within 1 ms after a commit: the next record is being built or written */
      for (int j = 1 + (int)(rnd_next(&s) % 3); j > 0 && read(fds[0], &seq, 4) == 4; j--) {
        assert_int_equal(seq, last);
        last = reported = seq + 1;
        nrep++;
      }
      struct timespec nap = {0, (long)(rnd_next(&s) % 1000000)};
      nanosleep(&nap, NULL);
    }
    kill(pid, SIGKILL);
    int status;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFSIGNALED(status));
    while (read(fds[0], &seq, 4) == 4) {
      assert_int_equal(seq, last);  /* the child commits in order */
      last = reported = seq + 1;
      nrep++;
    }
    close(fds[0]);
    /* Every reported record is there, whole and in order; maybe one more (committed
     * just before the kill, not yet reported); the tail may be torn. */
    nd_rfile_reader rd;
    if (nd_rfile_reader_open(&rd, path, ND_RFILE_KIND_ROLLOUTS, err, sizeof err)) {
      assert_int_equal(round, 0);  /* killed before it even created the file */
      continue;
    }
    nd_rfile_record rec;
    nd_rfile_tail t;
    uint32_t n = 0;
    while (nd_rfile_next(&rd, &rec, &t, err, sizeof err) == 1) {
      if (!payload_ok(&rec, n, big_len, scratch)) fail_msg("round %d: record %u damaged", round, n);
      n++;
    }
    nd_rfile_reader_close(&rd);
    if (nrep && n < reported) fail_msg("round %d: %u records, %u reported", round, n, reported);
    assert_true(n <= (nrep ? reported : count) + 1);
    torn_seen += t.status != ND_RFILE_END;
    reported_total += nrep;
    extra_total += (int)(n - (nrep ? reported : count));
    count = n;
  }
  /* the last torn tail (if any) is repaired by the next writer, which appends after it */
  nd_rfile_writer w;
  nd_rfile_tail t;
  assert_int_equal(nd_rfile_open_append(&w, path, ND_RFILE_KIND_ROLLOUTS, &t, err, sizeof err), 0);
  assert_int_equal(t.records, count);
  const uint32_t len = big_len(count);
  fill_payload(scratch, count, len);
  assert_int_equal(nd_rfile_append(&w, 7, scratch, len, err, sizeof err), 0);
  nd_rfile_writer_close(&w);
  nd_rfile_reader rd;
  assert_int_equal(nd_rfile_reader_open(&rd, path, 0, err, sizeof err), 0);
  nd_rfile_record rec;
  uint32_t n = 0;
  while (nd_rfile_next(&rd, &rec, &t, err, sizeof err) == 1) {
    assert_true(payload_ok(&rec, n, big_len, scratch));
    n++;
  }
  nd_rfile_reader_close(&rd);
  assert_int_equal(n, count + 1);
  assert_int_equal(t.status, ND_RFILE_END);
  printf("kills %d count\nkill_records_committed %u count\nkill_records_reported %d count\n"
         "kill_unreported_but_present %d count\nkill_torn_tails %d count\n",
         ROUNDS, count, reported_total, extra_total, torn_seen);
  assert_true(count > 20);
  free(scratch);
}

static void test_second_writer_refused(void **state) {
  (void)state;
  char path[128], err[512], want[96];
  path_of(path, sizeof path, "locked.nbuf");
  unlink(path);
  nd_rfile_writer w1, w2;
  assert_int_equal(nd_rfile_open_append(&w1, path, ND_RFILE_KIND_ROLLOUTS, NULL, err, sizeof err), 0);
  unsigned char p[64] = {1};
  assert_int_equal(nd_rfile_append(&w1, 3, p, sizeof p, err, sizeof err), 0);
  snprintf(want, sizeof want, "locked by another writer (pid %d)", (int)getpid());
  assert_int_equal(nd_rfile_open_append(&w2, path, ND_RFILE_KIND_ROLLOUTS, NULL, err, sizeof err), -1);
  if (!strstr(err, want) || !strstr(err, path)) fail_msg("'%s' lacks '%s'", err, want);
  assert_int_equal(w2.sys_errno, 0);  /* not a storage error: another writer has it */
  /* from another process too */
  int fds[2];
  assert_int_equal(pipe(fds), 0);
  pid_t pid = fork();
  if (pid == 0) {
    char e[512] = "";
    nd_rfile_writer w;
    int rc = nd_rfile_open_append(&w, path, ND_RFILE_KIND_ROLLOUTS, NULL, e, sizeof e);
    if (write(fds[1], e, strlen(e) + 1) < 0) _exit(2);
    _exit(rc == -1 ? 0 : 1);
  }
  close(fds[1]);
  char msg[512] = "";
  assert_true(read(fds[0], msg, sizeof msg - 1) > 0);
  close(fds[0]);
  int status;
  assert_int_equal(waitpid(pid, &status, 0), pid);
  assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  if (!strstr(msg, want)) fail_msg("child: '%s' lacks '%s'", msg, want);
  /* a reader is never blocked by the writer's lock */
  nd_rfile_reader rd;
  nd_rfile_record rec;
  assert_int_equal(nd_rfile_reader_open(&rd, path, 0, err, sizeof err), 0);
  assert_int_equal(nd_rfile_next(&rd, &rec, NULL, err, sizeof err), 1);
  assert_int_equal(rec.kind, 3);
  nd_rfile_reader_close(&rd);
  /* the lock goes with the writer */
  nd_rfile_writer_close(&w1);
  assert_int_equal(nd_rfile_open_append(&w2, path, ND_RFILE_KIND_ROLLOUTS, NULL, err, sizeof err), 0);
  assert_int_equal(w2.records, 1);
  nd_rfile_writer_close(&w2);
}

/* Two threads of one process create the same new file at once: whoever opens it, every
 * record appended lands in the one file (no writer left holding an orphaned inode). */
typedef struct {
  const char *path;
  pthread_barrier_t *go;
  int opened;
} race_arg;

static void *race_main(void *v) {
  race_arg *a = v;
  char err[512];
  nd_rfile_writer w;
  pthread_barrier_wait(a->go);
  if (nd_rfile_open_append(&w, a->path, ND_RFILE_KIND_ROLLOUTS, NULL, err, sizeof err) == 0) {
    unsigned char p[100] = {0};
    a->opened = nd_rfile_append(&w, 9, p, sizeof p, err, sizeof err) == 0;
    nd_rfile_writer_close(&w);
  } else if (!strstr(err, "locked by another writer")) {
    fprintf(stderr, "race: %s\n", err);
    a->opened = -1;
  }
  return NULL;
}

static void test_create_race(void **state) {
  (void)state;
  char path[128], err[512];
  int both = 0;
  for (int round = 0; round < 20; round++) {
    path_of(path, sizeof path, "race.nbuf");
    unlink(path);
    pthread_barrier_t go;
    pthread_barrier_init(&go, NULL, 2);
    race_arg a[2] = {{path, &go, 0}, {path, &go, 0}};
    pthread_t th[2];
    for (int i = 0; i < 2; i++) assert_int_equal(pthread_create(&th[i], NULL, race_main, &a[i]), 0);
    for (int i = 0; i < 2; i++) pthread_join(th[i], NULL);
    pthread_barrier_destroy(&go);
    assert_true(a[0].opened >= 0 && a[1].opened >= 0);
    assert_true(a[0].opened + a[1].opened >= 1);
    both += a[0].opened + a[1].opened == 2;
    nd_rfile_reader rd;
    nd_rfile_record rec;
    assert_int_equal(nd_rfile_reader_open(&rd, path, 0, err, sizeof err), 0);
    int n = 0;
    while (nd_rfile_next(&rd, &rec, NULL, err, sizeof err) == 1) n++;
    nd_rfile_reader_close(&rd);
    assert_int_equal(n, a[0].opened + a[1].opened);
  }
  printf("create_race_rounds_both_wrote %d count\n", both);
}

/* Run fn in a child; its message (through a pipe) into msg. Return its exit status. */
static int in_child(int (*fn)(const char *, char *, int), const char *arg, char *msg,
                    int cap) {
  int fds[2];
  assert_int_equal(pipe(fds), 0);
  pid_t pid = fork();
  assert_true(pid >= 0);
  if (pid == 0) {
    char m[1024] = "";
    int rc = fn(arg, m, sizeof m);
    if (write(fds[1], m, strlen(m) + 1) < 0) rc = 99;
    _exit(rc);
  }
  close(fds[1]);
  memset(msg, 0, (size_t)cap);
  int got = 0, k;
  while (got < cap - 1 && (k = (int)read(fds[0], msg + got, (size_t)(cap - 1 - got))) > 0) got += k;
  close(fds[0]);
  int status;
  assert_int_equal(waitpid(pid, &status, 0), pid);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 100 + WTERMSIG(status);
}

/* Root writes anywhere: become nobody, so permissions mean something. */
static int drop_root(char *msg, int cap) {
  if (geteuid() != 0) return 0;
  if (setgid(65534) || setuid(65534)) {
    snprintf(msg, (size_t)cap, "cannot drop root: %s", strerror(errno));
    return -1;
  }
  return 0;
}

static int child_open(const char *path, char *msg, int cap) {
  if (drop_root(msg, cap)) return 3;
  nd_rfile_writer w;
  if (nd_rbuf_open(&w, path, NULL, msg, cap) != -1) return 1;
  return w.sys_errno == EACCES ? 0 : 5;  /* callers tell storage errors by it */
}

/* A file-size limit below the end of the next record: the write stops part-way. */
static int child_fsize(const char *path, char *msg, int cap) {
  signal(SIGXFSZ, SIG_IGN);
  nd_rfile_writer w;
  if (nd_rfile_open_append(&w, path, ND_RFILE_KIND_ROLLOUTS, NULL, msg, cap)) return 1;
  const int64_t end = w.end;
  struct rlimit lim = {(rlim_t)end + 5000, (rlim_t)end + 5000};
  if (setrlimit(RLIMIT_FSIZE, &lim)) return 2;
  static unsigned char p[20000];
  if (nd_rfile_append(&w, 7, p, sizeof p, msg, cap) != -1) return 3;
  if (file_size(path) != end || w.end != end || w.sys_errno != EFBIG) return 4;
  /* the writer goes on once the record fits */
  char e2[256];
  if (nd_rfile_append(&w, 7, p, 1000, e2, sizeof e2) || w.sys_errno != 0) return 5;
  nd_rfile_writer_close(&w);
  return 0;
}

/* A full file system: a private tmpfs of 64 KiB in a private mount namespace. */
static int child_enospc(const char *dir, char *msg, int cap) {
  if (unshare(CLONE_NEWNS) || mount(NULL, "/", NULL, MS_REC | MS_PRIVATE, NULL) ||
      mount("tmpfs", dir, "tmpfs", 0, "size=64k,mode=0700")) {
    snprintf(msg, (size_t)cap, "skip: no private tmpfs (%s)", strerror(errno));
    return 0;
  }
  char path[256], err[512];
  snprintf(path, sizeof path, "%s/full.nbuf", dir);
  nd_rfile_writer w;
  if (nd_rfile_open_append(&w, path, ND_RFILE_KIND_ROLLOUTS, NULL, msg, cap)) return 1;
  static unsigned char p[10000];
  int ok = 0;
  while (ok < 100 && nd_rfile_append(&w, 7, p, sizeof p, err, sizeof err) == 0) ok++;
  const int64_t end = w.end;
  const int why = w.sys_errno;
  nd_rfile_writer_close(&w);
  snprintf(msg, (size_t)cap, "%s", err);
  if (ok == 0 || ok == 100 || file_size(path) != end || why != ENOSPC) return 2;
  nd_rfile_reader rd;
  nd_rfile_record rec;
  nd_rfile_tail t;
  if (nd_rfile_reader_open(&rd, path, 0, err, sizeof err)) return 3;
  int n = 0;
  while (nd_rfile_next(&rd, &rec, &t, err, sizeof err) == 1) n++;
  nd_rfile_reader_close(&rd);
  if (n != ok || t.status != ND_RFILE_END) return 4;
  umount(dir);
  return 0;
}

static void test_unwritable(void **state) {
  (void)state;
  char dir[128], path[160], newpath[160], err[512], msg[1024];
  path_of(dir, sizeof dir, "perm");
  mkdir(dir, 0755);
  snprintf(path, sizeof path, "%s/ro.nbuf", dir);
  unlink(path);
  const int steps[2] = {4, 5};
  nd_rollout rs[2];
  int64_t starts[3];
  write_rollouts(path, steps, 2, rs, starts);
  assert_int_equal(chmod(g_dir, 0711), 0);

  /* read-only file */
  assert_int_equal(chmod(path, 0444), 0);
  assert_int_equal(in_child(child_open, path, msg, sizeof msg), 0);
  if (!strstr(msg, path) || !strstr(msg, "Permission denied"))
    fail_msg("read-only file: '%s'", msg);
  printf("read-only file: %s\n", msg);
  /* unwritable directory */
  assert_int_equal(chmod(dir, 0555), 0);
  snprintf(newpath, sizeof newpath, "%s/new.nbuf", dir);
  assert_int_equal(in_child(child_open, newpath, msg, sizeof msg), 0);
  if (!strstr(msg, newpath) || !strstr(msg, "cannot create") ||
      !strstr(msg, "Permission denied"))
    fail_msg("unwritable dir: '%s'", msg);
  printf("unwritable dir: %s\n", msg);
  assert_int_equal(chmod(dir, 0755), 0);
  assert_int_equal(chmod(path, 0640), 0);
  assert_int_equal(chmod(g_dir, 0700), 0);

  /* a write stopped part-way (file-size limit): cut back, earlier records intact */
  assert_int_equal(in_child(child_fsize, path, msg, sizeof msg), 0);
  if (!strstr(msg, path) || !strstr(msg, "File too large") || !strstr(msg, "after 5000") ||
      !strstr(msg, "earlier records intact"))
    fail_msg("file-size limit: '%s'", msg);
  printf("size limit: %s\n", msg);

  /* a full file system */
  char full[160];
  path_of(full, sizeof full, "full");
  mkdir(full, 0700);
  const int rc = in_child(child_enospc, full, msg, sizeof msg);
  if (rc) fail_msg("full disk: child %d: '%s'", rc, msg);
  if (strncmp(msg, "skip", 4) != 0 && !strstr(msg, "No space left on device"))
    fail_msg("full disk: '%s'", msg);
  printf("full disk: %s\n", msg);
  rmdir(full);

  /* a bad descriptor under the writer: refused, and the writer then refuses to go on */
  nd_rfile_writer w;
  assert_int_equal(nd_rbuf_open(&w, path, NULL, err, sizeof err), 0);
  int ro = open("/dev/null", O_RDONLY);
  assert_true(ro >= 0);
  assert_int_equal(dup2(ro, w.fd), w.fd);
  close(ro);
  assert_int_equal(nd_rbuf_append(&w, &rs[0], err, sizeof err), -1);
  assert_non_null(strstr(err, "Bad file descriptor"));
  nd_rfile_writer_close(&w);

  /* after all that: the two rollouts and the one small record from the size test */
  nd_rfile_reader rd;
  nd_rollout r;
  nd_rfile_record rec;
  nd_rfile_tail t;
  assert_int_equal(nd_rbuf_reader_open(&rd, path, err, sizeof err), 0);
  for (int i = 0; i < 2; i++) {
    assert_int_equal(nd_rbuf_next(&rd, &r, &t, err, sizeof err), 1);
    assert_rollout_equal(&rs[i], &r);
    nd_rollout_free(&r);
  }
  assert_int_equal(nd_rfile_next(&rd, &rec, &t, err, sizeof err), 1);
  assert_int_equal(rec.len, 1000);
  assert_int_equal(nd_rfile_next(&rd, &rec, &t, err, sizeof err), 0);
  assert_int_equal(t.status, ND_RFILE_END);
  nd_rfile_reader_close(&rd);
  for (int i = 0; i < 2; i++) nd_rollout_free(&rs[i]);
}

/* ---- set-up ---- */

static int rm_entry(const char *p, const struct stat *sb, int flag, struct FTW *ftw) {
  (void)sb, (void)flag, (void)ftw;
  return remove(p);
}

static int setup(void **state) {
  (void)state;
  snprintf(g_dir, sizeof g_dir, "/tmp/nd_rfile_XXXXXX");
  return mkdtemp(g_dir) ? 0 : -1;
}

static int teardown(void **state) {
  (void)state;
  return nftw(g_dir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_encoding_round_trip_and_layout),
      cmocka_unit_test(test_decode_rejects),
      cmocka_unit_test(test_file_round_trip),
      cmocka_unit_test(test_undecodable_record),
      cmocka_unit_test(test_generic_records),
      cmocka_unit_test(test_cut_at_every_offset),
      cmocka_unit_test(test_bit_flips_caught),
      cmocka_unit_test(test_bad_header),
      cmocka_unit_test(test_concurrent_reader),
      cmocka_unit_test(test_sigkill_mid_append),
      cmocka_unit_test(test_second_writer_refused),
      cmocka_unit_test(test_create_race),
      cmocka_unit_test(test_unwritable),
  };
  return cmocka_run_group_tests(tests, setup, teardown);
}
