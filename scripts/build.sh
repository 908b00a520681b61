#!/usr/bin/env bash
# Configures and builds lrfnet (host, release with debug info) into build/ (or BUILD_DIR):
#   scripts/build.sh [BUILD_DIR]        the three programs lrfnet-tracker, lrfnetd and lrfnet (what
#                                       scripts/demo.sh runs; about half of the whole build)
#   scripts/build.sh --all [BUILD_DIR]  everything scripts/test.sh builds (tests, fuzz targets)
# The tree is configured as scripts/test.sh configures it, so a later test run reuses every object; both
# compile through ccache when it is installed (scripts/ccache_env.sh, LRFNET_CCACHE=0 without).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/ccache_env.sh
targets=(--target lrfnet-tracker lrfnetd lrfnet)
build_dir=build
for arg in "$@"; do
  case "$arg" in
    --all) targets=() ;;
    -h|--help) sed -n '2,6p' "$0"; exit 0 ;;
    -*) echo "build.sh: unknown option '$arg' (see --help)" >&2; exit 2 ;;
    *) build_dir=$arg ;;
  esac
done
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLRFNET_WERROR=ON >/dev/null
cmake --build "$build_dir" -j"$(nproc)" "${targets[@]}"
