#!/usr/bin/env bash
# Installs the Debian 12 packages lrfnet needs, only those that are missing, and the npm packages of
# the test clients (tests/node, from its package-lock.json). Idempotent; run as root.
#   scripts/install_deps.sh            everything: host build, tests, fuzzing, packages, aarch64 cross
#   scripts/install_deps.sh --demo     only what scripts/build.sh and scripts/demo.sh need (the three
#                                      programs; no clang, browser, broker, node, cross toolchain, qemu)
#   scripts/install_deps.sh --no-cross everything but the aarch64 cross toolchain and qemu-user
set -euo pipefail

cross=1
demo=0
for arg in "$@"; do
  case "$arg" in
    --no-cross) cross=0 ;;
    --demo) demo=1; cross=0 ;;
    -h|--help) sed -n '2,7p' "$0"; exit 0 ;;
    *) echo "install_deps.sh: unknown option '$arg'" >&2; exit 2 ;;
  esac
done

# Configure and build the three programs (CMake also looks for the test libraries: they are small).
demo_pkgs=(
  build-essential cmake ninja-build pkg-config git
  ccache                              # scripts/build.sh and test.sh compile through it
  libeigen3-dev libboost-dev libboost-program-options-dev
  libprotobuf-dev protobuf-compiler libspdlog-dev libfmt-dev
  libpcap-dev libyaml-cpp-dev nlohmann-json3-dev nanopb libnanopb-dev
  libsodium-dev                       # authenticated datagrams (common/datagram_auth)
  libgtest-dev libgmock-dev libbenchmark-dev
  libceres-dev coinor-libclp-dev zlib1g-dev   # calibration: joint refinement, LP oracle in tests, PNG report
  libmosquitto-dev                    # lrfnetd's MQTT output
)
test_pkgs=(
  clang libclang-rt-14-dev            # libFuzzer + sanitizers for the fuzz targets
  chromium fonts-dejavu-core          # the live view's browser test (headless)
  mosquitto mosquitto-clients         # the broker and mosquitto_sub for the MQTT tests
  liburdfdom-dev                      # the URDF export's round-trip test (ROS's URDF parser)
  nodejs                              # the Foxglove client and JSON Schema validator of the tests
  help2man dpkg-dev file man-db systemd systemd-container   # Debian packages: man pages,
                                      # shlibdeps, unit checks, the services booted in a container
)
cross_pkgs=(
  g++-aarch64-linux-gnu qemu-user
  libpcap-dev:arm64 libboost-dev:arm64 libboost-program-options-dev:arm64
  libspdlog-dev:arm64 libfmt-dev:arm64 libgtest-dev:arm64 libnanopb-dev:arm64 libsodium-dev:arm64
  libyaml-cpp0.7:arm64                # runtime only: libyaml-cpp-dev is not co-installable, the host headers serve both
)
host_pkgs=("${demo_pkgs[@]}")
[ "$demo" = 1 ] || host_pkgs+=("${test_pkgs[@]}")

if [ "$(id -u)" -ne 0 ]; then
  SUDO=sudo
else
  SUDO=
fi

missing=()
is_installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q 'install ok installed'; }
for p in "${host_pkgs[@]}"; do is_installed "$p" || missing+=("$p"); done
if [ "$cross" = 1 ]; then
  if ! dpkg --print-foreign-architectures | grep -qx arm64; then
    $SUDO dpkg --add-architecture arm64
  fi
  for p in "${cross_pkgs[@]}"; do is_installed "$p" || missing+=("$p"); done
fi

# Debian's nodejs comes without npm (other builds of nodejs bring their own).
if [ "$demo" = 0 ]; then
  command -v npm >/dev/null 2>&1 || is_installed npm || missing+=(npm)
fi

if [ "${#missing[@]}" -eq 0 ]; then
  echo "install_deps: all packages present"
else
  echo "install_deps: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  # --force-unsafe-io: dpkg otherwise syncs every unpacked file to disk one by one (the 14,000 Boost
  # headers alone took 96 s on a busy 2-core machine); the kernel writes them back as usual. Only a
  # power cut during the install could leave a file broken (apt-get install --reinstall mends it).
  $SUDO apt-get install -y -qq --no-install-recommends -o Dpkg::Options::=--force-unsafe-io \
    "${missing[@]}" >/dev/null
  echo "install_deps: done"
fi
[ "$demo" = 1 ] && exit 0

# The npm test clients (@foxglove/ws-protocol, ws, ajv, @foxglove/schemas) into tests/node/node_modules,
# exactly as locked; again only when the lock file changed.
node_dir="$(cd "$(dirname "$0")/.." && pwd)/tests/node"
if [ -f "$node_dir/package-lock.json" ] &&
   { [ ! -f "$node_dir/node_modules/.package-lock.json" ] ||
     [ "$node_dir/package-lock.json" -nt "$node_dir/node_modules/.package-lock.json" ]; }; then
  echo "install_deps: npm ci in tests/node"
  (cd "$node_dir" && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi
