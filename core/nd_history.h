/* nd_history: the adapter's parameter history, one entry per refit, as records of kind
 * ND_RFILE_KIND_PARAMS in an nd_rfile of the same kind (see nd_rfile.h for the framing).
 * A restarted adapter reads its last entry and goes on from there: version numbering and
 * the CEM distribution continue.
 *
 * Entry encoding (the record payload), version 1, every field little-endian, doubles as
 * IEEE-754 binary64 bit patterns (bitwise round trip), exactly 120 bytes:
 *
 *   offset  size  field
 *        0     4  u32 encoding version (1)
 *        4     4  u32 fit mask: bit i set when theta[i] is fitted (1..15)
 *        8     8  i64 version, >= 1, +1 per refit (params_t.version)
 *       16     8  i64 utime, when the refit ended, microseconds since the epoch (> 0)
 *       24     8  i64 buffer_created: creation time in the replay buffer's file header
 *                     (tells one buffer from another; >= 0)
 *       32    32  f64 mean[4]: a valid theta (nd_theta_check)
 *       64    32  f64 std[4]: finite, >= 0; 0 for a held parameter
 *       96     8  f64 loss: L(mean) on the buffer, finite, >= 0
 *      104     8  f64 fit_time, s, finite, >= 0
 *      112     4  i32 buffer_size: rollouts the refit used, >= 1
 *      116     4  u32 reserved (0)
 *
 * Decoding refuses anything encoding would not write, so a fuzzer that gets past the
 * decoder has produced a valid entry. */
#ifndef ND_HISTORY_H
#define ND_HISTORY_H

#include <stddef.h>
#include <stdint.h>

#include "nd_rfile.h"
#include "nd_theta.h"

#define ND_HISTORY_ENC_VERSION 1
#define ND_HISTORY_ENC_SIZE 120

typedef struct {
  int64_t version;
  int64_t utime;
  int64_t buffer_created;
  uint32_t mask;
  double mean[ND_NTHETA];
  double std[ND_NTHETA];
  double loss;
  double fit_time;
  int32_t buffer_size;
} nd_history_entry;

/* 0 if e is valid (see the table above), else -1 naming the first bad field. */
int nd_history_check(const nd_history_entry *e, char *err, int errlen);

/* Encode a valid e into buf. Return 0, or -1 with a message (e invalid, nothing written). */
int nd_history_encode(const nd_history_entry *e, unsigned char buf[ND_HISTORY_ENC_SIZE],
                       char *err, int errlen);

/* Decode len bytes into e. Return 0, or -1 with a message naming the field (wrong length
 * or version, reserved bits set, a value out of range); e is then unspecified. */
int nd_history_decode(nd_history_entry *e, const unsigned char *buf, size_t len, char *err,
                       int errlen);

/* What a history file holds. */
typedef struct {
  int64_t entries;            /* valid entries */
  int64_t bad;                /* sound records that are no valid entry (skipped) */
  int have_last;
  nd_history_entry last;     /* the valid entry with the highest version */
  nd_rfile_tail tail;         /* where the valid records end, and why */
  char first_bad[256];        /* why the first bad record was refused, "" if none */
} nd_history_summary;

/* Read every record of the history file at path. A missing file is an empty history
 * (return 0, entries 0). Return 0, or -1 with a message if the file exists but cannot be
 * read as a parameter history (wrong kind, corrupt header, I/O error). */
int nd_history_scan(const char *path, nd_history_summary *s, char *err, int errlen);

#endif
