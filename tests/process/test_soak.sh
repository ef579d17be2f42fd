#!/usr/bin/env bash
# test_soak: the whole process system under random faults, then its files and logs checked.
#
#   netns-run bash test_soak.sh BUILD_DIR [--faults N] [--duration S] [--seed N] [--keep]
#
# `nudge-up run --buffer B` (bridge, executor, planner, adapter refitting on B) and a task
# runner recording every task into B (`nudge-tasks --record B`, as `nudge-up demo` wires
# it; run here by the test, which restarts it when it is killed) push a long chain of
# goals while a fault is injected every 1.5-4 s: SIGKILL of a random process among
# bridge, executor, planner, adapter and tasks, or SIGSTOP, a pause of 0.2-1.5 s and
# SIGCONT (a stalled process). Choices and pauses come from bash's RANDOM seeded with
# --seed (printed; the same seed gives the same fault sequence, not the same run). A
# process is only hit when it has been up for 3 s since its last fault: a process killed
# right after its start is a crash loop to the supervisor, which backs off by design.
# lcm-logger records every channel. Injection stops after N faults or S seconds: by
# default 10 faults within 60 s (the CI size, ~60 s in all); --faults N alone allows 6 s
# a fault; --duration S alone injects until S is up. Then the task runner and the
# supervisor are stopped with SIGINT and the run is checked:
#   1. every record of the replay buffer reads back valid with the core reader, no tail
#      is torn at the end (a writer killed mid-append leaves one, which the next writer
#      cuts off: counted from the runners' logs), and every record a runner reported as
#      committed ("task N recorded", printed after the append's fdatasync) is in the file;
#   2. the adapter's parameter history reads back entry by entry: no corrupt entry,
#      versions +1 each, fitted on this buffer and never on more rollouts than it holds;
#   3. no EE_CMD setpoint in mode TRACKING follows a plan older than the executor's plan
#      timeout (EE_CMD.plan_utime), nor a plan made from a state (or, for a plan that
#      names one, a start) older than the plan's segment T plus that timeout
#      (nudge-logcheck stale-cmds);
#   4. every killed process was restarted, its new instance's first heartbeat on STATUS
#      within 2 s of the kill (the runner's restart is the test's, reported apart), and
#      no process exited that was not killed;
#   and nudge-up stops cleanly, nothing left running.
# Figures: faults_injected, kills, stops, records_committed, records_in_file,
# records_corrupt, records_missing, stale_commands, restart_s_max, restart_s_median,
# goals_reached, and more. --keep leaves the work directory (logs, buffer, lcm log).
set -u
PT_NAME=test_soak
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"

usage() { sed -n '2,/^set -u/{/^set -u/d;s/^# \{0,1\}//;p}' "${BASH_SOURCE[0]}"; }
[[ ${1:-} == -h || ${1:-} == --help ]] && { usage; exit 0; }
build=${1:-}
[[ -n $build && $build != -* ]] || { usage >&2; exit 2; }
shift
faults=""
duration=""
seed=$(((RANDOM << 15 | RANDOM) % 1000000 + 1))
while (($#)); do
  case $1 in
    --faults|--duration|--seed)
      (($# >= 2)) && [[ $2 =~ ^[0-9]+$ ]] && ((10#$2 > 0)) ||
        { echo "$PT_NAME: $1 needs a positive whole number" >&2; exit 2; }
      case $1 in
        --faults) faults=$((10#$2)) ;;
        --duration) duration=$((10#$2)) ;;
        --seed) seed=$((10#$2)) ;;
      esac
      shift 2
      ;;
    --keep) export PT_KEEP=1; shift ;;
    *) echo "$PT_NAME: unknown argument: $1" >&2; usage >&2; exit 2 ;;
  esac
done
# Neither: the CI size. --duration alone: faults until the time is up.
if [[ -z $faults && -z $duration ]]; then faults=10; duration=60; fi
[[ -n $duration ]] || duration=$((faults > 10 ? 6 * faults : 60))
want=${faults:-8}
[[ -n $faults ]] || faults=1000000
pt_init "$build"

LOG=$PT_WORK/soak.lcmlog
RUN=$PT_WORK/run
BUF=$PT_WORK/replay.nrb
HIST=$BUF.history
TIMEOUT_S=0.1              # the executor's plan/state timeout (passed explicitly)
RESTART_MAX_S=2            # target: a killed process heartbeats again within this
ELIGIBLE_US=3000000        # a process is hit again only this long after its last fault
SUPERVISED=(bridge executor planner adapter)
TARGETS=("${SUPERVISED[@]}" tasks)
pt_say "seed $seed ($want faults wanted, at most $duration s of injection)"
pt_figure seed "$seed" -

# The default chain of five pushes, over and over (1000 goals, nudge-tasks' most: well
# over an hour of tasks).
for ((i = 0; i < 200; i++)); do
  printf '0.15 0 0\n0.25 0.10 0.4\n0.25 0.25 0.8\n0.10 0.30 0.8\n0 0.20 0.3\n'
done >"$PT_WORK/goals.txt"

pt_logger "$LOG" '.*'
pt_spawn up "$PT_BIN/nudge-up" run --log-dir "$RUN" --buffer "$BUF" \
  --executor-arg --timeout --executor-arg "$TIMEOUT_S" \
  --executor-arg --plan-timeout --executor-arg "$TIMEOUT_S" 2>"$PT_WORK/up.err"
pt_up_wait "$RUN" 30 "$up" || { pt_fail "nudge-up run did not come up within 30 s (see supervisor.log below)"; exit 1; }
pt_ok "nudge-up run: all processes up"

# --- the task runner, restarted by this script --------------------------------------
tasks_n=0
tasks=""
start_tasks() {
  tasks_n=$((tasks_n + 1))
  pt_spawn tasks "$PT_BIN/nudge-tasks" --record "$BUF" --goals "$PT_WORK/goals.txt" --tau 4 \
    >"$PT_WORK/tasks-$tasks_n.out" 2>"$PT_WORK/tasks-$tasks_n.err"
}
start_tasks
"$PT_BIN/nudge-status" --wait nudge-tasks --pid "$tasks" --timeout 10 >/dev/null ||
  pt_fail "no heartbeat from nudge-tasks within 10 s"

# --- helpers -----------------------------------------------------------------------
# Pid of the current instance of process NAME: the supervisor's last logged, or the runner.
cur_pid() {
  if [[ $1 == tasks ]]; then
    printf '%s' "$tasks"
  else
    sed -n -E "s/.*(nudge-$1 up|restarted nudge-$1) \(pid ([0-9]+)\).*/\2/p" "$RUN/supervisor.log" |
      tail -n 1
  fi
}

# Alive and not a zombie waiting to be reaped.
alive() {
  local st=""
  [[ -n $1 ]] && read -r st <"/proc/$1/stat" 2>/dev/null || return 1
  st=${st##*) }
  [[ ${st%% *} != Z ]]
}

# rand_ms VAR A B: VAR uniform in [A, B]. No $(...): a subshell's RANDOM would not advance
# the script's own, and the sequence would no longer follow the seed.
rand_ms() { printf -v "$1" '%d' $(($2 + RANDOM % ($3 - $2 + 1))); }
sleep_ms() { sleep "$(($1 / 1000)).$(printf '%03d' $(($1 % 1000)))"; }

declare -A last_fault=() kills_of=() stops_of=()
for p in "${TARGETS[@]}"; do last_fault[$p]=0; kills_of[$p]=0; stops_of[$p]=0; done
KILLS=()        # "name old_pid t_kill_us"
n_faults=0 n_kills=0 n_stops=0 tasks_self_exits=0

# A runner that has run all its goals exits 0 and the next one goes on; any other exit
# the test did not cause is a failure (counted), and the runner is restarted.
check_tasks() {
  local st
  if [[ -n $tasks ]] && ! kill -0 "$tasks" 2>/dev/null; then
    wait "$tasks"
    st=$?
    if ((st == 0)); then
      pt_say "nudge-tasks (pid $tasks) ran all its goals: starting another"
    else
      pt_say "nudge-tasks (pid $tasks) exited by itself (status $st): restarting it"
      tasks_self_exits=$((tasks_self_exits + 1))
    fi
    start_tasks
  fi
}

# --- fault injection -----------------------------------------------------------------
RANDOM=$seed
t_inj0=$(pt_now_us)
t_inj_end=$((t_inj0 + duration * 1000000))
while ((n_faults < faults)); do
  rand_ms gap 1500 4000
  sleep_ms "$gap"
  check_tasks
  now=$(pt_now_us)
  ((now < t_inj_end)) || break
  # Draw the fault first, so the sequence depends on the seed alone.
  kind=$((RANDOM % 5 < 3 ? 1 : 2))   # 1 kill (60 %), 2 stop
  pick=$((RANDOM % ${#TARGETS[@]}))
  rand_ms pause 200 1500
  # The drawn target, or the next one that is eligible.
  target=""
  for ((k = 0; k < ${#TARGETS[@]}; k++)); do
    p=${TARGETS[(pick + k) % ${#TARGETS[@]}]}
    pid=$(cur_pid "$p")
    if alive "$pid" && ((now - last_fault[$p] >= ELIGIBLE_US)); then target=$p; break; fi
  done
  if [[ -z $target ]]; then
    pt_say "no process eligible for a fault now; skipping one"
    continue
  fi
  n_faults=$((n_faults + 1))
  if ((kind == 1)); then
    kill -KILL "$pid"
    t=$(pt_now_us)
    KILLS+=("$target $pid $t")
    n_kills=$((n_kills + 1))
    kills_of[$target]=$((kills_of[$target] + 1))
    pt_say "fault $n_faults at +$(((t - t_inj0) / 1000)) ms: SIGKILL nudge-$target (pid $pid)"
    if [[ $target == tasks ]]; then
      wait "$pid" 2>/dev/null
      start_tasks
    fi
  else
    kill -STOP "$pid"
    t=$(pt_now_us)
    sleep_ms "$pause"
    kill -CONT "$pid"
    n_stops=$((n_stops + 1))
    stops_of[$target]=$((stops_of[$target] + 1))
    pt_say "fault $n_faults at +$(((t - t_inj0) / 1000)) ms: SIGSTOP nudge-$target (pid $pid) for $pause ms"
  fi
  last_fault[$target]=$(pt_now_us)
done
t_inj_done=$(pt_now_us)
pt_say "injection over after $(((t_inj_done - t_inj0) / 1000)) ms"

# Let the last restart come back and the system run a little, then stop the runner (it
# records the task it was in) and the supervisor.
sleep 3
check_tasks
kill -INT "$tasks" 2>/dev/null
if pt_wait_pid "$tasks" 15; then
  pt_check "the last nudge-tasks stops on SIGINT with status 130 (got $PT_RC)" test "$PT_RC" -eq 130
else
  pt_fail "the last nudge-tasks did not stop within 15 s of SIGINT"
fi
pt_up_stop "$up" 30
pt_check "nudge-up run exits 0 after SIGINT (got $PT_RC)" test "$PT_RC" -eq 0
pt_stop_logger
pt_none_left "$RUN"

# --- 1. the replay buffer ------------------------------------------------------------
cat "$PT_WORK"/tasks-*.err | sed -n -E 's/^nudge-tasks: task ([0-9]+) recorded: .*/\1/p' \
  >"$PT_WORK/committed.txt"
cut_torn=$(cat "$PT_WORK"/tasks-*.err | grep -c 'cut off a torn tail')
cut_corrupt=$(cat "$PT_WORK"/tasks-*.err | grep -c 'cut off a corrupt tail')
pt_figure buffer_tails_cut_torn "$cut_torn" count
pt_figure buffer_tails_cut_corrupt "$cut_corrupt" count
pt_check "replay buffer: every record valid, none missing, duplicated or torn" \
  pt_lc buffer "$BUF" --committed "$PT_WORK/committed.txt"
pt_val in_file buffer "$BUF" --committed "$PT_WORK/committed.txt" records_in_file
pt_val committed buffer "$BUF" --committed "$PT_WORK/committed.txt" records_committed
pt_val corrupt buffer "$BUF" --committed "$PT_WORK/committed.txt" records_corrupt
pt_val missing buffer "$BUF" --committed "$PT_WORK/committed.txt" records_missing
corrupt=$((${corrupt:-1} + cut_corrupt))
pt_check "no corrupt record, in the file or cut off a tail by a writer ($corrupt)" test "$corrupt" -eq 0
pt_check "records were committed during the soak (${committed:-0})" test "${committed:-0}" -ge 1
# Tasks a fault spoiled are not recorded, by design (the bridge restarted, the runner
# stalled and lost its input, ...); a runner that could not record the first task after
# its start was a bug the soak found.
not_rec=$(cat "$PT_WORK"/tasks-*.err | grep -c '^nudge-tasks: task [0-9]* not recorded: ')
no_start=$(cat "$PT_WORK"/tasks-*.err | grep -c 'not recorded: no robot state received before')
pt_figure tasks_not_recorded "$not_rec" count
pt_check "every runner had a start state for its first task ($no_start without)" test "$no_start" -eq 0

# --- 2. the parameter history ---------------------------------------------------------
pt_check "parameter history: intact, versions +1 each, consistent with the buffer" \
  pt_lc history "$HIST" --buffer "$BUF"
hist_cut=$(grep -c 'cut off a [a-z]* tail' "$RUN/adapter.log")
pt_figure history_tails_cut "$hist_cut" count
pt_check "no corrupt history tail cut off by a restarted adapter" \
  bash -c "! grep -q 'cut off a corrupt tail' '$RUN/adapter.log'"

# --- 3. stale plans -------------------------------------------------------------------
pt_check "EE_CMD: no TRACKING setpoint on a plan older than $TIMEOUT_S s or made from a state older than its T + $TIMEOUT_S s" \
  pt_lc stale-cmds "$LOG" --timeout "$TIMEOUT_S"
pt_val stale stale-cmds "$LOG" --timeout "$TIMEOUT_S" stale_commands
pt_val stale_state stale-cmds "$LOG" --timeout "$TIMEOUT_S" stale_state_commands
pt_val tracking stale-cmds "$LOG" --timeout "$TIMEOUT_S" tracking_commands
pt_check "the executor tracked plans during the soak (${tracking:-0} setpoints)" \
  test "${tracking:-0}" -ge 1000

# --- 4. restarts -----------------------------------------------------------------------
"$PT_LC" first-beats "$LOG" >"$PT_WORK/beats.txt"
declare -A beat=()
while IFS=' .' read -r _ name pid utime _; do
  beat[$name.$pid]=$utime
done < <(grep '^first_beat\.' "$PT_WORK/beats.txt")
# Each instance's successor: the supervisor's pids per process in start order.
declare -A next_pid=()
for p in "${SUPERVISED[@]}"; do
  prev=""
  for q in $(sed -n -E "s/.*(nudge-$p up|restarted nudge-$p) \(pid ([0-9]+)\).*/\2/p" "$RUN/supervisor.log"); do
    [[ -n $prev ]] && next_pid[$p.$prev]=$q
    prev=$q
  done
done
sup_times=() tasks_times=() not_back=0
for k in "${KILLS[@]}"; do
  read -r name pid t <<<"$k"
  if [[ $name == tasks ]]; then
    # The runner after this one: the first heartbeat of a nudge-tasks pid after the kill.
    new=""
    best=0
    for key in "${!beat[@]}"; do
      [[ $key == nudge-tasks.* ]] || continue
      b=${beat[$key]}
      if ((b > t && (best == 0 || b < best))); then best=$b; new=${key#nudge-tasks.}; fi
    done
  else
    new=${next_pid[$name.$pid]:-}
    best=${beat[nudge-$name.$new]:-0}
  fi
  if [[ -z $new || $best -le 0 ]]; then
    pt_fail "nudge-$name (pid $pid, killed at $t us) never came back (no heartbeat of a new instance)"
    not_back=$((not_back + 1))
    continue
  fi
  s=$(awk -v a="$best" -v b="$t" 'BEGIN { printf "%.3f", (a - b) / 1e6 }')
  pt_say "nudge-$name: killed pid $pid, new pid $new heartbeats after $s s"
  if [[ $name == tasks ]]; then tasks_times+=("$s"); else sup_times+=("$s"); fi
done
stats() {  # max and median of the arguments, or "0 0"
  (($#)) || { echo "0 0"; return; }
  printf '%s\n' "$@" | sort -g | awk '{ v[NR] = $1 } END {
    m = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2; printf "%.3f %.3f\n", v[NR], m }'
}
read -r rmax rmed < <(stats "${sup_times[@]}")
read -r tmax tmed < <(stats "${tasks_times[@]}")
pt_check "every killed process came back ($not_back did not)" test "$not_back" -eq 0
pt_check "every supervised process was back within $RESTART_MAX_S s of its kill (max $rmax s)" \
  awk -v m="$rmax" -v l="$RESTART_MAX_S" 'BEGIN { exit !(m <= l) }'
pt_check "every killed task runner was back within $RESTART_MAX_S s (max $tmax s)" \
  awk -v m="$tmax" -v l="$RESTART_MAX_S" 'BEGIN { exit !(m <= l) }'
# Only what the soak killed died: an exit the test did not cause is a process that a
# fault elsewhere brought down.
for p in "${SUPERVISED[@]}"; do
  n=$(grep -c "nudge-$p exited" "$RUN/supervisor.log")
  pt_check "supervisor: nudge-$p exited $n times, killed ${kills_of[$p]} times" \
    test "$n" -eq "${kills_of[$p]}"
done
pt_check "the task runner never exited by itself ($tasks_self_exits)" test "$tasks_self_exits" -eq 0
pt_check "the crash-loop backoff never applied to a process killed after running fine" \
  bash -c "! grep -q 'crash loop' '$RUN/supervisor.log'"

# --- figures ---------------------------------------------------------------------------
pt_lc episodes "$(pt_events "$LOG")" >/dev/null
pt_val reached episodes "$(pt_events "$LOG")" episodes_success
pt_val started episodes "$(pt_events "$LOG")" episodes_start
pt_figure faults_injected "$n_faults" count
pt_figure kills "$n_kills" count
pt_figure stops "$n_stops" count
for p in "${TARGETS[@]}"; do
  pt_figure "kills_$p" "${kills_of[$p]}" count
  pt_figure "stops_$p" "${stops_of[$p]}" count
done
pt_figure injection_s "$(((t_inj_done - t_inj0) / 1000000))" s
pt_figure records_committed "${committed:-0}" count
pt_figure records_in_file "${in_file:-0}" count
pt_figure records_corrupt "$corrupt" count
pt_figure records_missing "${missing:-0}" count
pt_figure stale_commands "${stale:-0}" count
pt_figure stale_state_commands "${stale_state:-0}" count
pt_figure restart_s_max "$rmax" s
pt_figure restart_s_median "$rmed" s
pt_figure restarts_measured "${#sup_times[@]}" count
pt_figure tasks_restart_s_max "$tmax" s
pt_figure tasks_runs "$tasks_n" count
pt_figure goals_started "${started:-0}" count
pt_figure goals_reached "${reached:-0}" count
pt_check "at least $want faults were injected ($n_faults)" test "$n_faults" -ge "$want"
exit $((PT_FAILS > 0))
