/* ndp_validate: range and finiteness checks of every input message. */
#include "ndp_validate.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "nd_theta.h"

/* 0 if all n values are finite and |x| <= lim, else -1 with "<what>[i] = v". */
static int vec_ok(const double *x, int n, double lim, const char *what, char *why, int len) {
  for (int i = 0; i < n; i++)
    if (!isfinite(x[i]) || fabs(x[i]) > lim) {
      snprintf(why, len, "%s[%d] = %g is not finite or beyond %g", what, i, x[i], lim);
      return -1;
    }
  return 0;
}

static int utime_ok(int64_t utime, char *why, int len) {
  if (utime <= 0) {
    snprintf(why, len, "utime = %lld is not a time", (long long)utime);
    return -1;
  }
  return 0;
}

static int quat_ok(const double q[4], const char *what, char *why, int len) {
  if (vec_ok(q, 4, 2.0, what, why, len)) return -1;
  double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (fabs(n - 1.0) > 1e-2) {
    snprintf(why, len, "%s has norm %g, not a unit quaternion", what, n);
    return -1;
  }
  return 0;
}

int ndp_check_mocap(const nudge_mocap_t *m, char *why, int len) {
  if (utime_ok(m->utime, why, len) || vec_ok(m->obj_pos, 3, NDP_MAX_POS, "obj_pos", why, len) ||
      quat_ok(m->obj_quat, "obj_quat", why, len) ||
      vec_ok(m->ee_pos, 3, NDP_MAX_POS, "ee_pos", why, len))
    return -1;
  return 0;
}

int ndp_check_robot_state(const nudge_robot_state_t *m, char *why, int len) {
  if (utime_ok(m->utime, why, len) || vec_ok(m->ee_pos, 3, NDP_MAX_POS, "ee_pos", why, len) ||
      vec_ok(m->ee_vel, 3, NDP_MAX_VEL, "ee_vel", why, len) ||
      vec_ok(m->ee_force, 3, NDP_MAX_FORCE, "ee_force", why, len))
    return -1;
  if (m->mode < NUDGE_ROBOT_STATE_T_MODE_TRACKING || m->mode > NUDGE_ROBOT_STATE_T_MODE_STOPPED) {
    snprintf(why, len, "mode = %d is not a known mode", m->mode);
    return -1;
  }
  if (m->reflex < NUDGE_ROBOT_STATE_T_REFLEX_NONE ||
      m->reflex > NUDGE_ROBOT_STATE_T_REFLEX_NONFINITE ||
      (m->reflex != NUDGE_ROBOT_STATE_T_REFLEX_NONE) != (m->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED) ||
      m->reflex_joint < 0 || m->reflex_joint > 7) {
    snprintf(why, len, "reflex %d on joint %d with mode %d is not a known reflex", m->reflex,
             m->reflex_joint, m->mode);
    return -1;
  }
  return 0;
}

int ndp_check_ee_cmd(const nudge_ee_cmd_t *m, char *why, int len) {
  if (utime_ok(m->utime, why, len) || vec_ok(m->p, 3, NDP_MAX_POS, "p", why, len) ||
      vec_ok(m->v, 3, NDP_MAX_VEL, "v", why, len) || vec_ok(m->a, 3, NDP_MAX_ACC, "a", why, len) ||
      vec_ok(m->j, 3, NDP_MAX_JERK, "j", why, len))
    return -1;
  if (m->mode < NUDGE_EE_CMD_T_MODE_TRACKING || m->mode > NUDGE_EE_CMD_T_MODE_HOLDING) {
    snprintf(why, len, "mode = %d is not a known mode", m->mode);
    return -1;
  }
  if (m->plan_utime < 0) {
    snprintf(why, len, "plan_utime = %lld is negative", (long long)m->plan_utime);
    return -1;
  }
  if (vec_ok(m->seg_key, 2, NDP_MAX_POS, "seg_key position", why, len) ||
      vec_ok(m->seg_key + 2, 2, NDP_MAX_VEL, "seg_key velocity", why, len) ||
      vec_ok(m->hold, 2, NDP_MAX_POS, "hold", why, len))
    return -1;
  /* The pieces follow one another; a future more than a minute away is no executor's. */
  const int64_t t[3] = {m->seg_end_utime, m->brake_utime, m->rest_utime};
  static const char *name[3] = {"seg_end_utime", "brake_utime", "rest_utime"};
  for (int k = 0; k < 3; k++)
    if (t[k] <= 0 || t[k] > m->utime + 60000000) {
      snprintf(why, len, "%s = %lld is not within a minute of utime %lld", name[k],
               (long long)t[k], (long long)m->utime);
      return -1;
    }
  if (m->rest_utime < m->brake_utime) {
    snprintf(why, len, "rest_utime %lld is before brake_utime %lld", (long long)m->rest_utime,
             (long long)m->brake_utime);
    return -1;
  }
  return 0;
}

int ndp_check_plan(const nudge_plan_t *m, char *why, int len) {
  if (utime_ok(m->utime, why, len) || utime_ok(m->state_utime, why, len)) return -1;
  if (m->start_utime < 0) {
    snprintf(why, len, "start_utime = %lld is negative", (long long)m->start_utime);
    return -1;
  }
  if (vec_ok(m->start_p, 2, NDP_MAX_POS, "start_p", why, len)) return -1;
  if (m->M < 1 || m->M > NUDGE_PLAN_T_MAX_KEYPOINTS) {
    snprintf(why, len, "M = %d is outside [1, %d]", m->M, NUDGE_PLAN_T_MAX_KEYPOINTS);
    return -1;
  }
  if (!isfinite(m->T) || m->T <= 0.0 || m->T > 5.0) {
    snprintf(why, len, "T = %g is outside (0, 5] s", m->T);
    return -1;
  }
  for (int k = 0; k < m->M; k++) {
    if (vec_ok(m->keypoints[k], 2, NDP_MAX_POS, "keypoint position", why, len) ||
        vec_ok(m->keypoints[k] + 2, 2, NDP_MAX_VEL, "keypoint velocity", why, len))
      return -1;
  }
  /* The prediction is for drawing and figures: a diverged rollout may predict nonsense,
   * but never a number the receivers cannot hold. */
  if (vec_ok(m->predicted, 2, NDP_MAX_POS, "predicted", why, len) ||
      vec_ok(m->predicted + 2, 1, 100.0, "predicted yaw", why, len))
    return -1;
  return 0;
}

int ndp_check_task(const nudge_task_t *m, char *why, int len) {
  const double g[3] = {m->goal_x, m->goal_y, m->goal_yaw};
  if (utime_ok(m->utime, why, len) || vec_ok(g, 2, NDP_MAX_POS, "goal", why, len) ||
      vec_ok(g + 2, 1, 100.0, "goal_yaw", why, len))
    return -1;
  if (!isfinite(m->eps) || m->eps <= 0.0 || m->eps > 1.0) {
    snprintf(why, len, "eps = %g is outside (0, 1]", m->eps);
    return -1;
  }
  if (!isfinite(m->time_limit) || m->time_limit <= 0.0 || m->time_limit > 3600.0) {
    snprintf(why, len, "time_limit = %g is outside (0, 3600] s", m->time_limit);
    return -1;
  }
  if (!isfinite(m->v_max) || m->v_max < 0.0 || m->v_max > NDP_MAX_VEL) {
    snprintf(why, len, "v_max = %g is outside [0, %g] m/s (0: the planner's own)", m->v_max,
             NDP_MAX_VEL);
    return -1;
  }
  if (m->task_id < 0) {
    snprintf(why, len, "task_id = %lld is negative", (long long)m->task_id);
    return -1;
  }
  return 0;
}

int ndp_check_place(const nudge_place_t *m, char *why, int len) {
  const double g[3] = {m->x, m->y, m->yaw};
  if (utime_ok(m->utime, why, len) || vec_ok(g, 2, NDP_MAX_POS, "pose", why, len) ||
      vec_ok(g + 2, 1, 100.0, "yaw", why, len))
    return -1;
  if (!isfinite(m->clear) || m->clear < 0.0 || m->clear > NDP_MAX_PLACE_CLEAR) {
    snprintf(why, len, "clear = %g is outside [0, %g] m", m->clear, NDP_MAX_PLACE_CLEAR);
    return -1;
  }
  if (m->place_id < 0) {
    snprintf(why, len, "place_id = %lld is negative", (long long)m->place_id);
    return -1;
  }
  if (m->park != 0 && m->park != 1) {
    snprintf(why, len, "park = %d is neither 0 nor 1", m->park);
    return -1;
  }
  const double park[2] = {m->park_x, m->park_y};
  return m->park && vec_ok(park, 2, NDP_MAX_POS, "park", why, len) ? -1 : 0;
}

int ndp_check_params(const nudge_params_t *m, char *why, int len) {
  char th[200];
  if (utime_ok(m->utime, why, len)) return -1;
  if (nd_theta_check(m->theta_mean, th, sizeof(th))) {
    snprintf(why, len, "theta_mean: %s", th);
    return -1;
  }
  for (int i = 0; i < ND_NTHETA; i++) {
    const double s = m->theta_std[i];
    if (!isfinite(s) || s < 0.0) {
      snprintf(why, len, "theta_std[%d] (%s) = %g is not a valid std", i, nd_theta_name[i], s);
      return -1;
    }
  }
  if (m->version < 0 || m->buffer_size < 0) {
    snprintf(why, len, "version %lld / buffer_size %d must not be negative",
             (long long)m->version, m->buffer_size);
    return -1;
  }
  return 0;
}

int ndp_check_episode(const nudge_episode_t *m, char *why, int len) {
  if (utime_ok(m->utime, why, len)) return -1;
  if (m->task_id < 0) {
    snprintf(why, len, "task_id = %lld is negative", (long long)m->task_id);
    return -1;
  }
  if (m->event < NUDGE_EPISODE_T_EVENT_START || m->event > NUDGE_EPISODE_T_EVENT_STOPPED) {
    snprintf(why, len, "event = %d is not a known event", m->event);
    return -1;
  }
  return 0;
}

int ndp_check_arm_state(const nudge_arm_state_t *m, char *why, int len) {
  /* Bounds far beyond any arm's joints (a few rad, a few rad/s, hundreds of N m). */
  if (utime_ok(m->utime, why, len) || vec_ok(m->q, 7, 10.0, "q", why, len) ||
      vec_ok(m->dq, 7, 100.0, "dq", why, len) || vec_ok(m->tau, 7, 1e4, "tau", why, len))
    return -1;
  return 0;
}

/* Longest string accepted, NUL included: far beyond what the contracts allow (reason <
 * 256, names < 64 bytes), so only nonsense is refused. */
#define NDP_MAX_STRING 4096

/* Step *pos over a string field of an encoding of len bytes: its int32 length word
 * (big-endian, NUL included) must be in [1, NDP_MAX_STRING], the bytes must be in the
 * buffer and end with NUL. 0, or -1 with a reason. */
static int skip_string(const unsigned char *b, int len, int *pos, const char *what, char *why,
                       int wlen) {
  if (*pos + 4 > len) {
    snprintf(why, wlen, "message ends before %s (%d bytes)", what, len);
    return -1;
  }
  const uint32_t u = (uint32_t)b[*pos] << 24 | (uint32_t)b[*pos + 1] << 16 |
                     (uint32_t)b[*pos + 2] << 8 | (uint32_t)b[*pos + 3];
  const int32_t n = (int32_t)u;
  if (n < 1 || n > NDP_MAX_STRING || n > len - *pos - 4) {
    snprintf(why, wlen, "%s has length %d in a message of %d bytes", what, (int)n, len);
    return -1;
  }
  if (b[*pos + 4 + n - 1] != 0) {
    snprintf(why, wlen, "%s is not NUL-terminated", what);
    return -1;
  }
  *pos += 4 + n;
  return 0;
}

/* Enough bytes left for the fixed-size fields after the last string? */
static int tail_ok(int pos, int need, int len, char *why, int wlen) {
  if (pos + need > len) {
    snprintf(why, wlen, "message of %d bytes is truncated", len);
    return -1;
  }
  return 0;
}

int ndp_decode_episode(const void *buf, int len, nudge_episode_t *m, char *why, int wlen) {
  /* fingerprint, utime, task_id, event | reason | time, task_error */
  int pos = 8 + 8 + 8 + 1;
  if (len < 0 || skip_string(buf, len, &pos, "reason", why, wlen) ||
      tail_ok(pos, 8 + 8, len, why, wlen))
    return -1;
  /* Every length now holds, so only the fingerprint can fail, and it is checked before
   * anything is allocated. */
  if (nudge_episode_t_decode(buf, 0, len, m) < 0) {
    snprintf(why, wlen, "not a nudge_episode_t (fingerprint)");
    return -1;
  }
  return 0;
}

int ndp_decode_status(const void *buf, int len, nudge_status_t *m, char *why, int wlen) {
  /* fingerprint, utime | name | pid | state | 3 int64, 3 int32, int64, double */
  int pos = 8 + 8;
  if (len < 0 || skip_string(buf, len, &pos, "name", why, wlen)) return -1;
  pos += 4;
  if (skip_string(buf, len, &pos, "state", why, wlen) ||
      tail_ok(pos, 3 * 8 + 3 * 4 + 8 + 8, len, why, wlen))
    return -1;
  if (nudge_status_t_decode(buf, 0, len, m) < 0) {
    snprintf(why, wlen, "not a nudge_status_t (fingerprint)");
    return -1;
  }
  return 0;
}

int ndp_take_episode(const void *buf, int len, nudge_episode_t *m, char *why, int wlen) {
  if (ndp_decode_episode(buf, len, m, why, wlen)) return -1;
  if (ndp_check_episode(m, why, wlen) == 0) return 0;
  nudge_episode_t_decode_cleanup(m);
  return -1;
}
