#!/usr/bin/env bash
# Builds and runs every test: host unit + integration tests (ctest), the fuzz targets under libFuzzer for a
# fixed time, the tracker's aarch64 build under qemu-user, and the Debian packages. Ends with one line
# "N passed, N failed".
#   LRFNET_FUZZ_SECONDS   seconds per fuzz target (default 20)
#   LRFNET_SKIP_CROSS=1   skip the aarch64 stage; LRFNET_SKIP_FUZZ=1 skip the libFuzzer stage
#   LRFNET_SKIP_PACKAGES=1 skip the Debian packages (built from the trees above, installed into a
#                         throw-away root; the arm64 one run under qemu)
#   LRFNET_CCACHE=0       compile without ccache (used when installed: scripts/ccache_env.sh)
set -uo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
. scripts/ccache_env.sh
jobs=$(nproc)
fuzz_seconds=${LRFNET_FUZZ_SECONDS:-20}
passed=0
failed=0
failures=()

stage() { echo; echo "==== $* ($(date +%H:%M:%S))"; }
record() {  # record NAME PASSED FAILED
  passed=$((passed + $2)); failed=$((failed + $3))
  [ "$3" -gt 0 ] && failures+=("$1")
  return 0
}
ctest_counts() {  # parses "N% tests passed, F tests failed out of T"
  local line total bad
  line=$(grep -E 'tests passed, [0-9]+ tests? failed out of [0-9]+' "$1" | tail -n 1)
  if [ -z "$line" ]; then echo "0 1"; return; fi
  bad=$(echo "$line" | sed -E 's/.* ([0-9]+) tests? failed out of ([0-9]+).*/\1/')
  total=$(echo "$line" | sed -E 's/.* failed out of ([0-9]+).*/\1/')
  echo "$((total - bad)) $bad"
}

# ---- host build and tests
stage "host build"
if cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLRFNET_WERROR=ON >/dev/null &&
   cmake --build build -j"$jobs"; then
  stage "host tests (ctest)"
  (cd build && ctest -j"$jobs" --output-on-failure --timeout 600) 2>&1 | tee build/ctest.log
  read -r p f < <(ctest_counts build/ctest.log)
  record host-tests "$p" "$f"
else
  record host-build 0 1
fi

# ---- libFuzzer: every fuzz target for a fixed time, seeded by the corpus the host tests wrote
if [ "${LRFNET_SKIP_FUZZ:-0}" != 1 ]; then
  stage "fuzz build (clang, libFuzzer + ASan/UBSan)"
  if CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
       -DLRFNET_FUZZ=ON >/dev/null && cmake --build build-fuzz -j"$jobs" --target lrfnet_fuzz_targets; then
    # Every *_fuzz executable the build made, $jobs at a time (each libFuzzer process uses one core).
    mapfile -t targets < <(find build-fuzz/tests/fuzz -maxdepth 1 -type f -name '*_fuzz' -perm -u+x \
                             -printf '%f\n' | sort)
    stage "fuzz ${#targets[@]} targets for ${fuzz_seconds}s each, $jobs at a time"
    mkdir -p build-fuzz/logs
    declare -A fuzz_pid=()
    for target in "${targets[@]}"; do
      while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n || true; done
      corpus=build-fuzz/corpus/$target
      mkdir -p "$corpus"
      [ -d "build/fuzz_corpus/$target" ] && cp -n build/fuzz_corpus/$target/* "$corpus"/ 2>/dev/null
      (cd build-fuzz && exec "./tests/fuzz/$target" -max_total_time="$fuzz_seconds" -timeout=10 \
          -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="logs/$target-" "corpus/$target" \
          >"logs/$target.log" 2>&1) &
      fuzz_pid[$target]=$!
    done
    for target in "${targets[@]}"; do
      if wait "${fuzz_pid[$target]}"; then status=0; else status=1; fi
      stage "fuzz $target: $([ $status = 0 ] && echo passed || echo FAILED)"
      if [ $status = 0 ]; then
        tail -n 12 "build-fuzz/logs/$target.log"
        record "$target" 1 0
      else
        grep -v -E '^#[0-9]+' "build-fuzz/logs/$target.log" | tail -n 60
        ls build-fuzz/logs/"$target"-* 2>/dev/null
        record "$target" 0 1
      fi
    done
  else
    record fuzz-build 0 1
  fi
fi

# ---- aarch64: the tracker and its tests, cross-compiled and run under qemu-user
if [ "${LRFNET_SKIP_CROSS:-0}" != 1 ]; then
  stage "aarch64 cross build (tracker only)"
  if cmake -S . -B build-aarch64 -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
       -DCMAKE_TOOLCHAIN_FILE="$root/cmake/aarch64-linux-gnu.cmake" -DLRFNET_TRACKER_ONLY=ON \
       -DLRFNET_SHARED_DIR="$root/../shared" >/dev/null && cmake --build build-aarch64 -j"$jobs"; then
    stage "aarch64 tests under qemu-aarch64"
    file build-aarch64/firmware_tracker/app/lrfnet-tracker 2>/dev/null | sed 's/,.*//' || true
    (cd build-aarch64 && ctest -j"$jobs" --output-on-failure --timeout 120) 2>&1 | tee build-aarch64/ctest.log
    read -r p f < <(ctest_counts build-aarch64/ctest.log)
    record aarch64-tests "$p" "$f"
  else
    record aarch64-build 0 1
  fi
fi

# ---- Debian packages from the trees above: contents, dependencies, installed into a throw-away root
if [ "${LRFNET_SKIP_PACKAGES:-0}" != 1 ]; then
  stage "Debian packages (scripts/package.sh, tests/package_test.sh)"
  package_args=()
  [ "${LRFNET_SKIP_CROSS:-0}" = 1 ] && package_args+=(--no-cross)
  tests/package_test.sh "${package_args[@]}" 2>&1 | tee build/package_test.log
  line=$(grep -E '^package test: [0-9]+ passed, [0-9]+ failed' build/package_test.log | tail -n 1)
  if [ -n "$line" ]; then
    record packages "$(sed -E 's/.*: ([0-9]+) passed.*/\1/' <<<"$line")" \
      "$(sed -E 's/.* ([0-9]+) failed.*/\1/' <<<"$line")"
  elif ! grep -q '^package test: SKIP' build/package_test.log; then
    record packages 0 1
  fi
fi

echo
[ "${#failures[@]}" -gt 0 ] && echo "failed stages: ${failures[*]}"
echo "lrfnet: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
