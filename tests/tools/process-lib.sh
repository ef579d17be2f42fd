# process-lib.sh: what the process tests share (sourced by tests/test_*.sh).
#
# A test script runs inside tests/netns-run (private namespaces, LCM_DEFAULT_URL set),
# takes the build directory as $1, and calls pt_init first. Everything it starts goes
# through pt_spawn, so the EXIT trap can stop it; every wait has a deadline, so a test
# ends by itself. Assertions print "ok - ..." or "FAIL - ..." and the test exits 1 if any
# failed; figures are printed as 'name value unit' lines.
#
# Every test also fails on a sanitizer report in any log under its work directory (see
# pt_sanitizer_scan), and waits for things to happen scale with NUDGE_SLOW (pt_slow).
# PT_KEEP=1 (or ND_KEEP=1) keeps the work directory (logs, recordings) instead of
# removing it.

PT_NAME=${PT_NAME:-process-test}
PT_FAILS=0
PT_PIDS=()          # everything started, for the EXIT trap
PT_LOGGER=""
PT_EVLOGGER=""
PT_ON_CLEANUP=()    # functions called at exit after the processes stop, before PT_WORK goes

pt_say() { printf '%s: %s\n' "$PT_NAME" "$*"; }

pt_ok() { printf 'ok - %s\n' "$*"; }

pt_fail() {
  printf 'FAIL - %s\n' "$*"
  PT_FAILS=$((PT_FAILS + 1))
}

# pt_check DESCRIPTION COMMAND...: ok if COMMAND succeeds.
pt_check() {
  local what=$1
  shift
  if "$@"; then pt_ok "$what"; else pt_fail "$what"; fi
}

# pt_check_soon SECONDS DESCRIPTION COMMAND...: pt_check once COMMAND succeeds or SECONDS
# pass. For a log a running lcm-logger writes: it flushes every 100 ms, later when starved,
# so an event published just before the check may not be in the file yet.
pt_check_soon() {
  local s=$1
  shift
  pt_wait_for "$s" "${@:2}"
  pt_check "$@"
}

# pt_on_cleanup FUNCTION: call FUNCTION (a name, no arguments) at exit, after everything
# started has stopped and before the work directory is removed: e.g. unmount what the test
# mounted there, which rm -rf cannot remove. A function, not a string to eval, so no path
# is pasted into shell code.
pt_on_cleanup() { PT_ON_CLEANUP+=("$1"); }

# pt_check_not DESCRIPTION COMMAND...: ok if COMMAND fails. (Instead of bash -c "! ...":
# no path or value is ever pasted into a string a shell parses again.)
pt_check_not() {
  local what=$1
  shift
  if "$@"; then pt_fail "$what"; else pt_ok "$what"; fi
}

# A figure line, also kept in $PT_WORK/figures.
pt_figure() { printf '%s %s %s\n' "$1" "$2" "$3" | tee -a "$PT_WORK/figures"; }

pt_now_us() { local t=$EPOCHREALTIME; printf '%s' "${t/[.,]/}"; }

# NUDGE_SLOW=N (an integer >= 1, default 1): the programs run N times slower than a
# Release build, e.g. under the sanitizers. Deadlines for something to happen (start-up,
# a task, a stop) and time limits given to the programs are multiplied by it; what a test
# asserts about the system's own timing (loop gaps, the executor's brake) is not.
PT_SLOW=${NUDGE_SLOW:-1}
if [[ ! $PT_SLOW =~ ^[1-9][0-9]?$ ]]; then
  echo "process-lib: NUDGE_SLOW must be an integer from 1 to 99, got '$PT_SLOW'" >&2
  exit 2
fi

# pt_slow SECONDS: SECONDS scaled by NUDGE_SLOW (integers or decimals, e.g. 0.1).
pt_slow() { awk -v s="$1" -v k="$PT_SLOW" 'BEGIN { print s * k }'; }

# What a sanitizer writes when it finds something: an ASan error (also its SEGV report),
# UBSan's "runtime error:", any LeakSanitizer report or failure.
PT_SANITIZER_RE='ERROR: AddressSanitizer|runtime error:|LeakSanitizer'

# pt_sanitizer_scan DIR: fail for every log (*.log, *.out, *.err under DIR) that holds a
# sanitizer report, and show its first lines. A process that dies of one is restarted by
# the supervisor, and a leak report comes only as a process exits, so neither would fail
# a test by itself. Return 1 if any was found.
pt_sanitizer_scan() {
  local f found=0
  while IFS= read -r -d '' f; do
    grep -aqE "$PT_SANITIZER_RE" "$f" || continue
    found=1
    pt_fail "sanitizer report in ${f#"$1"/}:"
    grep -anE -A 12 "$PT_SANITIZER_RE" "$f" | head -n 40
  done < <(find "$1" -type f \( -name '*.log' -o -name '*.out' -o -name '*.err' \) -print0)
  return $found
}

# pt_init BUILD_DIR: locate the programs, make the work directory, arm the EXIT trap.
pt_init() {
  PT_BUILD=${1:?usage: $0 BUILD_DIR}
  PT_BIN=$PT_BUILD/bin
  PT_LC=$PT_BUILD/tests/nudge-logcheck
  PT_INJ=$PT_BUILD/tests/nudge-inject
  local p
  for p in "$PT_BIN"/nudge-{up,bridge,executor,planner,tasks,status} "$PT_LC" "$PT_INJ"; do
    [[ -x $p ]] || { echo "$PT_NAME: $p is missing: build first" >&2; exit 1; }
  done
  # PT_NO_LOGGER=1: a test that records nothing (pt_logger unused) runs without it.
  if [[ ${PT_NO_LOGGER:-} != 1 ]] && ! command -v lcm-logger >/dev/null; then
    echo "$PT_NAME: SKIP: lcm-logger is not installed (liblcm-bin)" >&2
    exit 77
  fi
  # The checks and the clean-up take every process in sight for the test's own.
  if [[ ${NETNS_RUN_INSIDE:-} != 1 || $(tr '\0' ' ' </proc/1/cmdline) != *netns-run* ]]; then
    echo "$PT_NAME: run me under tests/netns-run (private namespaces)" >&2
    exit 1
  fi
  PT_WORK=$(mktemp -d "${TMPDIR:-/tmp}/nudge-$PT_NAME.XXXXXX") || exit 1
  trap pt_cleanup EXIT
  trap 'exit 130' INT
  trap 'exit 143' TERM
  pt_say "work dir $PT_WORK, LCM $LCM_DEFAULT_URL"
}

# pt_spawn VAR CMD...: start CMD in the background, its pid into VAR and PT_PIDS. With
# SIGINT at its default: a script's background commands would otherwise ignore it.
pt_spawn() {
  local -n out=$1
  shift
  env --default-signal=INT "$@" &
  out=$!
  PT_PIDS+=("$out")
}

# pt_wait_pid PID SECONDS: wait for PID to exit; its status in PT_RC. 1 on timeout.
# Like every deadline of the pt_wait*/pt_up* helpers, SECONDS is multiplied by NUDGE_SLOW.
pt_wait_pid() {
  local pid=$1 end=$((SECONDS + $2 * PT_SLOW))
  while kill -0 "$pid" 2>/dev/null; do
    ((SECONDS >= end)) && return 1
    sleep 0.1
  done
  wait "$pid"
  PT_RC=$?
  return 0
}

# pt_wait_for SECONDS COMMAND...: poll COMMAND every 0.2 s until it succeeds.
pt_wait_for() {
  local end=$((SECONDS + $1 * PT_SLOW))
  shift
  until "$@" >/dev/null 2>&1; do
    ((SECONDS >= end)) && return 1
    sleep 0.2
  done
}

# pt_logger FILE [REGEX]: record the channels the checks read (by default not the 1 kHz
# ROBOT_STATE nor MOCAP: less load, fewer drops) into FILE until pt_stop_logger, and the
# one-per-event channels (EPISODE, TASK, PARAMS) also into pt_events FILE.
pt_logger() {
  local re=${2:-'^(EE_CMD|PLAN|TASK|PARAMS|EPISODE|STATUS)$'}
  # The instrument must not lose what it measures: as root it runs above the programs
  # under test (nice -10), whose load can starve it past its socket buffer. And a stall
  # of ~30 ms fills LCM's queue of 30 messages per subscription with 1 kHz EE_CMD, which
  # then drops whatever comes next: a one-off EPISODE gets its own logger and queue.
  local pre=()
  ((EUID == 0)) && pre=(nice -n -10)
  pt_spawn PT_LOGGER "${pre[@]}" lcm-logger -q -f -c "$re" "$1"
  pt_spawn PT_EVLOGGER "${pre[@]}" lcm-logger -q -f -c '^(EPISODE|TASK|PARAMS)$' \
    "$(pt_events "$1")"
  # lcm-logger creates the file once it has subscribed.
  pt_wait_for 5 test -e "$1" -a -e "$(pt_events "$1")" || pt_fail "lcm-logger did not start"
  sleep 0.2
}

# pt_events FILE: the log of FILE's one-per-event channels, for `nudge-logcheck episodes`.
pt_events() { printf '%s\n' "${1%.lcmlog}.events.lcmlog"; }

pt_stop_logger() {
  local pid
  for pid in $PT_LOGGER $PT_EVLOGGER; do
    kill -INT "$pid" 2>/dev/null
    pt_wait_pid "$pid" 5 || { kill -KILL "$pid"; wait "$pid"; }
  done
  PT_LOGGER="" PT_EVLOGGER=""
}

# pt_up_wait LOGDIR SECONDS PID: wait until the supervisor PID says all processes are up;
# 1 at the deadline or as soon as it has exited (it gives up when one cannot start).
pt_up_wait() {
  local end=$((SECONDS + $2 * PT_SLOW))
  until grep -q 'all up' "$1/supervisor.log" 2>/dev/null; do
    if ((SECONDS >= end)) || ! kill -0 "$3" 2>/dev/null; then return 1; fi
    sleep 0.2
  done
}

# pt_up_stop PID SECONDS: SIGINT to a supervisor, wait; its status in PT_RC.
pt_up_stop() {
  kill -INT "$1" 2>/dev/null
  if ! pt_wait_pid "$1" "$2"; then
    pt_fail "nudge-up (pid $1) did not stop within $(($2 * PT_SLOW)) s of SIGINT"
    kill -KILL "$1" 2>/dev/null
    wait "$1"
    PT_RC=137
  fi
}

# pt_restarts_are LOGDIR [NAME N]...: the supervisor's final "restarts:" summary has N
# for each NAME given and 0 for every other process, and only the named processes exited
# on their own ("nudge-X exited" lines).
pt_restarts_are() {
  local dir=$1 line p n want bad="" exits
  shift
  local -A expect=()
  while (($# >= 2)); do expect[$1]=$2; shift 2; done
  line=$(grep -o 'all stopped; restarts:.*' "$dir/supervisor.log" | tail -n 1)
  if [[ -z $line ]]; then
    pt_fail "supervisor: no 'all stopped' summary in $dir/supervisor.log"
    return
  fi
  line=${line#all stopped; restarts:}
  while read -r p n; do
    [[ -n $p ]] || continue
    want=${expect[$p]:-0}
    [[ $n == "$want" ]] || bad+=" $p $n (expected $want)"
  done < <(tr ',' '\n' <<<"$line")
  exits=$(grep -oE 'nudge-[a-z]+ exited' "$dir/supervisor.log" | sort -u | sed 's/nudge-//; s/ exited//')
  for p in $exits; do
    [[ -n ${expect[$p]:-} ]] || bad+=" $p exited"
  done
  if [[ -z $bad ]]; then
    pt_ok "supervisor: restarts:$line"
  else
    pt_fail "supervisor: restarts:$line; wrong:$bad"
    grep -E 'exited|restarted' "$dir/supervisor.log"
  fi
}

# Pids the supervisor logged in LOGDIR (started and restarted), one per line.
pt_logged_pids() {
  sed -n -E 's/.*nudge-[a-z]+ up \(pid ([0-9]+)\).*/\1/p; s/.*restarted nudge-[a-z]+ \(pid ([0-9]+)\).*/\1/p' \
    "$1/supervisor.log"
}

# pt_none_left LOGDIR: assert no process the supervisor logged is alive, and nothing but
# this script runs in the namespace.
pt_none_left() {
  local dir=$1 p alive=() n=0
  for p in $(pt_logged_pids "$dir"); do
    n=$((n + 1))
    [[ -d /proc/$p ]] && [[ $(cut -d' ' -f3 "/proc/$p/stat" 2>/dev/null) != Z ]] && alive+=("$p")
  done
  if ((${#alive[@]} == 0)); then
    pt_ok "none of the $n processes the supervisor logged is alive"
  else
    pt_fail "processes of the run still alive: ${alive[*]}"
    ps -o pid,ppid,stat,args -p "$(IFS=,; echo "${alive[*]}")" || true
  fi
  # The namespace holds netns-run (pid 1), this script and what the test started:
  # anything else alive now was left behind.
  pt_ns_others
  if ((${#PT_OTHERS[@]} == 0)); then
    pt_ok "no other process is running in the namespace"
  else
    pt_fail "processes still running in the namespace: ${PT_OTHERS[*]}"
  fi
}

# pt_ns_others: the live processes of the namespace other than netns-run (pid 1) and this
# script, as "pid:args", into the array PT_OTHERS. /proc is read without forking, so the
# scan itself adds no child of this shell to the list.
pt_ns_others() {
  local d q st args
  PT_OTHERS=()
  for d in /proc/[0-9]*; do
    q=${d#/proc/}
    ((q == 1 || q == $$)) && continue
    st=""
    read -r st <"$d/stat" 2>/dev/null || continue
    st=${st##*) }
    [[ ${st%% *} == Z ]] && continue
    args=()
    mapfile -d '' -t args <"$d/cmdline" 2>/dev/null
    PT_OTHERS+=("$q:${args[*]:-?}")
  done
}

# pt_lc ARGS...: run nudge-logcheck, echo its figures, keep them in $PT_WORK/figures.
# Returns its status.
pt_lc() {
  local out rc
  out=$("$PT_LC" "$@")
  rc=$?
  [[ -n $out ]] && printf '%s\n' "$out" | tee -a "$PT_WORK/figures"
  return $rc
}

# pt_val VAR LOGCHECK-ARGS... NAME: run nudge-logcheck quietly; VAR = the value of its
# figure NAME ("" if absent).
pt_val() {
  local -n out=$1
  local name=${!#}
  local args=("${@:2:$#-2}")
  out=$("$PT_LC" "${args[@]}" 2>/dev/null | awk -v n="$name" '$1 == n { print $2 }')
}

# Dump what helps to diagnose a failure: the tails of the process logs.
pt_dump_logs() {
  local f
  for f in "$@"; do
    [[ -f $f ]] || continue
    echo "----- tail of $f"
    tail -n 25 "$f" | grep -v 'error -1 decoding' | tail -n 15
  done
}

# pt_udp_drops: the namespace's UDP datagrams the kernel dropped for a full receive buffer
# (/proc/net/snmp RcvbufErrors; netns-run gives each test its own counters). A count
# that fell short beside a figure above 0 was lost in the kernel, not in a process.
pt_udp_drops() {
  awk '$1 == "Udp:" { if (!h) { for (i = 2; i <= NF; i++) c[$i] = i; h = 1 }
                      else { print $c["RcvbufErrors"]; exit } }' /proc/net/snmp 2>/dev/null
}

pt_cleanup() {
  local rc=$? p
  trap - EXIT INT TERM
  # Stop what is still running: SIGINT first (supervisors stop their children), then
  # SIGKILL what did not go.
  for p in "${PT_PIDS[@]}"; do kill -INT "$p" 2>/dev/null; done
  for p in "${PT_PIDS[@]}"; do pt_wait_pid "$p" 8 || kill -KILL "$p" 2>/dev/null; done
  for p in "${PT_PIDS[@]}"; do wait "$p" 2>/dev/null; done
  # Children of a supervisor that had to be killed: everything in the namespace is ours.
  local d q
  for d in /proc/[0-9]*; do
    q=${d#/proc/}
    ((q == 1 || q == $$)) && continue
    kill -KILL "$q" 2>/dev/null && pt_say "cleanup: killed leftover process $q"
  done
  local drops
  drops=$(pt_udp_drops)
  [[ -n ${NETNS_RUN_INSIDE:-} && -n $drops && -n ${PT_WORK:-} && -d $PT_WORK ]] &&
    pt_figure udp_rcvbuf_drops "$drops" count
  # Everything has stopped now, so every leak report has been written.
  if [[ -n ${PT_WORK:-} && -d $PT_WORK ]]; then
    pt_sanitizer_scan "$PT_WORK" && pt_ok "no sanitizer report in the logs"
  fi
  if ((rc != 0 || PT_FAILS > 0)); then
    pt_dump_logs "$PT_WORK"/*/*.log "$PT_WORK"/*.out "$PT_WORK"/*.err
  fi
  local c
  for c in "${PT_ON_CLEANUP[@]}"; do "$c"; done
  if [[ -n ${PT_KEEP:-}${ND_KEEP:-} ]]; then
    pt_say "kept the work directory $PT_WORK (PT_KEEP)"
  elif [[ -n ${PT_WORK:-} && -d $PT_WORK ]]; then
    rm -rf -- "$PT_WORK"
  fi
  if ((rc == 0 && PT_FAILS > 0)); then rc=1; fi
  if ((rc == 0)); then pt_say "PASSED"; elif ((rc != 77)); then pt_say "FAILED ($PT_FAILS failed checks, status $rc)"; fi
  exit $rc
}
