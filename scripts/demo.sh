#!/usr/bin/env bash
# Demo: `lrfnet emulate` plays a SICK LMS511 on loopback (synthetic: a room with a person walking an
# ellipse) and `lrfnet-tracker` connects to it over TCP (log-in, device ident, start of measurement, scan
# stream), learns the background for 5 s, tracks the person and writes every datagram (track frames,
# background snapshot, health, sensor info) to a recording. Prints the tracks of every 25th of 300 scans
# and the counters.
#   scripts/demo.sh [BUILD_DIR]    (default: build; build first with scripts/build.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${1:-build}
lrfnet=$build_dir/tools/lrfnet
tracker=$build_dir/firmware_tracker/app/lrfnet-tracker
for binary in "$lrfnet" "$tracker"; do
  if [ ! -x "$binary" ]; then
    echo "demo: $binary not found; build first (scripts/build.sh $build_dir)" >&2
    exit 1
  fi
done

source_args=(--synthetic lms511)
source_text="synthetic LMS511"

work=$(mktemp -d)
emulator_pid=""
cleanup() {
  if [ -n "$emulator_pid" ]; then
    kill "$emulator_pid" 2>/dev/null || true
    wait "$emulator_pid" 2>/dev/null || true
  fi
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
echo "demo: lrfnet-tracker --sensor 127.0.0.1:$port --sensor-id demo --out demo.rec --max-scans 300 --print-every 25"
"$tracker" --sensor "127.0.0.1:$port" --sensor-id demo --out "$work/demo.rec" --max-scans 300 \
  --print-every 25
echo "demo: recording of $(stat -c %s "$work/demo.rec") bytes written (removed on exit)"
