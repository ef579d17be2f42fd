/* nd_history: the adapter's parameter history entries and reading a history file. */
#include "nd_test.h"

#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "nd_history.h"

static nd_history_entry sample(int64_t version) {
  nd_history_entry e;
  memset(&e, 0, sizeof(e));
  e.version = version;
  e.utime = 1795496793843818 + version;
  e.buffer_created = 1795496793000000;
  e.mask = 7;
  const double mean[4] = {0.812345678901234, 0.0049, 1.05e-4, 1.0};
  const double std[4] = {0.0187, 5.41e-4, 6.25e-6, 0.0};
  memcpy(e.mean, nd_theta_true, sizeof(e.mean)); /* the box as built */
  memcpy(e.mean, mean, sizeof(mean));
  memcpy(e.std, std, sizeof(std));
  e.loss = 1.0851234e-2;
  e.fit_time = 3.25;
  e.buffer_size = 4;
  return e;
}

/* Every field comes back bit for bit, at the documented offsets, little-endian. */
static void round_trip(void **state) {
  (void)state;
  nd_history_entry e = sample(12), d;
  unsigned char buf[ND_HISTORY_ENC_SIZE];
  char err[256];
  assert_int_equal(nd_history_encode(&e, buf, err, sizeof(err)), 0);
  assert_int_equal(buf[0], 2);                 /* encoding version */
  assert_int_equal(buf[4], 7);                 /* mask */
  assert_int_equal(buf[8], 12);                /* version, low byte first */
  assert_int_equal(buf[160], 4);               /* buffer_size */
  assert_int_equal(buf[32 + 8 * 4 + 7], 0x3f); /* mean[4] = 1.0, sign and exponent last */
  assert_int_equal(buf[32 + 8 * 4 + 6], 0xf0);
  assert_int_equal(nd_history_decode(&d, buf, sizeof(buf), err, sizeof(err)), 0);
  assert_int_equal(d.version, 12);
  assert_int_equal(d.utime, e.utime);
  assert_int_equal(d.buffer_created, e.buffer_created);
  assert_int_equal(d.mask, 7);
  assert_int_equal(d.buffer_size, 4);
  assert_memory_equal(d.mean, e.mean, sizeof(e.mean));
  assert_memory_equal(d.std, e.std, sizeof(e.std));
  assert_memory_equal(&d.loss, &e.loss, sizeof(double));
  assert_memory_equal(&d.fit_time, &e.fit_time, sizeof(double));
}

/* A read-back value at offset off of an encoding, little-endian. */
static double peek_f64(const unsigned char *buf, int off) {
  uint64_t u = 0;
  for (int i = 0; i < 8; i++) u |= (uint64_t)buf[off + i] << (8 * i);
  double v;
  memcpy(&v, &u, sizeof(v));
  return v;
}

/* The box's entries, fitted and away from the box as built, come back bit for bit, at
 * their offsets in version 2. */
static void round_trip_box(void **state) {
  (void)state;
  nd_history_entry e = sample(5), d;
  e.mask = 0x7f;
  e.mean[ND_TH_BOX_SCALE] = 1.1;
  e.mean[ND_TH_COM_X] = 0.008;
  e.mean[ND_TH_COM_Y] = -0.004;
  e.std[ND_TH_MASS] = 0.02;
  e.std[ND_TH_BOX_SCALE] = 0.05;
  e.std[ND_TH_COM_X] = 1.5e-3;
  e.std[ND_TH_COM_Y] = 2.5e-3;
  unsigned char buf[ND_HISTORY_ENC_SIZE];
  char err[256];
  assert_int_equal(nd_history_encode(&e, buf, err, sizeof(err)), 0);
  assert_int_equal(buf[4], 0x7f);
  for (int i = 0; i < ND_NTHETA; i++) {
    const double m = peek_f64(buf, 32 + 8 * i), s = peek_f64(buf, 88 + 8 * i);
    assert_memory_equal(&m, &e.mean[i], sizeof(double));
    assert_memory_equal(&s, &e.std[i], sizeof(double));
  }
  const double loss = peek_f64(buf, 144), fit_time = peek_f64(buf, 152);
  assert_memory_equal(&loss, &e.loss, sizeof(double));
  assert_memory_equal(&fit_time, &e.fit_time, sizeof(double));
  assert_int_equal(buf[164] | buf[165] | buf[166] | buf[167], 0); /* reserved */

  assert_int_equal(nd_history_decode(&d, buf, sizeof(buf), err, sizeof(err)), 0);
  assert_int_equal(d.mask, 0x7f);
  assert_int_equal(d.version, 5);
  assert_int_equal(d.utime, e.utime);
  assert_int_equal(d.buffer_created, e.buffer_created);
  assert_int_equal(d.buffer_size, e.buffer_size);
  assert_memory_equal(d.mean, e.mean, sizeof(e.mean));
  assert_memory_equal(d.std, e.std, sizeof(e.std));
  assert_memory_equal(&d.loss, &e.loss, sizeof(double));
  assert_memory_equal(&d.fit_time, &e.fit_time, sizeof(double));
  unsigned char again[ND_HISTORY_ENC_SIZE];
  assert_int_equal(nd_history_encode(&d, again, err, sizeof(err)), 0);
  assert_memory_equal(again, buf, sizeof(buf));
}

static void put_le(unsigned char *p, uint64_t v, int n) {
  for (int i = 0; i < n; i++) p[i] = (unsigned char)(v >> (8 * i));
}

static void put_f64_le(unsigned char *p, double d) {
  uint64_t u;
  memcpy(&u, &d, sizeof(u));
  put_le(p, u, 8);
}

/* A version-1 entry as earlier builds wrote it, byte by byte: 120 bytes, mean[4] at 32,
 * std[4] at 64, loss 96, fit_time 104, buffer_size 112, reserved 116. */
static const double v1_mean[4] = {0.75, 0.0061, 9.5e-5, 1.25};
static const double v1_std[4] = {0.031, 7.5e-4, 0.0, 0.12};

static void v1_payload(unsigned char p[ND_HISTORY_ENC_SIZE_V1], uint32_t mask,
                       int64_t version) {
  memset(p, 0xee, ND_HISTORY_ENC_SIZE_V1);
  put_le(p + 0, 1, 4);                     /* encoding version */
  put_le(p + 4, mask, 4);
  put_le(p + 8, (uint64_t)version, 8);
  put_le(p + 16, 1795496793843818LL, 8);   /* utime */
  put_le(p + 24, 1795496793000000LL, 8);   /* buffer_created */
  for (int i = 0; i < ND_NTHETA_PAPER; i++) {
    put_f64_le(p + 32 + 8 * i, v1_mean[i]);
    put_f64_le(p + 64 + 8 * i, v1_std[i]);
  }
  put_f64_le(p + 96, 2.5e-3);              /* loss */
  put_f64_le(p + 104, 4.75);               /* fit_time */
  put_le(p + 112, 9, 4);                   /* buffer_size */
  put_le(p + 116, 0, 4);                   /* reserved */
}

/* v2, the version-2 encoding of a decoded version-1 entry, carries v1's fields unchanged,
 * and the box as built, held, in between. */
static void assert_v2_of_v1(const unsigned char *v2, const unsigned char *v1) {
  assert_int_equal(v2[0], 2);
  assert_memory_equal(v2 + 4, v1 + 4, 60);    /* header, mean[0..3] */
  assert_memory_equal(v2 + 88, v1 + 64, 32);  /* std[0..3] */
  assert_memory_equal(v2 + 144, v1 + 96, 24); /* loss, fit_time, buffer_size, reserved */
  for (int i = ND_NTHETA_PAPER; i < ND_NTHETA; i++) {
    const double m = peek_f64(v2, 32 + 8 * i), s = peek_f64(v2, 88 + 8 * i), zero = 0.0;
    assert_memory_equal(&m, &nd_theta_true[i], sizeof(double));
    assert_memory_equal(&s, &zero, sizeof(double));
  }
}

/* A version-1 entry still decodes: its four entries fill theta[0..3], the box's are the
 * box as built, held (std 0); its fit mask stays within the paper's four. Encoding it
 * again writes version 2, which decodes to the same entry. */
static void decode_v1(void **state) {
  (void)state;
  unsigned char p[ND_HISTORY_ENC_SIZE_V1];
  nd_history_entry d, d2;
  char err[256];
  v1_payload(p, 0xb, 41); /* slide, torsion, mass */
  assert_int_equal(nd_history_decode(&d, p, sizeof(p), err, sizeof(err)), 0);
  assert_int_equal(d.mask, 0xb);
  assert_int_equal(d.version, 41);
  assert_int_equal(d.utime, 1795496793843818LL);
  assert_int_equal(d.buffer_created, 1795496793000000LL);
  assert_int_equal(d.buffer_size, 9);
  assert_memory_equal(d.mean, v1_mean, sizeof(v1_mean));
  assert_memory_equal(d.std, v1_std, sizeof(v1_std));
  const double zero[ND_NTHETA - ND_NTHETA_PAPER] = {0};
  assert_memory_equal(d.mean + ND_NTHETA_PAPER, nd_theta_true + ND_NTHETA_PAPER, sizeof(zero));
  assert_memory_equal(d.std + ND_NTHETA_PAPER, zero, sizeof(zero));
  assert_true(d.mean[ND_TH_BOX_SCALE] == 1.0 && d.mean[ND_TH_COM_X] == 0.0 &&
              d.mean[ND_TH_COM_Y] == 0.0);
  const double loss = 2.5e-3, fit_time = 4.75;
  assert_memory_equal(&d.loss, &loss, sizeof(double));
  assert_memory_equal(&d.fit_time, &fit_time, sizeof(double));

  unsigned char buf[ND_HISTORY_ENC_SIZE];
  assert_int_equal(nd_history_encode(&d, buf, err, sizeof(err)), 0);
  assert_v2_of_v1(buf, p);
  assert_int_equal(nd_history_decode(&d2, buf, sizeof(buf), err, sizeof(err)), 0);
  assert_memory_equal(d2.mean, d.mean, sizeof(d.mean));
  assert_memory_equal(d2.std, d.std, sizeof(d.std));
  assert_int_equal(d2.mask, d.mask);

  /* A mask of the box's entries is no version-1 entry (valid in version 2). */
  v1_payload(p, 0x1b, 41);
  assert_int_equal(nd_history_decode(&d, p, sizeof(p), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "fit mask 27"));
  assert_non_null(strstr(err, "[1, 15]"));
  v1_payload(p, 0, 41);
  assert_int_equal(nd_history_decode(&d, p, sizeof(p), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "fit mask 0"));

  /* The same checks as version 2 otherwise. */
  v1_payload(p, 0xb, 41);
  p[119] = 1;
  assert_int_equal(nd_history_decode(&d, p, sizeof(p), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "reserved"));
  v1_payload(p, 0xb, 41);
  put_f64_le(p + 64 + 8 * 2, 0.1); /* std[2] of a held parameter */
  assert_int_equal(nd_history_decode(&d, p, sizeof(p), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "std[2]"));
  v1_payload(p, 0xb, 41);
  put_f64_le(p + 32 + 8 * 3, -1.0); /* a negative sphere mass */
  assert_int_equal(nd_history_decode(&d, p, sizeof(p), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[3]"));

  /* Each version only at its own length. */
  v1_payload(p, 0xb, 41);
  p[0] = 2;
  assert_int_equal(nd_history_decode(&d, p, sizeof(p), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "version 2 in 120 bytes"));
  nd_history_entry e = sample(2);
  assert_int_equal(nd_history_encode(&e, buf, err, sizeof(err)), 0);
  buf[0] = 1;
  assert_int_equal(nd_history_decode(&d, buf, sizeof(buf), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "version 1 in 168 bytes"));

  /* Every single flipped bit: refused, or decoded into a valid entry that version 2
   * carries unchanged. */
  unsigned char good[ND_HISTORY_ENC_SIZE_V1];
  v1_payload(good, 0xb, 41);
  int refused = 0;
  for (int bit = 0; bit < 8 * ND_HISTORY_ENC_SIZE_V1; bit++) {
    memcpy(p, good, sizeof(p));
    p[bit / 8] ^= (unsigned char)(1u << (bit % 8));
    if (nd_history_decode(&d, p, sizeof(p), err, sizeof(err))) {
      refused++;
      continue;
    }
    assert_int_equal(nd_history_encode(&d, buf, err, sizeof(err)), 0);
    assert_v2_of_v1(buf, p);
  }
  assert_true(refused > 64);
}

/* Each invalid value is refused by the encoder, naming the field. */
static void check_refuses(void **state) {
  (void)state;
  char err[256];
  unsigned char buf[ND_HISTORY_ENC_SIZE];
  nd_history_entry e;

  e = sample(1);
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), 0);
  e.mask = 0;
  assert_int_equal(nd_history_encode(&e, buf, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mask"));
  e = sample(1);
  e.mask = 0x7f; /* all of theta fitted: the held sphere mass's std 0 is still valid */
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), 0);
  e.mask = 0x80;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "fit mask 128: must be in [1, 127]"));
  e = sample(0);
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "version"));
  e = sample(1);
  e.utime = 0;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "utime"));
  e = sample(1);
  e.mean[0] = NAN;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[0]"));
  e = sample(1);
  e.mean[3] = 0.0; /* a massless sphere */
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[3]"));
  e = sample(1);
  e.mean[1] = -1e-9;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  e = sample(1);
  e.std[2] = -1.0;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "std[2]"));
  e = sample(1);
  e.std[3] = 0.1; /* mass is held (mask 7): its std must be 0 */
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "std[3]"));
  e = sample(1);
  e.std[ND_TH_COM_X] = 1e-3; /* a held box entry */
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "std[5]"));
  e = sample(1);
  e.mean[ND_TH_BOX_SCALE] = 0.0;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[4]"));
  e = sample(1);
  e.mean[ND_TH_COM_Y] = -0.004; /* a shift may be negative */
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), 0);
  e.mean[ND_TH_COM_Y] = -1.0;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[6]"));
  e = sample(1);
  e.loss = INFINITY;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "loss"));
  e = sample(1);
  e.fit_time = -0.5;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "fit_time"));
  e = sample(1);
  e.buffer_size = 0;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "buffer_size"));
}

/* The decoder refuses wrong lengths, versions, reserved bits and every value the
 * encoder would refuse. */
static void decode_refuses(void **state) {
  (void)state;
  nd_history_entry e = sample(3), d;
  unsigned char good[ND_HISTORY_ENC_SIZE], buf[ND_HISTORY_ENC_SIZE + 1];
  char err[256];
  assert_int_equal(nd_history_encode(&e, good, err, sizeof(err)), 0);

  memcpy(buf, good, sizeof(good));
  assert_int_equal(nd_history_decode(&d, buf, ND_HISTORY_ENC_SIZE - 1, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "167 bytes"));
  buf[ND_HISTORY_ENC_SIZE] = 0;
  assert_int_equal(nd_history_decode(&d, buf, ND_HISTORY_ENC_SIZE + 1, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "169 bytes"));
  assert_int_equal(nd_history_decode(&d, buf, 0, err, sizeof(err)), -1);

  memcpy(buf, good, sizeof(good));
  buf[0] = 3;
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "version 3"));
  buf[0] = 0;
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "version 0"));

  memcpy(buf, good, sizeof(good));
  buf[165] = 1;
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "reserved"));

  memcpy(buf, good, sizeof(good));
  put_f64_le(buf + 40, NAN); /* mean[1] */
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[1]"));

  memcpy(buf, good, sizeof(good));
  put_f64_le(buf + 32 + 8 * ND_TH_COM_X, 0.5); /* a shift out of the box */
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[5]"));

  memcpy(buf, good, sizeof(good));
  put_f64_le(buf + 88 + 8 * ND_TH_BOX_SCALE, 0.1); /* std of the held box scale */
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "std[4]"));

  memcpy(buf, good, sizeof(good));
  buf[4] = 0x80; /* fit mask beyond theta */
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "fit mask 128"));

  memcpy(buf, good, sizeof(good));
  buf[163] = 0x80; /* buffer_size negative */
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "buffer_size"));

  memcpy(buf, good, sizeof(good));
  buf[15] = 0x80; /* version negative */
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "version"));

  /* Every single flipped bit: refused, or decoded into a valid entry that differs. */
  int refused = 0;
  for (int bit = 0; bit < 8 * ND_HISTORY_ENC_SIZE; bit++) {
    memcpy(buf, good, sizeof(good));
    buf[bit / 8] ^= (unsigned char)(1u << (bit % 8));
    if (nd_history_decode(&d, buf, sizeof(good), err, sizeof(err))) {
      refused++;
      continue;
    }
    assert_int_equal(nd_history_check(&d, err, sizeof(err)), 0);
    unsigned char again[ND_HISTORY_ENC_SIZE];
    assert_int_equal(nd_history_encode(&d, again, err, sizeof(err)), 0);
    assert_memory_equal(again, buf, sizeof(again));
  }
  /* The version, reserved, sign and exponent bits at least. */
  assert_true(refused > 64);
}

static char dir[] = "/tmp/nd_test_history_XXXXXX";

/* A history file: the entry with the highest version wins, bad entries are counted and
 * skipped, a torn tail ends the scan, a missing file is an empty history. A file begun in
 * version 1 and continued in version 2 reads as one history. */
static void scan_file(void **state) {
  (void)state;
  char path[256], err[512];
  snprintf(path, sizeof(path), "%s/h.history", dir);
  nd_history_summary s;
  assert_int_equal(nd_history_scan(path, &s, err, sizeof(err)), 0);
  assert_int_equal(s.entries, 0);
  assert_int_equal(s.have_last, 0);

  nd_rfile_writer w;
  nd_rfile_tail repair;
  assert_int_equal(nd_rfile_open_append(&w, path, ND_RFILE_KIND_PARAMS, &repair, err,
                                        sizeof(err)), 0);
  unsigned char buf[ND_HISTORY_ENC_SIZE], v1[ND_HISTORY_ENC_SIZE_V1];
  v1_payload(v1, 0xb, 1);
  assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_PARAMS, v1, sizeof(v1), err,
                                   sizeof(err)), 0);
  for (int v = 2; v <= 3; v++) {
    nd_history_entry e = sample(v);
    e.buffer_size = v;
    assert_int_equal(nd_history_encode(&e, buf, err, sizeof(err)), 0);
    assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_PARAMS, buf, sizeof(buf), err,
                                     sizeof(err)), 0);
  }
  /* A sound frame whose payload is no entry, then one more good entry. */
  const char junk[] = "not a history entry";
  assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_PARAMS, junk, sizeof(junk), err,
                                   sizeof(err)), 0);
  nd_history_entry e4 = sample(4);
  e4.buffer_size = 4;
  e4.mean[0] = 0.9;
  assert_int_equal(nd_history_encode(&e4, buf, err, sizeof(err)), 0);
  assert_int_equal(nd_rfile_append(&w, ND_RFILE_KIND_PARAMS, buf, sizeof(buf), err,
                                   sizeof(err)), 0);
  const int64_t end = w.end;
  nd_rfile_writer_close(&w);

  assert_int_equal(nd_history_scan(path, &s, err, sizeof(err)), 0);
  assert_int_equal(s.entries, 4);
  assert_int_equal(s.bad, 1);
  assert_non_null(strstr(s.first_bad, "20 bytes"));
  assert_int_equal(s.have_last, 1);
  assert_int_equal(s.last.version, 4);
  assert_int_equal(s.last.buffer_size, 4);
  assert_near(s.last.mean[0], 0.9, 0.0);
  assert_near(s.last.mean[ND_TH_BOX_SCALE], 1.0, 0.0);
  assert_int_equal(s.tail.status, ND_RFILE_END);
  assert_int_equal(s.tail.offset, end);

  /* Half an entry appended by a crashed writer: the scan stops before it. */
  FILE *f = fopen(path, "ab");
  assert_non_null(f);
  const unsigned char half[20] = {ND_HISTORY_ENC_SIZE, 0, 0, 0, 2, 0, 0, 0};
  assert_int_equal(fwrite(half, 1, sizeof(half), f), sizeof(half));
  fclose(f);
  assert_int_equal(nd_history_scan(path, &s, err, sizeof(err)), 0);
  assert_int_equal(s.entries, 4);
  assert_int_equal(s.last.version, 4);
  assert_int_equal(s.tail.status, ND_RFILE_TORN);
  assert_int_equal(s.tail.offset, end);

  /* A replay buffer is no history. */
  char other[256];
  snprintf(other, sizeof(other), "%s/b.nrb", dir);
  assert_int_equal(nd_rfile_open_append(&w, other, ND_RFILE_KIND_ROLLOUTS, &repair, err,
                                        sizeof(err)), 0);
  nd_rfile_writer_close(&w);
  assert_int_equal(nd_history_scan(other, &s, err, sizeof(err)), -1);
  unlink(other);
  unlink(path);
}

static int setup(void **state) {
  (void)state;
  return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state) {
  (void)state;
  return rmdir(dir);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(round_trip),
      cmocka_unit_test(round_trip_box),
      cmocka_unit_test(decode_v1),
      cmocka_unit_test(check_refuses),
      cmocka_unit_test(decode_refuses),
      cmocka_unit_test(scan_file),
  };
  return cmocka_run_group_tests(tests, setup, teardown);
}
