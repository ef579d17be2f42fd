#!/usr/bin/env bash
# nudge set-up: installs what is missing (Debian packages), builds in Release into build/,
# then runs what you asked for. Safe to run again: it only installs what is absent and
# only rebuilds what changed.
set -euo pipefail
# Whatever the caller's umask, nothing built here (the programs in build/bin among them)
# or run from here may be world-writable.
umask "$(printf '%04o' $((8#$(umask) | 8#002)))"

usage() {
  cat <<'USAGE'
usage: ./setup.sh [COMMAND] [ARGS...]

  demo [ARGS]   set up, build, and run the process system pushing the object to 5 goals
                in emulation (nudge-up demo --view auto: in a window on a desktop, else
                an MP4 of the run; ARGS go to nudge-up, see build/bin/nudge-up --help)
  test          set up, build, and run every test (ctest)
  test-asan     set up, build with AddressSanitizer + UBSan into build-asan/, run the unit
                tests and the process tests (every nudge program instrumented; a sanitizer
                report in any process log fails the test; waits scaled by NUDGE_SLOW=3)
  build         set up and build only (the default)
  fuzz [SECS]   build the libFuzzer targets with clang into build-fuzz/ and run each for SECS
                seconds (default 60); prints fuzz_<name>_execs lines, fails on a crash
  -h, --help    this text

Programs land in build/bin/. Set NUDGE_JOBS to change build parallelism (default: nproc).
USAGE
}

cmd=${1:-build}
[ $# -gt 0 ] && shift
case "$cmd" in
  -h|--help|help) usage; exit 0 ;;
  demo|test|test-asan|build|fuzz) ;;
  *) echo "setup.sh: unknown command '$cmd'" >&2; usage >&2; exit 2 ;;
esac

root=$(cd "$(dirname "$0")" && pwd)
cd "$root"

# Debian packages the build, the tests and the tools need.
# libqhull-dev: MuJoCo's CMake config names its headers; libjchart2d-java: lcm-spy's charts.
packages=(build-essential cmake pkg-config libmujoco-dev libqhull-dev liblcm-dev liblcm-bin
          liblcm-java libjchart2d-java default-jdk-headless libcmocka-dev zlib1g-dev iproute2
          util-linux procps gnuplot-nox clang libclang-rt-14-dev
          libglfw3-dev libgl1-mesa-dri xvfb xauth ffmpeg xdotool)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "setup.sh: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
    sudo=sudo
  fi
  echo "setup.sh: installing ${missing[*]}" >&2
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

jobs=${NUDGE_JOBS:-$(nproc)}

build() { # build DIR [cmake args...]
  local dir=$1; shift
  cmake -S "$root" -B "$root/$dir" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
  cmake --build "$root/$dir" -j "$jobs" -- --no-print-directory >/dev/null \
    || cmake --build "$root/$dir" -j 1   # rebuild serially so the error is readable
}

# fuzz [SECONDS]: libFuzzer is clang's, so the targets get a tree of their own, build-fuzz,
# configured with clang and NUDGE_FUZZ (tests/CMakeLists.txt). Each target starts from its
# working corpus in build-fuzz/corpus/ (grown across runs) plus the seeds and saved crashes
# in tests/fuzz/; a crash input lands in build-fuzz/artifacts/. Figures as name value unit.
fuzz_run() {
  local secs=${1:-60} out="$root/build-fuzz" src="$root/tests/fuzz" failed=0
  [[ $secs =~ ^[1-9][0-9]*$ ]] || { echo "setup.sh: fuzz: SECONDS must be a positive integer, got '$secs'" >&2; exit 2; }
  command -v clang >/dev/null || { echo "setup.sh: fuzz needs clang" >&2; exit 1; }
  local targets=(fuzz_rbuf fuzz_msgs fuzz_goals)
  CC=clang cmake -S "$root" -B "$out" -DCMAKE_C_COMPILER=clang -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DNUDGE_FUZZ=ON >/dev/null
  cmake --build "$out" -j "$jobs" --target "${targets[@]}" -- --no-print-directory >/dev/null \
    || cmake --build "$out" -j 1 --target "${targets[@]}"
  mkdir -p "$out/artifacts"
  for t in "${targets[@]}"; do
    local dirs=("$out/corpus/$t" "$src/corpus/$t") log="$out/$t.log" rc=0
    [ -d "$src/regress/$t" ] && dirs+=("$src/regress/$t")
    local opts=(-max_total_time="$secs" -timeout=30 -print_final_stats=1
                -artifact_prefix="$out/artifacts/$t-")
    [ -f "$src/$t.dict" ] && opts+=(-dict="$src/$t.dict")
    mkdir -p "$out/corpus/$t"
    "$out/fuzz/$t" "${opts[@]}" "${dirs[@]}" >"$log" 2>&1 || rc=$?
    local last execs rate
    last=$(grep -E '^#[0-9]+' "$log" | tail -n 1 || true)
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -n 1)
    echo "${t}_execs ${execs:-0} count"
    echo "${t}_exec_rate ${rate:-0} per_s"
    echo "${t}_cov $(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last" | grep . || echo 0) edges"
    echo "${t}_ft $(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last" | grep . || echo 0) features"
    if [ "$rc" -ne 0 ]; then
      failed=1
      echo "setup.sh: $t failed (exit $rc), log $log:" >&2
      grep -E 'invariant broken|ERROR:|SUMMARY:|Test unit written' "$log" | head -n 5 >&2 || true
      echo "  keep the input as a regression case: tests/fuzz/regress/$t/" >&2
    fi
  done
  return $failed
}

case "$cmd" in
  build) build build ;;
  demo)
    build build
    # The view: a window on a desktop, else an MP4 of the run (nudge-up --view auto); an
    # explicit --view among ARGS wins.
    set -- --view auto "$@"
    if ip route get 239.255.76.67 >/dev/null 2>&1; then
      exec "$root/build/bin/nudge-up" demo "$@"
    fi
    # No multicast route (an isolated machine): LCM cannot open on the host, so run the
    # demo in a private network namespace where loopback carries it.
    echo "setup.sh: no multicast route on this host; running the demo in a private network namespace" >&2
    exec "$root/tests/tools/netns-run" "$root/build/bin/nudge-up" demo "$@" ;;
  test) build build; cd build && exec ctest --output-on-failure -j 2 ;;
  fuzz) fuzz_run "$@" ;;
  test-asan)
    build build-asan -DNUDGE_SANITIZE=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo
    cd build-asan && exec ctest --output-on-failure -j 2 -L 'unit|process' ;;
esac
