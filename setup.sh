#!/usr/bin/env bash
# nudge set-up: installs what is missing (Debian packages), builds in Release into build/,
# then runs what you asked for. Safe to run again: it only installs what is absent and
# only rebuilds what changed.
set -euo pipefail

usage() {
  cat <<'USAGE'
usage: ./setup.sh [COMMAND] [ARGS...]

  demo [ARGS]   set up, build, and run the process system pushing the object to 5 goals
                in emulation (nudge-up demo; ARGS go to it, see build/bin/nudge-up --help)
  test          set up, build, and run every test (ctest)
  test-asan     set up, build with AddressSanitizer + UBSan into build-asan/, run the unit tests
  build         set up and build only (the default)
  -h, --help    this text

Programs land in build/bin/. Set NUDGE_JOBS to change build parallelism (default: nproc).
USAGE
}

cmd=${1:-build}
[ $# -gt 0 ] && shift
case "$cmd" in
  -h|--help|help) usage; exit 0 ;;
  demo|test|test-asan|build) ;;
  *) echo "setup.sh: unknown command '$cmd'" >&2; usage >&2; exit 2 ;;
esac

root=$(cd "$(dirname "$0")" && pwd)
cd "$root"

# Debian packages the build, the tests and the tools need.
# libqhull-dev: MuJoCo's CMake config names its headers; libjchart2d-java: lcm-spy's charts.
packages=(build-essential cmake pkg-config libmujoco-dev libqhull-dev liblcm-dev liblcm-bin
          liblcm-java libjchart2d-java default-jdk-headless libcmocka-dev zlib1g-dev iproute2
          util-linux procps)

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

case "$cmd" in
  build) build build ;;
  demo)
    build build
    if ip route get 239.255.76.67 >/dev/null 2>&1; then
      exec "$root/build/bin/nudge-up" demo "$@"
    fi
    # No multicast route (an isolated machine): LCM cannot open on the host, so run the
    # demo in a private network namespace where loopback carries it.
    echo "setup.sh: no multicast route on this host; running the demo in a private network namespace" >&2
    exec "$root/tests/netns-run" "$root/build/bin/nudge-up" demo "$@" ;;
  test) build build; cd build && exec ctest --output-on-failure -j 2 ;;
  test-asan)
    build build-asan -DNUDGE_SANITIZE=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo
    cd build-asan && exec ctest --output-on-failure -j 2 -L unit ;;
esac
