#!/usr/bin/env bash
# The whole system on loopback, on real sockets and real protocols:
#   lrfnet sim SCENARIO --serve   one emulated SICK device per sensor (CoLa-B over TCP)
#   lrfnet-tracker                one per device: scans → tracks → UDP datagrams to lrfnetd
#   lrfnetd                       collects (progress bar: data still needed), calibrates when the data
#                                 links every sensor, then fuses; serves the live view
# then prints the calibration next to the simulator's truth (lrfnet eval), the report picture and a
# summary of the fused tracks. Every process it starts is stopped on exit (also on Ctrl-C).
#   scripts/demo.sh [BUILD_DIR]   (default: build; build first with scripts/build.sh)
# Environment:
#   LRFNET_DEMO_SCENARIO   scenario file (default tools/scenarios/office_distributed.yaml, six sensors)
#   LRFNET_DEMO_SPEED      scenario seconds per wall-clock second (default 1; faster looks to the
#                          trackers like people running, so tracks break more often)
#   LRFNET_DEMO_OUT        output folder (default BUILD_DIR/demo): calibration, report, fused tracks
#   LRFNET_DEMO_LIVE       address of the live view (default 127.0.0.1:8080; port 0: any free port)
#   LRFNET_DEMO_HOLD_S     keep everything running this long after the scenario (to watch the view)
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${1:-build}
lrfnet=$build_dir/tools/lrfnet
tracker=$build_dir/firmware_tracker/app/lrfnet-tracker
daemon=$build_dir/central_daemon/app/lrfnetd
for binary in "$lrfnet" "$tracker" "$daemon"; do
  if [ ! -x "$binary" ]; then
    echo "demo: $binary not found; build first (scripts/build.sh $build_dir)" >&2
    exit 1
  fi
done
scenario=${LRFNET_DEMO_SCENARIO:-tools/scenarios/office_distributed.yaml}
speed=${LRFNET_DEMO_SPEED:-1}
out=${LRFNET_DEMO_OUT:-$build_dir/demo}
live=${LRFNET_DEMO_LIVE:-127.0.0.1:8080}
hold_s=${LRFNET_DEMO_HOLD_S:-0}
duration_s=$(sed -n 's/^duration_s: *\([0-9.]*\).*/\1/p' "$scenario" | head -n 1)

rm -rf "$out"
mkdir -p "$out/logs"
pids=()
cleanup() {
  local pid
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT
trap 'echo; echo "demo: interrupted"; exit 130' INT TERM

# wait_for FILE PATTERN SECONDS PID WHAT: until a line of FILE matches PATTERN.
wait_for() {
  local i
  for ((i = 0; i < $3 * 10; ++i)); do
    grep -q "$2" "$1" 2>/dev/null && return 0
    if ! kill -0 "$4" 2>/dev/null; then
      echo "demo: $5 exited early; its log:" >&2
      tail -n 20 "$1" "$out/logs/"*.log 2>/dev/null >&2 || true
      exit 1
    fi
    sleep 0.1
  done
  echo "demo: $5 did not get ready within $3 s" >&2
  exit 1
}

echo "demo: scenario $(basename "$scenario") ($duration_s s at ${speed}x), output in $out"
"$lrfnet" sim "$scenario" --serve --speed "$speed" --out "$out" --log-level warn \
  >"$out/logs/sim.out" 2>"$out/logs/sim.log" &
pids+=($!)
sim_pid=$!
# One line "ID HOST:PORT" per sensor once every device listens.
wait_for "$out/logs/sim.out" ':[0-9]' 10 "$sim_pid" "lrfnet sim --serve"
sleep 0.3
mapfile -t devices < <(grep -E '^[^ ]+ [^ ]+:[0-9]+$' "$out/logs/sim.out")
echo "demo: ${#devices[@]} emulated devices: $(cut -d' ' -f1 <<<"$(printf '%s\n' "${devices[@]}")" | tr '\n' ' ')"

cat >"$out/lrfnetd.yaml" <<EOF
# The demo's lrfnetd settings (everything else: lrfnetd --print-config).
status:
  interval_s: 2.0
calibration:
  attempt_interval_s: 3.0
  min_pair_overlap_s: 10.0
  output: $out/calibration.yaml
  report_dir: $out/report
fusion:
  record: $out/fused.jsonl
live_view:
  listen: "$live"
EOF
"$daemon" --listen 127.0.0.1:0 --config "$out/lrfnetd.yaml" --record "$out/lrfnetd.rec" \
  --stats-out "$out/lrfnetd_stats.json" >"$out/logs/lrfnetd.out" 2>"$out/logs/lrfnetd.log" &
pids+=($!)
daemon_pid=$!
wait_for "$out/logs/lrfnetd.out" '^listening ' 10 "$daemon_pid" "lrfnetd"
uplink=$(sed -n 's/^listening //p' "$out/logs/lrfnetd.out")
wait_for "$out/logs/lrfnetd.out" '^live view ' 10 "$daemon_pid" "lrfnetd (live view)"
live_url=$(sed -n 's/^live view //p' "$out/logs/lrfnetd.out")
echo "demo: lrfnetd collects on $uplink; live view: $live_url (open it in a browser)"

for device in "${devices[@]}"; do
  id=${device%% *}
  address=${device#* }
  "$tracker" --sensor "$address" --sensor-id "$id" --uplink "$uplink" --log-level warn \
    >"$out/logs/tracker_$id.out" 2>"$out/logs/tracker_$id.log" &
  pids+=($!)
done
echo "demo: ${#devices[@]} lrfnet-tracker processes connected their devices to lrfnetd"

# The daemon's status lines (progress bar while collecting) until it has calibrated.
start=$(date +%s)
shown=0
deadline=$((start + ${duration_s%.*} / ${speed%.*} + 30))
while ! grep -q '^calibrated ' "$out/logs/lrfnetd.out"; do
  if ! kill -0 "$daemon_pid" 2>/dev/null; then
    echo "demo: lrfnetd exited; its log:" >&2
    tail -n 20 "$out/logs/lrfnetd.log" >&2
    exit 1
  fi
  if [ "$(date +%s)" -gt "$deadline" ]; then
    echo "demo: no calibration before the scenario ended; lrfnetd's last status:" >&2
    grep 'status:' "$out/logs/lrfnetd.log" | tail -n 1 >&2
    exit 1
  fi
  lines=$(grep -c 'status:' "$out/logs/lrfnetd.log" || true)
  if [ "$lines" -gt "$shown" ]; then
    line=$(grep 'status:' "$out/logs/lrfnetd.log" | tail -n 1)
    # "collecting [####----] 40% weakest link ..." and the sensor count of the status line.
    echo "  $(date +%H:%M:%S) $(sed -E 's/.*status: ([0-9]+ sensors[^|]*).*\| (collecting[^|]*|calibrating[^|]*).*/\1| \2/' <<<"$line")"
    shown=$lines
  fi
  sleep 0.5
done
echo "demo: calibrated after $(($(date +%s) - start)) s"
grep -E 'calibration: ' "$out/logs/lrfnetd.log" | sed -E 's/^.*calibration: /  /'
echo "demo: calibration vs truth (lrfnet eval $out/calibration.yaml $out/truth.yaml)"
"$lrfnet" eval "$out/calibration.yaml" "$out/truth.yaml" | sed 's/^/  /'

echo "demo: fusing until the scenario ends"
while kill -0 "$sim_pid" 2>/dev/null; do sleep 1; done
if [ "$hold_s" != 0 ]; then
  echo "demo: holding for $hold_s s; live view at $live_url"
  sleep "$hold_s"
fi
kill -INT "$daemon_pid"
wait "$daemon_pid" || true
tail -n 1 "$out/logs/lrfnetd.out" | sed 's/^/  /'
if [ -s "$out/fused.jsonl" ]; then
  ids=$(grep -o '"id":[0-9]*' "$out/fused.jsonl" | sort -u | wc -l)
  echo "demo: fused tracks: $(wc -l <"$out/fused.jsonl") snapshots in $out/fused.jsonl, $ids distinct fused ids"
fi
# The daemon calibrated from what it had received when the attempt started (calibration.yaml's
# input_window); its recording gives that input again, and the same poses: what differs between two
# runs of the demo is the live data and the moment the calibration starts, not the calibration.
window=$(sed -n 's/^input_window: {received_until_utc_ns: \([0-9]*\), scan_from_utc_ns: \([0-9]*\)}$/\1 \2/p' \
  "$out/calibration.yaml")
if [ -n "$window" ]; then
  read -r until_ns from_ns <<<"$window"
  "$lrfnet" calibrate "$out/lrfnetd.rec" --received-until-ns "$until_ns" --scan-from-ns "$from_ns" \
    --min-overlap-s 10 --out "$out/calibration_again.yaml" >"$out/logs/calibrate_again.log" 2>&1 || true
  # The same input, the same poses: equal to 1e-9 relative (the daemon and `lrfnet calibrate` may sum
  # in another order, which moves the last digit of a double, 1e-16 relative).
  if [ -s "$out/calibration_again.yaml" ] &&
    paste -d '\n' <(grep '^  - {id:' "$out/calibration.yaml") <(grep '^  - {id:' "$out/calibration_again.yaml") |
    awk 'NR % 2 == 1 { a = $0; next }
         { n = split(a, x, /[ ,{}]+/); m = split($0, y, /[ ,{}]+/); if (n != m) bad = 1
           for (i = 1; i <= n; i++) {
             if (x[i] ~ /^-?[0-9.]+(e-?[0-9]+)?$/) {
               d = x[i] - y[i]; if (d < 0) d = -d; s = x[i] < 0 ? -x[i] : x[i]
               if (d > 1e-9 * (1 + s)) bad = 1
             } else if (x[i] != y[i]) bad = 1
           } ++pairs }
         END { exit (bad || pairs == 0) }'; then
    echo "demo: the same poses again from the recording (lrfnet calibrate $out/lrfnetd.rec --received-until-ns $until_ns --scan-from-ns $from_ns --min-overlap-s 10)"
  else
    echo "demo: the recording's input window gave other poses: compare $out/calibration.yaml and $out/calibration_again.yaml" >&2
  fi
fi
echo "demo: report picture: $out/report/calibration.png (and .svg); calibration: $out/calibration.yaml"
