#!/usr/bin/env bash
# Builds the Debian 12 packages (CPack DEB) into build/packages/ (or --out DIR):
#   lrfnet-tracker_VERSION_amd64.deb, lrfnetd_VERSION_amd64.deb, lrfnet_VERSION_amd64.deb
#       from the host build tree (build/)
#   lrfnet-tracker_VERSION_arm64.deb
#       from the aarch64 cross build tree (build-aarch64/, Debian's g++-aarch64-linux-gnu; its
#       Depends resolved against the arm64 multiarch libraries)
# Only what the packages hold is built (the three binaries and their man pages); trees that exist
# (e.g. made by scripts/test.sh) are reused as they are.
#   scripts/package.sh [--no-cross] [--out DIR]
# Needs scripts/install_deps.sh (help2man, dpkg-dev; --no-cross skips the arm64 package).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
cross=1
out=build/packages
while [ $# -gt 0 ]; do
  case "$1" in
    --no-cross) cross=0 ;;
    --out) out=$2; shift ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "package.sh: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
for tool in help2man dpkg-shlibdeps dpkg-deb; do
  if ! command -v "$tool" >/dev/null; then
    echo "package.sh: $tool is missing; run scripts/install_deps.sh" >&2
    exit 1
  fi
done
jobs=$(nproc)
mkdir -p "$out"
out=$(cd "$out" && pwd)
rm -f "$out"/*.deb

# package TREE TARGETS...: configure (when new, as scripts/test.sh does), build TARGETS, cpack.
package() {
  local tree=$1
  shift
  local configure=(-G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLRFNET_WERROR=ON)
  if [ "$tree" = build-aarch64 ]; then
    configure+=(-DCMAKE_TOOLCHAIN_FILE="$root/cmake/aarch64-linux-gnu.cmake" -DLRFNET_TRACKER_ONLY=ON
                -DLRFNET_SHARED_DIR="$root/../shared")
  fi
  if [ -f "$tree/CMakeCache.txt" ]; then
    cmake -S . -B "$tree" >/dev/null
  else
    cmake -S . -B "$tree" "${configure[@]}" >/dev/null
  fi
  cmake --build "$tree" -j"$jobs" --target "$@"
  rm -rf "$tree/cpack"
  (cd "$tree" && cpack >/dev/null)
  cp "$tree"/cpack/*.deb "$out"/
}

package build lrfnet-tracker lrfnetd lrfnet lrfnet-tracker_man_page lrfnetd_man_page lrfnet_man_page
if [ "$cross" = 1 ]; then
  package build-aarch64 lrfnet-tracker lrfnet-tracker_man_page
fi
echo "package.sh: packages in $out:"
for deb in "$out"/*.deb; do
  echo "  $(basename "$deb")  $(du -k "$deb" | cut -f1) KiB"
done
