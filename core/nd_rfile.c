/* nd_rfile: append-only record file (format and guarantees in nd_rfile.h).
 *
 * Positional I/O (pread/pwritev at explicit offsets) everywhere: the writer knows where
 * the valid records end and writes exactly there, so undoing a failed append is one
 * ftruncate, and readers share no file position with anyone. */
#define _GNU_SOURCE
#include "nd_rfile.h"

#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/uio.h>
#include <time.h>
#include <unistd.h>
#include <zlib.h>

/* ---- bytes ---- */

static void nd_rf_put32(unsigned char *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (unsigned char)(v >> (8 * i));
}

static uint32_t nd_rf_get32(const unsigned char *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint32_t nd_rf_crc(uint32_t crc, const void *p, size_t n) {
  if (n == 0) return crc;  /* zlib answers 0 for a NULL buffer, whatever crc was */
  return (uint32_t)crc32(crc, (const Bytef *)p, (uInt)n);  /* n <= 64 MiB fits uInt */
}

static const char *nd_rf_kind_name(uint32_t kind) {
  switch (kind) {
    case ND_RFILE_KIND_ROLLOUTS: return "rollouts";
    case ND_RFILE_KIND_PARAMS: return "parameter history";
    default: return "unknown";
  }
}

const char *nd_rfile_status_name(int status) {
  switch (status) {
    case ND_RFILE_END: return "end";
    case ND_RFILE_TORN: return "torn";
    default: return "corrupt";
  }
}

/* Read up to n bytes at off; return how many were read (< n only at the end of the
 * file), or -1 with errno set. */
static ssize_t nd_rf_pread(int fd, void *buf, size_t n, int64_t off) {
  size_t got = 0;
  while (got < n) {
    ssize_t k = pread(fd, (char *)buf + got, n - got, (off_t)(off + (int64_t)got));
    if (k < 0) {
      if (errno == EINTR) continue;
      return -1;
    }
    if (k == 0) break;
    got += (size_t)k;
  }
  return (ssize_t)got;
}

static void nd_rf_stop(nd_rfile_tail *t, int status, int64_t off, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

static void nd_rf_stop(nd_rfile_tail *t, int status, int64_t off, const char *fmt, ...) {
  t->status = status;
  t->offset = off;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(t->why, sizeof t->why, fmt, ap);
  va_end(ap);
}

/* ---- header ---- */

static void nd_rf_header(unsigned char h[ND_RFILE_HEADER], uint32_t kind) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  const uint64_t us = (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
  memset(h, 0, ND_RFILE_HEADER);
  memcpy(h, ND_RFILE_MAGIC, 8);
  nd_rf_put32(h + 8, ND_RFILE_VERSION);
  nd_rf_put32(h + 12, ND_RFILE_HEADER);
  nd_rf_put32(h + 16, kind);
  nd_rf_put32(h + 24, (uint32_t)us);
  nd_rf_put32(h + 28, (uint32_t)(us >> 32));
  nd_rf_put32(h + 36, nd_rf_crc(0, h, 36));
}

/* Validate the header of fd; set *kind and *created_us. -1 and a message naming path. */
static int nd_rf_read_header(int fd, const char *path, uint32_t *kind, int64_t *created_us,
                             char *err, int errlen) {
  unsigned char h[ND_RFILE_HEADER];
  ssize_t got = nd_rf_pread(fd, h, sizeof h, 0);
  if (got < 0) {
    snprintf(err, (size_t)errlen, "%s: cannot read the header: %s", path, strerror(errno));
    return -1;
  }
  if (got == 0) {
    snprintf(err, (size_t)errlen, "%s: empty file, not a nudge record file", path);
    return -1;
  }
  const size_t m = got < 8 ? (size_t)got : 8;
  if (memcmp(h, ND_RFILE_MAGIC, m) != 0) {
    char shown[8 * 4 + 1];
    size_t k = 0;
    for (size_t i = 0; i < m; i++) {
      if (h[i] >= 0x20 && h[i] < 0x7f && h[i] != '"' && h[i] != '\\')
        shown[k++] = (char)h[i];
      else
        k += (size_t)snprintf(shown + k, sizeof shown - k, "\\x%02x", h[i]);
    }
    shown[k] = 0;
    snprintf(err, (size_t)errlen,
             "%s: not a nudge record file: it starts with \"%s\", expected magic \"%s\"",
             path, shown, ND_RFILE_MAGIC);
    return -1;
  }
  if (got < ND_RFILE_HEADER) {
    snprintf(err, (size_t)errlen, "%s: header truncated: %zd of %d bytes", path, got,
             ND_RFILE_HEADER);
    return -1;
  }
  const uint32_t version = nd_rf_get32(h + 8), hsize = nd_rf_get32(h + 12);
  if (version != ND_RFILE_VERSION) {
    snprintf(err, (size_t)errlen, "%s: format version %u, this build reads version %d",
             path, (unsigned)version, ND_RFILE_VERSION);
    return -1;
  }
  if (hsize != ND_RFILE_HEADER) {
    snprintf(err, (size_t)errlen, "%s: header size %u, version %d has %d", path,
             (unsigned)hsize, ND_RFILE_VERSION, ND_RFILE_HEADER);
    return -1;
  }
  const uint32_t stored = nd_rf_get32(h + 36), computed = nd_rf_crc(0, h, 36);
  if (stored != computed) {
    snprintf(err, (size_t)errlen,
             "%s: header checksum mismatch (stored %08x, computed %08x): header corrupt",
             path, (unsigned)stored, (unsigned)computed);
    return -1;
  }
  const uint32_t flags = nd_rf_get32(h + 20);
  if (flags != 0) {
    snprintf(err, (size_t)errlen, "%s: unknown header flags 0x%x (this build knows none)",
             path, (unsigned)flags);
    return -1;
  }
  *kind = nd_rf_get32(h + 16);
  *created_us =
      (int64_t)((uint64_t)nd_rf_get32(h + 24) | (uint64_t)nd_rf_get32(h + 28) << 32);
  return 0;
}

static int nd_rf_check_kind(const char *path, uint32_t have, uint32_t want, char *err,
                            int errlen) {
  if (want == 0 || have == want) return 0;
  snprintf(err, (size_t)errlen, "%s: holds kind %u (%s), expected kind %u (%s)", path,
           (unsigned)have, nd_rf_kind_name(have), (unsigned)want, nd_rf_kind_name(want));
  return -1;
}

/* ---- record frames ---- */

/* Check the frame header at off of a file of size bytes. Return 1 when it is plausible
 * and the whole record lies inside the file (*len, *kind, *crc set), 0 when reading must
 * stop there (tail filled), -1 on an I/O error (errno). */
static int nd_rf_frame(int fd, int64_t off, int64_t size, uint32_t *len, uint32_t *kind,
                       uint32_t *crc, unsigned char hdr[ND_RFILE_FRAME], nd_rfile_tail *t) {
  const int64_t avail = size - off;
  if (avail < 0) {
    nd_rf_stop(t, ND_RFILE_CORRUPT, off,
               "the file is %lld bytes, shorter than the read offset %lld (truncated or "
               "replaced?)", (long long)size, (long long)off);
    return 0;
  }
  if (avail == 0) {
    nd_rf_stop(t, ND_RFILE_END, off, "end of file");
    return 0;
  }
  ssize_t got =
      avail < ND_RFILE_FRAME ? (ssize_t)avail : nd_rf_pread(fd, hdr, ND_RFILE_FRAME, off);
  if (got < 0) return -1;
  if (got < ND_RFILE_FRAME) {
    nd_rf_stop(t, ND_RFILE_TORN, off, "record at offset %lld: frame incomplete, %lld of %d "
               "bytes", (long long)off, (long long)got, ND_RFILE_FRAME);
    return 0;
  }
  *len = nd_rf_get32(hdr);
  *kind = nd_rf_get32(hdr + 4);
  *crc = nd_rf_get32(hdr + 8);
  if (*kind == 0 || *kind > ND_RFILE_KIND_MAX) {
    nd_rf_stop(t, ND_RFILE_CORRUPT, off, "record at offset %lld: kind %u is impossible",
               (long long)off, (unsigned)*kind);
    return 0;
  }
  if (*len > ND_RFILE_MAX_PAYLOAD) {
    nd_rf_stop(t, ND_RFILE_CORRUPT, off, "record at offset %lld: length %u exceeds the "
               "limit of %u bytes", (long long)off, (unsigned)*len, ND_RFILE_MAX_PAYLOAD);
    return 0;
  }
  if (avail - ND_RFILE_FRAME < (int64_t)*len) {
    nd_rf_stop(t, ND_RFILE_TORN, off, "record at offset %lld: %u payload bytes announced, "
               "the file ends after %lld", (long long)off, (unsigned)*len,
               (long long)(avail - ND_RFILE_FRAME));
    return 0;
  }
  return 1;
}

/* Crc of the record at off whose frame is hdr, streaming the payload through a small
 * buffer (the writer's scan must not hold a 64 MiB payload). -1 on an I/O error or a
 * file that shrank under us. */
static int nd_rf_crc_stream(int fd, int64_t off, const unsigned char *hdr, uint32_t len,
                            uint32_t *out) {
  unsigned char chunk[16384];
  uint32_t crc = nd_rf_crc(0, hdr, 8);
  int64_t pos = off + ND_RFILE_FRAME;
  uint32_t left = len;
  while (left > 0) {
    const size_t n = left < sizeof chunk ? left : sizeof chunk;
    ssize_t got = nd_rf_pread(fd, chunk, n, pos);
    if (got < 0) return -1;
    if ((size_t)got < n) {
      errno = ENODATA;
      return -1;
    }
    crc = nd_rf_crc(crc, chunk, n);
    pos += (int64_t)n;
    left -= (uint32_t)n;
  }
  *out = crc;
  return 0;
}

/* Is there a complete record with a valid crc at off? 1 yes, 0 no, -1 I/O error. */
static int nd_rf_valid_at(int fd, int64_t off, int64_t size) {
  uint32_t len, kind, crc, computed;
  unsigned char hdr[ND_RFILE_FRAME];
  nd_rfile_tail t;
  int k = nd_rf_frame(fd, off, size, &len, &kind, &crc, hdr, &t);
  if (k <= 0) return k;
  if (nd_rf_crc_stream(fd, off, hdr, len, &computed)) return -1;
  return computed == crc;
}

/* First offset in (from, size) where a valid record starts, or -1 if none (-2 on an I/O
 * error). Cheap tests on a sliding window come first, so random bytes rarely cost a crc. */
static int64_t nd_rf_find_valid(int fd, int64_t from, int64_t size) {
  unsigned char win[65536];
  for (int64_t base = from + 1; base + ND_RFILE_FRAME <= size;) {
    ssize_t got = nd_rf_pread(fd, win, sizeof win, base);
    if (got < 0) return -2;
    if (got < ND_RFILE_FRAME) break;
    const ssize_t last = got - ND_RFILE_FRAME;  /* candidates whose frame is all here */
    for (ssize_t i = 0; i <= last; i++) {
      const uint32_t len = nd_rf_get32(win + i), kind = nd_rf_get32(win + i + 4);
      const int64_t at = base + i;
      if (kind == 0 || kind > ND_RFILE_KIND_MAX || len > ND_RFILE_MAX_PAYLOAD ||
          (int64_t)len > size - at - ND_RFILE_FRAME)
        continue;
      int v = nd_rf_valid_at(fd, at, size);
      if (v < 0) return -2;
      if (v) return at;
    }
    base += last + 1;
  }
  return -1;
}

/* ---- writer ---- */

static int nd_rf_fail(char *err, int errlen, const char *path, const char *what) {
  snprintf(err, (size_t)errlen, "%s: %s: %s", path, what, strerror(errno));
  return -1;
}

/* nd_rf_fail for a writer: also keep the errno, so callers can tell a full or read-only
 * file system from a file that is not theirs to write. */
static int nd_rf_wfail(nd_rfile_writer *w, char *err, int errlen, const char *path,
                       const char *what) {
  w->sys_errno = errno;
  return nd_rf_fail(err, errlen, path, what);
}

/* pid holding a flock on fd's file, from /proc/locks (Linux); -1 if unknown. flock
 * records no owner in the file, and a pid file would be one more thing to go stale. */
static int nd_rf_lock_holder(int fd) {
  struct stat st;
  if (fstat(fd, &st)) return -1;
  FILE *f = fopen("/proc/locks", "re");
  if (!f) return -1;
  char line[256];
  int pid = -1;
  while (pid < 0 && fgets(line, sizeof line, f)) {
    char type[16];
    int p;
    unsigned maj, min;
    unsigned long ino;
    if (sscanf(line, "%*d: %15s %*s %*s %d %x:%x:%lu", type, &p, &maj, &min, &ino) == 5 &&
        strcmp(type, "FLOCK") == 0 && ino == (unsigned long)st.st_ino &&
        maj == major(st.st_dev) && min == minor(st.st_dev))
      pid = p;
  }
  fclose(f);
  return pid;
}

/* Make the directory entry of path durable: fdatasync of the file alone does not. */
static int nd_rf_sync_dir(const char *path) {
  char dir[ND_RFILE_PATH_MAX];
  snprintf(dir, sizeof dir, "%s", path);
  char *slash = strrchr(dir, '/');
  if (!slash)
    snprintf(dir, sizeof dir, ".");
  else if (slash == dir)
    dir[1] = 0;
  else
    *slash = 0;
  int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return -1;
  int rc = fsync(fd);
  close(fd);
  return rc;
}

static int nd_rf_pwrite_all(int fd, const void *buf, size_t n, int64_t off) {
  size_t done = 0;
  while (done < n) {
    ssize_t k =
        pwrite(fd, (const char *)buf + done, n - done, (off_t)(off + (int64_t)done));
    if (k < 0) {
      if (errno == EINTR) continue;
      return -1;
    }
    done += (size_t)k;
  }
  return 0;
}

/* Create path holding just a header. Written under a temporary name and linked into
 * place, so the file appears complete or not at all: readers never see a half header,
 * and link() fails on a name someone else created meanwhile. Return an fd on the new
 * (or the concurrently created) file, or -1. */
static int nd_rf_create(nd_rfile_writer *w, const char *path, uint32_t kind, char *err,
                        int errlen) {
  static atomic_uint serial;  /* two threads of one process must not share a name */
  char tmp[ND_RFILE_PATH_MAX + 48];
  int fd = -1;
  for (int attempt = 0; fd < 0 && attempt < 8; attempt++) {
    /* An existing name is some other creator's, or left by a crash: never ours to
     * remove, just pick the next. */
    snprintf(tmp, sizeof tmp, "%s.new-%ld-%u", path, (long)getpid(),
             atomic_fetch_add(&serial, 1u));
    fd = open(tmp, O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (fd < 0 && errno != EEXIST) break;
  }
  if (fd < 0) return nd_rf_wfail(w, err, errlen, path, "cannot create");
  unsigned char h[ND_RFILE_HEADER];
  nd_rf_header(h, kind);
  if (nd_rf_pwrite_all(fd, h, sizeof h, 0) || fsync(fd)) {
    nd_rf_wfail(w, err, errlen, tmp, "cannot write the header");
    close(fd);
    unlink(tmp);
    return -1;
  }
  if (link(tmp, path)) {
    const int e = errno;
    close(fd);
    unlink(tmp);
    if (e != EEXIST) {
      errno = e;
      return nd_rf_wfail(w, err, errlen, path, "cannot create (link)");
    }
    fd = open(path, O_RDWR | O_CLOEXEC);
    if (fd < 0) return nd_rf_wfail(w, err, errlen, path, "cannot open for appending");
    return fd;
  }
  unlink(tmp);
  if (nd_rf_sync_dir(path)) {
    nd_rf_wfail(w, err, errlen, path, "cannot sync its directory");
    close(fd);
    return -1;
  }
  return fd;
}

int nd_rfile_open_append(nd_rfile_writer *w, const char *path, uint32_t kind,
                         nd_rfile_tail *repair, char *err, int errlen) {
  nd_rfile_tail scratch;
  nd_rfile_tail *t = repair ? repair : &scratch;
  memset(t, 0, sizeof *t);
  memset(w, 0, sizeof *w);
  w->fd = -1;
  if (kind == 0 || kind > ND_RFILE_KIND_MAX) {
    snprintf(err, (size_t)errlen, "%s: file kind %u out of [1, %u]", path, (unsigned)kind,
             ND_RFILE_KIND_MAX);
    return -1;
  }
  if (strlen(path) >= sizeof w->path) {
    snprintf(err, (size_t)errlen, "record file path longer than %d bytes",
             ND_RFILE_PATH_MAX - 1);
    return -1;
  }
  int fd = open(path, O_RDWR | O_CLOEXEC);
  if (fd < 0 && errno == ENOENT) {
    fd = nd_rf_create(w, path, kind, err, errlen);
    if (fd < 0) return -1;
  } else if (fd < 0) {
    return nd_rf_wfail(w, err, errlen, path, "cannot open for appending");
  }
  if (flock(fd, LOCK_EX | LOCK_NB)) {
    if (errno == EWOULDBLOCK) {
      const int pid = nd_rf_lock_holder(fd);
      if (pid > 0)
        snprintf(err, (size_t)errlen, "%s: locked by another writer (pid %d)", path, pid);
      else
        snprintf(err, (size_t)errlen, "%s: locked by another writer (pid unknown)", path);
    } else {
      nd_rf_wfail(w, err, errlen, path, "cannot lock");
    }
    close(fd);
    return -1;
  }
  struct stat st;
  if (fstat(fd, &st)) {
    nd_rf_wfail(w, err, errlen, path, "cannot stat");
    goto fail;
  }
  if (st.st_size == 0) {  /* created empty by someone else (touch): ours to initialise */
    unsigned char h[ND_RFILE_HEADER];
    nd_rf_header(h, kind);
    if (nd_rf_pwrite_all(fd, h, sizeof h, 0) || fdatasync(fd)) {
      nd_rf_wfail(w, err, errlen, path, "cannot write the header");
      goto fail;
    }
    st.st_size = ND_RFILE_HEADER;
  }
  int64_t created;
  if (nd_rf_read_header(fd, path, &w->kind, &created, err, errlen) ||
      nd_rf_check_kind(path, w->kind, kind, err, errlen))
    goto fail;

  /* Scan: every record is verified, so the first append cannot hide behind garbage. */
  const int64_t size = st.st_size;
  int64_t off = ND_RFILE_HEADER, records = 0;
  for (;;) {
    uint32_t len, rkind, crc, computed;
    unsigned char hdr[ND_RFILE_FRAME];
    int k = nd_rf_frame(fd, off, size, &len, &rkind, &crc, hdr, t);
    if (k < 0 || (k > 0 && nd_rf_crc_stream(fd, off, hdr, len, &computed))) {
      nd_rf_wfail(w, err, errlen, path, "cannot read while scanning the records");
      goto fail;
    }
    if (k == 0) break;
    if (computed != crc) {
      nd_rf_stop(t, ND_RFILE_CORRUPT, off, "record at offset %lld: checksum mismatch "
                 "(stored %08x, computed %08x)", (long long)off, (unsigned)crc,
                 (unsigned)computed);
      break;
    }
    off += ND_RFILE_FRAME + (int64_t)len;
    records++;
  }
  t->size = size;
  t->records = records;
  if (t->status != ND_RFILE_END) {
    const int64_t next = nd_rf_find_valid(fd, off, size);
    if (next == -2) {
      nd_rf_wfail(w, err, errlen, path, "cannot read while scanning the records");
      goto fail;
    }
    if (next >= 0) {
      snprintf(err, (size_t)errlen,
               "%s: %s, but a valid record follows at offset %lld: damage inside the file, "
               "not a torn tail; refusing to cut %lld bytes (copy the file and repair it)",
               path, t->why, (long long)next, (long long)(size - off));
      goto fail;
    }
    if (ftruncate(fd, (off_t)off) || fdatasync(fd)) {
      nd_rf_wfail(w, err, errlen, path, "cannot cut the torn tail");
      goto fail;
    }
  }
  w->fd = fd;
  w->end = off;
  w->records = records;
  memcpy(w->path, path, strlen(path) + 1);
  return 0;

fail:
  close(fd);  /* releases the lock */
  return -1;
}

int nd_rfile_append(nd_rfile_writer *w, uint32_t kind, const void *payload, uint32_t len,
                    char *err, int errlen) {
  if (w->fd < 0) {
    snprintf(err, (size_t)errlen, "record file writer is not open");
    return -1;
  }
  w->sys_errno = 0;
  if (w->broken) {
    snprintf(err, (size_t)errlen, "%s: writer unusable after a failed sync; reopen it (the "
             "reopen checks and repairs the tail)", w->path);
    return -1;
  }
  if (kind == 0 || kind > ND_RFILE_KIND_MAX || len > ND_RFILE_MAX_PAYLOAD) {
    snprintf(err, (size_t)errlen, "%s: record kind %u / length %u out of range", w->path,
             (unsigned)kind, (unsigned)len);
    return -1;
  }
  unsigned char hdr[ND_RFILE_FRAME];
  nd_rf_put32(hdr, len);
  nd_rf_put32(hdr + 4, kind);
  nd_rf_put32(hdr + 8, nd_rf_crc(nd_rf_crc(0, hdr, 8), payload, len));

  const size_t total = ND_RFILE_FRAME + (size_t)len;
  size_t done = 0;
  while (done < total) {
    struct iovec iov[2];
    int cnt = 0;
    if (done < ND_RFILE_FRAME) {
      iov[cnt++] = (struct iovec){hdr + done, ND_RFILE_FRAME - done};
      if (len) iov[cnt++] = (struct iovec){(void *)payload, len};
    } else {
      iov[cnt++] = (struct iovec){(char *)payload + (done - ND_RFILE_FRAME), total - done};
    }
    ssize_t k = pwritev(w->fd, iov, cnt, (off_t)(w->end + (int64_t)done));
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) {
      if (k == 0) errno = EIO;
      const int e = errno;
      w->sys_errno = e;
      int cut = ftruncate(w->fd, (off_t)w->end);
      if (cut) w->broken = 1;
      snprintf(err, (size_t)errlen,
               "%s: append of %zu bytes at offset %lld failed after %zu: %s (record not "
               "written; %s)", w->path, total, (long long)w->end, done, strerror(e),
               cut ? "cutting it back failed too, the next open repairs the tail"
                   : "earlier records intact");
      return -1;
    }
    done += (size_t)k;
  }
  if (fdatasync(w->fd)) {
    /* After a failed sync the kernel may have dropped the dirty pages: neither this
     * record nor a retried sync can be trusted, so undo and stop. */
    const int e = errno;
    w->sys_errno = e;
    w->broken = 1;
    int cut = ftruncate(w->fd, (off_t)w->end);
    snprintf(err, (size_t)errlen, "%s: fdatasync after appending at offset %lld failed: %s "
             "(record not committed%s; reopen the file)", w->path, (long long)w->end,
             strerror(e), cut ? ", cutting it back failed too" : ", cut back");
    return -1;
  }
  w->end += (int64_t)total;
  w->records++;
  return 0;
}

void nd_rfile_writer_close(nd_rfile_writer *w) {
  if (w->fd >= 0) close(w->fd);
  w->fd = -1;
}

/* ---- reader ---- */

int nd_rfile_reader_open(nd_rfile_reader *r, const char *path, uint32_t kind, char *err,
                         int errlen) {
  memset(r, 0, sizeof *r);
  r->fd = -1;
  if (strlen(path) >= sizeof r->path) {
    snprintf(err, (size_t)errlen, "record file path longer than %d bytes",
             ND_RFILE_PATH_MAX - 1);
    return -1;
  }
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return nd_rf_fail(err, errlen, path, "cannot open for reading");
  if (nd_rf_read_header(fd, path, &r->kind, &r->created_us, err, errlen) ||
      nd_rf_check_kind(path, r->kind, kind, err, errlen)) {
    close(fd);
    return -1;
  }
  r->fd = fd;
  r->offset = ND_RFILE_HEADER;
  memcpy(r->path, path, strlen(path) + 1);
  return 0;
}

int nd_rfile_reader_seek(nd_rfile_reader *r, int64_t offset, char *err, int errlen) {
  if (offset < ND_RFILE_HEADER) {
    snprintf(err, (size_t)errlen, "%s: offset %lld lies inside the %d-byte header", r->path,
             (long long)offset, ND_RFILE_HEADER);
    return -1;
  }
  r->offset = offset;
  r->records = 0;
  return 0;
}

int nd_rfile_next(nd_rfile_reader *r, nd_rfile_record *rec, nd_rfile_tail *tail, char *err,
                  int errlen) {
  nd_rfile_tail scratch;
  nd_rfile_tail *t = tail ? tail : &scratch;
  memset(t, 0, sizeof *t);
  if (r->fd < 0) {
    snprintf(err, (size_t)errlen, "record file reader is not open");
    return -1;
  }
  struct stat st;
  if (fstat(r->fd, &st)) return nd_rf_fail(err, errlen, r->path, "cannot stat");
  t->size = st.st_size;
  t->records = r->records;
  uint32_t len, kind, crc;
  unsigned char hdr[ND_RFILE_FRAME];
  int k = nd_rf_frame(r->fd, r->offset, st.st_size, &len, &kind, &crc, hdr, t);
  if (k < 0) return nd_rf_fail(err, errlen, r->path, "cannot read");
  if (k == 0) return 0;
  if (len > r->cap) {
    size_t cap = r->cap ? r->cap : 4096;
    while (cap < len) cap *= 2;
    unsigned char *b = realloc(r->buf, cap);
    if (!b) {
      snprintf(err, (size_t)errlen, "%s: out of memory for a %u-byte record", r->path,
               (unsigned)len);
      return -1;
    }
    r->buf = b;
    r->cap = cap;
  }
  ssize_t got = nd_rf_pread(r->fd, r->buf, len, r->offset + ND_RFILE_FRAME);
  if (got < 0) return nd_rf_fail(err, errlen, r->path, "cannot read");
  if ((size_t)got < len) {  /* cut under us, by a writer repairing a torn tail */
    nd_rf_stop(t, ND_RFILE_TORN, r->offset, "record at offset %lld: file shrank while "
               "reading", (long long)r->offset);
    return 0;
  }
  const uint32_t computed = nd_rf_crc(nd_rf_crc(0, hdr, 8), r->buf, len);
  if (computed != crc) {
    nd_rf_stop(t, ND_RFILE_CORRUPT, r->offset, "record at offset %lld: checksum mismatch "
               "(stored %08x, computed %08x)", (long long)r->offset, (unsigned)crc,
               (unsigned)computed);
    return 0;
  }
  rec->kind = kind;
  rec->len = len;
  rec->offset = r->offset;
  rec->data = r->buf;
  r->offset += ND_RFILE_FRAME + (int64_t)len;
  r->records++;
  t->offset = r->offset;
  t->records = r->records;
  return 1;
}

void nd_rfile_reader_close(nd_rfile_reader *r) {
  if (r->fd >= 0) close(r->fd);
  r->fd = -1;
  free(r->buf);
  r->buf = NULL;
  r->cap = 0;
}

void nd_rfile_umask_no_world_write(void) {
  const mode_t old = umask(0);
  umask(old | S_IWOTH);
}
