#!/usr/bin/env bash
# test_view_cli: nudge-view's command line refuses bad input before doing anything.
#
#   bash test_view_cli.sh BUILD_DIR
#
# Every option of its table (--list-options) gets the refusals of its kind, as
# tests/cli/test_cli.sh gives the other programs': each exits 2 with a first stderr line
# "nudge-view: ..." naming the option and nothing on stdout. Then the rules between
# options and what a kind alone does not catch. DISPLAY is unset and LCM_DEFAULT_URL names
# no transport, so a wrongly accepted command line fails with status 1 instead, touching
# neither a display nor the network. --help and -h exit 0 with the usage on stdout.
set -u
PT_NAME=test_view_cli
. "$(dirname "${BASH_SOURCE[0]}")/../tools/process-lib.sh"
BUILD=$(cd "${1:?usage: test_view_cli.sh BUILD_DIR}" && pwd) || exit 1
VW=$BUILD/bin/nudge-view
[[ -x $VW ]] || { echo "$PT_NAME: $VW is missing: build first" >&2; exit 1; }
W=$(mktemp -d "${TMPDIR:-/tmp}/nudge-test_view_cli.XXXXXX") || exit 1
trap 'rm -rf -- "$W"' EXIT
cd "$W" || exit 1
unset DISPLAY
export LCM_DEFAULT_URL='nudge-no-such-transport://'

bad() { # bad 'WANT|...' ARGS...: status 2, stdout empty, first stderr line has each part
  local want=$1 rc first="" part miss=""
  shift
  timeout 20 "$VW" "$@" </dev/null >"$W/out" 2>"$W/err"
  rc=$?
  read -r first <"$W/err"
  IFS='|' read -r -a parts <<<"$want"
  for part in "${parts[@]}"; do [[ $first == *"$part"* ]] || miss+=" '$part'"; done
  if ((rc == 2)) && [[ $first == "nudge-view: "* && -z $miss && ! -s $W/out ]]; then
    pt_ok "nudge-view $*: status 2: $first"
  else
    pt_fail "nudge-view $*: status $rc (want 2), stderr '$first'${miss:+, lacks$miss}"
  fi
}

for flag in --help -h; do
  timeout 20 "$VW" "$flag" >"$W/out" 2>"$W/err"
  rc=$?
  pt_check "nudge-view $flag: status 0 ($rc), usage on stdout, nothing on stderr" \
    eval '((rc == 0)) && [[ $(head -n 1 "$W/out") == "usage: nudge-view"* && ! -s $W/err ]]'
done
bad "unknown|--bogus" --bogus
bad "unknown|stray" stray

n=0
while IFS=$'\t' read -r name kind lo hi cnt def choices; do
  n=$((n + 1))
  case $kind in
    int)
      bad "$name|abc" "$name" abc
      bad "$name|1.5" "$name" 1.5
      bad "$name|out of range" "$name" $((${hi%.*} + 1))
      bad "$name needs a value" "$name" ;;
    double)
      bad "$name|nan" "$name" nan
      bad "$name|inf" "$name" inf
      bad "$name|0.5s" "$name" 0.5s
      bad "$name|out of range" "$name" "$(awk -v h="$hi" 'BEGIN { printf "%.17g", 2 * h + 1 }')"
      bad "$name needs a value" "$name" ;;
    list)
      bad "$name|'x' is not a finite number" "$name" x,0,0,1,90,-90
      bad "$name|expected $cnt comma-separated numbers" "$name" 0,0,0
      bad "$name|out of range" "$name" 0,0,0,1e9,90,-90 ;;
    choice)
      bad "$name|'xx' is not one of|${choices//,/, }" "$name" xx
      bad "$name needs a value" "$name" ;;
    string)
      bad "$name|empty value" "$name" ''
      bad "$name needs a value" "$name" ;;
    flag) bad "$name=1|takes no value" "$name=1" ;;
    custom) bad "$name needs a value" "$name" ;;
    *) pt_fail "option $name has an unknown kind '$kind'" ;;
  esac
done < <("$VW" --list-options)
pt_check "the option table lists options ($n)" test "$n" -ge 15

bad "--size|'641x480'|even" --size 641x480
bad "--size|'640x'|not a size" --size 640x
bad "--size|'8x8'" --size 8x8
bad "--size|'640x480x3'" --size 640x480x3
bad "--speed needs --log" --speed 2
bad "--png-at needs --png" --png-at 1
bad "--camera|DIST must be > 0" --camera 0,0,0,0,90,-90
bad "--camera|EL within [-90, 90]" --camera 0,0,0,1,90,-95
bad "--world|'mars' is not one of|ideal, lab" --world mars

# A good command line gets past the parser and fails for want of a display: status 1 and
# the hint, not a crash.
timeout 20 "$VW" --hidden --seconds 1 >"$W/out" 2>"$W/err"
rc=$?
pt_check "a valid command line without DISPLAY: status 1 ($rc) naming xvfb-run" \
  eval '((rc == 1)) && grep -q "xvfb-run -a" "$W/err"'
if ((PT_FAILS)); then pt_say "FAILED ($PT_FAILS failed checks)"; exit 1; fi
pt_say "PASSED"
