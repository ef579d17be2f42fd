#!/usr/bin/env bash
# test_up_signals: nudge-up acts on SIGINT/SIGTERM within a bound wherever the signal finds
# it, and leaves nothing running.
#
#   netns-run bash test_up_signals.sh BUILD_DIR [--rounds N] [--seed N] [--keep]
#
# The real supervisor over stand-in programs (no LCM: each is `sleep`, up at once; the
# stand-in nudge-status says "up" 20 ms after it starts), so one trial takes ~0.5 s and
# many fit. Each trial starts `nudge-up`, sends it one signal (SIGINT, a third of them
# SIGTERM) at a moment drawn at random, and times it until it has exited:
#   startup     0-0.6 s after it has set its traps: while it checks its arguments, makes
#               its log directory, starts a process, waits for its heartbeat (half of these
#               start it with SIGINT ignored, as `&` in a script does: it re-executes
#               itself first). Not before: bash itself can swallow a SIGINT that comes in
#               the first milliseconds, before the script has run its first lines;
#   restart     a random process SIGKILLed once all are up, the signal 0-0.5 s later: as
#               the supervisor notices the death, logs it, waits the 0.2 s restart delay,
#               restarts it;
#   at-restart  the planner SIGKILLed, the signal as soon as supervisor.log says that it
#               was restarted (where test_planner_kill once left nudge-up deaf to SIGINT
#               for 90 s, until the test's SIGKILL);
#   stubborn    the adapter ignores SIGINT: SIGKILL after the grace time (--grace 0.3);
#   demo        `nudge-up demo` with a stand-in task runner, the signal at 0-0.6 s after
#               the traps.
# Every trial must end within 1.5 s of the signal (stubborn: the grace time + 1.5 s;
# times NUDGE_SLOW), with exit status 0 (run, signalled once all were up) or 128 + the
# signal (demo: also the runner's 130, or its 137 and the grace time more: a runner that
# gets SIGINT before it can catch it is SIGKILLed), and no process left: neither one the
# supervisor logged nor any other in the namespace. A trial that hangs is cut at 10 s
# (the supervisor's wait channel and children are shown). --rounds N runs N times as
# many trials (default 1: 60 trials, ~40 s); --seed N repeats the same draws.
# Figures: up_stop_ms_max and up_stop_ms_median per kind, up_stop_ms_max overall, trials.
set -u
PT_NAME=test_up_signals
PT_NO_LOGGER=1
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"

usage() { sed -n '2,/^set -u/{/^set -u/d;s/^# \{0,1\}//;p}' "${BASH_SOURCE[0]}"; }
[[ ${1:-} == -h || ${1:-} == --help ]] && { usage; exit 0; }
build=${1:-}
[[ -n $build && $build != -* ]] || { usage >&2; exit 2; }
shift
rounds=1
seed=$(((RANDOM << 15 | RANDOM) % 1000000 + 1))
while (($#)); do
  case $1 in
    --rounds|--seed)
      (($# >= 2)) && [[ $2 =~ ^[0-9]+$ ]] && ((10#$2 > 0)) ||
        { echo "$PT_NAME: $1 needs a positive whole number" >&2; exit 2; }
      if [[ $1 == --rounds ]]; then rounds=$((10#$2)); else seed=$((10#$2)); fi
      shift 2
      ;;
    --keep) export PT_KEEP=1; shift ;;
    *) echo "$PT_NAME: unknown argument: $1" >&2; usage >&2; exit 2 ;;
  esac
done
pt_init "$build"
RANDOM=$seed
pt_say "seed $seed, rounds $rounds"

GRACE=0.3
BOUND_MS=$((1500 * PT_SLOW))
STUBBORN_BOUND_MS=$((300 + 1500 * PT_SLOW))
HANG_S=10

# --- the stand-ins ---------------------------------------------------------------------
STAND=$PT_WORK/bin
mkdir -p "$STAND"
cat >"$STAND/stand-in" <<'EOF'
#!/usr/bin/env bash
# A nudge program's stand-in: runs until a signal ends it. nudge-up starts it in the
# background, with SIGINT ignored: back to the default (as the programs' own handlers
# override it), except for the process named by STAND_IN_STUBBORN, which keeps ignoring it.
name=${0##*/}
if [[ $name == nudge-status ]]; then   # --wait NAME --pid PID ...: up if PID lives
  while (($#)); do [[ $1 == --pid ]] && pid=$2; shift; done
  # 20 ms on a fifo nobody writes: no child of its own to outlive a SIGKILL.
  read -r -t 0.02 _ <>"${0%/*}/.idle"
  kill -0 "${pid:?}" 2>/dev/null
  exit
fi
[[ $name == "nudge-${STAND_IN_STUBBORN:-}" ]] && exec sleep 1000
exec env --default-signal=INT sleep 1000
EOF
chmod 755 "$STAND/stand-in"
mkfifo -m 600 "$STAND/.idle"
for p in bridge executor planner adapter tasks status; do ln -s stand-in "$STAND/nudge-$p"; done

# --- helpers ---------------------------------------------------------------------------
# rand_s MS: a random duration in [0, MS) milliseconds, as seconds for sleep.
rand_s() { printf '0.%03d' $((RANDOM % $1)); }

# log_has DIR TEXT: supervisor.log in DIR has a line containing TEXT (no fork: read often).
log_has() {
  local -a lines=()
  mapfile -t lines 2>/dev/null <"$1/supervisor.log"
  [[ ${lines[*]} == *"$2"* ]]
}

# wait_log DIR TEXT SECONDS [PID]: poll every 2 ms until log_has; 1 at the deadline or
# when PID has exited.
wait_log() {
  local end=$((SECONDS + $3 * PT_SLOW))
  until log_has "$1" "$2"; do
    ((SECONDS >= end)) && return 1
    [[ -n ${4:-} ]] && ! kill -0 "$4" 2>/dev/null && return 1
    sleep 0.002
  done
}

# trapped PID: poll every 1 ms (no fork) until PID is nudge-up's bash and catches SIGTERM,
# i.e. nudge-up has set its traps (bash itself catches SIGINT from its start); 1 after 5 s
# or if PID is gone. The command line is read before and after the status: between the
# fork and its exec, PID is a copy of this shell and catches SIGTERM through our trap;
# a SIGINT sent then reaches nothing of nudge-up's (with SIGINT ignored, as `&` starts it,
# not even a later one), and the trial would wait on a supervisor that was never told.
trapped() {
  local key val n cgt
  for ((n = 0; n < 5000; n++)); do
    [[ -e /proc/$1/status ]] || return 1
    cgt=0
    if is_up "$1"; then
      while read -r key val; do
        [[ $key == SigCgt: ]] && cgt=$((16#$val))
      done 2>/dev/null <"/proc/$1/status"
      ((cgt & 1 << 14)) && is_up "$1" && return 0
    fi
    read -r -t 0.001 _ <>"$STAND/.idle"
  done
  return 1
}

# is_up PID: PID runs nudge-up under bash (its argv is bash, then nudge-up's path).
is_up() {
  local -a argv=()
  mapfile -d '' -t argv 2>/dev/null <"/proc/$1/cmdline"
  [[ ${argv[0]:-} == *bash && ${argv[1]:-} == */nudge-up ]]
}

# The pid of nudge-NAME as logged in DIR ("nudge-NAME up (pid N)").
logged_pid() { sed -n -E "s/.*nudge-$2 up \\(pid ([0-9]+)\\).*/\\1/p" "$1/supervisor.log" | tail -n 1; }

declare -A LAT=()   # kind -> latencies in ms, space-separated
FAILED_TRIALS=0
TRIALS=0
MAX_MS=0

# trial KIND: one run of nudge-up and one signal, checked (see the top).
trial() {
  local kind=$1 dir=$PT_WORK/t$TRIALS sig=INT mode=run bound=$BOUND_MS
  local up t0 t1 ms rc victim vpid ok=1 why=""
  TRIALS=$((TRIALS + 1))
  ((RANDOM % 3 == 0)) && sig=TERM
  [[ $kind == demo ]] && mode=demo
  [[ $kind == stubborn ]] && { sig=INT; bound=$STUBBORN_BOUND_MS; }
  # The runner may come too early for its stand-in (SIGINT still ignored before its exec),
  # as for a real one before it sets its handler: it is then SIGKILLed after the grace.
  [[ $kind == demo ]] && bound=$STUBBORN_BOUND_MS
  mkdir -p "$dir"
  local cmd=("$PT_BIN/nudge-up" "$mode" --bin-dir "$STAND" --lcm-url memq:// --log-dir "$dir"
             --grace "$GRACE" --ready-timeout 5)
  if [[ $kind == startup ]] && ((RANDOM % 2)); then
    # As a script's `&` starts it: SIGINT ignored, so nudge-up re-executes itself.
    STAND_IN_STUBBORN="" "${cmd[@]}" 2>"$dir/up.err" &
  else
    STAND_IN_STUBBORN=$([[ $kind == stubborn ]] && echo adapter) \
      env --default-signal=INT "${cmd[@]}" 2>"$dir/up.err" &
  fi
  up=$!
  PT_PIDS=("$up")
  case $kind in
    startup | demo)
      trapped "$up" || { ok=0; why="nudge-up set no trap for SIGTERM;"; }
      sleep "$(rand_s 600)"
      ;;
    restart | at-restart | stubborn)
      if ! wait_log "$dir" 'all up' 10 "$up"; then
        ok=0; why="not all up within $((10 * PT_SLOW)) s"
      elif [[ $kind != stubborn ]]; then
        victim=planner
        [[ $kind == restart ]] && { local v=(bridge executor planner adapter); victim=${v[RANDOM % 4]}; }
        vpid=$(logged_pid "$dir" "$victim")
        kill -KILL "$vpid"
        if [[ $kind == restart ]]; then
          sleep "$(rand_s 500)"
        elif ! wait_log "$dir" "restarted nudge-$victim" 5 "$up"; then
          ok=0; why="nudge-$victim not restarted within $((5 * PT_SLOW)) s"
        fi
      fi
      ;;
  esac
  t0=$(pt_now_us)
  kill -"$sig" "$up" 2>/dev/null
  local end=$((SECONDS + HANG_S))
  while kill -0 "$up" 2>/dev/null && ((SECONDS < end)); do sleep 0.005; done
  t1=$(pt_now_us)
  if kill -0 "$up" 2>/dev/null; then
    ok=0; why+=" still running ${HANG_S} s after SIG$sig;"
    printf '%s: hung supervisor %s, wchan %s; its children:\n' "$PT_NAME" "$up" "$(cat "/proc/$up/wchan" 2>/dev/null)"
    ps -o pid,stat,wchan:20,args --ppid "$up" 2>/dev/null
    kill -KILL "$up"
  fi
  wait "$up"
  rc=$?
  PT_PIDS=()
  ms=$(((t1 - t0) / 1000))
  LAT[$kind]+=" $ms"
  ((ms > MAX_MS)) && MAX_MS=$ms
  ((ms > bound)) && { ok=0; why+=" stopped ${ms} ms after SIG$sig (bound $bound ms);"; }
  local sigrc=143
  [[ $sig == INT ]] && sigrc=130
  if ! { ((rc == sigrc)) || { ((rc == 0)) && [[ $mode == run ]] && log_has "$dir" 'all up'; } ||
         { ((rc == 130 || rc == 137)) && [[ $mode == demo ]]; }; }; then
    ok=0; why+=" exit status $rc;"
  fi
  [[ $kind == stubborn ]] && ! log_has "$dir" 'nudge-adapter still running' &&
    { ok=0; why+=" the stubborn adapter was not SIGKILLed;"; }
  # Nothing left: a leftover dies here, so that the next trial starts clean.
  pt_ns_others
  if ((${#PT_OTHERS[@]})); then
    ok=0; why+=" left running: ${PT_OTHERS[*]};"
    local o
    for o in "${PT_OTHERS[@]}"; do kill -KILL "${o%%:*}" 2>/dev/null; done
  fi
  if ((!ok)); then
    FAILED_TRIALS=$((FAILED_TRIALS + 1))
    pt_fail "trial $TRIALS ($kind, SIG$sig):$why"
    tail -n 4 "$dir/supervisor.log" 2>/dev/null | sed 's/^/    /'
    grep -v '^nudge-up: ' "$dir/up.err" | head -n 5 | sed 's/^/    stderr: /'
  fi
  return 0
}

# --- the trials, kinds interleaved -----------------------------------------------------
plan=()
for ((r = 0; r < rounds; r++)); do
  for ((i = 0; i < 18; i++)); do plan+=(startup); done
  for ((i = 0; i < 20; i++)); do plan+=(restart); done
  for ((i = 0; i < 10; i++)); do plan+=(at-restart); done
  for ((i = 0; i < 4; i++)); do plan+=(stubborn); done
  for ((i = 0; i < 8; i++)); do plan+=(demo); done
done
# Shuffle (Fisher-Yates on RANDOM).
for ((i = ${#plan[@]} - 1; i > 0; i--)); do
  j=$((RANDOM % (i + 1)))
  t=${plan[i]}; plan[i]=${plan[j]}; plan[j]=$t
done
t_start=$SECONDS
for kind in "${plan[@]}"; do trial "$kind"; done

# --- figures ---------------------------------------------------------------------------
for kind in startup restart at-restart stubborn demo; do
  [[ -n ${LAT[$kind]:-} ]] || continue
  mapfile -t sorted < <(tr ' ' '\n' <<<"${LAT[$kind]}" | sed '/^$/d' | sort -n)
  n=${#sorted[@]}
  pt_figure "up_stop_ms_max_$kind" "${sorted[n - 1]}" ms
  pt_figure "up_stop_ms_median_$kind" "${sorted[n / 2]}" ms
done
pt_figure up_stop_ms_max "$MAX_MS" ms
pt_figure trials "$TRIALS" count
pt_figure trials_failed "$FAILED_TRIALS" count
pt_say "$TRIALS trials in $((SECONDS - t_start)) s"
pt_check "every one of the $TRIALS trials stopped in bound, with its status, nothing left" \
  test "$FAILED_TRIALS" -eq 0
exit $((PT_FAILS > 0))
