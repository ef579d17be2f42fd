#!/usr/bin/env bash
# test_system: the whole process system on two goals in real time, then a clean stop.
#
#   netns-run bash test_system.sh BUILD_DIR
#
# 1. `nudge-up demo` on the default chain's first two goals (tau 5 s) with lcm-logger
#    recording: the task runner exits 0, both tasks ran and at least one reached its goal
#    (EPISODE events in the log) at the demo's eps 1e-3, a moved object first moved
#    within its task (approach_time_mean their mean). The live system reaches the
#    chain's 5 and both of these on an idle machine; with the planner starved of CPU
#    (plans slower than the executor's 0.1 s timeout, so the robot stops and goes) the
#    first push can time out while the second still succeeds, so one of two is what the
#    test demands. And the setpoint stream EE_CMD is continuous in p, v, a, across plan
#    switches too (each step within what v_max, a_max, j_max allow in its dt). Its
#    largest gap is printed (ee_cmd_gap_max; the 20 ms target is a measured figure) but
#    only asserted below 500 ms, i.e. the loop is alive: a shared 2-core VM stalls a
#    SCHED_FIFO thread for tens of ms now and then (71 ms seen in CI), and timed
#    assertions flake there; nothing of the run is left afterwards.
# 2. `nudge-up run`: a task, then PLANs from outside drive the resting sphere onto the
#    object; the planner sends it clear again and the next recorded task starts with the
#    sphere at least 5 mm from the object. Then SIGINT: exit 0, every process it logged is
#    gone.
set -u
PT_NAME=test_system
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"
pt_init "$@"

LOG=$PT_WORK/system.lcmlog
DEMO=$PT_WORK/demo
RUN=$PT_WORK/run
GOALS=(--goal 0.15,0,0 --goal 0.25,0.10,0.4)   # the default chain's first two

# --- 1. demo on two goals --------------------------------------------------------------
pt_logger "$LOG"
t_start=$(pt_now_us)
pt_spawn demo "$PT_BIN/nudge-up" demo --log-dir "$DEMO" -- --tau "$(pt_slow 5)" "${GOALS[@]}" \
  >"$PT_WORK/demo.out" 2>"$PT_WORK/demo.err"
# Start-up ~1 s, two tasks of at most 5 s, settling, stopping: well under 60 s.
if pt_wait_pid "$demo" 90; then
  pt_check "nudge-up demo exits 0 (the task runner's status; got $PT_RC)" test "$PT_RC" -eq 0
else
  pt_fail "nudge-up demo did not finish within $((90 * PT_SLOW)) s"
fi
pt_figure demo_duration $((($(pt_now_us) - t_start) / 1000)) ms
pt_stop_logger
cat "$PT_WORK/demo.out"

pt_check "the task runner printed its summary" grep -q '^reached [0-9]*/2 goals' "$PT_WORK/demo.out"
pt_check "each moved object moved within its task, approach_time_mean their mean" \
  awk '/^task [12]\/2 goal/ {
      if (!match($0, /(in|after) [0-9.]+ s/)) exit 1
      split(substr($0, RSTART, RLENGTH), w, " "); t = w[2]
      if (/object not moved$/) next
      if (!match($0, /object moved at [0-9.]+ s$/)) exit 1
      split(substr($0, RSTART, RLENGTH), w, " ")
      if (!(w[4] > 0 && w[4] < t)) exit 1
      s += w[4]; n++ }
    $1 == "approach_time_mean" { a = $2 }
    END { exit !(n >= 1 && (s / n - a) ^ 2 <= 0.0051 ^ 2) }' "$PT_WORK/demo.out"  # 2 decimals
pt_check "EPISODE: both tasks started and ended, at least one reached its goal" \
  pt_lc episodes "$(pt_events "$LOG")" --min-start 2 --min-end 2 --min-success 1
pt_check "EE_CMD: loop alive (no gap over 0.5 s), steps within v_max dt, a_max dt, j_max dt (also at plan switches)" \
  pt_lc ee-cmd "$LOG" --max-gap-ms 500
pt_val switches ee-cmd "$LOG" plan_switches
pt_check "the continuity check saw plan switches (${switches:-0})" test "${switches:-0}" -ge 5
pt_val rate ee-cmd "$LOG" ee_cmd_rate
pt_check "EE_CMD at ~1 kHz (${rate:-0} Hz)" awk -v r="${rate:-0}" 'BEGIN { exit !(r > 900 && r < 1100) }'
pt_restarts_are "$DEMO"
pt_none_left "$DEMO"

# --- 2. nudge-up run, stopped by SIGINT ------------------------------------------------
pt_spawn up "$PT_BIN/nudge-up" run --log-dir "$RUN" 2>"$PT_WORK/run.err"
if pt_up_wait "$RUN" 30 "$up"; then
  pt_ok "nudge-up run: all processes up"
  # The sphere kept clear. After a task's release, valid PLANs drive the sphere into the
  # object and hold it there, as an object that slides or turns onto the resting sphere
  # leaves it. The planner sends the sphere clear again (whenever it comes within 7.5 mm),
  # and the next record starts with it at least half of --release (5 mm) from the object.
  "$PT_BIN/nudge-tasks" --goal 0.05,0,0 --eps 1e-3 --tau "$(pt_slow 2)" >"$PT_WORK/clear-task.out" 2>&1 ||
    pt_fail "nudge-tasks (the task before the release) failed: $(tail -n 3 "$PT_WORK/clear-task.out")"
  pt_wait_for 5 grep -q ': released: ' "$RUN/planner.log" || pt_fail "no release after the task"
  # The release settles first: the sphere may come to rest short of its key, and the
  # planner re-clears it 0.25 s on. Such a re-clear is not the one this checks, so wait
  # until none has come for 0.75 s, then count the lines from there on.
  n_clear=-1
  for ((i = 0; i < 20 * PT_SLOW; i++)); do
    n=$(grep -c 'the object came within' "$RUN/planner.log")
    ((n == n_clear)) && break
    n_clear=$n
    sleep 0.75
  done
  # Drive the sphere from where it rests 4 cm on toward the object (1 cm away): slowly
  # enough near it that an object pushed is not launched out of reach of the recorded
  # task's short time limit.
  rest=$(grep -o -E '(rests at|sent clear again, to) \([^)]*\)' "$RUN/planner.log" | tail -n 1 |
    tr -d '(),' | awk '{ printf "%.3f,%.3f", $(NF - 1) + 0.04, $NF }')
  if [[ -n $rest ]]; then
    pt_say "PLANs drive the resting sphere to ($rest) m, 4 cm on"
    "$PT_INJ" --plan-to "$rest" --repeat 40 --gap-ms 20 >/dev/null ||
      pt_fail "nudge-inject --plan-to failed"
  else
    pt_fail "the planner's log says nowhere where the sphere rests"
  fi
  # The object lies within a few cm of where the first task left it: at eps 1e-3 (3 cm)
  # the goal 0.3 m cannot be met at the start (such a task is not recorded), and the time
  # lets it move the 1 cm a record needs, under ASan too.
  "$PT_BIN/nudge-tasks" --goal 0.3,0,0 --eps 1e-3 --tau "$(pt_slow 1)" \
    --record "$PT_WORK/clear.nrb" \
    >"$PT_WORK/clear-rec.out" 2>&1 || pt_fail "nudge-tasks --record failed: $(tail -n 3 "$PT_WORK/clear-rec.out")"
  again=$(grep -o 'the object came within .*' "$RUN/planner.log" | tail -n +$((n_clear + 1)) |
    head -n 1)
  pt_check "the planner sent the sphere clear again after the PLANs (${again:-no new line})" \
    test -n "$again"
  pt_val nrec buffer "$PT_WORK/clear.nrb" records_in_file
  why=$(grep -m1 -o 'not recorded: .*' "$PT_WORK/clear-rec.out")
  pt_check "the task after the re-clear was recorded (${nrec:-0} records${why:+; $why})" \
    test "${nrec:-0}" -ge 1
  if [[ ${nrec:-0} -ge 1 ]]; then
    pt_val g0 buffer "$PT_WORK/clear.nrb" record_start_gap_min
    pt_figure clear_start_gap "$g0" m
    pt_check "the next record starts with the sphere clear of the object (${g0:-?} m)" \
      awk -v g="$g0" 'BEGIN { exit !(g != "" && g > 0.005) }'
  fi
  pids=$(pt_logged_pids "$RUN" | tr '\n' ' ')
  pt_figure run_processes "$(echo $pids | wc -w)" count
  t_int=$(pt_now_us)
  pt_up_stop "$up" 30
  pt_figure stop_time $((($(pt_now_us) - t_int) / 1000)) ms
  pt_check "nudge-up run exits 0 after SIGINT (got $PT_RC)" test "$PT_RC" -eq 0
  pt_restarts_are "$RUN"
  pt_check_not "no process needed SIGKILL" grep -q SIGKILL "$RUN/supervisor.log"
  pt_none_left "$RUN"
else
  pt_fail "nudge-up run did not come up within $((30 * PT_SLOW)) s (see supervisor.log below)"
fi
exit $((PT_FAILS > 0))
