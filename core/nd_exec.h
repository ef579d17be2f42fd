/* nd_exec: the executor's trajectory logic, on plain arrays (no LCM, no clock).
 *
 * The executor commands one planar trajectory that is continuous in position,
 * velocity, acceleration and jerk for all time. It is made of at most three pieces:
 *
 *   tracking segment  min-snap segment toward the newest plan's first keypoint,
 *                     started at the plan's arrival time from the trajectory's state
 *                     at that instant;
 *   brake segment     min-snap segment from a state on the tracking segment to rest
 *                     (v = a = j = 0); it departs at the tracking segment's end, or
 *                     earlier when the inputs go stale;
 *   hold              rest at the brake's end position, exactly still.
 *
 * Every piece is checked in continuous time against the speed, acceleration and jerk
 * limits before it is committed (a sampled maximum plus a rigorous bound on what lies
 * between samples), so no time at which the executor is later asked can give a
 * setpoint beyond the limits. A request that cannot be met within the limits is
 * rejected and the committed trajectory is left unchanged. The bound costs 1-2% of
 * conservatism, so a speed exactly at v_max cannot be certified: keypoint speeds within
 * ~0.1% of v_max are refused (ND_EXEC_ELIMIT), and emitted speeds stay just below it.
 *
 * Workspace: keypoints must lie in a box, and every committed piece (tracking segment and
 * its brake, and a brake begun when the inputs go stale) must stay within the box plus a
 * margin, bounded in continuous time like the limits. A plan that breaks either is
 * refused (ND_EXEC_EBOX), never clipped: see nd_exec.c for why.
 *
 * Times are seconds on one monotonic clock (the caller's); positions metres. */
#ifndef ND_EXEC_H
#define ND_EXEC_H

#include "nd_snap.h"

/* Limits and search settings; constant while the executor runs, and must pass
 * nd_exec_cfg_check (the other functions trust it). */
typedef struct {
  double v_max;        /* bound on planar speed |v|, m/s (Panda Cartesian: 1.7) */
  double a_max;        /* bound on |a|, m/s^2 (Panda: 13) */
  double j_max;        /* bound on |j|, m/s^3 (Panda: 6500) */
  double brake_a_max;  /* bound on |a| of the brake begun when the inputs go stale, m/s^2;
                        * 0: a_max. An arm's joints may take less than its Cartesian a_max in
                        * some directions, and that brake is not planned against them */
  double t_min;        /* shortest segment, s; shorter requests start the search here */
  double t_max;        /* longest tracking or brake segment, s; beyond it: rejected */
  double stretch;      /* factor (> 1) by which a segment's duration grows per try */
  int    n_check;      /* samples per limit check (>= 2) */
  double ws_lo[2];     /* workspace box, m: lower x, y bounds of every keypoint */
  double ws_hi[2];     /* upper x, y bounds (> ws_lo) */
  double ws_margin;    /* m (>= 0): how far the trajectory may leave the box between and
                        * beyond keypoints (a segment's overshoot, a brake's travel) */
} nd_exec_cfg;

/* The default workspace, also the planner's default keypoint box (nds_planner_cfg), and
 * the room its trajectories need beyond it: a segment's overshoot and a brake's travel
 * (nd_exec.c; doc/decisions.md#workspace). */
#define ND_EXEC_WS_LO (-0.5)
#define ND_EXEC_WS_HI 0.5
#define ND_EXEC_WS_MARGIN 0.04

/* Modes, as in nudge_ee_cmd_t.mode. */
enum {
  ND_EXEC_TRACK = 0,   /* on the tracking segment; a brake to rest follows its end */
  ND_EXEC_STOPPING,    /* committed to rest: on the brake (or still before its departure) */
  ND_EXEC_HOLD         /* at rest, setpoint constant */
};

/* Return codes. */
enum {
  ND_EXEC_OK = 0,
  ND_EXEC_EINVAL = -1, /* non-finite input or T <= 0 */
  ND_EXEC_ELIMIT = -2, /* no duration up to t_max keeps the segment within the limits */
  ND_EXEC_EBOX = -3    /* a keypoint outside the workspace, or a trajectory leaving its margin */
};

/* Mutable state; one per executor, plain data (copyable). Read-only for callers. */
typedef struct {
  int mode;            /* ND_EXEC_TRACK / _STOPPING / _HOLD */
  double t_last;       /* latest time passed to step or plan; time never goes back */
  double sp[2][4];     /* last setpoint from nd_exec_step, [axis][p, v, a, j] */
  nd_snap_seg seg;     /* tracking segment; seg.T is the duration actually used */
  double t_seg;        /* its start time */
  nd_snap_seg brake;   /* brake to rest, departing from seg at t_brake */
  double t_brake;      /* departure time of the brake (<= t_seg + seg.T) */
  double hold[2];      /* rest position: end of the brake */
} nd_exec;

/* Defaults: Panda Cartesian limits 1.7 m/s, 13 m/s^2, 6500 m/s^3, brakes at a_max; t_min
 * 0.01 s, t_max 2 s, stretch 1.1, n_check 64; workspace [-0.5, 0.5]^2 m, margin 0.04 m. */
nd_exec_cfg nd_exec_cfg_default(void);

/* The acceleration bound of the brake begun when the inputs go stale: brake_a_max where
 * set and below a_max, else a_max. */
double nd_exec_stale_brake_a(const nd_exec_cfg *cfg);

/* Check cfg (finite positive limits, brake_a_max finite and >= 0, t_min < t_max, stretch
 * > 1, n_check >= 2, a finite workspace with lo < hi, margin finite and >= 0).
 * Returns ND_EXEC_OK or ND_EXEC_EINVAL with a message in err. */
int nd_exec_cfg_check(const nd_exec_cfg *cfg, char *err, int errlen);

/* Start at rest, holding position p[2] (e.g. the measured end-effector) at time now. */
void nd_exec_init(nd_exec *ex, const double p[2], double now);

/* Commit a new tracking segment toward key = (x, y, vx, vy) with requested duration T,
 * starting at now from the trajectory's state at now (p, v, a, j: continuous); a now
 * before the last call counts as the last call's time. T is
 * stretched (by cfg->stretch steps, from at least t_min) until the segment and its
 * brake to rest at the end stay within the limits. Returns ND_EXEC_OK (mode TRACK,
 * ex->seg.T the duration used), or a negative code with a message in err and ex
 * unchanged: ND_EXEC_EBOX if key lies outside the workspace or the segment or its brake
 * leaves the workspace plus margin. O(log(t_max / T) * n_check). */
int nd_exec_plan(nd_exec *ex, const nd_exec_cfg *cfg, double now, const double key[4],
                 double T, char *err, int errlen);

/* Plan acceptance by workspace: ND_EXEC_OK if each of the n keypoints (x, y, vx, vy)
 * lies in the box (bounds included), else ND_EXEC_EBOX naming the first outside and the box. */
int nd_exec_keys_check(const nd_exec_cfg *cfg, const double (*keys)[4], int n, char *err,
                       int errlen);

/* A keypoint within this (m, m/s, per component) of the one the running segment is
 * heading for is that keypoint re-sent: the planner found nothing better and published its
 * previous best again, bit for bit. Anything its search changes moves by centimetres.
 * Such a plan renews the segment instead of restarting it: restarting postpones the
 * keypoint each time, and a segment from rest restarted every plan never gets going
 * (doc/decisions.md#exec-keep-segment). */
#define ND_EXEC_SAME_KEY 1e-6

/* 1 if ex is on a tracking segment that has not ended at now and that ends at key =
 * (x, y, vx, vy), each component within tol (m, m/s): a plan re-sending that keypoint
 * asks for nothing the segment is not doing already. 0 otherwise (stopping, holding). */
int nd_exec_heading_to(const nd_exec *ex, double now, const double key[4], double tol);

/* Setpoint at time now into out[axis][p, v, a, j]; returns the mode. If stale is
 * nonzero in mode TRACK, commits to stopping: of a few candidate brake departures from
 * now to the segment's end (now, unless the segment accelerates beyond brake_a_max there),
 * the one reaching rest first within the limits, brake_a_max and the workspace margin, else
 * the brake planned at the end. A non-finite now or one before the last call is treated as
 * the last call's time. No allocation; O(1) except the one brake search when going stale. */
int nd_exec_step(nd_exec *ex, const nd_exec_cfg *cfg, double now, int stale,
                 double out[2][4]);

/* State of the committed trajectory at time t >= ex->t_last, without changing ex. */
void nd_exec_eval(const nd_exec *ex, double t, double out[2][4]);

/* What the executor will command if no plan comes: the tracking segment ends at key at
 * t_seg_end, the brake departs at t_brake and rests at hold at t_rest, the hold follows.
 * Every piece is a min-snap segment that ends with a = j = 0, so a receiver that knows
 * one setpoint (p, v, a, j) and these ends rebuilds the rest exactly: the 7th-degree
 * polynomial through four conditions at each end is unique (nd_exec_future_eval). */
typedef struct {
  double t_seg_end;    /* end of the tracking segment (<= t_brake unless braking early) */
  double key[4];       /* its end state (x, y, vx, vy) */
  double t_brake;      /* departure of the brake */
  double t_rest;       /* its end: at rest from here */
  double hold[2];      /* rest position */
} nd_exec_future;

/* The committed trajectory's future, on ex's clock. */
void nd_exec_future_get(const nd_exec *ex, nd_exec_future *f);

/* The setpoint out[axis][p, v, a, j] at time t1 >= t of the trajectory whose setpoint at t
 * is sp and whose future is f (the same clock). Exact to rounding wherever a piece has
 * more than ND_EXEC_REBUILD_MIN left at t; a piece ending sooner is taken as ended. */
void nd_exec_future_eval(const double sp[2][4], double t, const nd_exec_future *f, double t1,
                         double out[2][4]);

/* Shortest piece remainder rebuilt from a setpoint, s: the polynomial through conditions
 * this close together magnifies rounding by 1/T^7. */
#define ND_EXEC_REBUILD_MIN 1e-3

/* Bounds over [0, seg->T] of speed, |acceleration| and |jerk| (max[0..2]) from n
 * samples plus a rigorous bound on the excursion between them. */
void nd_exec_seg_bounds(const nd_snap_seg *seg, int n, double max[3]);

/* Name of a mode ("tracking", "stopping", "holding"). */
const char *nd_exec_mode_name(int mode);

#endif
