/* Fuzz target: every message a process accepts from the network, as bytes off the wire.
 *
 * Each input is offered to the decoder of every nudge type (the fingerprint picks at most
 * one), the way the processes decode: NDP_TYPED_HANDLER for the fixed-size types, the
 * string-checking ndp_decode_episode / ndp_decode_status for the two types with strings
 * (lcm-gen 1.3.1's own decoders for those trust the length words; see ndp_validate.h).
 * A decoded message must re-encode to the bytes it came from and go through its
 * validator; whatever a validator accepts must lie inside the bounds ndp_validate.h
 * states. The adapter's parameter-history entry decoder (nd_history.h) gets the same
 * bytes. Decode, validate, clean up: any leak or bad access is a finding. */
#include <limits.h>
#include <math.h>
#include <string.h>

#include "fuzz.h"
#include "ndp.h"
#include "fuzz_history.h"
#include "ndp_validate.h"

#define FZ_MAX_ENC 16384  /* beyond any encoding: the strings are refused above 4096 */

/* Every value finite and |x| <= lim. */
static int fz_bounded(const double *x, int n, double lim) {
  for (int i = 0; i < n; i++)
    if (!isfinite(x[i]) || fabs(x[i]) > lim) return 0;
  return 1;
}

/* ---- what acceptance promises, per type ---- */

static void fz_valid_mocap(const nudge_mocap_t *m) {
  const double *q = m->obj_quat;
  FZ_CHECK(m->utime > 0 && fz_bounded(m->obj_pos, 3, NDP_MAX_POS) &&
           fz_bounded(m->ee_pos, 3, NDP_MAX_POS) && fz_bounded(q, 4, 2.0) &&
           fabs(sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) - 1.0) <= 1e-2,
           "accepted mocap out of bounds");
}

static void fz_valid_robot_state(const nudge_robot_state_t *m) {
  FZ_CHECK(m->utime > 0 && fz_bounded(m->ee_pos, 3, NDP_MAX_POS) &&
           fz_bounded(m->ee_vel, 3, NDP_MAX_VEL) && fz_bounded(m->ee_force, 3, NDP_MAX_FORCE) &&
           m->mode >= NUDGE_ROBOT_STATE_T_MODE_TRACKING &&
           m->mode <= NUDGE_ROBOT_STATE_T_MODE_STOPPED &&
           (m->reflex != NUDGE_ROBOT_STATE_T_REFLEX_NONE) ==
               (m->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED) &&
           m->reflex <= NUDGE_ROBOT_STATE_T_REFLEX_NONFINITE && m->reflex_joint >= 0 &&
           m->reflex_joint <= 7,
           "accepted robot_state out of bounds");
}

static void fz_valid_ee_cmd(const nudge_ee_cmd_t *m) {
  FZ_CHECK(m->utime > 0 && fz_bounded(m->p, 3, NDP_MAX_POS) &&
           fz_bounded(m->v, 3, NDP_MAX_VEL) && fz_bounded(m->a, 3, NDP_MAX_ACC) &&
           fz_bounded(m->j, 3, NDP_MAX_JERK) && m->mode >= NUDGE_EE_CMD_T_MODE_TRACKING && m->mode <= NUDGE_EE_CMD_T_MODE_HOLDING && m->plan_utime >= 0,
           "accepted ee_cmd out of bounds");
}

static void fz_valid_plan(const nudge_plan_t *m) {
  FZ_CHECK(m->utime > 0 && m->state_utime > 0 && m->M >= 1 &&
           m->M <= NUDGE_PLAN_T_MAX_KEYPOINTS && isfinite(m->T) && m->T > 0 && m->T <= 5.0,
           "accepted plan header out of bounds");
  for (int k = 0; k < m->M; k++)
    FZ_CHECK(fz_bounded(m->keypoints[k], 2, NDP_MAX_POS) &&
             fz_bounded(m->keypoints[k] + 2, 2, NDP_MAX_VEL), "accepted keypoint %d", k);
  FZ_CHECK(fz_bounded(m->predicted, 2, NDP_MAX_POS) && fz_bounded(m->predicted + 2, 1, 100.0),
           "accepted a prediction out of bounds");
}

static void fz_valid_arm_state(const nudge_arm_state_t *m) {
  FZ_CHECK(m->utime > 0 && fz_bounded(m->q, 7, 10.0) && fz_bounded(m->dq, 7, 100.0) &&
           fz_bounded(m->tau, 7, 1e4), "accepted arm_state out of bounds");
}

static void fz_valid_task(const nudge_task_t *m) {
  const double g[2] = {m->goal_x, m->goal_y};
  FZ_CHECK(m->utime > 0 && m->task_id >= 0 && fz_bounded(g, 2, NDP_MAX_POS) &&
           fz_bounded(&m->goal_yaw, 1, 100.0) && isfinite(m->eps) && m->eps > 0 &&
           m->eps <= 1.0 && isfinite(m->time_limit) && m->time_limit > 0 &&
           m->time_limit <= 3600.0 && isfinite(m->v_max) && m->v_max >= 0.0 &&
           m->v_max <= NDP_MAX_VEL,
           "accepted task out of bounds");
}

static void fz_valid_place(const nudge_place_t *m) {
  const double g[2] = {m->x, m->y};
  FZ_CHECK(m->utime > 0 && m->place_id >= 0 && fz_bounded(g, 2, NDP_MAX_POS) &&
           fz_bounded(&m->yaw, 1, 100.0) && isfinite(m->clear) && m->clear >= 0.0 &&
           m->clear <= NDP_MAX_PLACE_CLEAR, "accepted place out of bounds");
  const double park[2] = {m->park_x, m->park_y};
  FZ_CHECK(m->park == 0 || (m->park == 1 && fz_bounded(park, 2, NDP_MAX_POS)),
           "accepted place park out of bounds");
}

static void fz_valid_params(const nudge_params_t *m) {
  FZ_CHECK(m->utime > 0 && m->version >= 0 && m->buffer_size >= 0, "accepted params header");
  for (int i = 0; i < 7; i++) {
    const double v = m->theta_mean[i];
    const int shift = i == 5 || i == 6, positive = i == 3 || i == 4;
    FZ_CHECK(isfinite(v) && (shift ? fabs(v) <= 0.05 : v >= 0 && v <= 1e4) &&
             (!positive || v > 0) && isfinite(m->theta_std[i]) && m->theta_std[i] >= 0,
             "accepted theta[%d]", i);
  }
}

/* Bytes the processes' handler refused: it must say why. */
static void fz_bad(void *user, const char *ch, const char *why) {
  (void)user;
  (void)ch;
  FZ_CHECK(why[0] != 0, "refused without a reason");
}

/* Type T through the processes' own decoding (NDP_TYPED_HANDLER): if it decodes, the
 * message is all the bytes and re-encodes to them; then its validator and its promise. */
#define FZ_FIXED(T)                                                                       \
  static void fz_got_##T(const lcm_recv_buf_t *rb, const char *ch, const nudge_##T##_t *m, \
                         void *user) {                                                    \
    (void)ch;                                                                             \
    (void)user;                                                                           \
    const int k = nudge_##T##_t_encoded_size(m);                                          \
    FZ_CHECK(k == (int)rb->data_size, #T ": decoded %d of %d", k, (int)rb->data_size);    \
    uint8_t out[FZ_MAX_ENC];                                                              \
    FZ_CHECK(nudge_##T##_t_encode(out, 0, sizeof out, m) == k &&                          \
             memcmp(out, rb->data, (size_t)k) == 0, #T ": re-encodes differently");       \
    char why[256] = "";                                                                   \
    if (ndp_check_##T(m, why, sizeof why) == 0)                                           \
      fz_valid_##T(m);                                                                    \
    else                                                                                  \
      FZ_CHECK(why[0] != 0, #T ": refused without a reason");                             \
  }                                                                                       \
  NDP_TYPED_HANDLER(nudge_##T##_t, fz_raw_##T, fz_got_##T, fz_bad)                        \
  static void fz_##T(const uint8_t *d, int len) {                                         \
    lcm_recv_buf_t rb;                                                                    \
    memset(&rb, 0, sizeof rb);                                                            \
    rb.data = (void *)d;                                                                  \
    rb.data_size = (uint32_t)len;                                                         \
    fz_raw_##T(&rb, "FUZZ", NULL);                                                        \
  }

FZ_FIXED(mocap)
FZ_FIXED(robot_state)
FZ_FIXED(ee_cmd)
FZ_FIXED(plan)
FZ_FIXED(task)
FZ_FIXED(params)
FZ_FIXED(arm_state)
FZ_FIXED(place)

/* ---- the types with strings ---- */

static int32_t fz_be32(const uint8_t *p) {
  return (int32_t)((uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 |
                   (uint32_t)p[3]);
}

/* A string that decoded from a length word n holds n - 1 bytes unless it had a NUL
 * inside; only then is the re-encoding the input itself. */
static int fz_whole(const char *s, int32_t n) { return (int32_t)strlen(s) + 1 == n; }

static void fz_episode(const uint8_t *d, int len) {
  nudge_episode_t m, m2;
  char why[256] = "";
  if (ndp_decode_episode(d, len, &m, why, sizeof why)) {
    FZ_CHECK(why[0] != 0, "episode: refused without a reason");
    return;
  }
  FZ_CHECK(m.reason != NULL && strlen(m.reason) < (size_t)len, "episode: bad reason");
  static uint8_t out[FZ_MAX_ENC], out2[FZ_MAX_ENC];
  const int k = nudge_episode_t_encoded_size(&m);
  FZ_CHECK(k <= len && nudge_episode_t_encode(out, 0, sizeof out, &m) == k,
           "episode: encodes to %d of %d", k, len);
  if (fz_whole(m.reason, fz_be32(d + 25)))
    FZ_CHECK(memcmp(out, d, (size_t)k) == 0, "episode: re-encodes differently");
  FZ_CHECK(ndp_decode_episode(out, k, &m2, why, sizeof why) == 0, "episode: own encoding "
           "refused: %s", why);
  FZ_CHECK(nudge_episode_t_encode(out2, 0, sizeof out2, &m2) == k &&
           memcmp(out, out2, (size_t)k) == 0, "episode: second round trip differs");
  nudge_episode_t_decode_cleanup(&m2);
  nudge_episode_t_decode_cleanup(&m);
}

static void fz_status(const uint8_t *d, int len) {
  nudge_status_t m, m2;
  char why[256] = "";
  if (ndp_decode_status(d, len, &m, why, sizeof why)) {
    FZ_CHECK(why[0] != 0, "status: refused without a reason");
    return;
  }
  FZ_CHECK(m.name && m.state && strlen(m.name) < (size_t)len && strlen(m.state) < (size_t)len,
           "status: bad strings");
  static uint8_t out[FZ_MAX_ENC], out2[FZ_MAX_ENC];
  const int k = nudge_status_t_encoded_size(&m);
  FZ_CHECK(k <= len && nudge_status_t_encode(out, 0, sizeof out, &m) == k,
           "status: encodes to %d of %d", k, len);
  const int32_t n1 = fz_be32(d + 16), n2 = fz_be32(d + 16 + 4 + n1 + 4);
  if (fz_whole(m.name, n1) && fz_whole(m.state, n2))
    FZ_CHECK(memcmp(out, d, (size_t)k) == 0, "status: re-encodes differently");
  FZ_CHECK(ndp_decode_status(out, k, &m2, why, sizeof why) == 0, "status: own encoding "
           "refused: %s", why);
  FZ_CHECK(nudge_status_t_encode(out2, 0, sizeof out2, &m2) == k &&
           memcmp(out, out2, (size_t)k) == 0, "status: second round trip differs");
  nudge_status_t_decode_cleanup(&m2);
  nudge_status_t_decode_cleanup(&m);
}

/* ---- the adapter's history entry ---- */

static void fz_history(const uint8_t *d, size_t len) {
  nd_history_entry e;
  char why[256] = "";
  if (nd_history_decode(&e, d, len, why, sizeof why)) {
    FZ_CHECK(why[0] != 0, "history: refused without a reason");
    return;
  }
  FZ_CHECK(nd_history_check(&e, why, sizeof why) == 0, "history: decoded invalid: %s", why);
  fz_history_reencodes(d, len, &e, "history");
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size > INT_MAX / 2) return 0;  /* LCM lengths are int; a datagram is < 64 KB */
  const int len = (int)size;
  fz_mocap(data, len);
  fz_robot_state(data, len);
  fz_ee_cmd(data, len);
  fz_plan(data, len);
  fz_task(data, len);
  fz_params(data, len);
  fz_arm_state(data, len);
  fz_place(data, len);
  fz_episode(data, len);
  fz_status(data, len);
  fz_history(data, size);
  return 0;
}
