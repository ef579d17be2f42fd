/* nd_rbuf: the replay buffer, rollouts (nd_rollout encodings, see nd_rollout.h) as
 * records of kind ND_RFILE_KIND_ROLLOUTS in an nd_rfile of the same kind. The tasks
 * process appends one rollout per finished task; the adapter reads them all at start and
 * then polls with nd_rbuf_next for the ones appended since. */
#ifndef ND_RBUF_H
#define ND_RBUF_H

#include "nd_rfile.h"
#include "nd_rollout.h"

/* nd_rfile_open_append for a rollouts file (see there: creates, locks, repairs). */
int nd_rbuf_open(nd_rfile_writer *w, const char *path, nd_rfile_tail *repair, char *err,
                 int errlen);

/* Encode r (refused unless nd_rollout_check passes) and append it; 0 once committed.
 * Allocates the encoding buffer for the call: once per task, not a hot path. */
int nd_rbuf_append(nd_rfile_writer *w, const nd_rollout *r, char *err, int errlen);

/* nd_rfile_reader_open for a rollouts file. */
int nd_rbuf_reader_open(nd_rfile_reader *rd, const char *path, char *err, int errlen);

/* Read the next rollout into r (fresh arrays, free with nd_rollout_free). Return 1; 0
 * when none is complete now (tail says where the valid records end and why); -1 on an
 * I/O error or on a sound record that is not a decodable rollout (wrong kind, another
 * encoding version), named by offset: the reader has moved past such a record. */
int nd_rbuf_next(nd_rfile_reader *rd, nd_rollout *r, nd_rfile_tail *tail, char *err,
                 int errlen);

/* Read every valid rollout of path into *out (*n of them, file order; free with
 * nd_rbuf_free_all), *tail (may be NULL) saying where they end and why. Return 0, or -1
 * (nothing returned) if the file cannot be read or holds an undecodable record. */
int nd_rbuf_read_all(const char *path, nd_rollout **out, int *n, nd_rfile_tail *tail,
                     char *err, int errlen);

/* Free an array from nd_rbuf_read_all. */
void nd_rbuf_free_all(nd_rollout *rs, int n);

#endif
