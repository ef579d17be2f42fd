/* record: each task's rollout appended to the replay buffer (tasks.h). */
#define _GNU_SOURCE /* strerrorname_np */
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "tasks.h"

/* A condition of the file system that may pass while the runner works (full, over
 * quota, read-only, failing): the tasks go on without recording. */
static int storage_error(int e) {
  return e == ENOSPC || e == EDQUOT || e == EROFS || e == EIO || e == EFBIG;
}

/* "ENOSPC" for ENOSPC: what people grep logs for; "" for 0. */
static const char *errno_name(int e) {
  const char *n = e ? strerrorname_np(e) : "";
  return n ? n : "?";
}

static void say_repaired(const char *path, const nd_rfile_tail *repair) {
  if (repair->status != ND_RFILE_END)
    fprintf(stderr, PROG ": %s: cut off a %s tail: %s\n", path,
            nd_rfile_status_name(repair->status), repair->why);
}

/* Allocate the recorder for tasks of up to tau s at step dt and open the buffer (a second
 * writer is refused by its lock). A file system that refuses writes now (storage_error) is
 * reported and leaves the buffer closed for the appends to retry. */
int tasks_buffer_open(tasks_buffer *b, const char *path, double tau, double dt, int control,
                      const double theta[ND_NTHETA], char *err, int errlen) {
  memset(b, 0, sizeof(*b));
  b->control = control;
  b->w.fd = -1;
  memcpy(b->theta, theta, sizeof(b->theta));
  b->theta_version = -1;
  b->path = path;
  char why[300];
  if (nd_recorder_init(&b->rec, tau, dt, why, sizeof(why))) {
    snprintf(err, errlen, "%s: %s", path, why);
    return -1;
  }
  nd_rfile_tail repair;
  if (nd_rbuf_open(&b->w, path, &repair, err, errlen)) {
    if (storage_error(b->w.sys_errno)) {
      fprintf(stderr, PROG ": cannot record into %s now: %s [%s]; running the tasks anyway, "
              "each one's append tries again\n", path, err, errno_name(b->w.sys_errno));
      return 0;
    }
    if (strstr(err, "locked"))
      snprintf(err + strlen(err), errlen - strlen(err),
               ": another nudge-tasks is recording into it");
    return -1;
  }
  say_repaired(path, &repair);
  fprintf(stderr, PROG ": recording into %s (%lld rollouts there), up to %d steps of %g s\n",
          path, (long long)b->w.records, b->rec.cap, dt);
  return 0;
}

/* Open the buffer again if it is not open, or after a failed sync left the writer
 * unusable (the reopen checks and repairs the tail). 0 when ready to append, or -1 with
 * a message (b->w.sys_errno says whether a system call failed). */
static int reopen(tasks_buffer *b, char *err, int errlen) {
  if (b->w.fd >= 0 && !b->w.broken) return 0;
  nd_rfile_writer_close(&b->w);
  nd_rfile_tail repair;
  if (nd_rbuf_open(&b->w, b->path, &repair, err, errlen)) return -1;
  say_repaired(b->path, &repair);
  fprintf(stderr, PROG ": %s is writable again: recording into it (%lld rollouts there)\n",
          b->path, (long long)b->w.records);
  return 0;
}

void tasks_buffer_close(tasks_buffer *b) {
  nd_rfile_writer_close(&b->w);
  nd_recorder_free(&b->rec);
}

void tasks_buffer_begin(tasks_buffer *b, const nudge_mocap_t *m, int64_t id, const nd_goal *g) {
  double pose[ND_ROLLOUT_OBJ];
  memcpy(pose, m->obj_pos, 3 * sizeof(double));
  memcpy(pose + 3, m->obj_quat, 4 * sizeof(double));
  const double goal[3] = {g->x, g->y, g->yaw};
  nd_recorder_begin(&b->rec, b->have_rs ? &b->rs : NULL, m->utime, pose, id, goal, b->theta,
                    b->control);
}

/* Stop recording the task and append it with outcome (ND_OUTCOME_*) unless its object
 * moved under TASKS_RECORD_MOVED_MIN (obj_path, m), or say why not. A failure is reported
 * and the runner goes on. */
void tasks_buffer_finish(tasks_buffer *b, int64_t id, int outcome, double obj_path) {
  b->last_ok = 0;
  if (!b->rec.on) return;
  char why[600];
  const nd_rollout *r;
  const int ok = nd_recorder_finish(&b->rec, outcome, &r, why, sizeof(why)) == 0;
  if (ok && obj_path < TASKS_RECORD_MOVED_MIN) {
    fprintf(stderr, PROG ": task %lld not recorded: the object moved %.3f m (under %g m), "
            "nothing of its friction to fit\n", (long long)id, obj_path, TASKS_RECORD_MOVED_MIN);
    return;
  }
  if (ok) {
    char err[512];
    if (reopen(b, err, sizeof(err)) == 0 && nd_rbuf_append(&b->w, r, err, sizeof(err)) == 0) {
      b->appended++;
      b->last_ok = 1;
      fprintf(stderr, PROG ": task %lld recorded: %d steps (%lld filled, %d cut off), %d "
              "MOCAP frames, record %lld of %s\n", (long long)id, r->n,
              (long long)b->rec.filled, b->rec.dropped, b->rec.nframes,
              (long long)b->w.records, b->w.path);
      return;
    }
    /* The rollout was sound; the file took none of it. */
    b->failed++;
    if (b->w.sys_errno)
      snprintf(b->last_err, sizeof(b->last_err), "%s [%s]", err, errno_name(b->w.sys_errno));
    else
      snprintf(b->last_err, sizeof(b->last_err), "%s", err);
    snprintf(why, sizeof(why), "%s", b->last_err);
  }
  fprintf(stderr, PROG ": task %lld not recorded: %s\n", (long long)id, why);
}
