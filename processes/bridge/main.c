/* nudge-bridge: the mocap/robot bridge. In emulation (the only mode built here) it owns
 * the world (sim/nds_world.h), stepped in real time by a real-time loop (bridge_loop.c on
 * nd_rtloop), and publishes what the robot and the motion capture would: ROBOT_STATE every
 * step, MOCAP at the capture rate. The robot follows EE_CMD and holds when commands go
 * stale. This thread owns LCM (bridge_io.c). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bridge_io.h"
#include "nd_opt.h"

#define PROG "nudge-bridge"

int main(int argc, char **argv) {
  static bridge_opts o;
  const int st = bridge_options(argc, argv, &o);
  if (st != ND_OPT_RUN) return st;
  nds_world_cfg wc = o.wc;
  nd_rtloop_cfg rc = o.rt;
  const nd_box ws = o.ws;
  const double cmd_timeout = o.cmd_timeout, seconds = o.seconds;
  const char *url = o.url;
  nd_opt_spec spec = o.spec;
  char err[512];
  ndp_signals();
  ndp_mujoco_handlers(PROG);
  nds_world *w = nds_world_create(&wc, err, sizeof(err));
  if (!w) return nd_opt_fail(&spec, "%s", err);
  rc.rate = 1.0 / nds_world_config(w)->dt;
  if (rc.rate < 20.0 || rc.rate > 10000.0) {
    nds_world_free(w);
    return nd_opt_fail(&spec, "--model %s: timestep %g s is outside [0.1, 50] ms for a real-time "
                       "world; give --rate", wc.model_path, 1.0 / rc.rate);
  }
  rc.catch_up_max = bridge_loop_catch_up_max(rc.rate);
  bridge_loop *b = calloc(1, sizeof(*b));  /* the ring is 256 KB: not on the stack */
  static bridge_io io;
  static nd_rtloop loop;
  lcm_t *lcm = NULL;
  int status = 1;
  char how[200];
  if (!b) {
    snprintf(err, sizeof(err), "out of memory");
    goto done;
  }
  bridge_loop_init(b, w, cmd_timeout);
  io.b = b;
  io.ws = ws;
  io.holding = -1;
  ndp_status_init(&io.st, PROG);
  nd_rtloop_stats ls = {0};
  io.st.loop = &ls;
  /* The loop first: it raises this thread to the I/O priority, and LCM's receive thread,
   * created with the LCM instance, inherits it (doc/decisions.md#command-sampling). */
  if (nd_rtloop_start(&loop, &rc, bridge_loop_tick, b, how, sizeof how, err, sizeof err) ||
      !(lcm = ndp_lcm_create(url, err, sizeof(err))) ||
      bridge_io_subscribe(&io, lcm, err, sizeof(err)))
    goto done;
  const nd_mocap_cfg *mc = &wc.mocap;
  const nds_scene_cfg *ob = &wc.object;
  char theta[200];
  nd_theta_str(wc.theta, ", ", theta, sizeof(theta));
  fprintf(stderr,
          PROG ": emulation, %s world (%s), dt %.3g ms at %g Hz real time (%s); MOCAP %g Hz, "
               "noise %g m %g rad, latency %g +- %g s, %g%% lost in bursts of %g; object %g x "
               "%g x %g m, %g kg, centre of mass (%g, %g, %g), solref %g %g; theta (%s); "
               "start object (%g, %g, %g), ee (%g, %g); EE_CMD timeout %g s, "
               "workspace x [%g, %g] y [%g, %g] m (+%g m); model %s; LCM %s\n",
          wc.kind == NDS_WORLD_LAB ? "lab" : "ideal",
          wc.arm ? "a Panda holds the sphere" : "the sphere on slide joints", 1e3 / rc.rate,
          rc.rate, how, mc->rate, mc->sigma_pos, mc->sigma_rot, mc->latency,
          mc->latency_jitter, 100 * mc->drop_prob * mc->drop_burst, mc->drop_burst,
          2 * ob->obj_half[0], 2 * ob->obj_half[1], 2 * ob->obj_half[2], ob->obj_mass,
          ob->obj_com[0], ob->obj_com[1], ob->obj_com[2], ob->solref[0], ob->solref[1],
          theta, wc.obj[0], wc.obj[1], wc.obj[2],
          wc.ee[0], wc.ee[1], cmd_timeout, ws.lo[0], ws.hi[0], ws.lo[1], ws.hi[1],
          BRIDGE_WS_MARGIN, wc.model_path ? wc.model_path : "built-in scene", ndp_url(url));

  const double t0 = ndp_mono();
  uint64_t v_rep = 0, v_loop = 0;
  int pub_fail_said = 0;
  io.st.state = "holding";
  status = 0;
  while (!ndp_quit && !(seconds > 0 && ndp_mono() - t0 >= seconds)) {
    if (ndp_handle(lcm, 0.001)) {
      fprintf(stderr, PROG ": LCM receive failed: %s\n", strerror(errno));
      status = 1;
      break;
    }
    if (bridge_io_publish(&io, lcm) && !pub_fail_said) {
      fprintf(stderr, PROG ": LCM publish failed (said once)\n");
      pub_fail_said = 1;
    }
    nd_rtloop_stats_take(&loop, &v_loop, &ls);
    bridge_io_report(&io, &v_rep, &ls);
    if (ndp_status_tick(lcm, &io.st, 0) < 0 && !pub_fail_said) {
      fprintf(stderr, PROG ": STATUS publish failed (said once)\n");
      pub_fail_said = 1;
    }
  }
  nd_rtloop_stop(&loop);
  bridge_loop_report_post(b);
  bridge_io_publish(&io, lcm);
  nd_rtloop_stats_take(&loop, &v_loop, &ls);
  bridge_io_report(&io, &v_rep, &ls);
  io.st.state = "stopped";
  ndp_status_tick(lcm, &io.st, 1);
  const double up = ndp_mono() - t0;
  const bridge_report *r = &io.rep;
  fprintf(stderr,
          PROG ": stopped after %.2f s: %lld steps (%.1f /s), %lld ROBOT_STATE, %lld MOCAP, "
               "%lld ARM_STATE, %lld reflex stops, %lld EE_CMD silences over %g ms followed, %lld "
               "commands after a followed future joined, %lld placements (%lld dropped), %lld holds "
               "for EE_CMD stamps apart, inputs %lld received %lld refused (%lld "
               "EE_CMD outside the workspace), period error p50 %d p99 %d max %d us, overruns "
               "%lld, dropped steps %lld, steps replayed unpublished %lld, resets %lld, ring drops %llu\n",
          up, (long long)r->steps, r->steps / up, (long long)r->robot_states,
          (long long)r->frames, (long long)r->arm_states, (long long)r->stops,
          (long long)r->silent_events, 1e3 * BRIDGE_CMD_HORIZON, (long long)r->joins,
          (long long)r->places, (long long)r->places_dropped, (long long)r->apart_events,
          (long long)io.st.received, (long long)io.st.rejected,
          (long long)io.refused_ws.count, ls.p50_us, ls.p99_us, ls.max_us,
          (long long)ls.overruns, (long long)ls.skipped, (long long)r->unpublished,
          (long long)r->resets,
          (unsigned long long)atomic_load(&b->out.dropped));
done:
  nd_rtloop_stop(&loop);
  if (status) fprintf(stderr, PROG ": %s\n", err);
  if (lcm) lcm_destroy(lcm);
  free(b);
  nds_world_free(w);
  return status;
}
