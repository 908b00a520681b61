#!/usr/bin/env bash
# The Debian packages, built by scripts/package.sh from the build trees scripts/test.sh made (so only
# the man pages and cpack are new work), checked as a user would meet them:
#  - fields and contents with dpkg-deb: names, architectures, Depends from dpkg-shlibdeps,
#    Recommends chrony, conffiles (the shipped documented YAML), units, sysusers, man pages,
#    scenarios; lrfnetd holds no tracker code;
#  - installed with dpkg --root into a throw-away root (a copy-on-write overlay of this machine's
#    root on a tmpfs, in a private mount namespace: dependencies are checked against what is
#    installed here, the maintainer scripts run, nothing outside the overlay changes): the user
#    lrfnet, lrfnetd.service enabled, --help and man pages, systemd-analyze verify and security
#    (each unit rated <= 2.0), and a short replay (lrfnet sim -> lrfnet-tracker --replay ->
#    lrfnetd --input) with the installed binaries; removal keeps the config, purge removes it;
#  - the services booted: a third throw-away root started with systemd-nspawn (private network),
#    where tests/service_boot_check.sh checks lrfnetd.service and lrfnet-tracker@gate-1.service
#    against an emulated scanner: ready, sandboxed (user, capabilities, seccomp), recording into
#    the state directory, reload, the watchdog restarting a tracker whose scanner link hangs;
#  - lrfnet-tracker for arm64 installed into a second throw-away root (its Depends resolved against
#    the arm64 multiarch packages) and run under qemu-aarch64 on the same capture, giving the same
#    track frames as the amd64 build.
# Ends with "package test: N passed, M failed". Needs root (mounts); scripts/install_deps.sh.
#   tests/package_test.sh [--no-cross]
set -uo pipefail
cd "$(dirname "$0")/.."
repo=$(pwd)
cross=1
[ "${1:-}" = --no-cross ] && cross=0

if [ "${LRFNET_PACKAGE_TEST_INNER:-0}" != 1 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "package test: SKIP (needs root for the throw-away root's mounts)"
    exit 0
  fi
  # The mounts live and die with a private mount namespace.
  LRFNET_PACKAGE_TEST_INNER=1 exec unshare --mount --propagation private "$0" "$@"
fi

passed=0
failed=0
check() {  # check NAME COMMAND...: one line per check
  local name=$1
  shift
  local output
  if output=$("$@" 2>&1); then
    passed=$((passed + 1))
    echo "ok   $name"
  else
    failed=$((failed + 1))
    echo "FAIL $name"
    [ -n "$output" ] && sed 's/^/       /' <<<"$output" | tail -n 15
  fi
}
finish() {
  echo "package test: $passed passed, $failed failed"
  [ "$failed" -eq 0 ]
  exit $?
}

version=$(sed -n 's/^project(lrfnet VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)
out=build/packages
package_args=()
[ "$cross" = 0 ] && package_args+=(--no-cross)
check "scripts/package.sh builds the packages" scripts/package.sh "${package_args[@]}" --out "$out"
tracker_amd64=$out/lrfnet-tracker_${version}_amd64.deb
daemon_deb=$out/lrfnetd_${version}_amd64.deb
tools_deb=$out/lrfnet_${version}_amd64.deb
tracker_arm64=$out/lrfnet-tracker_${version}_arm64.deb
debs=("$tracker_amd64" "$daemon_deb" "$tools_deb")
[ "$cross" = 1 ] && debs+=("$tracker_arm64")
for deb in "${debs[@]}"; do
  check "$(basename "$deb") exists" test -s "$deb"
done
[ "$failed" -eq 0 ] || finish

# ---- fields and contents
field() { dpkg-deb -f "$1" "$2"; }
expect_field() {  # expect_field DEB FIELD VALUE
  local got
  got=$(field "$1" "$2")
  [ "$got" = "$3" ] || { echo "$2: '$got', expected '$3'"; return 1; }
}
depends_on() {  # depends_on DEB PACKAGE...: each is in Depends
  local deps names p
  deps=$(field "$1" Depends)
  names=$(tr ',|' '\n\n' <<<"$deps" | sed -E 's/^ *//; s/ .*//')
  for p in "${@:2}"; do
    grep -qxF "$p" <<<"$names" || { echo "Depends lacks $p: $deps"; return 1; }
  done
}
files_are() {  # files_are DEB FILE...: exactly these regular files (and symlinks)
  diff <(dpkg-deb -c "$1" | awk '$1 !~ /^d/ {print $6}' | sed 's#^\./#/#' | sort) \
       <(printf '%s\n' "${@:2}" | sort)
}
conffiles_are() {
  diff <(dpkg-deb --ctrl-tarfile "$1" | tar -xO ./conffiles) <(printf '%s\n' "${@:2}")
}
same_file_in_deb() {  # same_file_in_deb DEB PATH SOURCE
  cmp <(dpkg-deb --fsys-tarfile "$1" | tar -xO ".$2") "$3"
}
scenarios=()
for f in tools/scenarios/*.yaml; do scenarios+=("/usr/share/lrfnet/scenarios/$(basename "$f")"); done

for deb in "$tracker_amd64" "$tracker_arm64"; do
  [ -f "$deb" ] || continue
  arch=$(sed -E 's/.*_([a-z0-9]+)\.deb$/\1/' <<<"$deb")
  name=$(basename "$deb")
  check "$name: Package, Version, Architecture" bash -c \
    "$(declare -f field expect_field); expect_field $deb Package lrfnet-tracker &&
     expect_field $deb Version $version && expect_field $deb Architecture $arch"
  check "$name: Depends (shlibdeps) and Recommends chrony" bash -c \
    "$(declare -f field expect_field depends_on); depends_on $deb libc6 libstdc++6 libpcap0.8 \
       libyaml-cpp0.7 libboost-program-options1.74.0 libspdlog1.10-fmt9 libsodium23 &&
     expect_field $deb Recommends chrony"
  check "$name: files" files_are "$deb" /usr/bin/lrfnet-tracker /etc/lrfnet/lrfnet-tracker.yaml \
    "/lib/systemd/system/lrfnet-tracker@.service" /usr/lib/sysusers.d/lrfnet-tracker.conf \
    /usr/share/man/man1/lrfnet-tracker.1.gz
  check "$name: conffiles" conffiles_are "$deb" /etc/lrfnet/lrfnet-tracker.yaml
  check "$name: the config is the shipped documented YAML" same_file_in_deb "$deb" \
    /etc/lrfnet/lrfnet-tracker.yaml firmware_tracker/config/lrfnet-tracker.yaml
done
check "lrfnet-tracker arm64: an aarch64 binary" bash -c \
  "dpkg-deb --fsys-tarfile $tracker_arm64 | tar -xO ./usr/bin/lrfnet-tracker > /tmp/lrfnet_pkg_tracker.$$ &&
   file /tmp/lrfnet_pkg_tracker.$$ | grep -q 'ARM aarch64'; r=\$?; rm -f /tmp/lrfnet_pkg_tracker.$$; exit \$r"
check "lrfnetd: Package, Version, Architecture, Recommends chrony" bash -c \
  "$(declare -f field expect_field); expect_field $daemon_deb Package lrfnetd &&
   expect_field $daemon_deb Version $version && expect_field $daemon_deb Architecture amd64 &&
   expect_field $daemon_deb Recommends chrony"
check "lrfnetd: Depends (shlibdeps)" bash -c \
  "$(declare -f field depends_on); depends_on $daemon_deb libc6 libstdc++6 libpcap0.8 \
     libprotobuf-lite32 libyaml-cpp0.7 libspdlog1.10-fmt9 libsodium23"
check "lrfnetd: files" files_are "$daemon_deb" /usr/bin/lrfnetd /etc/lrfnet/lrfnetd.yaml \
  /lib/systemd/system/lrfnetd.service /usr/lib/sysusers.d/lrfnetd.conf \
  /usr/share/man/man1/lrfnetd.1.gz
check "lrfnetd: conffiles" conffiles_are "$daemon_deb" /etc/lrfnet/lrfnetd.yaml
check "lrfnetd: the config is the shipped documented YAML" same_file_in_deb "$daemon_deb" \
  /etc/lrfnet/lrfnetd.yaml central_daemon/config/lrfnetd.yaml
check "lrfnetd holds no tracker code (no lrfnet::io/cola/tracking/tracker symbol)" bash -c \
  "! nm -C build/central_daemon/app/lrfnetd | grep -E 'lrfnet::(io|cola|tracking|tracker)::'"
check "lrfnet: Package, Architecture, Depends" bash -c \
  "$(declare -f field expect_field depends_on); expect_field $tools_deb Package lrfnet &&
   expect_field $tools_deb Architecture amd64 && depends_on $tools_deb libc6 libpcap0.8 libsodium23"
check "lrfnet: files (binary, man page, every shipped scenario)" files_are "$tools_deb" \
  /usr/bin/lrfnet /usr/share/man/man1/lrfnet.1.gz "${scenarios[@]}"

# ---- throw-away roots: copy-on-write overlays of / on a tmpfs
scratch=$(mktemp -d /tmp/lrfnet_package_test.XXXXXX)
cleanup() {
  umount -R "$scratch" 2>/dev/null
  rmdir "$scratch" 2>/dev/null
}
trap cleanup EXIT
mount -t tmpfs -o size=1g tmpfs "$scratch" || { echo "FAIL tmpfs"; failed=$((failed + 1)); finish; }
make_root() {  # make_root NAME -> $scratch/NAME/root
  local dir=$scratch/$1
  mkdir -p "$dir/upper" "$dir/work" "$dir/root"
  mount -t overlay overlay -o "lowerdir=/,upperdir=$dir/upper,workdir=$dir/work" "$dir/root" &&
    mount -t proc proc "$dir/root/proc" && mount --bind /dev "$dir/root/dev" &&
    mount -t tmpfs tmpfs "$dir/root/tmp" && mount -t tmpfs tmpfs "$dir/root/run"
}
check "throw-away root for amd64" make_root amd64
r=$scratch/amd64/root
in_root() { chroot "$r" "$@"; }

check "dpkg --root installs the amd64 packages (dependencies satisfied, scripts run)" \
  dpkg --root="$r" -i "$tracker_amd64" "$daemon_deb" "$tools_deb"
check "installed: status of all three" bash -c \
  "for p in lrfnet-tracker lrfnetd lrfnet; do
     dpkg --root=$r -s \$p | grep -qx 'Status: install ok installed' || exit 1; done"
check "postinst made the system user lrfnet (nologin)" bash -c \
  "chroot $r getent passwd lrfnet | grep -q ':/var/lib/lrfnet:/usr/sbin/nologin$'"
check "lrfnetd.service is enabled, no tracker instance is" bash -c \
  "test -L $r/etc/systemd/system/multi-user.target.wants/lrfnetd.service &&
   ! ls $r/etc/systemd/system/multi-user.target.wants/ | grep -q lrfnet-tracker"
for binary in lrfnet-tracker lrfnetd lrfnet; do
  check "$binary --help from the root" bash -c \
    "chroot $r $binary --help | grep -qE '^(usage: )?$binary '"
  check "man $binary from the root" in_root man -w "$binary"
done
for unit in lrfnetd.service lrfnet-tracker@.service; do
  check "systemd-analyze verify $unit" bash -c \
    "out=\$(chroot $r systemd-analyze verify /lib/systemd/system/$unit 2>&1); echo \"\$out\"; [ -z \"\$out\" ]"
done
security_ok() {  # security_ok UNIT: "Overall exposure level for UNIT: X.Y OK" with X.Y <= 2.0
  local line level
  line=$(systemd-analyze security --offline=yes --root="$r" "$1" 2>&1 | grep 'Overall exposure level')
  echo "$line"
  level=$(sed -E 's/.*: ([0-9.]+) .*/\1/' <<<"$line")
  [ -n "$level" ] && awk -v l="$level" 'BEGIN { exit !(l <= 2.0) }'
}
check "systemd-analyze security lrfnetd.service <= 2.0" security_ok lrfnetd.service
check "systemd-analyze security lrfnet-tracker@gate-1.service <= 2.0" \
  security_ok lrfnet-tracker@gate-1.service

cat >"$r/tmp/pkg.yaml" <<'EOF'
name: package_test
seed: 3
duration_s: 20
world:
  walls: [[[0, 0], [10, 0], [10, 8], [0, 8], [0, 0]]]
sensors:
  - {id: s1, model: tim561, x_m: 0.5, y_m: 0.5, yaw_deg: 40}
targets:
  - {shape: person, a_m: 0.25, b_m: 0.15, path: [[2, 2], [8, 6], [2, 6]], speed_mps: 1.2, loop: true}
EOF
check "installed lrfnet sim writes a capture" in_root lrfnet sim /tmp/pkg.yaml --out /tmp/sim
check "installed lrfnet finds its shipped scenarios by name" bash -c \
  "chroot $r lrfnet sim quenzel_sim --out /tmp/sim_named --log-level warn >/dev/null 2>&1 &&
   ls $r/tmp/sim_named/*.pcap >/dev/null"
check "installed lrfnet-tracker replays it into a recording" bash -c \
  "chroot $r lrfnet-tracker --replay /tmp/sim/s1.pcap --sensor-id s1 --out /tmp/s1.rec |
   tee $r/tmp/amd64.summary | grep -q ' scans=300 '"
check "installed lrfnetd reads the recording: every datagram accepted" bash -c \
  "chroot $r lrfnetd --input /tmp/s1.rec --log-level error |
   grep -E 'summary: sensors=1 datagrams=([1-9][0-9]*) accepted=\\1 rejected=0'"
check "dpkg -r lrfnetd keeps /etc/lrfnet/lrfnetd.yaml, removes the binary" bash -c \
  "dpkg --root=$r -r lrfnetd >/dev/null && test -f $r/etc/lrfnet/lrfnetd.yaml &&
   test ! -e $r/usr/bin/lrfnetd && dpkg --root=$r -s lrfnetd | grep -q config-files"
check "dpkg -P lrfnetd purges the config" bash -c \
  "dpkg --root=$r -P lrfnetd >/dev/null && test ! -e $r/etc/lrfnet/lrfnetd.yaml &&
   test ! -e $r/etc/systemd/system/multi-user.target.wants/lrfnetd.service"

# ---- the services as systemd runs them: a third throw-away root booted with systemd-nspawn
# (private network), tests/service_boot_check.sh run inside as a oneshot unit.
boot_root() {  # boot_root DIR: overlay of / with the amd64 packages installed, not mounted inside
  mkdir -p "$1/upper" "$1/work" "$1/root"
  mount -t overlay overlay -o "lowerdir=/,upperdir=$1/upper,workdir=$1/work" "$1/root" &&
    mount -t proc proc "$1/root/proc" && mount --bind /dev "$1/root/dev" &&
    dpkg --root="$1/root" -i "$tracker_amd64" "$daemon_deb" "$tools_deb" >/dev/null &&
    umount "$1/root/proc" "$1/root/dev"
}
boot_check_unit='[Unit]
Description=lrfnet package test: the services in their sandbox
After=lrfnetd.service multi-user.target
[Service]
Type=oneshot
TimeoutStartSec=300
ExecStart=/usr/local/lib/lrfnet-test/check.sh /root/service_checks.txt
[Install]
WantedBy=multi-user.target'
if command -v systemd-nspawn >/dev/null; then
  boot=$scratch/boot
  check "throw-away root to boot, packages installed" boot_root "$boot"
  b=$boot/root
  if [ -f "$b/etc/lrfnet/lrfnetd.yaml" ]; then
    # What an admin does: record, and keep the calibration, in the state directory.
    sed -i -e '/^record:/,/^$/ s/^  path: ""/  path: lrfnet.rec/' \
      -e '/^calibration:/,/^$/ s/^  output: ""/  output: calibration.yaml/' \
      "$b/etc/lrfnet/lrfnetd.yaml"
    install -D -m 755 tests/service_boot_check.sh "$b/usr/local/lib/lrfnet-test/check.sh"
    printf '%s\n' "$boot_check_unit" >"$b/etc/systemd/system/lrfnet-check.service"
    ln -sf /etc/systemd/system/lrfnet-check.service \
      "$b/etc/systemd/system/multi-user.target.wants/lrfnet-check.service"
    : >"$b/etc/machine-id"  # the container makes a machine id of its own
    # nspawn's own filter forbids reading the clock state (adjtimex) in the container, as a
    # gateway's kernel does not: allowed, so the check sees what the tracker's unit allows.
    timeout 300 systemd-nspawn -q -D "$b" --private-network --register=no --keep-unit \
      --link-journal=no --system-call-filter='adjtimex clock_adjtime' --boot \
      >"$scratch/boot.log" 2>&1 </dev/null
  fi
  results=$boot/upper/root/service_checks.txt
  failed_before=$failed
  if [ -f "$results" ]; then
    while IFS= read -r line; do
      case "$line" in
        "ok   "*) passed=$((passed + 1)); echo "ok   [booted] ${line#ok   }" ;;
        "FAIL "*) failed=$((failed + 1)); echo "FAIL [booted] ${line#FAIL }" ;;
      esac
    done <"$results"
  fi
  check "[booted] every service check ran" grep -qx done "$results"
  [ "$failed" -eq "$failed_before" ] || tail -n 30 "$scratch/boot.log" | sed 's/^/       /'
else
  echo "SKIP the services booted with systemd (no systemd-nspawn: scripts/install_deps.sh)"
fi

if [ "$cross" = 1 ]; then
  check "throw-away root for arm64" make_root arm64
  r64=$scratch/arm64/root
  check "dpkg --root installs lrfnet-tracker:arm64 (Depends met by the arm64 multiarch packages)" \
    dpkg --root="$r64" -i "$tracker_arm64"
  check "installed: lrfnet-tracker:arm64" bash -c \
    "dpkg --root=$r64 -s lrfnet-tracker:arm64 | grep -qx 'Status: install ok installed'"
  cp "$r/tmp/sim/s1.pcap" "$r64/tmp/s1.pcap"
  check "installed arm64 lrfnet-tracker replays the capture under qemu-aarch64" bash -c \
    "chroot $r64 qemu-aarch64 /usr/bin/lrfnet-tracker --replay /tmp/s1.pcap --sensor-id s1 \
       --out /tmp/s1.rec | tee $r64/tmp/arm64.summary | grep -q ' scans=300 '"
  # Same scans, tracks and datagrams on both architectures (the recordings differ in session id
  # and creation time only).
  counts() { grep -oE ' (scans|tracks_created|tracks_confirmed|datagrams|frames)=[0-9]+' "$1"; }
  check "arm64 and amd64 replays agree (scans, tracks, datagrams, frames)" \
    diff <(counts "$r/tmp/amd64.summary") <(counts "$r64/tmp/arm64.summary")
  check "the arm64 recording reads back with lrfnet dump" bash -c \
    "cp $r64/tmp/s1.rec $r/tmp/s1_arm64.rec &&
     chroot $r lrfnet dump /tmp/s1_arm64.rec --summary | grep -q '\"track_frame\":300'"
fi
finish
