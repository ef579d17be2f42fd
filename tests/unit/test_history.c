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
  assert_int_equal(buf[0], 1);                 /* encoding version */
  assert_int_equal(buf[4], 7);                 /* mask */
  assert_int_equal(buf[8], 12);                /* version, low byte first */
  assert_int_equal(buf[112], 4);               /* buffer_size */
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
  e.mask = 16;
  assert_int_equal(nd_history_check(&e, err, sizeof(err)), -1);
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

/* A put_f64 at offset off of a valid encoding. */
static void poke_f64(unsigned char *buf, int off, double v) {
  uint64_t u;
  memcpy(&u, &v, sizeof(u));
  for (int i = 0; i < 8; i++) buf[off + i] = (unsigned char)(u >> (8 * i));
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
  assert_non_null(strstr(err, "119 bytes"));
  buf[ND_HISTORY_ENC_SIZE] = 0;
  assert_int_equal(nd_history_decode(&d, buf, ND_HISTORY_ENC_SIZE + 1, err, sizeof(err)), -1);

  memcpy(buf, good, sizeof(good));
  buf[0] = 2;
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "version 2"));

  memcpy(buf, good, sizeof(good));
  buf[117] = 1;
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "reserved"));

  memcpy(buf, good, sizeof(good));
  poke_f64(buf, 40, NAN); /* mean[1] */
  assert_int_equal(nd_history_decode(&d, buf, sizeof(good), err, sizeof(err)), -1);
  assert_non_null(strstr(err, "mean: theta[1]"));

  memcpy(buf, good, sizeof(good));
  buf[115] = 0x80; /* buffer_size negative */
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
 * skipped, a torn tail ends the scan, a missing file is an empty history. */
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
  unsigned char buf[ND_HISTORY_ENC_SIZE];
  for (int v = 1; v <= 3; v++) {
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
      cmocka_unit_test(check_refuses),
      cmocka_unit_test(decode_refuses),
      cmocka_unit_test(scan_file),
  };
  return cmocka_run_group_tests(tests, setup, teardown);
}
