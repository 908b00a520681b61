#!/usr/bin/env bash
# Demo: `lrfnet emulate` plays a SICK LMS511 on loopback (the LMS511 capture of ../shared/data/sick when it
# is there, else synthetic scans) and `lrfnet-tracker` connects to it over TCP: log-in, device ident, start
# of measurement, scan stream. Prints every 10th of 100 scans and the link counters.
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

shared_dir=${LRFNET_SHARED_DIR:-../shared}
capture=$shared_dir/data/sick/lms511_20210301.pcap
if [ -f "$capture" ]; then
  source_args=("$capture")
  source_text="LMS511 capture $capture"
else
  source_args=(--synthetic lms511)
  source_text="synthetic LMS511 (no capture at $capture)"
fi

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
echo "demo: lrfnet-tracker --sensor 127.0.0.1:$port --sensor-id demo --max-scans 100 --print-every 10"
"$tracker" --sensor "127.0.0.1:$port" --sensor-id demo --max-scans 100 --print-every 10
