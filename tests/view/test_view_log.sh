#!/usr/bin/env bash
# test_view_log: nudge-view drawing recorded logs in a real X server (Xvfb): MP4 frame
# counts, timing, and the refusal of bad messages judged by pixels with the text on.
#
#   netns-run bash test_view_log.sh BUILD_DIR
#
# 1. A log nudge-viewpub writes with LCM's eventlog API, spanning exactly 2.5 s, drawn at
#    20 fps as fast as it can (--speed 0): the MP4 has 50 frames (ffprobe -count_frames),
#    lasts 2.5 s, and --png-at 2 writes frame 40.
# 2. The same at --speed 1: 50 frames again, taking about the log's 2.5 s of wall time.
# 3. The same log with invalid and undecodable messages on every channel interleaved: the
#    frame at 2 s, text overlay included, is identical to the clean log's, and the view
#    refused exactly the messages injected. The text is drawn in both top corners.
# 4. lcm-logger recording a scripted live run: its log becomes an MP4 of ceil(span x fps)
#    frames, span being the log's first to last timestamp, and shows the box.
set -u
PT_NAME=test_view_log
HERE=$(dirname "${BASH_SOURCE[0]}")
. "$HERE/../tools/process-lib.sh"
. "$HERE/view-lib.sh"
vw_need "${1:-}"
pt_init "$@"
vw_xvfb
W=$PT_WORK

frames_of() { ffprobe -v error -count_frames -select_streams v:0 -show_entries stream=nb_read_frames -of csv=p=0 "$1" 2>&1; }
duration_of() { ffprobe -v error -show_entries format=duration -of csv=p=0 "$1" 2>&1; }

A=(at 0 status nudge-planner,planning at 0.05 mocap 0,0,0.3,-0.12,0 task 0.15,0.05,0.5,0.01
   params 0.9,0.005,0.0001,1 at 0.1 sweep -0.25,-0.05,-0.1,0,0.5)
B=(at 0.6 plan 0.12,0.04,0.4,0.3,0.0,-0.08,0.2,0.05,0.1,-0.05,0.1,0.05 at 1.2
   status nudge-planner,planning mocap 0.01,0,0.32,-0.08,0 at 1.5 episode 1)
C=(at 2.5 status nudge-planner,idle)
"$VW_PUB" --log "$W/good.lcmlog" "${A[@]}" "${B[@]}" "${C[@]}" || pt_fail "nudge-viewpub (good log)"
# Bad messages after the first event (so both logs start at the same time), between the
# good ones and at the end.
"$VW_PUB" --log "$W/bad.lcmlog" "${A[@]:0:4}" bad "${A[@]:4}" bad "${B[@]}" bad "${C[@]}" bad \
  >"$W/bad.pub" || pt_fail "nudge-viewpub (bad log)"
nbad=$(awk '$1 == "inject_bad" { s += $2 } END { print s + 0 }' "$W/bad.pub")

# --- 1. as fast as it can ------------------------------------------------------------------
"$VW" --hidden --log "$W/good.lcmlog" --speed 0 --fps 20 --record "$W/fast.mp4" \
  --png "$W/good.png" --png-at 2 >"$W/fast.out" 2>"$W/fast.err"
rc=$?
pt_check "log at --speed 0 exits 0 (got $rc)" test "$rc" -eq 0
span=$(vw_fig "$W/fast.out" view_log_span)
pt_check "the log spans 2.5 s (${span:-?})" vw_near "${span:-0}" 2.5 1e-6
n=$(frames_of "$W/fast.mp4")
pt_figure view_log_mp4_frames "${n:-0}" count
pt_check "MP4 of a 2.5 s log at 20 fps: 50 frames (ffprobe: ${n:-?}, the view: $(vw_fig "$W/fast.out" view_frames))" \
  eval 'test "${n:-0}" = 50 && test "$(vw_fig "$W/fast.out" view_frames)" = 50'
d=$(duration_of "$W/fast.mp4")
pt_check "the MP4 lasts the log's 2.5 s (${d:-?} s)" vw_near "${d:-0}" 2.5 0.051
pt_check "--png-at 2 wrote frame 40" grep -q 'wrote .*good.png (--png-at, frame 40)' "$W/fast.err"
pt_figure view_log_fps_fast "$(vw_fig "$W/fast.out" view_fps)" per_s

# --- 2. real time ----------------------------------------------------------------------------
"$VW" --hidden --log "$W/good.lcmlog" --speed 1 --fps 20 --record "$W/real.mp4" \
  >"$W/real.out" 2>"$W/real.err"
wall=$(vw_fig "$W/real.out" view_wall)
n=$(frames_of "$W/real.mp4")
pt_check "at --speed 1: 50 frames again (${n:-?})" test "${n:-0}" = 50
pt_check "at --speed 1 it takes about the log's 2.5 s (${wall:-?} s)" \
  awk -v w="${wall:-0}" 'BEGIN { exit !(w >= 2.4 && w < 2.5 * 2) }'

# --- 3. bad messages interleaved ---------------------------------------------------------
"$VW" --hidden --log "$W/bad.lcmlog" --speed 0 --fps 20 --png "$W/bad.png" --png-at 2 \
  >"$W/bad.out" 2>"$W/bad.err"
for f in good bad; do ffmpeg -nostdin -loglevel error -y -i "$W/$f.png" "$W/$f.ppm"; done
d=$("$VW_PIX" diff "$W/good.ppm" "$W/bad.ppm" | awk '$1 == "diff_pixels" { print $2 }')
pt_check "with $nbad bad messages interleaved the frame at 2 s, text included, is identical ($d pixels differ)" \
  test "${d:-x}" = 0
pt_check "the view refused all $nbad ($(vw_fig "$W/bad.out" view_rejected)), none of the clean log ($(vw_fig "$W/fast.out" view_rejected))" \
  eval 'test "$(vw_fig "$W/bad.out" view_rejected)" = "$nbad" && test "$(vw_fig "$W/fast.out" view_rejected)" = 0'
read -r ng < <("$VW_PIX" blob "$W/good.ppm" green | awk '{ v[$1] = $2 } END { print v["blob_n"] }')
read -r nc < <("$VW_PIX" blob "$W/good.ppm" cyan | awk '{ v[$1] = $2 } END { print v["blob_n"] }')
pt_check "the frame shows the goal ghost ($ng green pixels) and the setpoint trail ($nc cyan)" \
  eval 'test "${ng:-0}" -gt 500 && test "${nc:-0}" -gt 100'
# The text: drawn in both top corners (task and theta at the left, the heartbeats at the
# right), and nowhere else a frame without it differs.
"$VW" --hidden --log "$W/good.lcmlog" --speed 0 --fps 20 --png "$W/plain.png" --png-at 2 \
  --no-overlay >/dev/null 2>&1
ffmpeg -nostdin -loglevel error -y -i "$W/plain.png" "$W/plain.ppm"
read -r tl < <("$VW_PIX" blob "$W/good.ppm" white 0 0 400 120 | awk '$1 == "blob_n" { print $2 }')
read -r tr < <("$VW_PIX" blob "$W/good.ppm" white 880 0 1280 60 | awk '$1 == "blob_n" { print $2 }')
read -r t0 < <("$VW_PIX" blob "$W/plain.ppm" white 0 0 1280 120 | awk '$1 == "blob_n" { print $2 }')
pt_check "text at the top left ($tl white pixels) and right ($tr), none without it ($t0)" \
  eval 'test "${tl:-0}" -gt 400 && test "${tr:-0}" -gt 100 && test "${t0:-1}" -lt 20'

# --- 4. lcm-logger on a live run -------------------------------------------------------------
pt_spawn logger lcm-logger -q -f "$W/live.lcmlog"
pt_wait_for 5 test -e "$W/live.lcmlog" || pt_fail "lcm-logger did not start"
sleep 0.3
"$VW_PUB" at 0 mocap 0,0,0,-0.2,0 task 0.2,0,0,0.01 at 0.1 sweep -0.2,0,-0.1,0,1 at 1.2 \
  plan 0.1,0,0,0.3,-0.06,0,0.2,0,0.0,0,0.1,0 >/dev/null || pt_fail "nudge-viewpub live"
sleep 0.3
kill -INT "$logger"
pt_wait_pid "$logger" 5
"$VW" --hidden --log "$W/live.lcmlog" --speed 0 --fps 25 --record "$W/live.mp4" --png "$W/live.png" \
  >"$W/live.out" 2>"$W/live.err"
span=$(vw_fig "$W/live.out" view_log_span)
want=$(awk -v s="${span:-0}" 'BEGIN { n = s * 25; k = int(n); if (k < n - 1e-9) k++; if (k < 1) k = 1; print k }')
n=$(frames_of "$W/live.mp4")
pt_figure view_logger_span "${span:-0}" s
pt_check "lcm-logger's log of ${span:-?} s: MP4 of ceil(span x 25) = $want frames (ffprobe: ${n:-?})" \
  test "${n:-0}" = "$want"
ffmpeg -nostdin -loglevel error -y -i "$W/live.png" "$W/live.ppm"
read -r nb < <("$VW_PIX" blob "$W/live.ppm" blue | awk '{ v[$1] = $2 } END { print v["blob_n"] }')
pt_check "its last frame shows the box ($nb blue pixels)" test "${nb:-0}" -gt 500
exit $((PT_FAILS > 0))
