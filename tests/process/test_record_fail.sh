#!/usr/bin/env bash
# test_record_fail: nudge-tasks recording into a replay buffer that stops taking appends.
#
#   netns-run bash test_record_fail.sh BUILD_DIR
#
# The system runs (`nudge-up run`) and nudge-tasks pushes with --record into buffers on
# file systems mounted in the test's private mount namespace (netns-run makes one; the
# test runs as root, so a mode of 0444 would not stop a write: the kernel has to refuse).
# Goals follow the default chain with eps 2.5e-3, tau 2 s, so every task is a real push.
#
# 0. seed: one task recorded into a buffer on a 1 MiB tmpfs, so the file holds a record
#    written by the real recorder before trouble starts; then a goal met where the object
#    lies (eps 1): reached at once, not recorded (no push to learn from), said so; then a
#    task whose 50 ms limit ends before the sphere can move the object: not recorded, said
#    so (a record every theta replays alike teaches a refit nothing);
# 1. disk full: a dummy file fills the tmpfs; two tasks;
# 2. read-only: a copy of the seeded buffer behind a read-only bind mount; two tasks;
# 3. read-only, then writable again: the mount turns read-write after the first task's
#    failure; the second task's append reopens the file and is recorded;
# 4. placed, then moved: with --place the object is put at the origin; another PLACE moves it
#    during the settle; the runner places it again, and the record starts at the origin;
# 5. moved after every placement: the runner gives up after its 3 placements and runs the
#    task from where the object lies, unrecorded.
# In 1 and 2 nudge-tasks runs both goals to their end (both task lines and its summary),
# says for every task it could not record which file and why (ENOSPC / EROFS, by name
# and text), exits 3 and reports the failures as tasks_record_failed; the seeded records
# are all readable and the file is byte for byte what it was. A task whose recording is
# refused for its data (messages lost on a loaded machine) is not an append failure, so
# 1 and 2 demand at least one failed append and every task either failed to append or
# was refused for its data; none recorded. 3 demands exactly one of each.
set -u
PT_NAME=test_record_fail
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"
pt_init "$@"

UP=$PT_WORK/up
FULL=$PT_WORK/full          # tmpfs, 1 MiB
RW=$PT_WORK/rw              # plain directory ...
RO=$PT_WORK/ro              # ... bind-mounted here read-only
mkdir -p "$FULL" "$RW" "$RO"
if ! why=$(mount -t tmpfs -o size=1m,mode=0700 nudge-full "$FULL" 2>&1); then
  echo "$PT_NAME: SKIP: cannot mount a tmpfs here: $why" >&2
  exit 77
fi
unmount_all() {
  umount -l "$FULL" 2>/dev/null
  umount -l "$RO" 2>/dev/null
  return 0
}
pt_on_cleanup unmount_all
TASK_ARGS=(--eps 2.5e-3 --tau 2 --settle 0.5)

# tasks NAME BUFFER GOAL...: run nudge-tasks recording into BUFFER in the background
# (pid in TASKS_PID), output in $PT_WORK/NAME.out / .err.
tasks() {
  local name=$1 buf=$2
  shift 2
  local g goals=()
  for g in "$@"; do goals+=(--goal "$g"); done
  pt_spawn TASKS_PID "$PT_BIN/nudge-tasks" --record "$buf" "${TASK_ARGS[@]}" "${goals[@]}" \
    >"$PT_WORK/$name.out" 2>"$PT_WORK/$name.err"
}

# finish NAME: wait for the runner started by tasks; its status in PT_RC.
finish() {
  if ! pt_wait_pid "$TASKS_PID" 40; then
    pt_fail "$1: nudge-tasks did not finish within 40 s"
    kill -INT "$TASKS_PID"
    pt_wait_pid "$TASKS_PID" 5 || kill -KILL "$TASKS_PID"
    PT_RC=124
  fi
}

# figure NAME FILE: value of summary line NAME in FILE ("" if absent).
figure() { awk -v n="$1" '$1 == n { print $2 }' "$2"; }

# records FILE: the buffer's record count via nudge-logcheck buffer ("" if unreadable).
records() { "$PT_LC" buffer "$1" 2>/dev/null | awk '$1 == "records_in_file" { print $2 }'; }

# check_unrecorded NAME WHY: the run NAME (after finish) exited 0, said its one task was not
# recorded for WHY (an ERE), and left $BUF's one seeded record alone.
check_unrecorded() {
  cat "$PT_WORK/$1.out"
  pt_check "$1: nudge-tasks exits 0 (got $PT_RC)" test "$PT_RC" -eq 0
  pt_check "$1: it says why it records nothing" \
    grep -qE "^nudge-tasks: task [0-9]+ not recorded: $2\$" "$PT_WORK/$1.err"
  pt_check "$1: nothing appended (still one record)" test "$(records "$BUF")" = 1
}

# check_failed_run NAME BUFFER REASON ENAME: the assertions of cases 1 and 2.
check_failed_run() {
  local name=$1 buf=$2 reason=$3 ename=$4 out=$PT_WORK/$1.out err=$PT_WORK/$1.err
  local failed recorded run appends appends_ok others
  cat "$out"
  grep -E 'not recorded|cannot record' "$err"
  pt_check "$name: nudge-tasks exits 3, appends failed (got $PT_RC)" test "$PT_RC" -eq 3
  pt_check "$name: both goals were attempted to their end" \
    grep -qE '^task 2/2 goal .*: (reached in|timed out after)' "$out"
  pt_check "$name: the summary line 'reached K/2 goals' came" grep -qE '^reached [0-9]/2 goals$' "$out"
  run=$(figure tasks_run "$out")
  failed=$(figure tasks_record_failed "$out")
  recorded=$(figure tasks_recorded "$out")
  pt_check "$name: tasks_run 2 (got ${run:-none})" test "${run:-0}" -eq 2
  pt_check "$name: tasks_recorded 0 (got ${recorded:-none})" test "${recorded:-x}" = 0
  # Each failed append is one line naming the file, the errno text and its name.
  appends=$(grep -E '^nudge-tasks: task [0-9]+ not recorded: ' "$err" | grep -cF "not recorded: $buf: ")
  appends_ok=$(grep -E '^nudge-tasks: task [0-9]+ not recorded: ' "$err" | grep -F "not recorded: $buf: " |
    grep -F "$reason" | grep -cF "[$ename]")
  others=$(grep -cE '^nudge-tasks: task [0-9]+ not recorded: ' "$err")
  pt_check "$name: at least one append failed and the summary counts them (tasks_record_failed ${failed:-none}, $appends error lines)" \
    test "${failed:-0}" -ge 1 -a "${failed:-0}" -eq "$appends"
  pt_check "$name: every failed append names $buf, '$reason' and [$ename] ($appends_ok of $appends)" \
    test "$appends_ok" -eq "$appends"
  pt_check "$name: every task is either a failed append or refused for its data ($others not-recorded lines)" \
    test "$others" -eq 2
  pt_check "$name: the final line counts the lost tasks and names the file" \
    grep -qE "^nudge-tasks: $failed task\(s\) not recorded: appending to $buf failed; the last error: .*\[$ename\]" "$err"
  pt_figure "${name}_record_failed" "${failed:-0}" count
}

# --- the system ----------------------------------------------------------------------
pt_spawn up "$PT_BIN/nudge-up" run --log-dir "$UP" 2>"$PT_WORK/up.err"
pt_up_wait "$UP" 30 "$up" || { pt_fail "nudge-up run did not come up within 30 s"; exit 1; }
pt_ok "nudge-up run: all processes up"

# --- 0. seed ---------------------------------------------------------------------------
BUF=$FULL/replay.nrb
t0=$(pt_now_us)
tasks seed "$BUF" 0.15,0,0
finish seed
cat "$PT_WORK/seed.out"
pt_check "seed: nudge-tasks exits 0 (got $PT_RC)" test "$PT_RC" -eq 0
n_seed=$(records "$BUF")
pt_check "seed: one record in the buffer on the tmpfs (got ${n_seed:-unreadable})" test "${n_seed:-0}" -eq 1
pt_figure seed_duration $((($(pt_now_us) - t0) / 1000)) ms
((n_seed == 1)) || exit 1   # the rest compares against it
pt_check "seed: its goal was not met at the start" \
  test "$(figure tasks_met_at_start "$PT_WORK/seed.out")" = 0

# --- 0b. a goal met where the object lies (eps 1 holds anywhere) --------------------------
tasks met "$BUF" 0,0,0,1
finish met
check_unrecorded met 'its goal is met at the start \(task error [0-9.e-]+ < eps 1\), nothing to push'
pt_check "met: reached at once" grep -q '^reached 1/1 goals' "$PT_WORK/met.out"
pt_check "met: counted as met at the start" \
  test "$(figure tasks_met_at_start "$PT_WORK/met.out")" = 1

# --- 0c. a task over before the object moved (50 ms: the plan is barely out) -----------
tasks still "$BUF" 0.25,0.10,0.4,2.5e-3,0.05
finish still
check_unrecorded still 'the object moved 0\.00[0-9] m \(under 0\.01 m\), nothing of its friction to fit'
pt_check "still: timed out, not met at the start" \
  test "$(figure tasks_met_at_start "$PT_WORK/still.out") $(figure tasks_reached "$PT_WORK/still.out")" = "0 0"

# --- 1. disk full ----------------------------------------------------------------------
dd if=/dev/zero of="$FULL/filler" bs=4k status=none 2>/dev/null
pt_check "the tmpfs is full (0 blocks free)" test "$(stat -f -c %a "$FULL")" -eq 0
size_before=$(stat -c %s "$BUF")
sum_before=$(sha256sum <"$BUF")
t0=$(pt_now_us)
tasks full "$BUF" 0.25,0.10,0.4 0.25,0.25,0.8
finish full
pt_figure full_duration $((($(pt_now_us) - t0) / 1000)) ms
check_failed_run full "$BUF" "No space left on device" ENOSPC
pt_check "full: the seeded record is still there and readable ($(records "$BUF") records)" \
  test "$(records "$BUF")" = 1
pt_check "full: the buffer is byte for byte unchanged ($size_before bytes)" \
  test "$(sha256sum <"$BUF")" = "$sum_before"
pt_check "full: the failed appends were cut back: no stray temp or partial file left" \
  test "$(ls "$FULL")" = "$(printf 'filler\nreplay.nrb')"

# --- 2. read-only ----------------------------------------------------------------------
cp "$BUF" "$RW/replay.nrb"
rm -f "$FULL/filler"
if ! why=$({ mount --bind "$RW" "$RO" && mount -o remount,bind,ro "$RO"; } 2>&1); then
  pt_fail "cannot make a read-only bind mount: $why"
  exit 1
fi
ROBUF=$RO/replay.nrb
pt_check "read-only: a write into the mount is refused by the kernel" \
  bash -c "! : 2>/dev/null >>'$ROBUF'"
sum_before=$(sha256sum <"$ROBUF")
t0=$(pt_now_us)
tasks ro "$ROBUF" 0.10,0.30,0.8 0.00,0.20,0.3
finish ro
pt_figure ro_duration $((($(pt_now_us) - t0) / 1000)) ms
check_failed_run ro "$ROBUF" "Read-only file system" EROFS
pt_check "read-only: the start said it cannot record there now, and went on" \
  grep -qF "cannot record into $ROBUF now: $ROBUF: cannot open for appending: Read-only file system [EROFS]; running the tasks anyway" "$PT_WORK/ro.err"
pt_check "read-only: the seeded record is still there and readable" test "$(records "$ROBUF")" = 1
pt_check "read-only: the buffer is byte for byte unchanged" test "$(sha256sum <"$ROBUF")" = "$sum_before"

# --- 3. read-only, then writable again ---------------------------------------------------
size_before=$(stat -c %s "$ROBUF")
tasks back "$ROBUF" 0.15,0.05,0 0.25,0.10,0.4
if pt_wait_for 30 grep -qE '^nudge-tasks: task [0-9]+ not recorded: ' "$PT_WORK/back.err"; then
  mount -o remount,bind,rw "$RO" || pt_fail "cannot remount $RO read-write"
else
  pt_fail "back: no failed append reported within 30 s"
fi
finish back
cat "$PT_WORK/back.out"
grep -E 'not recorded|writable again|recorded:' "$PT_WORK/back.err"
pt_check "back: nudge-tasks exits 3, one append failed (got $PT_RC)" test "$PT_RC" -eq 3
pt_check "back: tasks_record_failed 1, tasks_recorded 1" \
  test "$(figure tasks_record_failed "$PT_WORK/back.out") $(figure tasks_recorded "$PT_WORK/back.out")" = "1 1"
pt_check "back: the runner reopened the buffer once it was writable" \
  grep -qF "$ROBUF is writable again: recording into it (1 rollouts there)" "$PT_WORK/back.err"
pt_check "back: the buffer holds the seeded record and the new one" test "$(records "$ROBUF")" = 2
pt_check "back: the seeded record's bytes are unchanged" \
  cmp -s -n "$size_before" "$BUF" "$ROBUF"

# --- 4. placed, then moved before the task ----------------------------------------------
# nudge-tasks --place puts the object at the origin, then settles for 4 s; a PLACE from
# elsewhere (nudge-inject: a hand, or a sphere still on its way out) moves it meanwhile.
# The runner sees it off the pose, places it again, and the record starts at the pose.
PBUF=$RW/placed.nrb
BLOG=$UP/bridge.log
n_origin() { grep -c ': the object placed at (+0.000, +0.000) m, yaw +0.0 deg' "$BLOG"; }
placed_once() { (($(n_origin) >= 1)); }
pt_spawn TASKS_PID "$PT_BIN/nudge-tasks" --record "$PBUF" --eps 2.5e-3 --tau 2 --settle 4 \
  --place 0,0,0 --goal 0.15,0,0 >"$PT_WORK/moved.out" 2>"$PT_WORK/moved.err"
if pt_wait_for 20 placed_once; then
  out=$("$PT_INJ" --place-at 0.03,0.02,0.3 2>&1) || pt_fail "nudge-inject --place-at failed: $out"
else
  pt_fail "moved: the bridge did not place the object at the origin within 20 s"
fi
finish moved
cat "$PT_WORK/moved.out"
grep -E 'placed pose|not recorded' "$PT_WORK/moved.err"
pt_check "moved: nudge-tasks exits 0 (got $PT_RC)" test "$PT_RC" -eq 0
pt_check "moved: the bridge moved the object to the other PLACE" \
  grep -q ': the object placed at (+0.030, +0.020) m, yaw +17.2 deg' "$BLOG"
pt_check "moved: the runner saw it off the pose and placed it again" \
  grep -qE '^nudge-tasks: the object was moved [0-9.]+ mm and [0-9.]+ rad off the placed pose before the task: placing it again$' \
  "$PT_WORK/moved.err"
pt_check "moved: placed at the origin twice (got $(n_origin))" test "$(n_origin)" -eq 2
pt_check "moved: the task was recorded ($(records "$PBUF") records)" test "$(records "$PBUF")" = 1
pt_val o0 buffer "$PBUF" record_start_off_origin_max
pt_check "moved: the record starts with the object at the origin (off by $o0 m)" \
  awk -v o="$o0" 'BEGIN { exit !(o != "" && o < 0.005) }'

# --- 5. moved after every placement ----------------------------------------------------
# The runner places the object at most 3 times (PLACE_TRIES). Moved off the pose after each,
# the task still runs, from where the object lies, but is not recorded: a record starts at
# the placed pose.
n0=$(n_origin)
placed_k() { (($(n_origin) >= n0 + k)); }
pt_spawn TASKS_PID "$PT_BIN/nudge-tasks" --record "$PBUF" --eps 2.5e-3 --tau 2 --settle 4 \
  --place 0,0,0 --goal 0.15,0,0 >"$PT_WORK/moved3.out" 2>"$PT_WORK/moved3.err"
for k in 1 2 3; do
  if ! pt_wait_for 20 placed_k; then
    pt_fail "moved3: the bridge did not make placement $k of 3 at the origin within 20 s"
    break
  fi
  out=$("$PT_INJ" --place-at -0.03,0.02,-0.3 2>&1) || pt_fail "nudge-inject --place-at failed: $out"
done
finish moved3
cat "$PT_WORK/moved3.out"
grep -E 'placed pose|not recorded' "$PT_WORK/moved3.err"
pt_check "moved3: nudge-tasks exits 0 (got $PT_RC)" test "$PT_RC" -eq 0
pt_check "moved3: placed at the origin 3 more times (got $(($(n_origin) - n0)))" \
  test "$(($(n_origin) - n0))" -eq 3
pt_check "moved3: the runner gave up after 3 placements and said the task goes unrecorded" \
  grep -qE '^nudge-tasks: the object was moved off the placed pose after each of 3 placements \([0-9.]+ mm, [0-9.]+ rad the last time\): the next task is not recorded \(a record starts at the placed pose\)$' \
  "$PT_WORK/moved3.err"
pt_check "moved3: the task ran all the same" grep -q '^task 1/1 goal (+0.15, +0.00, +0.0 deg): ' \
  "$PT_WORK/moved3.out"
pt_check "moved3: tasks_recorded 0" test "$(figure tasks_recorded "$PT_WORK/moved3.out")" = 0
pt_check "moved3: the buffer still holds the one record of section 4 (got $(records "$PBUF"))" \
  test "$(records "$PBUF")" = 1

# A sender re-sends its PLACE until it sees the object there, so a re-send can arrive after
# a newer PLACE (the bump above). The bridge must not carry the older one out again.
last_id=$(sed -n 's/^nudge-bridge: PLACE \([0-9]*\): the object placed at (+0.000, +0.000) m.*/\1/p' \
  "$BLOG" | tail -n 1)
n_placed() { grep -c ': the object placed at' "$BLOG"; }
p1=$(n_placed)
out=$("$PT_INJ" --place-at 0,0,0 --place-id "${last_id:-1}" 2>&1) ||
  pt_fail "nudge-inject --place-id failed: $out"
sleep 2
pt_check "resent: the runner's last PLACE was found in the bridge log (id ${last_id:-none})" \
  test -n "$last_id"
pt_check "resent: the bridge did not place the object again for a re-sent PLACE (placements $p1 -> $(n_placed))" \
  test "$(n_placed)" -eq "$p1"

# --- the system is unharmed --------------------------------------------------------------
pt_up_stop "$up" 30
pt_check "nudge-up run exits 0 after SIGINT (got $PT_RC)" test "$PT_RC" -eq 0
pt_restarts_are "$UP"
pt_none_left "$UP"
exit $((PT_FAILS > 0))
