#!/usr/bin/env bash
# test_cli: every program's command line refuses bad input before doing anything, and no
# argument is ever read by a shell.
#
#   bash test_cli.sh BUILD_DIR
#
# 1. Every C program, every option that takes a value: a missing value, an empty one, a
#    word, NaN, inf, trailing junk and an out-of-range number each exit with status 2 and a
#    line "nudge-X: ..." on stderr naming the option and the bad value; unknown options and
#    stray words too; --help and -h exit 0 with the usage on stdout. LCM_DEFAULT_URL names
#    a transport that does not exist, so a program that opened LCM before checking its
#    arguments would fail with status 1 ("cannot open LCM") and this test with it: no
#    network is needed, and none is touched.
# 2. Input files named on the command line: a missing or malformed --model (nudge-bridge)
#    and --goals file (nudge-tasks) give status 2 and a message naming the file.
# 3. nudge-up's own options; then nudge-up run against stand-in programs (tiny scripts in
#    a scratch bin dir that record their argv): arguments with spaces, quotes, ';', $(..),
#    backquotes, globs and empty strings reach the processes and the task runner literally
#    and nothing is executed; --workspace reaches planner, executor and bridge; a process
#    that refuses its arguments makes nudge-up exit 2.
#    These runs are under umask 000: nothing in the log directory may be world-writable,
#    and the processes must inherit a umask without o+w.
# 4. nudge-spy passes its arguments to java (a stand-in) literally.
# 5. nudge-refit refuses bad arguments, and passes the options after -- to nudge-adapter
#    (a stand-in) literally, after the ones the study's adapter was started with.
set -u
PT_NAME=test_cli
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"

BUILD=${1:?usage: test_cli.sh BUILD_DIR}
BIN=$(cd "$BUILD/bin" && pwd) || exit 1
for p in bridge executor planner adapter tasks status demo experiment bench calibrate up spy refit; do
  [[ -x $BIN/nudge-$p ]] || { echo "test_cli: $BIN/nudge-$p is missing: build first" >&2; exit 1; }
done
PT_WORK=$(mktemp -d "${TMPDIR:-/tmp}/nudge-test_cli.XXXXXX") || exit 1
W=$PT_WORK
STARTED=()   # pids of nudge-up runs, for the EXIT trap
cleanup() {
  local p
  for p in "${STARTED[@]}"; do kill -KILL "$p" 2>/dev/null; done
  [[ -f $W/fake.pids ]] && while read -r p _; do kill -KILL "$p" 2>/dev/null; done <"$W/fake.pids"
  [[ -n ${KEEP_WORK:-} ]] || rm -rf -- "$W"
}
trap cleanup EXIT
cd "$W" || exit 1   # a program that wrongly runs writes here, not into the tree
export LCM_DEFAULT_URL='nudge-no-such-transport://'
NCASES=0

# bad PROG 'WANT...' ARGS...: PROG ARGS exits 2 within 20 s, stdout stays empty, and the
# first line on stderr is "PROG: ..." containing every '|'-separated part of WANT.
bad() {
  local prog=$1 want=$2 rc first="" part miss=""
  shift 2
  NCASES=$((NCASES + 1))
  timeout 20 "$BIN/$prog" "$@" </dev/null >"$W/out" 2>"$W/err"
  rc=$?
  read -r first <"$W/err"
  IFS='|' read -r -a parts <<<"$want"
  for part in "${parts[@]}"; do [[ $first == *"$part"* ]] || miss+=" '$part'"; done
  local shown
  printf -v shown '%q ' "$@"
  if ((rc == 2)) && [[ $first == "$prog: "* && -z $miss && ! -s $W/out ]]; then
    pt_ok "$prog ${shown% }: status 2: $first"
  else
    pt_fail "$prog ${shown% }: status $rc (want 2), stderr '$first'${miss:+, lacks$miss}$([[ -s $W/out ]] && echo ', wrote to stdout')"
  fi
}

# help PROG: --help and -h exit 0, usage on stdout, nothing on stderr.
help() {
  local prog=$1 flag rc
  for flag in --help -h; do
    NCASES=$((NCASES + 1))
    timeout 20 "$BIN/$prog" "$flag" </dev/null >"$W/out" 2>"$W/err"
    rc=$?
    if ((rc == 0)) && [[ $(head -n 1 "$W/out") == "usage: $prog"* && ! -s $W/err ]]; then
      pt_ok "$prog $flag: status 0, usage on stdout"
    else
      pt_fail "$prog $flag: status $rc, stdout '$(head -n 1 "$W/out")', stderr '$(head -n 1 "$W/err")'"
    fi
  done
}

# Option kinds. Each bad value is given alone (the other options at their defaults) and
# must be named in the message together with the option.
num_cases() { # PROG OPT OUT_OF_RANGE: a real number option
  local prog=$1 opt=$2 oor=$3
  bad "$prog" "$opt|abc" "$opt" abc
  bad "$prog" "$opt|nan" "$opt" nan
  bad "$prog" "$opt|inf" "$opt" inf
  bad "$prog" "$opt|-inf" "$opt" -inf
  bad "$prog" "$opt|0.5s" "$opt" 0.5s
  bad "$prog" "$opt|empty" "$opt" ''
  bad "$prog" "$opt|out of range" "$opt" "$oor"
  bad "$prog" "$opt needs a value" "$opt"
}
int_cases() { # PROG OPT OUT_OF_RANGE: an integer option
  local prog=$1 opt=$2 oor=$3
  bad "$prog" "$opt|abc" "$opt" abc
  bad "$prog" "$opt|nan" "$opt" nan
  bad "$prog" "$opt|1.5" "$opt" 1.5
  bad "$prog" "$opt|99999999999999999999" "$opt" 99999999999999999999
  bad "$prog" "$opt|empty" "$opt" ''
  bad "$prog" "$opt|out of range" "$opt" "$oor"
  bad "$prog" "$opt needs a value" "$opt"
}
seed_cases() { # PROG OPT: an unsigned 64-bit option
  local prog=$1 opt=$2
  bad "$prog" "$opt|-1" "$opt" -1
  bad "$prog" "$opt|abc" "$opt" abc
  bad "$prog" "$opt|1e3" "$opt" 1e3
  bad "$prog" "$opt|18446744073709551616" "$opt" 18446744073709551616
  bad "$prog" "$opt needs a value" "$opt"
}
list_cases() { # PROG OPT GOOD OUT_OF_RANGE_FIRST: a comma list like GOOD
  local prog=$1 opt=$2 good=$3 oor=$4 rest=${3#*,} n
  n=$(($(tr -cd , <<<"$good" | wc -c) + 1))
  bad "$prog" "$opt|'nan' is not a finite number" "$opt" "nan,$rest"
  bad "$prog" "$opt|'inf' is not a finite number" "$opt" "inf,$rest"
  bad "$prog" "$opt|'x' is not a finite number" "$opt" "x,$rest"
  bad "$prog" "$opt|out of range" "$opt" "$oor,$rest"
  bad "$prog" "$opt|expected $n comma-separated numbers|${good%,*}" "$opt" "${good%,*}"
  bad "$prog" "$opt|expected $n comma-separated numbers|$good,1" "$opt" "$good,1"
  bad "$prog" "$opt|expected $n comma-separated numbers|${good//,/;}" "$opt" "${good//,/;}"
  bad "$prog" "$opt needs a value" "$opt"
}
theta_cases() { # PROG OPT: S,T,R,M or S,T,R,M,B,X,Y, each entry by its own rule
  local prog=$1 opt=$2 rest=0.005,0.0001,1
  bad "$prog" "$opt|'nan' is not a finite number" "$opt" "nan,$rest"
  bad "$prog" "$opt|'inf' is not a finite number" "$opt" "inf,$rest"
  bad "$prog" "$opt|'x' is not a finite number" "$opt" "x,$rest"
  bad "$prog" "$opt|100000 is out of range" "$opt" "1e5,$rest"
  bad "$prog" "$opt|sliding friction|= -0.1" "$opt" "-0.1,$rest"
  bad "$prog" "$opt|expected 4 values|or 7" "$opt" 1,0.005,0.0001
  bad "$prog" "$opt|expected 4 values|or 7" "$opt" "1,$rest,1"
  bad "$prog" "$opt|expected 4 values|or 7" "$opt" "1;0.005;0.0001;1"
  bad "$prog" "$opt needs a value" "$opt"
  bad "$prog" "$opt|sphere mass|= 0" "$opt" 1,0.005,0.0001,0
  bad "$prog" "$opt|sphere mass|= -2" "$opt" 1,0.005,0.0001,-2
  bad "$prog" "$opt|box mass scale|= 0" "$opt" "1,$rest,0,0,0"
  bad "$prog" "$opt|box COM shift x|= 0.2" "$opt" "1,$rest,1,0.2,0"
}
common_cases() { # PROG: what every program refuses
  local prog=$1
  help "$prog"
  bad "$prog" "unknown|--bogus" --bogus
  bad "$prog" "unknown|--bogus" --bogus 1
  bad "$prog" "unknown|stray" stray
  bad "$prog" "unknown|-x" -x
  bad "$prog" "--help=1|takes no value" --help=1
}

# --- 1. the C programs ---------------------------------------------------------------

# Every option of every program, from the program's own table (--list-options: name,
# kind, bounds, default): each kind gets the refusals of its kind, so an option added to a
# table is tested here without a line more. Then the rules between options and the values
# a kind alone does not catch, by hand.
NOPTS=0
walk() { # PROG: the generic cases of every option in PROG's table
  local prog=$1 name kind lo hi n def choices oor
  common_cases "$prog"
  while IFS=$'\t' read -r name kind lo hi n def choices; do
    NOPTS=$((NOPTS + 1))
    grep -q -- "$name" <<<"$("$BIN/$prog" --help)" || pt_fail "$prog --help does not show $name"
    case $kind in
      int)
        if [[ $hi == 2147483647 ]]; then oor=$((lo - 1)); else oor=$((hi + 1)); fi
        int_cases "$prog" "$name" "$oor" ;;
      double)
        oor=$(awk -v l="$lo" -v h="$hi" 'BEGIN { if (h < 1e8) printf "%.17g", 2 * h + 1;
                                                  else printf "%.17g", l - (l < 0 ? -l : l) - 1 }')
        num_cases "$prog" "$name" "$oor" ;;
      u64) seed_cases "$prog" "$name" ;;
      list) list_cases "$prog" "$name" "$def" "$(awk -v l="$lo" 'BEGIN { printf "%.17g", l - 1 }')" ;;
      theta) theta_cases "$prog" "$name" ;;
      box)
        list_cases "$prog" "$name" -0.5,-0.5,0.5,0.5 -20
        bad "$prog" "$name|'0.5,-0.5,-0.5,0.5' is not a box|XLO < XHI" "$name" 0.5,-0.5,-0.5,0.5
        bad "$prog" "$name|'-0.5,0.5,0.5,0.5' is not a box" "$name" -0.5,0.5,0.5,0.5
        bad "$prog" "$name|'0,0,0,0' is not a box" "$name" 0,0,0,0 ;;
      choice)
        bad "$prog" "$name|'xx' is not one of|${choices//,/, }" "$name" xx
        bad "$prog" "$name needs a value" "$name" ;;
      string)
        bad "$prog" "$name|empty value" "$name" ''
        bad "$prog" "$name needs a value" "$name" ;;
      flag) bad "$prog" "$name=1|takes no value" "$name=1" ;;
      custom) bad "$prog" "$name needs a value" "$name" ;;
      *) pt_fail "$prog: option $name has an unknown kind '$kind'" ;;
    esac
  done < <("$BIN/$prog" --list-options)
}
for p in bridge executor planner adapter tasks status demo experiment bench calibrate; do
  walk "nudge-$p"
done
pt_check "the option tables list options ($NOPTS)" test "$NOPTS" -gt 80

# Unabbreviated names: getopt_long would take --thr for --threads.
bad nudge-planner "unknown argument: --thr|--threads?" --thr 2
# A later value replaces an earlier one (nudge-up relies on it: a user's --X-arg after its own).
bad nudge-planner "--pop|out of range" --pop 10 --pop 3

bad nudge-bridge "--mode hardware is not available" --mode hardware
bad nudge-bridge "unknown|--threads" --threads 2
bad nudge-bridge "motion capture at 2000 Hz exceeds|1000" --mocap-hz 2000
bad nudge-bridge "the sphere at 0,0|overlaps the object" --ee 0,0
bad nudge-bridge "--ee 0.7,0 starts outside the workspace" --ee 0.7,0
bad nudge-bridge "--ee -0.1,0 starts outside the workspace|(--workspace)" --workspace 0,0,0.5,0.5

bad nudge-adapter "--threads|out of range" --replay-window 0 --threads 0
bad nudge-adapter "--shift-restart|out of range" --buffer x.nrb --shift-restart 17
bad nudge-adapter "--fit|unknown parameter 'friction'" --fit slide,friction
bad nudge-adapter "--fit|'slide' given twice" --fit slide,slide
bad nudge-adapter "--fit|no parameter" --fit ,
bad nudge-adapter "--scan|unknown parameter 'all'" --scan all
bad nudge-adapter "--log-fit|'torsion' given twice" --log-fit torsion,torsion
bad nudge-adapter "--buffer FILE is required"
bad nudge-adapter "--history|empty value" --buffer x.nrb --history ''
bad nudge-adapter "--prior-ref|slide is fitted|> 0" --buffer x.nrb --prior-ref 0,0.005,0.0001,1
bad nudge-adapter "--replay-phases|out of range" --buffer x.nrb --replay-phases 17
bad nudge-adapter "--replay-phases 2 needs --replay-window" --buffer x.nrb --replay-phases 2 --replay-window 0
bad nudge-adapter "--replay-phases 4 needs|--robust" --buffer x.nrb --replay-phases 4 --robust 1e-9

bad nudge-tasks "--goal|'nan,0,0'|x: 'nan' is not a finite number" --goal nan,0,0
bad nudge-tasks "--goal|'0,inf,0'" --goal 0,inf,0
bad nudge-tasks "--goal|'20,0,0'|x = 20 m is beyond 10 m" --goal 20,0,0
bad nudge-tasks "--goal|'0.1,0,90'|yaw" --goal 0.1,0,90
bad nudge-tasks "--goal|'1,2'|expected X,Y,YAW" --goal 1,2
bad nudge-tasks "--goal|'1,2,3,4,5,6'" --goal 1,2,3,4,5,6
bad nudge-tasks "--goal|'0.1,0,0,0'|eps" --goal 0.1,0,0,0
bad nudge-tasks "--await-fit needs --record" --await-fit 5
bad nudge-tasks "--place|expected X,Y,YAW|'0,0'" --place 0,0
bad nudge-tasks "--place|'0,nan,0'|y: 'nan' is not a finite number" --place 0,nan,0
bad nudge-tasks "--place-wait needs --place" --place-wait 5
bad nudge-tasks "--park needs --place" --park -0.1,0
bad nudge-tasks "--park|expected 2 comma-separated numbers|'-0.1'" --place 0,0,0 --park -0.1

bad nudge-status "--pid needs --wait NAME" --pid 5

bad nudge-experiment "--runs|out of range" --window 0 --runs 0
bad nudge-experiment "--d|out of range" --d 0,1
bad nudge-experiment "--d|nan" --d nan
bad nudge-experiment "--d|appears twice" --d 1,1
bad nudge-experiment "--d|expected" --d 1,
bad nudge-experiment "--out DIR is required" --runs 1
# --draws: one "D run S,T,R,M" line per run, the same for the same seed, another for another,
# each friction within the D = 1 range (0, 2 theta], the mass at the truth; no --out needed.
d1=$("$BIN/nudge-experiment" --draws --d 1 --runs 3 --seed 4)
d2=$("$BIN/nudge-experiment" --draws --d 1 --runs 3 --seed 4)
d3=$("$BIN/nudge-experiment" --draws --d 1 --runs 3 --seed 5)
pt_check "nudge-experiment --draws: 3 lines within D = 1 of the truth, mass 1" awk '
  { split($3, t, ","); n++
    if ($1 != 1 || $2 != n - 1 || !(t[1] > 0 && t[1] <= 2 && t[2] > 0 && t[2] <= 0.01 && t[4] == 1)) bad = 1 }
  END { exit bad || n != 3 }' <<<"$d1"
pt_check "nudge-experiment --draws: reproducible for a seed" test "$d1" = "$d2"
pt_check "nudge-experiment --draws: another seed, other draws" test "$d1" != "$d3"
[[ -z $(ls -A "$W" | grep -v -e '^out$' -e '^err$') ]] ||
  pt_fail "a refused program created files: $(ls -A "$W")"

# --- 2. input files named by options -------------------------------------------------

bad nudge-bridge "cannot open|$W/none.xml|No such file" --model "$W/none.xml"
printf '<mujoco><worldbody>' >"$W/cut.xml"
bad nudge-bridge "cannot use|$W/cut.xml|XML" --model "$W/cut.xml"
printf '\x7fELF\x02\x01\x01\x00\x00\x00' >"$W/binary.xml"
bad nudge-bridge "cannot use|$W/binary.xml" --model "$W/binary.xml"
printf '<mujoco><worldbody><body name="object"><freejoint/><geom size=".1"/></body></worldbody></mujoco>\n' >"$W/noee.xml"
bad nudge-bridge "cannot use|$W/noee.xml|no body named \"ee\"" --model "$W/noee.xml"
mkdir "$W/dir.xml"
bad nudge-bridge "$W/dir.xml" --model "$W/dir.xml"
rmdir "$W/dir.xml"
# A usable scene, at a timestep no real-time world can step; the same at 1 ms passes every
# check and fails only at LCM (status 1): the refusals above are the files', not the test's.
scene() { # TIMESTEP
  printf '<mujoco><option timestep="%s"/><worldbody>
  <body name="object" pos="0 0 0.025"><freejoint/><geom type="box" size=".05 .03 .025" mass=".5"/></body>
  <body name="ee" pos="-0.1 0 0.025"><joint name="ee_x" type="slide" axis="1 0 0"/>
    <joint name="ee_y" type="slide" axis="0 1 0"/><geom type="sphere" size=".025" mass="1"/></body>
</worldbody></mujoco>\n' "$1"
}
scene 0.00001 >"$W/fast.xml"
bad nudge-bridge "--model $W/fast.xml: timestep 1e-05 s is outside|give --rate" --model "$W/fast.xml"
scene 0.001 >"$W/ok.xml"
NCASES=$((NCASES + 1))
timeout 20 "$BIN/nudge-bridge" --model "$W/ok.xml" </dev/null >"$W/out" 2>"$W/err"
rc=$?
pt_check "a usable --model passes its checks and fails only at LCM (status $rc)" \
  test "$rc" -eq 1 -a -n "$(grep -F "cannot open LCM on '$LCM_DEFAULT_URL'" "$W/err")"

bad nudge-tasks "cannot open $W/none.txt|No such file" --goals "$W/none.txt"
printf '0.1 0 0\n0.2 x 0\n' >"$W/g1.txt"
bad nudge-tasks "$W/g1.txt:2|y: 'x' is not a finite number" --goals "$W/g1.txt"
printf '# only a comment\n\n' >"$W/g2.txt"
bad nudge-tasks "$W/g2.txt: no goals in the file" --goals "$W/g2.txt"
printf '0.1 0 nan\n' >"$W/g3.txt"
bad nudge-tasks "$W/g3.txt:1|nan" --goals "$W/g3.txt"
printf '0.1 0 0 0.01 5 7\n' >"$W/g4.txt"
bad nudge-tasks "$W/g4.txt:1" --goals "$W/g4.txt"
printf '0.1 0 45\n' >"$W/g5.txt"
bad nudge-tasks "$W/g5.txt:1|yaw" --goals "$W/g5.txt"
head -c 300 "$BIN/nudge-status" >"$W/g6.txt"
bad nudge-tasks "$W/g6.txt:1" --goals "$W/g6.txt"
rm -f "$W"/*.xml "$W"/g?.txt

# --- 3. nudge-up ---------------------------------------------------------------------

help nudge-up
bad nudge-up "unknown argument: --bogus" --bogus
bad nudge-up "unknown argument: stray" stray
bad nudge-up "unknown option: --camera-arg|processes" --camera-arg x
bad nudge-up "--bridge-arg needs a value" --bridge-arg
bad nudge-up "--log-dir needs a value" --log-dir
bad nudge-up "'demo' must come first" --grace 1 demo
bad nudge-up "options after -- are for the task runner" run -- --goal 0.1,0,0
bad nudge-up "--grace|'abc'" --grace abc
bad nudge-up "--grace|'-1'" --grace -1
bad nudge-up "--grace|'nan'" --grace nan
bad nudge-up "--ready-timeout|'inf'" --ready-timeout inf
bad nudge-up "--ready-timeout must be positive" --ready-timeout 0
bad nudge-up "--theta|'nan,1,1,1'" --theta nan,1,1,1
bad nudge-up "--theta|'1,2,3'" --theta 1,2,3
bad nudge-up "--theta|'1,2,3,4;touch x'" --theta '1,2,3,4;touch x'
bad nudge-up "--theta|'1,2,3,4 5'" --theta '1,2,3,4 5'
bad nudge-up "--theta|'1,2,3,4,5'|4 or 7" --theta 1,2,3,4,5
bad nudge-up "--workspace|'1,2,3'|XLO,YLO,XHI,YHI" --workspace 1,2,3
bad nudge-up "--workspace|'1,2,3,4;touch x'" --workspace '1,2,3,4;touch x'
bad nudge-up "--workspace needs a value" --workspace
bad nudge-up "--world: expected ideal or lab, got 'moon'" --world moon
bad nudge-up "--view: expected window, mp4, auto or off, got 'vr'" demo --view vr
bad nudge-up "--view is for 'nudge-up demo'" run --view mp4

# Stand-ins for the programs: each records its argv (NUL-separated), its pid and its umask,
# then runs until SIGINT/SIGTERM; nudge-tasks exits at once; nudge-status --wait says
# "heartbeat seen" once the process has lived 0.3 s (so one that exits at start is seen
# exiting); the program named by $FAKE_REFUSE says what a real one says on a bad value
# and exits 2.
FAKE=$W/fake-bin
mkdir "$FAKE"
cat >"$FAKE/fake" <<'EOF'
#!/usr/bin/env bash
# Started in the background, a script inherits SIGINT ignored and could not trap it; the C
# programs set their handlers with sigaction, which overrides that. Do the same here.
[[ -n ${FAKE_SIGINT:-} ]] || FAKE_SIGINT=1 exec env --default-signal=INT "$0" "$@"
name=${0##*/}
printf '%s\0' "$@" >"$FAKE_OUT/$name.args"
umask >"$FAKE_OUT/$name.umask"
echo "$$ $name" >>"$FAKE_OUT/fake.pids"
case $name in
  nudge-tasks) exit 0 ;;
  nudge-status)
    while (($#)); do [[ $1 == --pid ]] && pid=$2; shift; done
    sleep 0.3
    kill -0 "${pid:?}" 2>/dev/null
    exit ;;
esac
if [[ $name == "${FAKE_REFUSE:-}" ]]; then
  echo "$name: --threads: 'abc' is not an integer" >&2
  exit 2
fi
trap 'exit 0' INT TERM
while :; do sleep 0.05; done
EOF
chmod 755 "$FAKE/fake"
for p in bridge executor planner adapter tasks status; do ln -s fake "$FAKE/nudge-$p"; done
cp "$BIN/nudge-up" "$FAKE/nudge-up"
export FAKE_OUT=$W

# args_are NAME ARG...: the stand-in NAME was called with exactly these arguments.
args_are() {
  local name=$1 got=() want
  shift
  mapfile -d '' -t got <"$W/$name.args" 2>/dev/null
  want=("$@")
  local g w
  printf -v g '%q ' "${got[@]}"
  printf -v w '%q ' "${want[@]}"
  if [[ $g == "$w" ]]; then pt_ok "$name got its arguments literally: ${w% }"
  else pt_fail "$name got: ${g% }; want: ${w% }"; fi
}

# Every hostile character sequence a value can carry. None of them may be run.
EVIL=("0.5;touch $W/pwned1" 'a b  c' "\$(touch $W/pwned2)" "\`touch $W/pwned3\`" '*' ''
      "x' ; touch $W/pwned4 ; '" "\"; touch $W/pwned5; \"" $'line1\nline2' '--help')
LOGDIR="$W/logs with space;\$(touch $W/pwned6)"
BUF="$W/buf dir/replay \`x\`.nrb"
mkdir -p "$W/buf dir"
THETA=0.3,0.005,1e-4,1
WS=-0.4,-0.3,0.4,0.3

( umask 000
  exec "$FAKE/nudge-up" demo --lcm-url memq:// --log-dir "$LOGDIR" --buffer "$BUF" \
    --theta "$THETA" --workspace "$WS" --grace 2 --ready-timeout 5 \
    --bridge-arg "${EVIL[0]}" --bridge-arg "${EVIL[1]}" \
    --planner-arg --pop --planner-arg "${EVIL[2]}" \
    --executor-arg "${EVIL[3]}" --executor-arg "${EVIL[4]}" --executor-arg "${EVIL[5]}" \
    --adapter-arg "${EVIL[6]}" --adapter-arg "${EVIL[7]}" \
    -- --goal "${EVIL[8]}" "${EVIL[9]}" "${EVIL[4]}" ) >"$W/up.out" 2>"$W/up.err" &
STARTED+=($!)
if pt_wait_pid "${STARTED[-1]}" 30; then
  pt_check "nudge-up demo with stand-ins exits 0 (got $PT_RC)" test "$PT_RC" -eq 0
else
  pt_fail "nudge-up demo with stand-ins did not finish within 30 s"
fi
[[ $PT_RC == 0 ]] || cat "$W/up.err"
# --workspace reaches the three processes that keep to the box, ahead of the user's own
# --X-arg (a later --workspace there wins).
args_are nudge-bridge --workspace "$WS" --world ideal "${EVIL[0]}" "${EVIL[1]}"
args_are nudge-executor --workspace "$WS" "${EVIL[3]}" "${EVIL[4]}" "${EVIL[5]}"
args_are nudge-planner --workspace "$WS" --theta "$THETA" --pop "${EVIL[2]}"
args_are nudge-adapter --theta "$THETA" --buffer "$BUF" "${EVIL[6]}" "${EVIL[7]}"
args_are nudge-tasks --record "$BUF" --world ideal --eps 1e-3 --theta "$THETA" --goal "${EVIL[8]}" "${EVIL[9]}" "${EVIL[4]}"
pwned=$(find "$W" -name 'pwned[0-9]')
pt_check "no argument was run as a command (no pwned* file)" test -z "$pwned"
pt_check "the log directory has its literal name" test -f "$LOGDIR/supervisor.log"
# umask 000 outside: what nudge-up created, and what its processes inherit, is not
# world-writable.
ww=$(find "$LOGDIR" -perm -o+w -printf '%m %p\n')
pt_check "under umask 000 nothing nudge-up created is world-writable (${ww:-none})" test -z "$ww"
n=$(find "$LOGDIR" | wc -l)
pt_figure cli_up_files_checked "$n" count
for p in bridge executor planner adapter tasks; do
  u=$(<"$W/nudge-$p.umask")
  pt_check "nudge-$p runs with umask $u (o+w masked)" test $((8#$u & 2)) -eq 2
done

# --world lab gives the arm's box and limits and the adapter's velocity replay with the
# mass, ahead of the user's own; a --workspace given to nudge-up wins over the arm's box.
rm -f "$W"/*.args
"$FAKE/nudge-up" demo --world lab --lcm-url memq:// --log-dir "$W/logs-lab" --buffer "$W/lab.nrb" \
  --grace 2 --ready-timeout 5 --planner-arg --pop --planner-arg 16 >"$W/up-lab.out" 2>"$W/up-lab.err"
rc=$?
pt_check "nudge-up demo --world lab with stand-ins exits 0 (got $rc)" test "$rc" -eq 0
LAB=-0.15,-0.30,0.15,0.40
args_are nudge-bridge --workspace "$LAB" --world lab
args_are nudge-executor --workspace "$LAB" --v-max 0.65 --a-max 2.8 --brake-a-max 2.0
args_are nudge-planner --workspace "$LAB" --v-max 0.6 --a-max 2.5 --segment-time 0.6 --arrival 0.8 --prox-way round --arm panda --arm-load 0.9 --pop 16
args_are nudge-tasks --record "$W/lab.nrb" --world lab --eps 1e-3 --record-control velocity
args_are nudge-adapter --replay-mode velocity --fit slide,torsion,mass,com_x,com_y --replay-window 0.6 --shift-restart 1 --buffer "$W/lab.nrb"
rm -f "$W"/*.args
"$FAKE/nudge-up" demo --world lab --workspace "$WS" --lcm-url memq:// --log-dir "$W/logs-lab2" \
  --buffer "$W/lab.nrb" --grace 2 --ready-timeout 5 >"$W/up-lab2.out" 2>"$W/up-lab2.err"
args_are nudge-executor --workspace "$WS" --v-max 0.65 --a-max 2.8 --brake-a-max 2.0

# A process refusing its arguments: nudge-up stops what it started and exits 2, showing
# the refusal.
rm -f "$W"/*.args "$W/fake.pids"
FAKE_REFUSE=nudge-planner "$FAKE/nudge-up" run --lcm-url memq:// --log-dir "$W/logs2" \
  --planner-arg --threads --planner-arg abc --grace 2 >"$W/up2.out" 2>"$W/up2.err" &
STARTED+=($!)
if pt_wait_pid "${STARTED[-1]}" 30; then
  pt_check "nudge-up exits 2 when nudge-planner refuses its arguments (got $PT_RC)" test "$PT_RC" -eq 2
else
  pt_fail "nudge-up run did not give up within 30 s on a refused argument"
fi
pt_check "nudge-up names the process that refused" grep -q 'nudge-planner refused its arguments' "$W/up2.err"
pt_check "nudge-up shows the refusal" grep -q "nudge-planner: --threads: 'abc' is not an integer" "$W/up2.err"
pt_check "the planner ran once, the adapter never" \
  test "$(grep -c ' nudge-planner$' "$W/fake.pids")" -eq 1 -a "$(grep -c ' nudge-adapter$' "$W/fake.pids")" -eq 0
left=""
while read -r p _; do kill -0 "$p" 2>/dev/null && left+=" $p"; done <"$W/fake.pids"
pt_check "nothing nudge-up started is left running (${left:-none})" test -z "$left"
grep -qE 'restarted|restart #' "$W/up2.err" && pt_fail "nudge-up tried to restart: $(grep restart "$W/up2.err")"

# --- 4. nudge-spy ------------------------------------------------------------------------

help nudge-spy
bad nudge-spy "--lcm-url needs a value" --lcm-url
mkdir "$W/java-bin"
cat >"$W/java-bin/java" <<'EOF'
#!/usr/bin/env bash
printf '%s\0' "$@" >"$FAKE_OUT/java.args"
EOF
chmod 755 "$W/java-bin/java"
: >"$W/t.jar"
SPY_URL="udpm://239.255.76.67:7667?ttl=0;touch $W/pwned7"
PATH="$W/java-bin:$PATH" NUDGE_LCMTYPES_JAR=$W/t.jar LCM_JAR=$W/t.jar JCHART2D_JAR=$W/t.jar \
  DISPLAY= WAYLAND_DISPLAY= "$BIN/nudge-spy" --lcm-url "$SPY_URL" "${EVIL[1]}" "${EVIL[2]}" \
  >"$W/spy.out" 2>"$W/spy.err"
pt_check "nudge-spy ran java (status $?)" test -f "$W/java.args"
mapfile -d '' -t jargs <"$W/java.args"
tail3=("${jargs[@]: -3}")
pt_check "nudge-spy passed its arguments to lcm-spy literally" \
  test "${tail3[0]}" = "--lcm-url=$SPY_URL" -a "${tail3[1]}" = "${EVIL[1]}" -a "${tail3[2]}" = "${EVIL[2]}"
pt_check "nudge-spy ran nothing else (no pwned* file)" test -z "$(find "$W" -name 'pwned[0-9]')"

# --- 5. nudge-refit ----------------------------------------------------------------------

help nudge-refit
bad nudge-refit "--study needs a value" --study
bad nudge-refit "--study DIR is required" --csv x.csv
bad nudge-refit "unknown argument: --frob" --frob
bad nudge-refit "holds no nudge-study results" --study "$W/none"
# A study of one run, one episode, and a stand-in adapter that records each call's argv.
ST="$W/study;\$(touch $W/pwned8)"
mkdir -p "$ST/run_0/logs" "$W/refit-bin"
printf 'replay_mode force\nfit slide\n' >"$ST/config.txt"
printf 'episode,slide,val_loss\n1,1,2e-05\n' >"$ST/run_0.csv"
echo x >"$ST/run_0/train.nrb"
echo x >"$ST/run_0/val.nrb"
echo "=== t: starting nudge-adapter --fit slide --pop 8" >"$ST/run_0/logs/adapter.log"
cat >"$W/refit-bin/nudge-adapter" <<'EOF'
#!/usr/bin/env bash
case " $* " in
  *" --offline "*) printf '%s\0' "$@" >"$FAKE_OUT/adapter.args"
    echo "refit version 1: 1 rollout(s) in 0.1 s, loss 1e-05, theta 1 0.005 0.0001 1 1 0 0, std 0 0 0 0 0 0 0" ;;
  *" --score "*) echo "loss 2e-05 m^2" ;;
esac
EOF
chmod 755 "$W/refit-bin/nudge-adapter"
FAKE_OUT=$W "$BIN/nudge-refit" --study "$ST" --bin-dir "$W/refit-bin" -- "${EVIL[@]:0:9}" \
  >"$W/refit.out" 2>"$W/refit.err"
rc=$?
pt_check "nudge-refit ran on the stand-in (status $rc)" test "$rc" -eq 0
pt_check "nudge-refit printed the ratio of equal losses, 1" \
  grep -qx "val_loss_ratio_ep1 1.000 ratio (geometric mean of 1 runs)" "$W/refit.out"
# The --offline call: the logged options, the buffer, --offline, then the given ones.
mapfile -d '' -t aargs <"$W/adapter.args"
pt_check "nudge-refit passed the logged options and then the given ones literally" \
  bash -c 'a=("$@"); want=(--fit slide --pop 8 --buffer "$0/run_0/train.nrb" --offline)
    n=${#want[@]}; ((${#a[@]} == n + 9)) || exit 1
    for ((i = 0; i < n; i++)); do [[ ${a[i]} == "${want[i]}" ]] || exit 1; done
    [[ ${a[n]} == "0.5;touch "* && ${a[n + 1]} == "a b  c" && ${a[n + 4]} == "*" && ${a[n + 5]} == "" ]]' \
  "$ST" "${aargs[@]}"
pt_check "nudge-refit ran nothing else (no pwned* file)" test -z "$(find "$W" -name 'pwned[0-9]')"

pt_figure cli_cases "$NCASES" count
if ((PT_FAILS)); then
  pt_say "FAILED ($PT_FAILS failed checks)"
  exit 1
fi
pt_say "PASSED"
