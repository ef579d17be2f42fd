# view-lib.sh: what nudge-view's tests share (sourced by tests/view/test_*.sh, after
# tools/process-lib.sh).
#
# vw_need BUILD_DIR    skip (exit 77) unless Xvfb, ffmpeg and ffprobe are installed and the
#                      view and its helpers are built; call before pt_init
# vw_xvfb              start a private X server (Xvfb, its own display number) and export
#                      DISPLAY; it stops with the test (pt_spawn)
# vw_shot PID NAME     ask the running view PID for a frame (SIGUSR1 writes its --png file,
#                      which must be $PT_WORK/shot.png) and keep it as $PT_WORK/NAME.ppm
# vw_fig FILE NAME     the value of figure NAME in FILE ('name value unit' lines)
# vw_blob NAME COLOUR [X0 Y0 X1 Y1]   'N X Y': pixel count and centroid of a colour class
# vw_near A B TOL      A and B (numbers) differ by at most TOL

vw_need() {
  local b=${1:?usage: vw_need BUILD_DIR} t
  for t in Xvfb ffmpeg ffprobe; do
    if ! command -v "$t" >/dev/null; then
      echo "$PT_NAME: SKIP: $t is not installed (apt-get install xvfb xauth ffmpeg; setup.sh does)" >&2
      exit 77
    fi
  done
  for t in "$b/bin/nudge-view" "$b/tests/nudge-viewpub" "$b/tests/nudge-viewpix"; do
    [[ -x $t ]] || { echo "$PT_NAME: $t is missing: build first" >&2; exit 1; }
  done
  VW=$b/bin/nudge-view
  VW_PUB=$b/tests/nudge-viewpub
  VW_PIX=$b/tests/nudge-viewpix
}

vw_xvfb() {
  local fd_file=$PT_WORK/xdisplay n
  # -displayfd: Xvfb picks a free display number itself and writes it when it is ready.
  pt_spawn VW_XVFB Xvfb -displayfd 3 -screen 0 1280x1024x24 -nolisten tcp 3>"$fd_file" \
    2>"$PT_WORK/xvfb.err"
  if ! pt_wait_for 15 test -s "$fd_file"; then
    echo "$PT_NAME: SKIP: Xvfb did not start: $(head -c 300 "$PT_WORK/xvfb.err")" >&2
    exit 77
  fi
  read -r n <"$fd_file"
  export DISPLAY=:$n
  pt_say "Xvfb on $DISPLAY"
}

vw_shot() {
  local pid=$1 name=$2
  rm -f "$PT_WORK/shot.png"
  kill -USR1 "$pid"
  if ! pt_wait_for 10 test -s "$PT_WORK/shot.png"; then
    pt_fail "no frame from the view (pid $pid) for $name"
    return 1
  fi
  mv "$PT_WORK/shot.png" "$PT_WORK/$name.png"
  ffmpeg -nostdin -loglevel error -y -i "$PT_WORK/$name.png" "$PT_WORK/$name.ppm"
}

vw_fig() { awk -v n="$2" '$1 == n { print $2 }' "$1"; }

vw_blob() {
  local name=$1
  shift
  "$VW_PIX" blob "$PT_WORK/$name.ppm" "$@" | awk '{ v[$1] = $2 } END { print v["blob_n"], v["blob_x"], v["blob_y"] }'
}

vw_near() { awk -v a="$1" -v b="$2" -v t="$3" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(d <= t) }'; }
