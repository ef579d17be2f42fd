/* nd_history: the adapter's parameter history, one entry per refit, as records of kind
 * ND_RFILE_KIND_PARAMS in an nd_rfile of the same kind (see nd_rfile.h for the framing).
 * A restarted adapter reads its last entry and goes on from there: version numbering and
 * the CEM distribution continue.
 *
 * Entry encoding (the record payload), version 2, every field little-endian, doubles as
 * IEEE-754 binary64 bit patterns (bitwise round trip), exactly 168 bytes:
 *
 *   offset  size  field
 *        0     4  u32 encoding version (2)
 *        4     4  u32 fit mask: bit i set when theta[i] is fitted (1..127)
 *        8     8  i64 version, >= 1, +1 per refit (params_t.version)
 *       16     8  i64 utime, when the refit ended, microseconds since the epoch (> 0)
 *       24     8  i64 buffer_created: creation time in the replay buffer's file header
 *                     (tells one buffer from another; >= 0)
 *       32    56  f64 mean[7] (ND_NTHETA, nd_theta.h's order): a valid theta (nd_theta_check)
 *       88    56  f64 std[7]: finite, >= 0; 0 for a held parameter
 *      144     8  f64 loss: L(mean) on the buffer, finite, >= 0
 *      152     8  f64 fit_time, s, finite, >= 0
 *      160     4  i32 buffer_size: the buffer's rollouts up to the newest the refit used, >= 1
 *      164     4  u32 reserved (0)
 *
 * Version 1, exactly 120 bytes, holds the paper's ND_NTHETA_PAPER entries only: the same
 * first 32 bytes (encoding version 1, fit mask 1..15), then
 *
 *       32    32  f64 mean[4]
 *       64    32  f64 std[4]
 *       96     8  f64 loss
 *      104     8  f64 fit_time
 *      112     4  i32 buffer_size
 *      116     4  u32 reserved (0)
 *
 * Encoding writes version 2 only. Decoding reads both, so a history kept in version 1 is
 * not lost: a version-1 entry's entries ND_NTHETA_PAPER.. are nd_theta_true's (the box as
 * built) with std 0 (held), which is what such a fit assumed. A change of ND_NTHETA needs
 * a new version (nd_history.c asserts the size).
 *
 * Decoding refuses anything the encoder of that version would not write, so a fuzzer that
 * gets past the decoder has produced a valid entry. */
#ifndef ND_HISTORY_H
#define ND_HISTORY_H

#include <stddef.h>
#include <stdint.h>

#include "nd_rfile.h"
#include "nd_theta.h"

#define ND_HISTORY_ENC_VERSION 2  /* what encoding writes */
#define ND_HISTORY_ENC_SIZE 168    /* its size */
#define ND_HISTORY_ENC_SIZE_V1 120 /* version 1's size, still decoded */

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

/* 0 if e is valid (see the version-2 table above), else -1 naming the first bad field. */
int nd_history_check(const nd_history_entry *e, char *err, int errlen);

/* Encode a valid e into buf. Return 0, or -1 with a message (e invalid, nothing written). */
int nd_history_encode(const nd_history_entry *e, unsigned char buf[ND_HISTORY_ENC_SIZE],
                       char *err, int errlen);

/* Decode len bytes, a version-2 or a version-1 entry, into e. Return 0, or -1 with a
 * message naming the field (a length or version other than 168 bytes of version 2 or 120
 * of version 1, reserved bits set, a value out of range); e is then unspecified. */
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
