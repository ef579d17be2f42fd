#!/usr/bin/env bash
# test_view_live: nudge-view drawing the live bus in a real X server (Xvfb), judged by its
# pixels.
#
#   netns-run bash test_view_live.sh BUILD_DIR
#
# The view runs hidden at 640x480 with a camera straight down on the origin from 0.8 m
# (MuJoCo's 45 degree field of view: a point at height z lands (240 / tan 22.5 deg) /
# (0.8 - z) pixels per metre from the image centre, x right, y up), without text, and
# writes a frame on SIGUSR1. nudge-viewpub publishes scripted messages.
# 1. Nothing published: no box (blue) and no goal (green) on screen.
# 2. MOCAP moves the box: its blue blob's centroid sits at the image centre for (0, 0) and
#    moves right by 77 px for +0.1 m in x and up by 77 px for +0.1 m in y (top face).
# 3. The goal ghost (green) is absent before the TASK and appears where the TASK puts it.
# 4. With a plan, setpoints, theta and a heartbeat on screen (keypoints and path yellow,
#    predicted pose orange), invalid and undecodable messages on every channel the view
#    reads (nudge-inject on seven, nudge-viewpub bad-arm on ARM_STATE) change no pixel,
#    and the view's heartbeat counts every one of them as rejected.
# 5. In a visible window (xdotool drives the mouse), as in MuJoCo's sample viewer: the
#    scroll wheel zooms, a right drag moves, a left drag rotates; R restores the camera
#    (the frame is then identical to the first).
# 6. The lab world draws the Panda arm posed from ARM_STATE: moving joint 1 moves pixels.
# 7. SIGINT while recording: exit 0, and the MP4 holds every frame the view said it wrote.
# 8. No DISPLAY: exit 1 with a message naming xvfb-run, not a crash.
set -u
PT_NAME=test_view_live
HERE=$(dirname "${BASH_SOURCE[0]}")
. "$HERE/../tools/process-lib.sh"
. "$HERE/view-lib.sh"
vw_need "${1:-}"
pt_init "$@"
vw_xvfb

CAM=0,0,0,0.8,90,-90
VIEW_ARGS=(--hidden --no-overlay --size 640x480 --camera "$CAM" --png "$PT_WORK/shot.png")
# Pixels per metre at height z, camera 0.8 m above the table.
ppm() { awk -v z="$1" 'BEGIN { printf "%.2f", 240 / (sin(3.14159265/8) / cos(3.14159265/8)) / (0.8 - z) }'; }
pub() { "$VW_PUB" "$@" >/dev/null || pt_fail "nudge-viewpub $*"; sleep 0.3; }
rejected() { # the view's rejected count from its next heartbeat
  "$PT_BIN/nudge-status" --count 1 --timeout 3 | awk '$1 == "nudge-view" { for (i = 1; i < NF; i++) if ($i == "rej") print $(i + 1); exit }'
}

# --- 1-4: the ideal world ---------------------------------------------------------------
pt_spawn view "$VW" "${VIEW_ARGS[@]}" >"$PT_WORK/view.out" 2>"$PT_WORK/view.err"
"$PT_BIN/nudge-status" --wait nudge-view --timeout "$(pt_slow 15)" ||
  { pt_fail "no heartbeat from nudge-view"; exit 1; }

vw_shot "$view" empty
read -r n _ _ < <(vw_blob empty blue)
pt_check "before MOCAP no box is drawn ($n blue pixels)" test "$n" -eq 0

pub mocap 0,0,0,-0.3,0.2
vw_shot "$view" box0
read -r n0 x0 y0 < <(vw_blob box0 blue)
pt_check "MOCAP box at (0, 0): a blue blob of $n0 px centred at ($x0, $y0), the image centre" \
  eval 'test "$n0" -gt 2000 && vw_near "$x0" 319.5 2 && vw_near "$y0" 239.5 2'
read -r ng _ _ < <(vw_blob box0 green)
pt_check "no goal ghost before a TASK ($ng green pixels)" test "$ng" -eq 0

step=$(awk -v s="$(ppm 0.05)" 'BEGIN { printf "%.1f", 0.1 * s }')
pub mocap 0.1,0,0,-0.3,0.2
vw_shot "$view" boxx
read -r n1 x1 y1 < <(vw_blob boxx blue)
pt_check "box +0.1 m in x: the blob moves right by $(awk -v a="$x1" -v b="$x0" 'BEGIN{print a-b}') px (expected $step), not up or down" \
  eval 'vw_near "$(awk -v a="$x1" -v b="$x0" "BEGIN{print a-b}")" "$step" 4 && vw_near "$y1" "$y0" 1'
pub mocap 0,0.1,0,-0.3,0.2
vw_shot "$view" boxy
read -r n2 x2 y2 < <(vw_blob boxy blue)
pt_check "box +0.1 m in y: the blob moves up by $(awk -v a="$y0" -v b="$y2" 'BEGIN{print a-b}') px (expected $step), not sideways" \
  eval 'vw_near "$(awk -v a="$y0" -v b="$y2" "BEGIN{print a-b}")" "$step" 4 && vw_near "$x2" "$x0" 1'
pub mocap 0,0,1.5707963,-0.3,0.2
vw_shot "$view" boxyaw
"$VW_PIX" blob "$PT_WORK/boxyaw.ppm" blue 0 0 640 480 >/dev/null
# Turned by 90 degrees the 10 x 6 cm top face is 6 cm wide and 10 cm tall: count the
# blue pixels of the centre row and column.
wrow=$(vw_blob boxyaw blue 0 239 640 240 | cut -d' ' -f1)
hcol=$(vw_blob boxyaw blue 319 0 320 480 | cut -d' ' -f1)
pt_check "box turned 90 degrees: its blob is $wrow px wide and $hcol px tall (taller than wide)" \
  eval 'test "$hcol" -gt $((wrow + 20))'

pub mocap 0,0,0,-0.3,0.2 task 0.2,0.15,0,0.01
vw_shot "$view" goal
read -r ng gx gy < <(vw_blob goal green)
s=$(ppm 0.0515)
ex=$(awk -v s="$s" 'BEGIN { printf "%.1f", 319.5 + 0.2 * s }')
ey=$(awk -v s="$s" 'BEGIN { printf "%.1f", 239.5 - 0.15 * s }')
pt_check "TASK goal (0.2, 0.15): a green ghost of $ng px centred at ($gx, $gy), expected ($ex, $ey)" \
  eval 'test "$ng" -gt 2000 && vw_near "$gx" "$ex" 6 && vw_near "$gy" "$ey" 6'
read -r nb _ _ < <(vw_blob goal blue)
pt_check "the box is still drawn ($nb blue pixels)" test "$nb" -gt 2000

pub at 0 sweep -0.3,0.2,-0.12,0.02,0.4 plan -0.05,-0.1,0.3,0.3,-0.08,-0.05,0.2,0,0.05,-0.1,0.1,0 \
  params 0.9,0.005,0.0001,1 status nudge-planner,planning episode 0
vw_shot "$view" full
read -r ny _ _ < <(vw_blob full yellow)
read -r no _ _ < <(vw_blob full orange)
read -r nc _ _ < <(vw_blob full cyan)
pt_check "the plan is drawn: keypoints and path ($ny yellow px), predicted pose ($no orange px), trail ($nc cyan px)" \
  eval 'test "$ny" -gt 100 && test "$no" -gt 1000 && test "$nc" -gt 20'

r0=$(rejected)
inj=0
for ch in MOCAP EE_CMD PLAN TASK PARAMS EPISODE STATUS; do
  out=$("$PT_INJ" --channel "$ch" 2>&1) || pt_fail "nudge-inject --channel $ch: $out"
  k=$(awk '$1 ~ /^inject_.*_(bad|garbage)$/ { s += $2 } END { print s + 0 }' <<<"$out")
  inj=$((inj + k))
done
out=$("$VW_PUB" bad-arm)
inj=$((inj + $(awk '$1 ~ /^inject_ARM_STATE/ { s += $2 } END { print s + 0 }' <<<"$out")))
sleep 0.5
vw_shot "$view" after_bad
r1=$(rejected)
pt_figure view_injected "$inj" count
d=$("$VW_PIX" diff "$PT_WORK/full.ppm" "$PT_WORK/after_bad.ppm" | awk '$1 == "diff_pixels" { print $2 }')
pt_check "$inj invalid or undecodable messages changed no pixel ($d differ)" test "${d:-x}" = 0
pt_check "the heartbeat's rejected count rose by all $inj (from ${r0:-?} to ${r1:-?})" \
  test "$((${r1:-0} - ${r0:-0}))" -eq "$inj"
pt_check_not "no lcm-gen line per undecodable message in the view's log" grep -q 'error -1 decoding' "$PT_WORK/view.err"

kill -INT "$view"
pt_wait_pid "$view" 10 && pt_check "the view exits 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0

# --- 5. the mouse, in a visible window -------------------------------------------------------
if command -v xdotool >/dev/null; then
  # Elevation -89, not -90: MuJoCo's mouse moves (mjv_moveCamera) take a camera looking
  # exactly straight down for one whose right and up are swapped.
  pt_spawn win "$VW" --no-overlay --size 640x480 --camera 0,0,0,0.8,90,-89 --png "$PT_WORK/shot.png" \
    >"$PT_WORK/win.out" 2>"$PT_WORK/win.err"
  "$PT_BIN/nudge-status" --wait nudge-view --pid "$win" --timeout "$(pt_slow 15)" ||
    pt_fail "no heartbeat from the windowed view"
  pub mocap 0,0.1,0,-0.3,0.2
  vw_shot "$win" m0
  # No window manager: the window sits at the screen's origin, so its centre is (320, 240).
  mouse() { xdotool mousemove 320 240 "$@"; sleep 0.4; }
  mouse click 5 click 5 click 5
  vw_shot "$win" m_zoom
  mouse key r  # (xdotool's key takes every word after it as a key: one call each)
  mouse mousedown 3 mousemove 370 240 mouseup 3
  vw_shot "$win" m_move
  mouse key r
  mouse mousedown 1 mousemove 400 240 mouseup 1
  vw_shot "$win" m_rot
  mouse key r
  vw_shot "$win" m_reset
  read -r n0 x0 y0 < <(vw_blob m0 blue)
  read -r nz _ _ < <(vw_blob m_zoom blue)
  read -r _ xm ym < <(vw_blob m_move blue)
  read -r _ xr yr < <(vw_blob m_rot blue)
  pt_check "scrolling (down) zooms in: the box covers $nz px, was $n0" test "$nz" -gt $((n0 * 3 / 2))
  pt_check "right drag 50 px right moves the scene right: the box from x $x0 to $xm" \
    eval 'vw_near "$(awk -v a="$xm" -v b="$x0" "BEGIN{print a-b}")" 50 20 && vw_near "$ym" "$y0" 3'
  pt_check "left drag rotates the view about its centre: the box from ($x0, $y0) to ($xr, $yr)" \
    eval '! vw_near "$xr" "$x0" 10 && ! vw_near "$yr" "$y0" 3'
  d=$("$VW_PIX" diff "$PT_WORK/m0.ppm" "$PT_WORK/m_reset.ppm" | awk '$1 == "diff_pixels" { print $2 }')
  pt_check "R resets the camera: the frame equals the first again ($d pixels differ)" test "${d:-x}" = 0
  kill -INT "$win"
  pt_wait_pid "$win" 10 && pt_check "the windowed view exits 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0
else
  pt_say "SKIP the mouse checks: xdotool is not installed (setup.sh installs it)"
fi

# --- 6. the lab world ----------------------------------------------------------------------
# A later --camera replaces the first: the arm's base is at x = -0.62.
pt_spawn lab "$VW" --world lab "${VIEW_ARGS[@]}" --camera -0.3,0,0.3,1.6,90,-60 \
  >"$PT_WORK/lab.out" 2>"$PT_WORK/lab.err"
"$PT_BIN/nudge-status" --wait nudge-view --pid "$lab" --timeout "$(pt_slow 15)" || pt_fail "no heartbeat from the lab view"
pub arm 0,0,0,-1.5,0,1.5,0.8 mocap 0.1,0,0,-0.1,0
vw_shot "$lab" arm0
pub arm 0.8,0,0,-1.5,0,1.5,0.8
vw_shot "$lab" arm1
d=$("$VW_PIX" diff "$PT_WORK/arm0.ppm" "$PT_WORK/arm1.ppm" | awk '$1 == "diff_pixels" { print $2 }')
pt_check "lab world: turning joint 1 by 0.8 rad moves the arm ($d pixels change)" test "${d:-0}" -gt 2000
read -r nb _ _ < <(vw_blob arm0 blue)
pt_check "lab world: the box is drawn ($nb blue pixels)" test "$nb" -gt 200
kill -INT "$lab"
pt_wait_pid "$lab" 10 && pt_check "the lab view exits 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0

# --- 7. SIGINT while recording ----------------------------------------------------------------
pt_spawn rec "$VW" --hidden --size 640x480 --fps 30 --record "$PT_WORK/live.mp4" \
  >"$PT_WORK/rec.out" 2>"$PT_WORK/rec.err"
"$PT_BIN/nudge-status" --wait nudge-view --pid "$rec" --timeout "$(pt_slow 15)" || pt_fail "no heartbeat from the recording view"
sleep 3
kill -INT "$rec"
if pt_wait_pid "$rec" 20; then
  pt_check "recording view exits 0 on SIGINT (got $PT_RC)" test "$PT_RC" -eq 0
fi
frames=$(vw_fig "$PT_WORK/rec.out" view_frames)
got=$(ffprobe -v error -count_frames -select_streams v:0 -show_entries stream=nb_read_frames \
  -of csv=p=0 "$PT_WORK/live.mp4" 2>&1)
pt_figure view_live_frames "${frames:-0}" count
pt_check "the MP4 cut by SIGINT is complete: ffprobe counts ${got:-none} frames, the view wrote ${frames:-?}" \
  test "${got:-x}" = "${frames:-y}"
pt_check "about 3 s at 30 fps (${frames:-0} frames)" test "${frames:-0}" -ge 60

# --- 8. no display ------------------------------------------------------------------------------
env -u DISPLAY "$VW" --hidden --seconds 1 >"$PT_WORK/nodisp.out" 2>"$PT_WORK/nodisp.err"
rc=$?
pt_check "without DISPLAY: exit 1 (got $rc) saying how to get a video: $(head -c 160 "$PT_WORK/nodisp.err")" \
  eval 'test "$rc" -eq 1 && grep -q "xvfb-run" "$PT_WORK/nodisp.err"'
exit $((PT_FAILS > 0))
