#!/usr/bin/env bash
# test_files: the files nudge reads and writes, when they are bad or when the umask is.
#
#   bash test_files.sh BUILD_DIR
#
# Every program runs under umask 000 (the test's own files are made under 022, so any
# world-writable file in the end is the programs' doing).
# 1. nudge-experiment writes its CSVs, gnuplot's figures and replay buffers into an --out
#    directory whose name carries shell syntax: the figures appear in it (gnuplot got the
#    name literally) and nothing is run.
# 2. nudge-adapter on a replay buffer that is missing (it waits), not a record file or of
#    a newer format version (it says so once and keeps polling), damaged in the middle or
#    torn at the end (it fits the records before the damage and says where they stop);
#    a reader never changes the file. With --max-rollouts it fits the newest only, and
#    a restart does not refit the records its history covers; --offline refits once per
#    record, the window kept, and leaves the buffer and the history as they were.
# 3. nudge-adapter's history of the wrong kind, not a record file, or damaged before valid
#    entries: exit 1 naming the file, file untouched; a torn tail: cut off, reported, the
#    adapter resumes from the entries before it.
# 4. nudge-tasks --record on a file of the wrong kind or damaged in the middle: exit 1
#    naming it, file untouched; a torn tail is cut off and reported; a missing directory
#    is named.
# 5. Nothing any of them created is world-writable.
# The adapter runs on LCM's in-process transport memq:// and nudge-tasks on a transport
# that does not exist (it fails after the file checks): no network is used.
set -u
PT_NAME=test_files
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"

BUILD=${1:?usage: test_files.sh BUILD_DIR}
BIN=$(cd "$BUILD/bin" && pwd) || exit 1
for p in adapter tasks experiment; do
  [[ -x $BIN/nudge-$p ]] || { echo "test_files: $BIN/nudge-$p is missing: build first" >&2; exit 1; }
done
PT_WORK=$(mktemp -d "${TMPDIR:-/tmp}/nudge-test_files.XXXXXX") || exit 1
W=$PT_WORK
cleanup() {
  local p
  for p in "${PT_PIDS[@]}"; do kill -KILL "$p" 2>/dev/null; done
  [[ -n ${KEEP_WORK:-} ]] || rm -rf -- "$W"
}
trap cleanup EXIT
cd "$W" || exit 1
umask 022

# Offsets of the records of a record file (40-byte header, then [u32 len][u32 kind]
# [u32 crc][len bytes]), one per line, then the end of the last complete one.
record_offsets() {
  local f=$1 off=40 size len
  size=$(stat -c %s "$f")
  while ((off + 12 <= size)); do
    len=$(od -An -t u4 -j "$off" -N 4 "$f" | tr -d ' ')
    ((off + 12 + len <= size)) || break
    echo "$off"
    off=$((off + 12 + len))
  done
  echo "$off"
}

# poke FILE OFFSET BYTE: overwrite one byte (BYTE as octal escape, e.g. '\377').
poke() { printf "$3" | dd of="$1" bs=1 seek="$2" conv=notrunc status=none; }

# adapter NAME ARGS...: start nudge-adapter (memq://, one worker) in the background;
# its stdout/stderr in $W/NAME.out, $W/NAME.err; pid in APID.
adapter() {
  local n=$1
  shift
  ( umask 000
    exec env --default-signal=INT "$BIN/nudge-adapter" --lcm-url memq:// --threads 1 --nice 0 "$@"
  ) >"$W/$n.out" 2>"$W/$n.err" &
  APID=$!
  PT_PIDS+=("$APID")
}
# said FILE TEXT SECONDS: TEXT appears in FILE within SECONDS.
said() { pt_wait_for "$3" grep -qF -- "$2" "$1"; }
# stop_adapter: SIGINT; its status in PT_RC (137 if it had to be killed).
stop_adapter() {
  kill -INT "$APID" 2>/dev/null
  pt_wait_pid "$APID" 15 || { pt_fail "nudge-adapter ignored SIGINT for 15 s"; kill -KILL "$APID"; wait "$APID"; PT_RC=137; }
}
# exits_within SECONDS: the adapter exits by itself within SECONDS; status in PT_RC.
exits_within() { pt_wait_pid "$APID" "$1" || { kill -KILL "$APID"; wait "$APID"; PT_RC=timeout; }; }

# --- 1. experiment outputs ---------------------------------------------------------------

OUT="$W/exp \$(touch $W/pwned1);'\`touch $W/pwned2\`'"
t0=$(pt_now_us)
( umask 000
  exec "$BIN/nudge-experiment" --out "$OUT" --runs 1 --episodes 3 --pop 8 --iters 1 --tau 0.3 \
    --eval-tasks 1 --d 1 --threads 1 ) >"$W/exp.out" 2>"$W/exp.err"
rc=$?
pt_figure files_experiment_ms "$((($(pt_now_us) - t0) / 1000))" ms
pt_check "nudge-experiment --out with shell syntax in the name: exit 0 (got $rc)" test "$rc" -eq 0
pt_check "its summary.csv is where --out says" test -s "$OUT/summary.csv"
if command -v gnuplot >/dev/null; then
  pt_check "gnuplot ran in that directory: both figures there" \
    test -s "$OUT/fig2_param_errors.png" -a -s "$OUT/fig3_performance.png"
else
  pt_say "gnuplot not installed: figures not checked"
fi
pt_check "no part of --out was run as a command" test -z "$(find "$W" -name 'pwned[0-9]')"
# The validation loss's resolution: a band 0 < min <= max measured at the truth, and the
# runs above it counted out of the runs made.
band=$(awk '$1 == "val_loss_band_min" {lo = $2} $1 == "val_loss_band_max" {hi = $2}
  END {print (lo > 0 && hi >= lo && hi < 1) ? "ok" : "bad " lo " " hi}' "$W/exp.out")
pt_check "it prints the validation loss band at the truth ($band)" test "$band" = ok
pt_check "it counts the runs whose initial loss is above the band, of 1" \
  grep -Eq '^runs_val_loss_resolved_ep0_d1 [01]/1 runs$' "$W/exp.out"
BUF3=$OUT/buffer_d1_r00.nbuf   # three rollouts
VAL=$OUT/validation.nbuf
mapfile -t OFF < <(record_offsets "$BUF3")
pt_check "the experiment's buffer holds 3 records (offsets ${OFF[*]})" test "${#OFF[@]}" -eq 4
cp "$BUF3" "$W/b3.nbuf"

# --- 2. the replay buffer, as the adapter reads it ----------------------------------------

adapter good --buffer "$W/b3.nbuf"
said "$W/good.out" "refit version 1: 3 rollout(s)" 60 || pt_fail "the adapter did not fit the 3 rollouts within 60 s"
stop_adapter
pt_check "the adapter fitted a good buffer and stopped with 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0
HIST1=$W/b3.nbuf.history
pt_check "it created its history $HIST1" test -s "$HIST1"
cp "$HIST1" "$W/h1.keep"

# --max-rollouts 2: each refit uses the newest two, the history covers every record read,
# and a restarted adapter does not refit what that covers.
cp "$BUF3" "$W/win.nbuf"
adapter win --buffer "$W/win.nbuf" --max-rollouts 2
said "$W/win.out" "refit version 1: 2 rollout(s) (the newest of 3)" 60 ||
  pt_fail "--max-rollouts 2: no fit on the newest 2 of 3 within 60 s"
mapfile -t VOFF < <(record_offsets "$VAL")
tail -c +$((VOFF[0] + 1)) "$VAL" | head -c $((VOFF[1] - VOFF[0])) >>"$W/win.nbuf"
said "$W/win.out" "refit version 2: 2 rollout(s) (the newest of 4)" 60 ||
  pt_fail "--max-rollouts 2: no fit on the newest 2 of 4 within 60 s of a fourth record"
stop_adapter
adapter win2 --buffer "$W/win.nbuf" --max-rollouts 2
said "$W/win2.err" "resuming after version 2 (fit up to rollout 4 " 20 ||
  pt_fail "--max-rollouts 2: the restart did not resume after version 2 covering 4"
# It decides whether to refit in the poll that opens the buffer, and says so at once.
said "$W/win2.err" "reading $W/win.nbuf" 20 || pt_fail "--max-rollouts 2: the restart did not read"
sleep 0.5
pt_check "--max-rollouts 2: the restart starts no refit on what its history covers" \
  bash -c "! grep -q 'refitting on' '$W/win2.err' && test ! -s '$W/win2.out'"
stop_adapter
# --offline on that buffer: one refit per record, as if it had arrived alone, the window
# kept; the file untouched.
cp "$W/win.nbuf" "$W/win.keep"
cp "$W/win.nbuf.history" "$W/winh.keep"
"$BIN/nudge-adapter" --buffer "$W/win.nbuf" --max-rollouts 2 --threads 1 --offline \
  >"$W/off.out" 2>"$W/off.err"
PT_RC=$?
pt_check "--offline: exit 0 (got $PT_RC), refits on 1, 2, the newest 2 of 3 and of 4, then 'refits 4 count'" \
  bash -c 'test "$1" -eq 0 && grep -q "^refit version 1: 1 rollout(s) in" "$2" &&
    grep -q "^refit version 2: 2 rollout(s) in" "$2" &&
    grep -q "^refit version 3: 2 rollout(s) (the newest of 3) in" "$2" &&
    grep -q "^refit version 4: 2 rollout(s) (the newest of 4) in" "$2" &&
    test "$(grep -c "^refit version" "$2")" -eq 4 && grep -qx "refits 4 count" "$2"' _ "$PT_RC" "$W/off.out"
pt_check "--offline: the buffer and its history are untouched" \
  bash -c 'cmp -s "$1" "$2" && cmp -s "$3" "$4"' _ "$W/win.nbuf" "$W/win.keep" \
  "$W/win.nbuf.history" "$W/winh.keep"

# The buffer replaced under the adapter (a new run's file moved into place): it drops the
# old rollouts and fits the new file's.
cp "$BUF3" "$W/r.nbuf"
adapter repl --buffer "$W/r.nbuf"
said "$W/repl.out" "refit version 1: 3 rollout(s)" 60 || pt_fail "replaced buffer: no first fit"
cp "$VAL" "$W/r.new"
mv "$W/r.new" "$W/r.nbuf"
said "$W/repl.err" "$W/r.nbuf was replaced: dropping its 3 rollout(s)" 10 || pt_fail "replaced buffer: not noticed"
said "$W/repl.out" "refit version 2: 1 rollout(s)" 60 || pt_fail "replaced buffer: the new file was not fitted"
# A second adapter on the same history: refused while the first holds it.
APID1=$APID
adapter locked --buffer "$W/r.nbuf"
exits_within 20
pt_check "a second adapter on a history in use: exit 1 (got $PT_RC), says why" \
  test "$PT_RC" = 1 -a -n "$(grep -F "$W/r.nbuf.history: locked by another writer (pid $APID1)" "$W/locked.err" | grep -F 'another nudge-adapter')"
APID=$APID1
stop_adapter
pt_check "replaced buffer: exit 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0

adapter missing --buffer "$W/none.nrb"
said "$W/missing.err" "waiting for $W/none.nrb to appear" 10 || pt_fail "missing buffer: no 'waiting for' line"
pt_check "missing buffer: the adapter keeps running" kill -0 "$APID"
stop_adapter
pt_check "missing buffer: exit 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0

printf 'x,y\n1,2\n' >"$W/text.nrb"
"$BIN/nudge-adapter" --buffer "$W/text.nrb" --offline >/dev/null 2>"$W/offtext.err"
PT_RC=$?
pt_check "--offline on a text file: exit 1 (got $PT_RC) naming it" \
  bash -c 'test "$1" -eq 1 && grep -qF "$3: not a nudge record file" "$2"' _ "$PT_RC" "$W/offtext.err" "$W/text.nrb"
adapter text --buffer "$W/text.nrb"
said "$W/text.err" "$W/text.nrb: not a nudge record file" 10 || pt_fail "text buffer: not named as 'not a nudge record file'"
sleep 0.5
pt_check "text buffer: the adapter keeps running" kill -0 "$APID"
stop_adapter
n=$(grep -c 'not a nudge record file' "$W/text.err")
pt_check "text buffer: exit 0 on SIGINT (got $PT_RC), said once while polling ($n)" test "$PT_RC" -eq 0 -a "$n" -eq 1

cp "$BUF3" "$W/v2.nbuf"
poke "$W/v2.nbuf" 8 '\002'
adapter v2 --buffer "$W/v2.nbuf"
said "$W/v2.err" "format version 2, this build reads version 1" 10 || pt_fail "version 2 buffer: not named"
pt_check "version 2 buffer: the adapter keeps running" kill -0 "$APID"
stop_adapter

# Damage inside: one payload byte of the second record flipped, a valid third after it.
cp "$BUF3" "$W/mid.nbuf"
b=$(od -An -t u1 -j $((OFF[1] + 100)) -N 1 "$W/mid.nbuf" | tr -d ' ')
poke "$W/mid.nbuf" $((OFF[1] + 100)) "\\$(printf '%03o' $((b ^ 0x10)))"
cp "$W/mid.nbuf" "$W/mid.keep"
adapter mid --buffer "$W/mid.nbuf"
said "$W/mid.err" "valid records stop at offset ${OFF[1]} (corrupt" 30 || pt_fail "mid-file damage: no 'valid records stop at offset ${OFF[1]} (corrupt'"
said "$W/mid.out" "refit version 1: 1 rollout(s)" 60 || pt_fail "mid-file damage: no fit on the one record before it"
stop_adapter
pt_check "mid-file damage: exit 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0
pt_check "mid-file damage: the reader left the buffer as it was" cmp -s "$W/mid.nbuf" "$W/mid.keep"

# A torn tail: the third record cut in half, as a crash mid-append leaves it.
cp "$BUF3" "$W/torn.nbuf"
truncate -s $((OFF[2] + (OFF[3] - OFF[2]) / 2)) "$W/torn.nbuf"
size=$(stat -c %s "$W/torn.nbuf")
adapter torn --buffer "$W/torn.nbuf"
said "$W/torn.out" "refit version 1: 2 rollout(s)" 60 || pt_fail "torn tail: no fit on the two records before it"
said "$W/torn.err" "valid records stop at offset ${OFF[2]} (torn" 10 || pt_fail "torn tail: not reported after 2 s"
stop_adapter
pt_check "torn tail: exit 0 on SIGINT (got $PT_RC); the reader did not cut it ($size bytes)" \
  test "$PT_RC" -eq 0 -a "$(stat -c %s "$W/torn.nbuf")" -eq "$size"

# --- 3. the history ----------------------------------------------------------------------

cp "$VAL" "$W/kind1.hist"
cp "$W/kind1.hist" "$W/kind1.keep"
adapter hkind --buffer "$W/b3.nbuf" --history "$W/kind1.hist"
exits_within 20
pt_check "history of kind 1: exit 1 (got $PT_RC)" test "$PT_RC" = 1
pt_check "history of kind 1: named, with the kinds" \
  grep -qF "$W/kind1.hist: holds kind 1 (rollouts), expected kind 2 (parameter history)" "$W/hkind.err"
pt_check "history of kind 1: untouched" cmp -s "$W/kind1.hist" "$W/kind1.keep"

printf 'version,theta\n' >"$W/text.hist"
adapter htext --buffer "$W/b3.nbuf" --history "$W/text.hist"
exits_within 20
pt_check "text history: exit 1 (got $PT_RC), named" \
  test "$PT_RC" = 1 -a -n "$(grep -F "$W/text.hist: not a nudge record file" "$W/htext.err")"
pt_check "text history: untouched" test "$(cat "$W/text.hist")" = "version,theta"

# A torn tail (a crash mid-append): cut off, reported; the adapter resumes at version 1 on
# the same buffer without refitting, so the file ends where it did before.
cp "$W/h1.keep" "$W/h.hist"
hsize=$(stat -c %s "$W/h.hist")
printf '\x40\x00\x00\x00\x02\x00' >>"$W/h.hist"
adapter htorn --buffer "$W/b3.nbuf" --history "$W/h.hist"
said "$W/htorn.err" "$W/h.hist: cut off a torn tail" 20 || pt_fail "torn history: not reported"
said "$W/htorn.err" "resuming after version 1" 10 || pt_fail "torn history: did not resume after version 1"
sleep 0.5
stop_adapter
pt_check "torn history: exit 0 on SIGINT (got $PT_RC), cut back to $hsize bytes" \
  test "$PT_RC" -eq 0 -a "$(stat -c %s "$W/h.hist")" -eq "$hsize"

# Damage before a valid entry: a second fit on another buffer (another creation time) gives
# entry 2; then a byte of entry 1 flipped. Cutting would destroy entry 2: refused.
cp "$W/h1.keep" "$W/h2.hist"
cp "$VAL" "$W/other.nbuf"
adapter h2 --buffer "$W/other.nbuf" --history "$W/h2.hist"
said "$W/h2.out" "refit version 2" 60 || pt_fail "no second history entry within 60 s"
stop_adapter
mapfile -t HOFF < <(record_offsets "$W/h2.hist")
if ((${#HOFF[@]} >= 3)); then
  poke "$W/h2.hist" $((HOFF[0] + 14)) '\125'
  cp "$W/h2.hist" "$W/h2.keep"
  adapter hmid --buffer "$W/other.nbuf" --history "$W/h2.hist"
  exits_within 20
  pt_check "history damaged before a valid entry: exit 1 (got $PT_RC)" test "$PT_RC" = 1
  pt_check "history damaged before a valid entry: refused, named" \
    grep -qE "$(printf '%s' "$W/h2.hist" | sed 's/[]\.[*^$]/\\&/g').*refusing to cut" "$W/hmid.err"
  pt_check "history damaged before a valid entry: untouched" cmp -s "$W/h2.hist" "$W/h2.keep"
else
  pt_fail "the history has ${#HOFF[@]} offsets (${HOFF[*]}), expected 2 entries"
fi

# --- 4. nudge-tasks --record ---------------------------------------------------------------

export LCM_DEFAULT_URL='nudge-no-such-transport://'
rec() { # NAME ARGS...: nudge-tasks --record ... --goal; status in RC, stderr in $W/NAME.err
  local n=$1
  shift
  (umask 000; exec timeout 30 "$BIN/nudge-tasks" --goal 0.1,0,0 "$@") </dev/null >"$W/$n.out" 2>"$W/$n.err"
  RC=$?
}
rec rkind --record "$W/h1.keep"
pt_check "--record on a history: exit 1 (got $RC), named with the kinds" \
  test "$RC" -eq 1 -a -n "$(grep -F "$W/h1.keep: holds kind 2 (parameter history), expected kind 1" "$W/rkind.err")"
pt_check "--record on a history: untouched" cmp -s "$W/h1.keep" "$HIST1"
rec rmid --record "$W/mid.nbuf"
pt_check "--record on a buffer damaged before valid records: exit 1 (got $RC), refused" \
  test "$RC" -eq 1 -a -n "$(grep -F "$W/mid.nbuf" "$W/rmid.err" | grep 'refusing to cut')"
pt_check "--record on a buffer damaged before valid records: untouched" cmp -s "$W/mid.nbuf" "$W/mid.keep"
rec rtorn --record "$W/torn.nbuf"
pt_check "--record on a torn buffer: the tail is cut off and reported" \
  grep -qF "$W/torn.nbuf: cut off a torn tail" "$W/rtorn.err"
pt_check "--record on a torn buffer: it ends after the 2 good records (${OFF[2]} bytes)" \
  test "$(stat -c %s "$W/torn.nbuf")" -eq "${OFF[2]}"
pt_check "--record on a torn buffer: then LCM fails, exit 1 (got $RC)" test "$RC" -eq 1
rec rdir --record "$W/no/such/dir/r.nbuf"
pt_check "--record in a missing directory: exit 1 (got $RC), named" \
  test "$RC" -eq 1 -a -n "$(grep -F "$W/no/such/dir/r.nbuf" "$W/rdir.err" | grep 'No such file')"
rec rnew --record "$W/new.nbuf"
pt_check "--record creates a new buffer (then LCM fails, exit $RC)" test -s "$W/new.nbuf" -a "$RC" -eq 1

# --- 5. modes ---------------------------------------------------------------------------

n=$(find "$W" -type f | wc -l)
ww=$(find "$W" -mindepth 1 -perm -o+w -printf '%m %p\n')
pt_figure files_created_checked "$n" count
pt_check "under umask 000 none of the $n files and directories is world-writable${ww:+: $ww}" test -z "$ww"
for f in "$W/new.nbuf" "$HIST1" "$BUF3"; do
  pt_check "record file $(basename "$f") has mode 640 (got $(stat -c %a "$f"))" test "$(stat -c %a "$f")" = 640
done

if ((PT_FAILS)); then
  for f in "$W"/*.err; do echo "----- $f"; tail -n 5 "$f"; done
  pt_say "FAILED ($PT_FAILS failed checks)"
  exit 1
fi
pt_say "PASSED"
