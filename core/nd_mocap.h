/* nd_mocap: motion capture as a lab has it, for an emulated world: frames at the capture
 * rate, Gaussian noise on position and orientation, a latency (each frame is released for
 * publication a while after its capture), and dropped frames (occlusions come in bursts).
 * Seeded: the same seed and poses give the same frames. Allocation-free.
 *
 * Defaults, from published figures of OptiTrack-class systems (the paper's):
 *  - latency: 4.17 ms camera latency at 240 Hz (exposure centre to the 2D data; OptiTrack
 *    documentation, "Latency Measurements", PrimeX 41) plus ~1.5 ms of solving and
 *    streaming: 6 ms, with +-0.5 ms jitter;
 *  - position noise: 0.1 mm per axis. Krumpek et al. 2025 (arXiv:2502.21189) measured
 *    per-plane noise standard deviations of 0.02-0.07 mm with PrimeX 22 cameras on a
 *    precision rig, accuracies of +-0.12 mm across and +-0.74 mm along the line of sight;
 *    a rigid body's pose from a few markers in an ordinary lab is noisier than one marker
 *    on that rig;
 *  - orientation noise: 0.002 rad, the position noise over the ~5 cm marker spread of a
 *    small rigid body;
 *  - drops: 1 % of frames, in bursts of 3 on average (a passing end-effector occludes
 *    markers for several frames); no published figure, an assumption of this emulation. */
#ifndef ND_MOCAP_H
#define ND_MOCAP_H

#include <stdint.h>

#include "nd_rng.h"

typedef struct {
  double rate;            /* frames per second, > 0 */
  double sigma_pos;       /* m, per axis, object and end-effector positions */
  double sigma_rot;       /* rad, per axis of a small rotation applied to the orientation */
  double latency;         /* s from capture to release */
  double latency_jitter;  /* s, uniform +- around latency, < latency */
  double drop_prob;       /* probability that a frame starts a drop burst, [0, 1) */
  double drop_burst;      /* mean frames a burst lasts (geometric), >= 1 */
  uint64_t seed;
} nd_mocap_cfg;

/* The lab's figures above, at 240 Hz, seed 1. */
void nd_mocap_cfg_lab(nd_mocap_cfg *cfg);

/* Exact motion capture at 240 Hz: no noise, no latency, no drops. */
void nd_mocap_cfg_exact(nd_mocap_cfg *cfg);

/* Check cfg. Return 0, or -1 naming the bad field. */
int nd_mocap_cfg_check(const nd_mocap_cfg *cfg, char *err, int errlen);

typedef struct {
  int64_t index;          /* the camera's frame number: frames due since init, 0 first;
                           * a dropped frame's number is skipped */
  double t_capture;       /* s, the world's time of the capture */
  double t_release;       /* s, when it may be published */
  double obj_pos[3], obj_quat[4];  /* w-first, unit */
  double ee_pos[3];
} nd_mocap_frame;

#define ND_MOCAP_QUEUE 32   /* frames in flight: > latency x rate with margin */

typedef struct {
  nd_mocap_cfg cfg;
  nd_rng rng;
  double next;            /* time of the next capture */
  int burst;              /* frames left in the current drop burst */
  nd_mocap_frame q[ND_MOCAP_QUEUE];
  int head, n;
  int64_t captured, dropped, overflow;
} nd_mocap;

/* Start capturing at time t0 (the first frame is due then). */
void nd_mocap_init(nd_mocap *m, const nd_mocap_cfg *cfg, double t0);

/* At world time t with the true object pose and end-effector position: if a frame is due,
 * capture it (noisy), or count it dropped. Return 1 if a frame was captured. */
int nd_mocap_capture(nd_mocap *m, double t, const double obj_pos[3], const double obj_quat[4],
                     const double ee_pos[3]);

/* Move the frames released by time t into out (at most max), oldest first. Return the
 * number moved. */
int nd_mocap_release(nd_mocap *m, double t, nd_mocap_frame *out, int max);

#endif
