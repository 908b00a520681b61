#!/usr/bin/env bash
# Runs the benchmarks (not part of the test command) and writes their tables to results/.
# Run them on an otherwise idle machine: daemon_benchmark pins threads to CPUs 0 and 1.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${1:-build}
cmake --build "$build_dir" --target decode_benchmark tracker_benchmark store_benchmark daemon_benchmark \
  rotation_averaging_benchmark calibration_benchmark fusion_benchmark outputs_benchmark tracking_benchmark \
  monitoring_benchmark lrfnet lrfnet-tracker lrfnetd \
  >/dev/null
mkdir -p results
"$build_dir/tests/bench/decode_benchmark" --out results/decode_benchmark.md
"$build_dir/tests/bench/tracker_benchmark" --out results/tracker_benchmark.md
# Tracking accuracy (CLEAR-MOT, NEES) over every shipped scenario, old and new tracker, per sensor
# and fused, at upper-body and knee height, where the per-sensor error comes from and what the false
# positives are (under a minute).
"$build_dir/tests/bench/tracking_benchmark" --scenarios tools/scenarios --jobs 2 --breakdown --explain \
  --before-one-leg --before-confirm-time --before-whole-person --before-box-size --before-single-beam \
  --before-deep-pieces --before-deep-evidence --before-isotropic-bias --before-across-walk \
  --before-side-uncertainty --before-side-from-view --before-lone-leg-standing \
  --before-few-point-legs --before-deep-legs --before-legs-seen-through --before-legs-report-coasting \
  --before-legs-coasting-sigma --before-coasting-sigma \
  --before-leg-edges --before-outline-departure --before-partial-view --before-underdetermined-fit \
  --before-recent-veil --before-stance-weight \
  --before-box-occluders --before-box-rejoin --before-see-through --before-step-seam --before-deep-tail --before-torso-edge-echo --before-box-unseen-cov --before-box-seen-extent --before-knee-box-faces --before-single-beam-partner \
  --before-edge-echo-birth --before-lone-beam-echo --before-far-leg-birth \
  --before-person-reach --before-partial-extent --before-neighbour --before-segment-excess --before-box-view --before-box-view-torso --before-gain-covariance --before-range-noise \
  --before-single-precision-fit --before-edge-sides --before-outside-start --before-across-sway --before-receded-edges --before-adopt --before-inherit-moved --before-touching-legs --before-occluded-gap --before-still-legs-cov --before-walking-legs-cov --before-still-legs --before-mixed-legs --before-mixed-leg-band \
  --before-fusion-merge \
  --out results/tracking_benchmark.md
"$build_dir/tests/bench/store_benchmark" results/store_benchmark.md
"$build_dir/tests/bench/daemon_benchmark" --out results/daemon_benchmark.md
"$build_dir/tests/bench/rotation_averaging_benchmark" --out results/rotation_averaging_benchmark.md
# The whole calibration chain over every shipped scenario (3 seeds; a few minutes). A failed sim or
# tracker run is run again (--attempts, 3); a seed whose input still lacks a sensor is listed with the
# cause under its table and the benchmark exits 1 (the table is still written).
"$build_dir/tests/bench/calibration_benchmark" --tool "$build_dir/tools/lrfnet" \
  --tracker "$build_dir/firmware_tracker/app/lrfnet-tracker" --scenarios tools/scenarios --seeds 3 \
  --out results/calibration_benchmark.md
# Fusion on synthetic multi-sensor scenes (accuracy, id continuity, update time).
"$build_dir/tests/bench/fusion_benchmark" --out results/fusion_benchmark.md
# The outputs for other systems: zones, MQTT object lists, Publish with a real, a stalled and no broker.
"$build_dir/tests/bench/outputs_benchmark" --out results/outputs_benchmark.md
# Authenticated datagrams: cost per datagram here, and its ratio to the unsealed path on the gateway's
# architecture (the aarch64 build under qemu-user, as scripts/test.sh configures it).
cmake --build "$build_dir" --target auth_benchmark >/dev/null
"$build_dir/tests/bench/auth_benchmark" --out results/auth_benchmark.md --platform "$(uname -m), native"
if [ "${LRFNET_SKIP_CROSS:-0}" != 1 ] && command -v qemu-aarch64 >/dev/null; then
  [ -f build-aarch64/build.ninja ] || cmake -S . -B build-aarch64 -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_TOOLCHAIN_FILE="$(pwd)/cmake/aarch64-linux-gnu.cmake" -DLRFNET_TRACKER_ONLY=ON >/dev/null
  cmake --build build-aarch64 --target auth_benchmark >/dev/null
  qemu-aarch64 -L /usr/aarch64-linux-gnu build-aarch64/auth_benchmark --datagrams 5000 --append \
    --out results/auth_benchmark.md --platform "aarch64 under qemu-user (tracker only: no daemon)"
fi
# A moved sensor (0.5/2/10 deg, 0.02/0.1/0.5 m; 2/5 deg, 0.1/0.2 m with the tracks alone) and furniture only,
# through sim → trackers → lrfnetd --input.
"$build_dir/tests/bench/monitoring_benchmark" --tool "$build_dir/tools/lrfnet" \
  --tracker "$build_dir/firmware_tracker/app/lrfnet-tracker" --daemon "$build_dir/central_daemon/app/lrfnetd" \
  --seeds 5 --out results/monitoring_benchmark.md
