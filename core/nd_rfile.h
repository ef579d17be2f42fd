/* nd_rfile: an append-only file of framed, typed, checksummed records.
 *
 * One writer appends, any number of readers (other processes, other hosts over a shared
 * file system) poll for new records without ever blocking it. A crash or SIGKILL of the
 * writer at any instant leaves every committed record readable; whatever it was in the
 * middle of writing is detected and never returned, and the next writer cuts it off.
 * Users: the replay buffer (kind 1, records are nd_rollout encodings, see nd_rbuf.h)
 * and the adapter's parameter history (kind 2, defined by its owner).
 *
 * Format, version 1. Every integer little-endian; crc32 is zlib's (CRC-32/ISO-HDLC,
 * the one of gzip and PNG).
 *
 *   file header, 40 bytes at offset 0
 *     0   8  magic "NUDGEBUF"
 *     8   4  u32 format version (1)
 *    12   4  u32 header size (40); records start here
 *    16   4  u32 file kind: 1 rollouts, 2 parameter history
 *    20   4  u32 flags (0; a reader refuses a flag it does not know)
 *    24   8  i64 creation time, microseconds since the epoch
 *    32   4  u32 reserved (0)
 *    36   4  u32 crc32 of bytes [0, 36)
 *
 *   then records, back to back, no padding
 *     0   4  u32 len, payload bytes, <= ND_RFILE_MAX_PAYLOAD
 *     4   4  u32 kind, in [1, ND_RFILE_KIND_MAX] (never 0: zero-filled space is invalid)
 *     8   4  u32 crc32 of bytes [0, 8) of this record followed by the payload
 *    12 len  payload
 *
 * Why this detects every torn or corrupt record. The writer appends a record with one
 * pwritev at the end of the valid records and then fdatasync; append returning 0 is the
 * commit. A record counts only when its 12 + len bytes are all in the file and its crc
 * matches. A crash leaves at most the record being appended damaged: any prefix of it is
 * shorter than its length field says (or than the 12-byte frame); zeros or stale blocks
 * a file system may expose after a power cut fail the kind or crc test. Because the crc
 * covers len and kind too, a flipped bit anywhere in a record fails it: in kind, crc or
 * payload always (crc32 catches every 1- and 2-bit error below 512 MiB); in len the
 * record either runs past the end of the file or the crc covers other bytes and fails
 * with probability 1 - 2^-32. No separate commit marker is needed: length plus crc
 * already are one, written in the same call.
 *
 * Reading stops at the first record that fails and reports where and why; nothing after
 * it is returned, because without a valid frame there is no trustworthy next boundary.
 * Reopening for append distinguishes a torn tail (no valid record anywhere after the bad
 * one: cut off, reported) from damage inside the file (valid records follow: refused, so
 * good records are never destroyed). */
#ifndef ND_RFILE_H
#define ND_RFILE_H

#include <stddef.h>
#include <stdint.h>

#define ND_RFILE_MAGIC "NUDGEBUF"
#define ND_RFILE_VERSION 1
#define ND_RFILE_HEADER 40
#define ND_RFILE_FRAME 12                     /* record header bytes */
#define ND_RFILE_MAX_PAYLOAD (64u << 20)      /* 64 MiB; the longest rollout is 65.3 MB */
#define ND_RFILE_KIND_MAX 0xFFFFu
#define ND_RFILE_PATH_MAX 1024

/* File (and record) kinds. */
enum { ND_RFILE_KIND_ROLLOUTS = 1, ND_RFILE_KIND_PARAMS = 2 };

/* Where the valid records end, and why. */
enum {
  ND_RFILE_END = 0,      /* at the end of the file: nothing more */
  ND_RFILE_TORN = 1,     /* an incomplete record: a write in progress, or a crash */
  ND_RFILE_CORRUPT = 2,  /* a complete record failed its checks (or the file shrank) */
};

typedef struct {
  int status;            /* ND_RFILE_END / _TORN / _CORRUPT */
  int64_t offset;        /* end of the valid records: resume (or cut) here */
  int64_t size;          /* file size seen */
  int64_t records;       /* valid records before offset (the writer's scan; the reader's
                            count since open or seek) */
  char why[256];         /* for TORN / CORRUPT: what failed, with the offset */
} nd_rfile_tail;

typedef struct {
  int fd;                /* -1 when closed */
  uint32_t kind;         /* file kind */
  int64_t end;           /* offset after the last committed record */
  int64_t records;       /* committed records */
  int broken;            /* an fdatasync failed: the file state is unknown, reopen */
  int sys_errno;         /* errno of the system call that failed the last open or append
                            (ENOSPC, EROFS, EIO, ...); 0 after a success and after a
                            failure of another kind (locked by another writer, not a
                            record file, wrong kind, damage inside the file, arguments) */
  char path[ND_RFILE_PATH_MAX];
} nd_rfile_writer;

typedef struct {
  int fd;
  uint32_t kind;         /* file kind from the header */
  int64_t created_us;    /* creation time from the header */
  int64_t offset;        /* next record to read = end of the valid records read so far */
  int64_t records;       /* records returned since open or seek */
  unsigned char *buf;    /* payload of the last record returned; grows to the largest */
  size_t cap;
  char path[ND_RFILE_PATH_MAX];
} nd_rfile_reader;

typedef struct {
  uint32_t kind, len;
  int64_t offset;               /* where the record starts */
  const unsigned char *data;    /* len bytes, valid until the next call on the reader */
} nd_rfile_record;

/* Open path for appending records, creating it (mode 0640 less the umask, header
 * written and synced under the name "<path>.new-<pid>-<n>", then hard-linked into place
 * and the directory synced; a crash in between leaves that name behind, harmless) if
 * missing; kind is the file kind, an
 * existing file of another kind is refused. Takes an exclusive flock without waiting:
 * a second writer gets "locked by another writer (pid N)". Scans the records; a torn or
 * corrupt tail is cut off and described in *repair (status != ND_RFILE_END; may be
 * NULL), damage followed by valid records is refused. Return 0, or -1 and a message
 * naming the file. */
int nd_rfile_open_append(nd_rfile_writer *w, const char *path, uint32_t kind,
                         nd_rfile_tail *repair, char *err, int errlen);

/* Append one record (kind in [1, ND_RFILE_KIND_MAX], len <= ND_RFILE_MAX_PAYLOAD) with
 * one write and fdatasync. Return 0 once it is committed, or -1 with a message naming
 * the file and the errno text; the file then still ends after the previous record (a
 * partial write is truncated away). After a failed sync the writer refuses to go on.
 * (A process under a file-size limit must ignore SIGXFSZ to get EFBIG here.) */
int nd_rfile_append(nd_rfile_writer *w, uint32_t kind, const void *payload, uint32_t len,
                    char *err, int errlen);

/* Release the lock and close. Safe on a closed writer. */
void nd_rfile_writer_close(nd_rfile_writer *w);

/* Open path for reading without any lock (never blocks the writer); kind 0 accepts any
 * file kind. Positioned at the first record. Return 0, or -1 and a message (missing
 * file, wrong magic, version, kind, corrupt header). */
int nd_rfile_reader_open(nd_rfile_reader *r, const char *path, uint32_t kind, char *err,
                         int errlen);

/* Continue from offset, the end of valid records reported earlier (tail->offset or
 * r->offset of a previous reader). Return 0, or -1 if it lies before the first record. */
int nd_rfile_reader_seek(nd_rfile_reader *r, int64_t offset, char *err, int errlen);

/* Read the record at r->offset. Return 1 with *rec filled and r->offset advanced past
 * it; 0 when there is no complete valid record there now, *tail saying where and why
 * (call again later to poll: a torn record may complete, a new one may appear); -1 on an
 * I/O error. tail may be NULL. */
int nd_rfile_next(nd_rfile_reader *r, nd_rfile_record *rec, nd_rfile_tail *tail, char *err,
                  int errlen);

/* Close and free the buffer. Safe on a closed reader. */
void nd_rfile_reader_close(nd_rfile_reader *r);

/* "end", "torn" or "corrupt". */
const char *nd_rfile_status_name(int status);

/* Add "others may not write" to the process umask, keeping every bit already set: what
 * this process and its children then create with default modes (CSVs, figures, MuJoCo's
 * log) is never world-writable, even when it was started under umask 0. Record files need
 * no help (created 0640). umask is per process: call it before starting threads. */
void nd_rfile_umask_no_world_write(void);

#endif
