#!/usr/bin/env bash
# bench_view: nudge-view's figures with the whole system running (not a ctest: ~1 min a
# round).
#
#   tests/tools/netns-run bash tests/view/bench_view.sh BUILD_DIR [ROUNDS] [VIEW-ARGS...]
#
# Each round runs `nudge-up demo` (the default chain of 5 goals) twice in this private
# namespace, once alone and once with nudge-view attached (hidden, 1280x720 at 30 fps, on
# a private Xvfb, in a session of its own as nudge-up would start it; VIEW-ARGS replace the
# default --record of an MP4), in alternating order.
# Planner throughput is the planner's own per-task lines ("N plans, R plans/s over S s of
# fresh state"): all plans over all fresh seconds of a run. Prints 'name value unit' lines:
#   view_sys_fps          frames the view rendered per second of wall time (target >= 30)
#   view_sys_frames_late  frame slots it missed (live: each is the previous frame repeated)
#   view_sys_frame_ms_*   one frame's work (scene, render, read-back, write)
#   view_sys_cpu_cores    the view process's CPU time (all its threads, not ffmpeg's) over
#                         its wall time: what it takes from the planner's two cores
#   planner_rate_without  plans/s with no view, mean over rounds
#   planner_rate_with     plans/s with the view
#   planner_rate_cost     1 - with/without, percent (the budget is 10 %)
#   load_before           the 1-minute load average before the runs (other work skews all)
set -u
PT_NAME=bench_view
HERE=$(dirname "${BASH_SOURCE[0]}")
. "$HERE/../tools/process-lib.sh"
. "$HERE/view-lib.sh"
BUILD=${1:?usage: bench_view.sh BUILD_DIR [ROUNDS] [VIEW-ARGS...]}
ROUNDS=${2:-2}
shift $(($# >= 2 ? 2 : 1))
vw_need "$BUILD"
PT_NO_LOGGER=1 pt_init "$BUILD"
vw_xvfb
W=$PT_WORK
VIEW_ARGS=("$@")
((${#VIEW_ARGS[@]})) || VIEW_ARGS=(--record "$W/sys.mp4")
pt_figure load_before "$(cut -d' ' -f1 /proc/loadavg)" load

# planner_rate LOGDIR: all plans over all fresh seconds of the run's tasks.
planner_rate() {
  sed -n 's/.*: task [0-9]* .* after [0-9.]* s: \([0-9]*\) plans, [0-9.]* plans\/s over \([0-9.]*\) s of fresh.*/\1 \2/p' \
    "$1/planner.log" | awk '{ p += $1; s += $2 } END { if (s > 0) printf "%.2f", p / s; else print 0 }'
}

# cpu_cores PID: the process's user + system time over the time since it started.
cpu_cores() {
  awk -v hz="$(getconf CLK_TCK)" 'NR == FNR { up = $1; next }
    { sub(/^.*\) /, ""); printf "%.3f", ($12 + $13) / hz / (up - $20 / hz) }' /proc/uptime "/proc/$1/stat"
}

demo() { # demo NAME WITH_VIEW
  local dir=$W/$1 up view=""
  if (($2)); then
    # In a session of its own, as nudge-up starts every process (--nice then acts on its
    # autogroup too: see ndp_nice in processes/common/ndp.h).
    pt_spawn view setsid "$VW" --hidden "${VIEW_ARGS[@]}" >"$W/$1.view.out" 2>"$W/$1.view.err"
    "$PT_BIN/nudge-status" --wait nudge-view --timeout 15 || pt_fail "$1: no heartbeat from the view"
  fi
  pt_spawn up "$PT_BIN/nudge-up" demo --log-dir "$dir" >"$W/$1.out" 2>"$W/$1.err"
  pt_wait_pid "$up" 300 || pt_fail "$1: nudge-up demo did not finish"
  if [[ -n $view ]]; then
    VIEW_CORES=$(cpu_cores "$view")
    kill -INT "$view"
    pt_wait_pid "$view" 30 || pt_fail "$1: the view did not stop"
  fi
  RATE=$(planner_rate "$dir")
  pt_say "$1: planner $RATE plans/s, $(grep -c . "$dir/planner.log") log lines; $(tail -n 1 "$W/$1.out")"
}

with=() without=() cores=()
for ((r = 1; r <= ROUNDS; r++)); do
  if ((r % 2)); then
    demo "r$r-without" 0; without+=("$RATE")
    demo "r$r-with" 1; with+=("$RATE")
  else
    demo "r$r-with" 1; with+=("$RATE")
    demo "r$r-without" 0; without+=("$RATE")
  fi
  o=$W/r$r-with.view.out
  pt_figure "view_sys_fps_r$r" "$(vw_fig "$o" view_fps)" per_s
  pt_figure "view_sys_frames_late_r$r" "$(vw_fig "$o" view_frames_late)" count
  pt_figure "view_sys_frame_ms_mean_r$r" "$(vw_fig "$o" view_frame_ms_mean)" ms
  pt_figure "view_sys_frame_ms_p99_r$r" "$(vw_fig "$o" view_frame_ms_p99)" ms
  pt_figure "view_sys_cpu_cores_r$r" "$VIEW_CORES" cores
  cores+=("$VIEW_CORES")
  pt_figure "planner_rate_without_r$r" "${without[-1]}" per_s
  pt_figure "planner_rate_with_r$r" "${with[-1]}" per_s
done
mean() { printf '%s\n' "$@" | awk '{ s += $1 } END { printf "%.2f", s / NR }'; }
a=$(mean "${without[@]}")
b=$(mean "${with[@]}")
fps=$(for ((r = 1; r <= ROUNDS; r++)); do vw_fig "$W/r$r-with.view.out" view_fps; done | awk '{ s += $1 } END { printf "%.2f", s / NR }')
pt_figure view_sys_fps "$fps" per_s
pt_figure view_sys_cpu_cores "$(mean "${cores[@]}")" cores
pt_figure planner_rate_without "$a" per_s
pt_figure planner_rate_with "$b" per_s
pt_figure planner_rate_cost "$(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.1f", (a > 0 ? 100 * (1 - b / a) : 0) }')" percent
pt_figure load_after "$(cut -d' ' -f1 /proc/loadavg)" load
exit 0
