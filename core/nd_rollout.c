/* nd_rollout: storage and the byte encoding of a recorded task (layout in nd_rollout.h).
 *
 * Bytes are assembled with shifts, not by casting the struct, so the encoding is the
 * same on every host and immune to padding. check() is shared by encode and decode:
 * whatever the writer accepts, the reader accepts, and nothing else. */
#include "nd_rollout.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The metadata doubles after dt, in encoding order. */
static const struct {
  const char *name;
  size_t offset;
  int count;
} nd_rollout_meta[] = {
    {"goal", offsetof(nd_rollout, goal), 3},
    {"theta", offsetof(nd_rollout, theta), ND_NTHETA_PAPER},
    {"obj_pos", offsetof(nd_rollout, obj_pos), 3},
    {"obj_quat", offsetof(nd_rollout, obj_quat), 4},
    {"obj_vel", offsetof(nd_rollout, obj_vel), 6},
    {"ee_pos", offsetof(nd_rollout, ee_pos), 2},
    {"ee_vel", offsetof(nd_rollout, ee_vel), 2},
};
#define ND_ROLLOUT_NMETA (int)(sizeof(nd_rollout_meta) / sizeof(nd_rollout_meta[0]))

static const double *nd_rollout_meta_ptr(const nd_rollout *r, int k) {
  return (const double *)((const char *)r + nd_rollout_meta[k].offset);
}

int nd_rollout_alloc(nd_rollout *r, int n) {
  r->u = r->obj = r->ee = r->sp = NULL;
  r->n = 0;
  if (n < 0 || n > ND_ROLLOUT_MAX_STEPS) return -1;
  if (n == 0) return 0;
  r->u = calloc((size_t)n * 2, sizeof(double));
  r->obj = calloc((size_t)n * ND_ROLLOUT_OBJ, sizeof(double));
  r->ee = calloc((size_t)n * 2, sizeof(double));
  r->sp = calloc((size_t)n * 6, sizeof(double));
  if (!r->u || !r->obj || !r->ee || !r->sp) {
    nd_rollout_free(r);
    return -1;
  }
  r->n = n;
  return 0;
}

void nd_rollout_free(nd_rollout *r) {
  free(r->u);
  free(r->obj);
  free(r->ee);
  free(r->sp);
  r->u = r->obj = r->ee = r->sp = NULL;
  r->n = 0;
}

int nd_rollout_copy(nd_rollout *dst, const nd_rollout *src) {
  nd_rollout t = *src;
  if (nd_rollout_alloc(&t, src->n)) {
    *dst = t;
    return -1;
  }
  const size_t n = (size_t)src->n;
  memcpy(t.u, src->u, sizeof(double) * 2 * n);
  memcpy(t.obj, src->obj, sizeof(double) * ND_ROLLOUT_OBJ * n);
  memcpy(t.ee, src->ee, sizeof(double) * 2 * n);
  memcpy(t.sp, src->sp, sizeof(double) * 6 * n);
  *dst = t;
  return 0;
}

double *nd_rollout_obj(const nd_rollout *r, int i) { return r->obj + ND_ROLLOUT_OBJ * i; }

double nd_rollout_duration(const nd_rollout *r) { return r->n * r->dt; }

size_t nd_rollout_encoded_size(int n) {
  return ND_ROLLOUT_ENC_FIXED + (size_t)(n > 0 ? n : 0) * ND_ROLLOUT_ENC_STEP;
}

/* -1 with "name[i][j] = value" if some entry of the rows x cols array is not finite. */
static int nd_rollout_check_array(const double *a, int rows, int cols, const char *name,
                                  char *err, int errlen) {
  for (int i = 0; i < rows; i++)
    for (int j = 0; j < cols; j++)
      if (!isfinite(a[i * cols + j])) {
        snprintf(err, (size_t)errlen, "rollout: %s[%d][%d] = %g is not finite", name, i, j,
                 a[i * cols + j]);
        return -1;
      }
  return 0;
}

/* -1 with "name = (w, x, y, z) has norm ..." unless q's norm is within ND_ROLLOUT_QUAT_TOL
 * of 1 (q finite). */
static int nd_rollout_check_quat(const double q[4], const char *name, int i, char *err,
                                 int errlen) {
  const double norm = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (fabs(norm - 1) <= ND_ROLLOUT_QUAT_TOL) return 0;
  char at[16] = "";
  if (i >= 0) snprintf(at, sizeof(at), "[%d]", i);
  snprintf(err, (size_t)errlen,
           "rollout: %s%s = (%g, %g, %g, %g) has norm %g, not a unit quaternion", name, at,
           q[0], q[1], q[2], q[3], norm);
  return -1;
}

int nd_rollout_check(const nd_rollout *r, char *err, int errlen) {
  if (r->n < 1 || r->n > ND_ROLLOUT_MAX_STEPS) {
    snprintf(err, (size_t)errlen, "rollout: n = %d steps is out of [1, %d]", (int)r->n,
             ND_ROLLOUT_MAX_STEPS);
    return -1;
  }
  if (r->outcome != ND_OUTCOME_SUCCESS && r->outcome != ND_OUTCOME_TIMEOUT &&
      r->outcome != ND_OUTCOME_ABORTED) {
    snprintf(err, (size_t)errlen, "rollout: outcome = %d is unknown (1 success, 2 timeout, "
             "3 aborted)", (int)r->outcome);
    return -1;
  }
  if (r->control != ND_CTRL_FORCE && r->control != ND_CTRL_VELOCITY) {
    snprintf(err, (size_t)errlen, "rollout: control = %d is unknown (0 force, 1 velocity)",
             (int)r->control);
    return -1;
  }
  if (!(isfinite(r->dt) && r->dt > 0)) {
    snprintf(err, (size_t)errlen, "rollout: dt = %g s, expected a finite step > 0", r->dt);
    return -1;
  }
  for (int k = 0; k < ND_ROLLOUT_NMETA; k++) {
    const double *v = nd_rollout_meta_ptr(r, k);
    for (int i = 0; i < nd_rollout_meta[k].count; i++)
      if (!isfinite(v[i])) {
        snprintf(err, (size_t)errlen, "rollout: %s[%d] = %g is not finite",
                 nd_rollout_meta[k].name, i, v[i]);
        return -1;
      }
  }
  if (!r->u || !r->obj || !r->ee || !r->sp) {
    snprintf(err, (size_t)errlen, "rollout: n = %d but the step arrays are not allocated",
             (int)r->n);
    return -1;
  }
  if (nd_rollout_check_array(r->u, r->n, 2, "u", err, errlen) ||
      nd_rollout_check_array(r->obj, r->n, ND_ROLLOUT_OBJ, "obj", err, errlen) ||
      nd_rollout_check_array(r->ee, r->n, 2, "ee", err, errlen) ||
      nd_rollout_check_array(r->sp, r->n, 6, "sp", err, errlen) ||
      nd_rollout_check_quat(r->obj_quat, "obj_quat", -1, err, errlen))
    return -1;
  for (int i = 0; i < r->n; i++)
    if (nd_rollout_check_quat(nd_rollout_obj(r, i) + 3, "obj quaternion", i, err, errlen))
      return -1;
  return 0;
}

/* ---- little-endian primitives ---- */

static unsigned char *nd_put_u32(unsigned char *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (unsigned char)(v >> (8 * i));
  return p + 4;
}

static unsigned char *nd_put_u64(unsigned char *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (unsigned char)(v >> (8 * i));
  return p + 8;
}

static unsigned char *nd_put_f64(unsigned char *p, const double *v, size_t count) {
  for (size_t k = 0; k < count; k++) {
    uint64_t bits;
    memcpy(&bits, &v[k], 8);
    p = nd_put_u64(p, bits);
  }
  return p;
}

static uint32_t nd_get_u32(const unsigned char *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint64_t nd_get_u64(const unsigned char *p) {
  return (uint64_t)nd_get_u32(p) | (uint64_t)nd_get_u32(p + 4) << 32;
}

static const unsigned char *nd_get_f64(const unsigned char *p, double *v, size_t count) {
  for (size_t k = 0; k < count; k++) {
    uint64_t bits = nd_get_u64(p);
    memcpy(&v[k], &bits, 8);
    p += 8;
  }
  return p;
}

int nd_rollout_encode(const nd_rollout *r, unsigned char *buf, size_t cap, size_t *len,
                      char *err, int errlen) {
  if (nd_rollout_check(r, err, errlen)) return -1;
  const size_t need = nd_rollout_encoded_size(r->n);
  if (cap < need) {
    snprintf(err, (size_t)errlen, "rollout: encoding needs %zu bytes, buffer holds %zu",
             need, cap);
    return -1;
  }
  unsigned char *p = buf;
  p = nd_put_u32(p, ND_ROLLOUT_ENC_VERSION);
  p = nd_put_u32(p, (uint32_t)r->n);
  p = nd_put_u64(p, (uint64_t)r->task_id);
  p = nd_put_u64(p, (uint64_t)r->utime);
  p = nd_put_u32(p, (uint32_t)r->outcome);
  p = nd_put_u32(p, (uint32_t)r->control);
  p = nd_put_f64(p, &r->dt, 1);
  for (int k = 0; k < ND_ROLLOUT_NMETA; k++)
    p = nd_put_f64(p, nd_rollout_meta_ptr(r, k), (size_t)nd_rollout_meta[k].count);
  p = nd_put_f64(p, r->u, (size_t)r->n * 2);
  p = nd_put_f64(p, r->obj, (size_t)r->n * ND_ROLLOUT_OBJ);
  p = nd_put_f64(p, r->ee, (size_t)r->n * 2);
  p = nd_put_f64(p, r->sp, (size_t)r->n * 6);
  *len = (size_t)(p - buf);
  return 0;
}

int nd_rollout_decode(nd_rollout *r, const unsigned char *buf, size_t len, char *err,
                      int errlen) {
  r->u = r->obj = r->ee = r->sp = NULL;
  r->n = 0;
  if (len < ND_ROLLOUT_ENC_FIXED) {
    snprintf(err, (size_t)errlen, "rollout: %zu bytes, shorter than the %d-byte fixed part",
             len, ND_ROLLOUT_ENC_FIXED);
    return -1;
  }
  const uint32_t version = nd_get_u32(buf);
  if (version == 2) {
    snprintf(err, (size_t)errlen,
             "rollout: encoding version 2 (object x, y, yaw only), this build reads %d: its "
             "replay needs the object's full pose; record the rollouts again",
             ND_ROLLOUT_ENC_VERSION);
    return -1;
  }
  if (version != ND_ROLLOUT_ENC_VERSION) {
    snprintf(err, (size_t)errlen, "rollout: encoding version %u, this build reads %d",
             (unsigned)version, ND_ROLLOUT_ENC_VERSION);
    return -1;
  }
  /* n is checked before anything is sized from it: a corrupt n must not allocate. */
  const int32_t n = (int32_t)nd_get_u32(buf + 4);
  if (n < 1 || n > ND_ROLLOUT_MAX_STEPS) {
    snprintf(err, (size_t)errlen, "rollout: n = %d steps is out of [1, %d]", (int)n,
             ND_ROLLOUT_MAX_STEPS);
    return -1;
  }
  if (len != nd_rollout_encoded_size(n)) {
    snprintf(err, (size_t)errlen, "rollout: %zu bytes, but n = %d steps needs exactly %zu",
             len, (int)n, nd_rollout_encoded_size(n));
    return -1;
  }
  const unsigned char *p = buf + 8;
  r->task_id = (int64_t)nd_get_u64(p);
  r->utime = (int64_t)nd_get_u64(p + 8);
  r->outcome = (int32_t)nd_get_u32(p + 16);
  r->control = (int32_t)nd_get_u32(p + 20);
  p = nd_get_f64(p + 24, &r->dt, 1);
  for (int k = 0; k < ND_ROLLOUT_NMETA; k++)
    p = nd_get_f64(p, (double *)((char *)r + nd_rollout_meta[k].offset),
                   (size_t)nd_rollout_meta[k].count);
  if (nd_rollout_alloc(r, n)) {
    snprintf(err, (size_t)errlen, "rollout: out of memory for %d steps", (int)n);
    return -1;
  }
  p = nd_get_f64(p, r->u, (size_t)n * 2);
  p = nd_get_f64(p, r->obj, (size_t)n * ND_ROLLOUT_OBJ);
  p = nd_get_f64(p, r->ee, (size_t)n * 2);
  nd_get_f64(p, r->sp, (size_t)n * 6);
  if (nd_rollout_check(r, err, errlen)) {
    nd_rollout_free(r);
    return -1;
  }
  return 0;
}
