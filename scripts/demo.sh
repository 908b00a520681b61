#!/usr/bin/env bash
# Demo: `lrfnet emulate` plays a SICK LMS511 on loopback (synthetic: a room with a person walking an
# ellipse) and `lrfnet-tracker` connects to it over TCP (log-in, device ident, start of measurement, scan
# stream), learns the background for 5 s, tracks the person and sends every datagram (track frames,
# background snapshot, health, sensor info) over UDP to `lrfnetd`, which validates, stores and records
# them (and asks the tracker for what it lacks). Prints the tracks of every 25th of 300 scans, the
# daemon's status lines and counters, and a summary of the daemon's recording (`lrfnet dump --summary`).
#   scripts/demo.sh [BUILD_DIR]    (default: build; build first with scripts/build.sh)
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

source_args=(--synthetic lms511)
source_text="synthetic LMS511"

work=$(mktemp -d)
emulator_pid=""
daemon_pid=""
cleanup() {
  for pid in "$emulator_pid" "$daemon_pid"; do
    if [ -n "$pid" ]; then
      kill "$pid" 2>/dev/null || true
      wait "$pid" 2>/dev/null || true
    fi
  done
  rm -rf "$work"
}
trap cleanup EXIT

"$lrfnet" emulate "${source_args[@]}" --port 0 --port-file "$work/port" --log-level warn \
  >"$work/emulator.out" &
emulator_pid=$!
for _ in $(seq 100); do
  [ -s "$work/port" ] && break
  if ! kill -0 "$emulator_pid" 2>/dev/null; then
    echo "demo: the emulator exited before listening" >&2
    exit 1
  fi
  sleep 0.1
done
if [ ! -s "$work/port" ]; then
  echo "demo: the emulator did not report its port within 10 s" >&2
  exit 1
fi
port=$(cat "$work/port")
echo "demo: emulated device ($source_text) on 127.0.0.1:$port"

echo "demo: lrfnetd --listen 127.0.0.1:0 --record daemon.rec --status-interval-s 2"
"$daemon" --listen 127.0.0.1:0 --record "$work/daemon.rec" --status-interval-s 2 >"$work/daemon.out" &
daemon_pid=$!
for _ in $(seq 100); do
  grep -q '^listening ' "$work/daemon.out" 2>/dev/null && break
  if ! kill -0 "$daemon_pid" 2>/dev/null; then
    echo "demo: lrfnetd exited before listening" >&2
    exit 1
  fi
  sleep 0.1
done
uplink=$(sed -n 's/^listening //p' "$work/daemon.out")
if [ -z "$uplink" ]; then
  echo "demo: lrfnetd did not report its address within 10 s" >&2
  exit 1
fi

echo "demo: lrfnet-tracker --sensor 127.0.0.1:$port --sensor-id demo --uplink $uplink --out demo.rec --max-scans 300 --print-every 25"
"$tracker" --sensor "127.0.0.1:$port" --sensor-id demo --uplink "$uplink" --out "$work/demo.rec" \
  --max-scans 300 --print-every 25
sleep 0.5
kill -INT "$daemon_pid"
wait "$daemon_pid"
daemon_pid=""
cat "$work/daemon.out"
echo "demo: lrfnet dump --summary daemon.rec"
"$lrfnet" dump --summary "$work/daemon.rec"
echo "demo: the tracker's own recording has $(stat -c %s "$work/demo.rec") bytes, the daemon's $(stat -c %s "$work/daemon.rec") (both removed on exit)"
