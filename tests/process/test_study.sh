#!/usr/bin/env bash
# test_study: nudge-study, the live study, on the real processes.
#
#   netns-run bash test_study.sh BUILD_DIR
#
# 1. Bad arguments are refused with status 2 and a message naming the input, before
#    anything starts; a results directory that holds a study is refused (status 1).
#    Each world's training goals (--show-goals) repeat under one seed, differ under another
#    and lie in its ring, yaw range and x range (on the lab none behind the start).
# 2. One run of two episodes from sliding and torsional friction half the truth's: every episode's row
#    is there, theta's seven entries and their stds in their columns (the four given
#    completed with the box's neutral 1, 0, 0, which the fit, not fitting them, keeps),
#    with the fit it evaluated (versions 0, 1, 2 on 0, 1, 2 rollouts), the
#    buffers hold the two training pushes and the five held-out evaluation tasks (less any
#    met at the start or that left the object still: nothing recorded), a training push
#    left unrecorded is drawn again and said so, the training goals are --show-goals' in the
#    order drawn, the validation loss was scored for each
#    row, every record starts with the object placed, at rest and the sphere released
#    clear of it, the training commands kept to --train-v-max and the evaluation's did
#    not, the sliding error at episode 2 is below half the starting 50 %, the validation
#    loss fell, and the summary lines, summary.csv and (with gnuplot) both figures are
#    written.
# 3. --episodes 0: the five evaluation tasks alone at a held theta, no training push and no
#    refit; eval_time_ep0 is their mean, eval_approach_ep0 the mean of the times their object
#    first moved (each within its task), and no figure of a fit or a later episode is printed.
# 4. nudge-refit on the study of 2: with no adapter option it repeats each episode's theta
#    and validation loss exactly (ratio 1, no run lower); another CEM seed gives other
#    thetas; bad arguments are refused with status 2 naming the input.
set -u
PT_NAME=test_study
PT_NO_LOGGER=1
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"
pt_init "$@"
STUDY=$PT_BIN/nudge-study
[[ -x $STUDY ]] || { echo "$PT_NAME: $STUDY is missing: build first" >&2; exit 1; }

# refused_by PROG CODE WORD ARGS...: PROG ARGS exits CODE and its stderr names WORD.
refused_by() {
  local prog=$1 code=$2 word=$3 rc
  shift 3
  "$prog" "$@" >/dev/null 2>"$PT_WORK/refused.err"
  rc=$?
  if ((rc == code)) && grep -q -- "$word" "$PT_WORK/refused.err"; then
    pt_ok "${prog##*/} $* -> status $code naming $word"
  else
    pt_fail "${prog##*/} $* -> status $rc (want $code), stderr: $(head -c 300 "$PT_WORK/refused.err")"
  fi
}
# refused CODE WORD ARGS...: the same for nudge-study.
refused() { refused_by "$STUDY" "$@"; }

# --- 1. bad arguments --------------------------------------------------------------------
refused 2 "--out" --runs 1
refused 2 "--world" --out "$PT_WORK/x" --world moon
refused 2 "--runs" --out "$PT_WORK/x" --runs 0
refused 2 "--episodes" --out "$PT_WORK/x" --episodes 1
refused 2 "--theta" --out "$PT_WORK/x" --theta 1,2,3
refused 2 "--theta" --out "$PT_WORK/x" --theta 1,0.005,0.0001,1,1,0
# Seven entries pass (the box's shifts may be negative): the next check refuses instead.
refused 2 "--await-fit" --out "$PT_WORK/x" --theta 1,0.005,0.0001,1,1.1,-0.004,1e-05 --await-fit x
refused 2 "--replay-mode" --out "$PT_WORK/x" --replay-mode setpoint
refused 2 "eps" --out "$PT_WORK/x" --eps 7
refused 2 "--train-v-max" --out "$PT_WORK/x" --train-v-max -1
refused 2 "--show-goals" --show-goals 0
pt_check_not "nothing was started or written for refused arguments" test -e "$PT_WORK/x/config.txt"

# --- 1b. training goals ------------------------------------------------------------------
# goals_in WORLD RMIN YMIN YMAX XMIN XMAX: 4 runs x 25 of the world's goals, the same on a
# second call, differing under another seed, each RMIN-0.15 m from the origin (0.5 mm for
# rounding), turned YMIN-YMAX rad and with x in [XMIN, XMAX].
goals_in() {
  local w=$1 a b c
  a=$("$STUDY" --world "$w" --runs 4 --show-goals 25)
  b=$("$STUDY" --world "$w" --runs 4 --show-goals 25)
  c=$("$STUDY" --world "$w" --runs 4 --show-goals 25 --seed 2)
  pt_check "$w training goals: the same for the same seed" test -n "$a" -a "$a" = "$b"
  pt_check "$w training goals: others for another seed" test "$a" != "$c"
  pt_check "$w training goals: 100 of them, $2-0.15 m out, |yaw| $3-$4 rad, x $5 to $6 m" \
    awk -v r0="$2" -v y0="$3" -v y1="$4" -v x0="$5" -v x1="$6" '
      { for (i = 3; i <= NF; i++) { split($i, g, ","); n++; r = sqrt(g[1] ^ 2 + g[2] ^ 2)
          y = g[3] < 0 ? -g[3] : g[3]
          if (r < r0 - 5e-4 || r > 0.1505 || y < y0 || y > y1 || g[1] < x0 || g[1] > x1) bad++ } }
      END { exit !(n == 100 && bad == 0) }' <<<"$a"
}
goals_in ideal 0.08 0 0.4 -0.15 0.15
goals_in lab 0.12 0.2 0.5 -0.05 0.12

# --- 2. one run, two episodes ------------------------------------------------------------
OUT=$PT_WORK/study
TV=0.2
"$STUDY" --out "$OUT" --runs 1 --episodes 2 --theta 0.5,0.0025,0.0001,1 --train-v-max $TV \
  --await-fit "$(pt_slow 60)" --tau "$(pt_slow 5)" >"$PT_WORK/study.out" 2>"$PT_WORK/study.err"
rc=$?
cat "$PT_WORK/study.out"
pt_check "nudge-study exits 0 (got $rc)" test "$rc" -eq 0
CSV=$OUT/run_0.csv
# col EPISODE NAME: the value in column NAME (the header's) of episode EPISODE's row.
col() {
  awk -F, -v e="$1" -v n="$2" 'NR == 1 { for (i = 1; i <= NF; i++) { if ($i == "episode") ce = i; if ($i == n) c = i }; next }
    ce && c && $ce == e { print $c }' "$CSV"
}
KEYS="slide torsion roll mass box_scale com_x com_y"
HDR=episode,version,rollouts,${KEYS// /,},${KEYS// /_std,}_std,fit_loss,val_loss,train_reached,train_time,eval_success,eval_time,eval_approach,eval_obj_path,eval_ee_path,reflex_stops
pt_check "run_0.csv: the header of theta's 7 entries and their stds, and 3 rows of its 27 columns" \
  awk -F, -v h="$HDR" 'NR == 1 && $0 != h { bad = 1 } NF != 27 { bad = 1 } END { exit bad || NR != 4 }' "$CSV"
pt_check "versions 0, 1, 2 fitted on 0, 1, 2 rollouts" \
  test "$(col 0 version)$(col 1 version)$(col 2 version)/$(col 0 rollouts)$(col 1 rollouts)$(col 2 rollouts)" = "012/012"
pt_check "every row has a positive validation loss" \
  awk -v v="$(col 0 val_loss) $(col 1 val_loss) $(col 2 val_loss)" \
    'BEGIN { n = split(v, a, " "); for (i = 1; i <= n; i++) if (!(a[i] > 0)) bad = 1; exit bad || n != 3 }'
num='^[+-]?([0-9]+([.][0-9]*)?|[.][0-9]+)([eE][+-]?[0-9]+)?$'
bad_cells=""
for e in 0 1 2; do
  for k in $KEYS; do
    for n in "$k" "${k}_std"; do [[ $(col $e "$n") =~ $num ]] || bad_cells+=" $e:$n='$(col $e "$n")'"; done
  done
done
pt_check "every row has 7 means and 7 stds, all numbers${bad_cells:+ (not:$bad_cells)}" test -z "$bad_cells"
box=""
for e in 0 1 2; do box+=" $(col $e box_scale),$(col $e com_x),$(col $e com_y)"; done
pt_check "the box's entries, given as four and not fitted, are 1, 0, 0 in every row (got$box)" \
  awk -v b="$box" 'BEGIN { n = split(b, r, " "); for (i = 1; i <= n; i++) {
    split(r[i], v, ","); if (!(v[1] == 1 && v[2] == 0 && v[3] == 0)) bad = 1 }; exit bad || n != 3 }'
s0=$(col 0 slide) s2=$(col 2 slide)
pt_figure study_sliding_ep2 "$s2" ratio
pt_check "the run started at sliding friction 0.5 (got $s0)" test "$s0" = 0.5
pt_check "sliding error at episode 2 below 25 % (got $s2)" \
  awk -v s="$s2" 'BEGIN { e = s - 1; if (e < 0) e = -e; exit !(s != "" && e < 0.25) }'
pt_val n_train buffer "$OUT/run_0/train.nrb" records_in_file
pt_val n_val buffer "$OUT/run_0/val.nrb" records_in_file
pt_check "train.nrb holds the 2 training pushes (got $n_train)" test "$n_train" = 2
# A goal met where the object lies is not pushed, and a push that moved the object under
# 1 cm is not kept (nudge-tasks --record): neither has a record.
met0=$(awk '$1 == "tasks_met_at_start" { print $2 }' "$OUT/run_0/eval_ep0.txt")
still0=$(grep -c '^task .*object path 0\.00[0-9] m' "$OUT/run_0/eval_ep0.txt")
pt_check "val.nrb holds the 5 held-out evaluation tasks but the ${met0:-?} met at the start and the $still0 that left the object still (got $n_val)" \
  test -n "$met0" -a "$n_val" = $((5 - ${met0:-0} - still0))
# Every task starts from the object placed at the origin (nudge-tasks --place): the bridge
# puts it there once the planner has moved the sphere 1 cm clear, and its record assumes it
# at rest. A sphere left pressing on it pushes it on (the controller's integral builds up):
# each task ends with the planner's release, the sphere 1 cm clear of the object (half of
# it is asked for here: the object may still slide after the release is planned).
for b in train val; do
  pt_val o0 buffer "$OUT/run_0/$b.nrb" record_start_off_origin_max
  pt_val y0 buffer "$OUT/run_0/$b.nrb" record_start_yaw_abs_max
  pt_check "$b.nrb: every record starts with the object placed at the origin (off by $o0 m, $y0 rad)" \
    awk -v o="$o0" -v y="$y0" 'BEGIN { exit !(o != "" && o < 0.005 && y < 0.05) }'
  pt_val v0 buffer "$OUT/run_0/$b.nrb" record_start_speed_max
  pt_check "$b.nrb: every record starts with the object at rest (fastest $v0 m/s)" \
    awk -v v="$v0" 'BEGIN { exit !(v != "" && v < 0.01) }'
  pt_val g0 buffer "$OUT/run_0/$b.nrb" record_start_gap_min
  pt_figure "${b}_start_gap_min" "$g0" m
  pt_check "$b.nrb: every record starts with the sphere clear of the object (closest $g0 m)" \
    awk -v g="$g0" 'BEGIN { exit !(g != "" && g > 0.005) }'
done
PLOG=$OUT/run_0/logs/planner.log
BLOG=$OUT/run_0/logs/bridge.log
n_tasks=$(cat "$OUT"/run_0/{train,eval}_ep*.txt | grep -c '^task [0-9]')
n_placed=$(grep -c ': the object placed at (+0.000, +0.000) m, yaw +0.0 deg' "$BLOG")
# An object moved off the pose before the sphere parks or its task starts is placed again
# (nudge-tasks says so).
n_again=$(grep -cE 'off the placed pose (while the sphere parked|before the task): placing it again$' \
  "$OUT/run_0/tasks.err")
pt_check "the bridge placed the object before each of the $n_tasks tasks and the $n_again placed again (placed $n_placed)" \
  test "$n_tasks" -ge 17 -a "$n_placed" = $((n_tasks + n_again))
pt_check_not "the bridge dropped no PLACE" grep -q 'dropped: the sphere stayed' "$BLOG"
# Each evaluation task starts with the sphere at the system's start too (nudge-tasks
# --park): the planner takes it there round the placed object, and the runner waits for it
# there (a task placed again parks again).
at0='\([+-]0\.00[0-9], [+-]0\.00[0-9]\)'
n_eval=$(cat "$OUT"/run_0/eval_ep*.txt | grep -c '^task [0-9]')
n_park=$(grep -cE ": the sphere parks at \(-0\.100, \+0\.000\) m, round the object at $at0 m" "$PLOG")
pt_check "the planner parked the sphere before each of the $n_eval evaluation tasks (got $n_park)" \
  test "$n_eval" -eq 15 -a "$n_park" -ge "$n_eval"
pt_check_not "no park was given up$(grep -m1 -o 'does not park.*' "$PLOG" | sed 's/^/ (/; s/$/)/')" \
  grep -q 'the sphere does not park' "$PLOG"
n_end=$(grep -cE ': task [0-9]+ (succeeded|timed out|ended in a reflex stop) after' "$PLOG")
n_rel=$(grep -c ': released: ' "$PLOG")
pt_check "the planner released the sphere after each of the $n_end tasks that ended (got $n_rel)" \
  test "$n_end" -ge 7 -a "$n_rel" = "$n_end"
# Training pushes keep to their speed limit: the executor's commands do (the planner ranks a
# segment past it behind every one within it; 5 % for the odd plan with none within). The
# sphere follows them with the world's tracking: it lags while it pushes and closes the lag
# when the contact eases (0.24 m/s on commands of 0.19 here, 0.31 under ASan), so its
# bound only tells a robot that ran off. Evaluation runs at the planner's own, faster.
top() { sed -n "s/.*$1 top speed \([0-9.]*\) m\/s.*/\1/p" "${@:2}" | sort -g | tail -n 1; }
ct=$(top command "$OUT"/run_0/train_ep*.txt) ce=$(top command "$OUT"/run_0/eval_ep*.txt)
vt=$(top sphere "$OUT"/run_0/train_ep*.txt)
pt_figure study_train_cmd_top_speed "$ct" m/s
pt_figure study_train_top_speed "$vt" m/s
pt_check "training commands within --train-v-max $TV (top speed $ct m/s)" \
  awk -v v="$ct" -v l="$TV" 'BEGIN { exit !(v != "" && v > 0 && v <= 1.05 * l) }'
pt_check "the sphere in training within twice that (top speed $vt m/s)" \
  awk -v v="$vt" -v l="$TV" 'BEGIN { exit !(v != "" && v > 0 && v <= 2 * l) }'
pt_check "evaluation commands faster than training's limit (top speed $ce m/s)" \
  awk -v v="$ce" -v l="$TV" 'BEGIN { exit !(v != "" && v > 1.5 * l) }'
# A training push left unrecorded (the object did not move) is drawn again, its lines kept
# as train_epE_tryK.txt.
n_tries=$(find "$OUT/run_0" -name 'train_ep*_try*.txt' | wc -l)
pt_check "the study said so for each training push it drew again ($n_tries)" \
  test "$(grep -c 'was not recorded: .*; drawing another$' "$PT_WORK/study.err")" = "$n_tries"
pt_check "the planner planned the $((2 + n_tries)) training tasks at $TV m/s" \
  test "$(grep -c "started: .*speed limit $TV m/s" "$PLOG")" = $((2 + n_tries))
# The study pushed to the goals --show-goals gives run 0, in the order it drew them (the
# task lines give x, y to 0.01 m and the yaw to 0.1 degrees).
drawn=""
for e in 1 2; do
  for f in $(ls -v "$OUT"/run_0/train_ep${e}_try*.txt 2>/dev/null) "$OUT/run_0/train_ep$e.txt"; do
    drawn+=" $(sed -n 's/^task 1\/1 goal (\([^,]*\), \([^,]*\), \([^ ]*\) deg).*/\1,\2,\3/p' "$f")"
  done
done
shown=$("$STUDY" --runs 1 --show-goals $((2 + n_tries)) | cut -d' ' -f3-)
pt_check "the training goals pushed to are --show-goals' ($drawn against $shown)" \
  awk -v d="$drawn" -v s="$shown" 'BEGIN { n = split(d, a, " "); m = split(s, b, " ")
    if (n != m || n < 2) exit 1
    for (i = 1; i <= n; i++) { split(a[i], p, ","); split(b[i], q, ",")
      if ((p[1] - q[1]) ^ 2 > 0.0051 ^ 2 || (p[2] - q[2]) ^ 2 > 0.0051 ^ 2) exit 1
      if ((p[3] - q[3] * 180 / atan2(0, -1)) ^ 2 > 0.051 ^ 2) exit 1 }
    exit 0 }'
# fig NAME [FILE]: the value of summary line NAME in FILE (default the study's output).
fig() { awk -v n="$1" '$1 == n { print $2 }' "${2:-$PT_WORK/study.out}"; }
for f in eval_success_ep0 eval_success_ep2 eval_success_last eval_time_ratio_ep2 \
  eval_time_ratio_last eval_time_ep0 eval_time_ep2 eval_approach_ep0 eval_approach_ep2 \
  val_loss_ratio_ep2 reflex_stops runs_sliding_within5pct_ep2 torsional_err_drop_pct_last sliding_err_pct_max reflex_stops_robot; do
  pt_check "summary line $f ($(fig "$f"))" test -n "$(fig "$f")"
done
pt_check "eval_time_ratio_ep2 is eval_time_ep2 over eval_time_ep0 ($(fig eval_time_ep2) s, $(fig eval_time_ep0) s)" \
  awk -v r="$(fig eval_time_ratio_ep2)" -v a="$(fig eval_time_ep2)" -v b="$(fig eval_time_ep0)" \
  'BEGIN { exit !(b > 0 && a > 0 && r > 0 && (a / b - r) ^ 2 < 1e-5) }'
bridge_stops=$(grep -h 'the robot stopped:' "$OUT"/run_*/logs/bridge.log | wc -l)
pt_check "reflex_stops_robot is the bridges' stops ($(fig reflex_stops_robot), $bridge_stops logged)" \
  test "$(fig reflex_stops_robot)" = "$bridge_stops"
pt_check "val_loss_ratio_ep2 below 1 ($(fig val_loss_ratio_ep2))" \
  awk -v v="$(fig val_loss_ratio_ep2)" 'BEGIN { exit !(v != "" && v < 1) }'
pt_check "summary.csv: a header and episodes 0..2" \
  awk -F, 'END { exit !(NR == 4 && $1 == 2) }' "$OUT/summary.csv"
if command -v gnuplot >/dev/null; then
  for p in fig4_params fig5_performance; do
    pt_check "$p.png is a PNG" bash -c '[[ $(head -c 8 "$1" | od -An -tx1 | tr -d " \n") == 89504e470d0a1a0a ]]' _ "$OUT/$p.png"
  done
fi
refused 1 "holds results" --out "$OUT" --runs 1

# --- 3. the evaluation alone -------------------------------------------------------------
OUT0=$PT_WORK/held
"$STUDY" --out "$OUT0" --runs 1 --episodes 0 --theta 1,0.005,0.0001,1 --tau "$(pt_slow 5)" \
  >"$PT_WORK/held.out" 2>"$PT_WORK/held.err"
rc=$?
cat "$PT_WORK/held.out"
pt_check "nudge-study --episodes 0 exits 0 (got $rc)" test "$rc" -eq 0
pt_check "run_0.csv: episode 0 alone, at the given theta (version 0)" \
  awk -F, 'NR == 2 && !($1 == 0 && $2 == 0 && $4 == 1 && $5 == 0.005) { bad = 1 }
    END { exit bad || NR != 2 }' "$OUT0/run_0.csv"
pt_check "the five evaluation tasks ran" \
  test "$(grep -c '^task [1-5]/5 goal' "$OUT0/run_0/eval_ep0.txt")" -eq 5
pt_check "no training push, no refit (the adapter's log holds no refit line)" \
  bash -c 'test -s "$1/logs/adapter.log" && ! test -e "$1/train_ep1.txt" &&
    ! grep -q "^refit version" "$1/logs/adapter.log"' _ "$OUT0/run_0"
pt_check "eval_time_ep0 is the five tasks' mean ($(fig eval_time_ep0 "$PT_WORK/held.out") s)" \
  awk -v t="$(fig eval_time_ep0 "$PT_WORK/held.out")" '/^task [1-5]\/5 goal/ && match($0, /(in|after) [0-9.]+ s/) {
      split(substr($0, RSTART, RLENGTH), w, " "); s += w[2]; n++ }
    END { exit !(n == 5 && t > 0 && (s / n - t) ^ 2 < 1e-5) }' "$OUT0/run_0/eval_ep0.txt"
pt_check "each task's approach lies within it, and eval_approach_ep0 is their mean ($(fig \
  eval_approach_ep0 "$PT_WORK/held.out") s)" \
  awk -v a="$(fig eval_approach_ep0 "$PT_WORK/held.out")" '/^task [1-5]\/5 goal/ {
      if (!match($0, /(in|after) [0-9.]+ s/)) exit 1
      split(substr($0, RSTART, RLENGTH), w, " "); t = w[2]
      if (!match($0, /object moved at [0-9.]+ s$/)) exit 1
      split(substr($0, RSTART, RLENGTH), w, " "); m = w[4]
      if (!(m > 0 && m < t)) bad = 1; s += m; n++ }
    END { exit bad || !(n == 5 && a > 0 && (s / n - a) ^ 2 < 1e-5) }' "$OUT0/run_0/eval_ep0.txt"
pt_check_not "no figure of a fit or of later episodes" \
  grep -qE '^(eval_time_ratio|eval_success_(ep2|last)|val_loss|runs_sliding|torsional)' \
  "$PT_WORK/held.out"

# --- 4. the study refitted offline -------------------------------------------------------
REFIT=$PT_BIN/nudge-refit
refused_by "$REFIT" 2 "--study" --csv "$PT_WORK/r.csv"
refused_by "$REFIT" 2 "config.txt" --study "$PT_WORK"
refused_by "$REFIT" 2 "--pop" --study "$OUT" -- --pop 1
"$REFIT" --study "$OUT" --csv "$PT_WORK/refit.csv" >"$PT_WORK/refit.out" 2>"$PT_WORK/refit.err"
rc=$?
cat "$PT_WORK/refit.out"
pt_check "nudge-refit exits 0 (got $rc)" test "$rc" -eq 0
for e in 1 2; do
  pt_check "episode $e refitted to the study's theta and validation loss (ratio $(fig \
    val_loss_ratio_ep$e "$PT_WORK/refit.out"), runs lower $(fig runs_lower_ep$e "$PT_WORK/refit.out"))" \
    awk -F, -v e="$e" -v r="$(fig val_loss_ratio_ep$e "$PT_WORK/refit.out")" \
      -v l="$(fig runs_lower_ep$e "$PT_WORK/refit.out")" -v s="$(col "$e" slide)" \
      -v t="$(col "$e" torsion)" 'NR > 1 && $2 == e { n++; if ($3 != s || $4 != t || $10 != $11) bad = 1 }
      END { exit bad || n != 1 || r != "1.000" || l != "0/1" }' "$PT_WORK/refit.csv"
done
"$REFIT" --study "$OUT" --csv "$PT_WORK/refit2.csv" -- --seed 2 >/dev/null 2>"$PT_WORK/refit2.err"
pt_check "with --seed 2 the refit of episode 2 differs from the study's ($(col 2 slide))" \
  awk -F, -v s="$(col 2 slide)" 'NR > 1 && $2 == 2 { n++; d = ($3 != s) }
    END { exit !(n == 1 && d) }' "$PT_WORK/refit2.csv"
pt_sanitizer_scan "$OUT" || true
pt_sanitizer_scan "$OUT0" || true
((PT_FAILS)) && { tail -n 20 "$PT_WORK/study.err"; pt_dump_logs 2>/dev/null; }
exit $((PT_FAILS > 0))
