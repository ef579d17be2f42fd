/* ffmpeg: frames out through ffmpeg (view.h), started without a shell; raw rgb24 frames go
 * to its stdin. It runs in a process group of its own, so a Ctrl-C on the terminal reaches
 * only nudge-view, which then closes the pipe: ffmpeg sees the end of its input and
 * finishes the file (an MP4 cut off by a signal has no index and does not play). */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "view.h"

extern char **environ;

#define FFMPEG "ffmpeg"

int view_ffmpeg_check(char *err, int errlen) {
  const char *path = getenv("PATH");
  char buf[4096];
  while (path && *path) {
    const size_t n = strcspn(path, ":");
    if (n > 0 && n < sizeof buf - sizeof("/" FFMPEG)) {
      snprintf(buf, sizeof buf, "%.*s/" FFMPEG, (int)n, path);
      if (access(buf, X_OK) == 0) return 0;
    }
    path += n + (path[n] == ':');
  }
  snprintf(err, errlen, "ffmpeg is not on PATH: it encodes --record and --png (Debian: "
                        "apt-get install ffmpeg)");
  return -1;
}

/* Start argv with its stdin the read end of a new pipe; the write end into f->fd. */
static int spawn(view_ffmpeg *f, char *const argv[], char *err, int errlen) {
  int p[2];
  if (pipe2(p, O_CLOEXEC)) {
    snprintf(err, errlen, "pipe: %s", strerror(errno));
    return -1;
  }
  posix_spawn_file_actions_t fa;
  posix_spawnattr_t at;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, p[0], 0);
  posix_spawnattr_init(&at);
  sigset_t none, dflt;
  sigemptyset(&none);
  sigemptyset(&dflt);
  sigaddset(&dflt, SIGPIPE);  /* ndp_signals ignores it; ffmpeg should not inherit that */
  posix_spawnattr_setsigmask(&at, &none);
  posix_spawnattr_setsigdefault(&at, &dflt);
  posix_spawnattr_setpgroup(&at, 0);
  posix_spawnattr_setflags(&at, POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK |
                                    POSIX_SPAWN_SETSIGDEF);
  const int rc = posix_spawnp(&f->pid, argv[0], &fa, &at, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&at);
  close(p[0]);
  if (rc) {
    close(p[1]);
    f->pid = 0;
    snprintf(err, errlen, "cannot start %s: %s", argv[0], strerror(rc));
    return -1;
  }
  f->fd = p[1];
  /* A frame is megabytes: a larger pipe lets ffmpeg take one while we render the next. */
  fcntl(f->fd, F_SETPIPE_SZ, 1 << 20);
  return 0;
}

int view_ffmpeg_mp4(view_ffmpeg *f, const char *out, int w, int h, int fps, char *err,
                    int errlen) {
  memset(f, 0, sizeof(*f));
  f->w = w;
  f->h = h;
  f->out = out;
  if (!(f->rows = malloc((size_t)w * h * 3))) {
    snprintf(err, errlen, "out of memory for a %dx%d frame", w, h);
    return -1;
  }
  char size[32], rate[16];
  snprintf(size, sizeof size, "%dx%d", w, h);
  snprintf(rate, sizeof rate, "%d", fps);
  /* H.264 at the "ultrafast" preset: the encoder shares the machine with the planner,
   * and costs several times less CPU there than at x264's default preset. yuv420p is what
   * players expect. */
  char *const argv[] = {FFMPEG, "-nostdin", "-hide_banner", "-loglevel", "error", "-y",
                        "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", size, "-r", rate,
                        "-i", "-", "-an", "-c:v", "libx264", "-preset", "ultrafast",
                        "-pix_fmt", "yuv420p", "-f", "mp4", (char *)out, NULL};
  return spawn(f, argv, err, errlen);
}

/* Write all n bytes; a signal mid-frame must not tear the stream. */
static int write_all(int fd, const unsigned char *p, size_t n) {
  while (n > 0) {
    const ssize_t k = write(fd, p, n);
    if (k < 0) {
      if (errno == EINTR) continue;
      return -1;
    }
    p += k;
    n -= (size_t)k;
  }
  return 0;
}

/* OpenGL's rows come bottom-up; video and image rows go top-down. */
static void flip(unsigned char *dst, const unsigned char *src, int w, int h) {
  const size_t row = (size_t)w * 3;
  for (int y = 0; y < h; y++) memcpy(dst + (size_t)y * row, src + (size_t)(h - 1 - y) * row, row);
}

int view_ffmpeg_frame(view_ffmpeg *f, const unsigned char *rgb, char *err, int errlen) {
  if (!f->pid) {
    snprintf(err, errlen, "ffmpeg for %s is not running", f->out);
    return -1;
  }
  flip(f->rows, rgb, f->w, f->h);
  if (write_all(f->fd, f->rows, (size_t)f->w * f->h * 3)) {
    snprintf(err, errlen, "ffmpeg writing %s stopped taking frames: %s", f->out, strerror(errno));
    return -1;
  }
  return 0;
}

int view_ffmpeg_close(view_ffmpeg *f, char *err, int errlen) {
  int rc = 0;
  if (f->pid) {
    close(f->fd);
    int st;
    pid_t r;
    while ((r = waitpid(f->pid, &st, 0)) < 0 && errno == EINTR) {
    }
    if (r < 0 || !WIFEXITED(st) || WEXITSTATUS(st) != 0) {
      snprintf(err, errlen, "ffmpeg writing %s failed (%s %d)", f->out,
               r >= 0 && WIFSIGNALED(st) ? "signal" : "status",
               r < 0 ? -1 : WIFSIGNALED(st) ? WTERMSIG(st) : WEXITSTATUS(st));
      rc = -1;
    }
  }
  free(f->rows);
  memset(f, 0, sizeof(*f));
  return rc;
}

int view_png(const char *out, const unsigned char *rgb, int w, int h, unsigned char *rows,
             char *err, int errlen) {
  char tmp[4096], size[32];
  if (snprintf(tmp, sizeof tmp, "%s.tmp-%d", out, (int)getpid()) >= (int)sizeof tmp) {
    snprintf(err, errlen, "--png path is too long");
    return -1;
  }
  snprintf(size, sizeof size, "%dx%d", w, h);
  char *const argv[] = {FFMPEG, "-nostdin", "-hide_banner", "-loglevel", "error", "-y",
                        "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", size, "-i", "-",
                        "-frames:v", "1", "-c:v", "png", "-f", "image2", "-update", "1",
                        tmp, NULL};
  view_ffmpeg f = {0};
  f.w = w;
  f.h = h;
  f.out = out;
  if (spawn(&f, argv, err, errlen)) return -1;
  flip(rows, rgb, w, h);
  const int bad = write_all(f.fd, rows, (size_t)w * h * 3);
  const int werr = errno;
  close(f.fd);
  int st;
  pid_t r;
  while ((r = waitpid(f.pid, &st, 0)) < 0 && errno == EINTR) {
  }
  if (bad || r < 0 || !WIFEXITED(st) || WEXITSTATUS(st) != 0) {
    snprintf(err, errlen, "ffmpeg could not write %s%s%s", out, bad ? ": " : "",
             bad ? strerror(werr) : "");
    unlink(tmp);
    return -1;
  }
  if (rename(tmp, out)) {
    snprintf(err, errlen, "cannot rename %s to %s: %s", tmp, out, strerror(errno));
    unlink(tmp);
    return -1;
  }
  return 0;
}
