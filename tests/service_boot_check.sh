#!/bin/sh
# Runs inside a booted throw-away root (systemd-nspawn, see tests/package_test.sh) where the amd64
# packages are installed and /etc/lrfnet/lrfnetd.yaml records to lrfnet.rec and writes
# calibration.yaml: the services as systemd runs them, in their sandbox. One line per check
# ("ok   NAME" / "FAIL NAME: detail") into the file $1, then the machine powers off.
out=${1:-/root/service_checks.txt}
: >"$out"
check() {  # check NAME COMMAND...
  name=$1
  shift
  if detail=$("$@" 2>&1); then
    echo "ok   $name" >>"$out"
  else
    echo "FAIL $name: $(echo "$detail" | tail -n 5 | tr '\n' ' ')" >>"$out"
  fi
}
prop() { systemctl show -P "$2" "$1"; }
wait_until() {  # wait_until SECONDS COMMAND...: until COMMAND succeeds
  limit=$1
  shift
  i=0
  while [ "$i" -lt $((limit * 5)) ]; do
    "$@" >/dev/null 2>&1 && return 0
    sleep 0.2
    i=$((i + 1))
  done
  "$@"
}
status_of() {  # status_of PID: the sandbox as the kernel sees it
  grep -E '^(Uid|CapEff|CapBnd|NoNewPrivs|Seccomp):' "/proc/$1/status" | tr -s '\t ' ' '
}
sandboxed() {  # sandboxed UNIT: runs as lrfnet, no capability, no new privileges, seccomp filter
  pid=$(prop "$1" MainPID)
  uid=$(id -u lrfnet)
  s=$(status_of "$pid")
  echo "$s"
  echo "$s" | grep -q "^Uid: $uid $uid $uid $uid" &&
    echo "$s" | grep -q '^CapEff: 0000000000000000' &&
    echo "$s" | grep -q '^CapBnd: 0000000000000000' &&
    echo "$s" | grep -q '^NoNewPrivs: 1' && echo "$s" | grep -q '^Seccomp: 2'
}
journal_has() { journalctl -q --no-pager -u "$1" | grep -q "$2"; }

# lrfnetd: enabled by the package, started at boot, ready (Type=notify) once its socket is bound.
check "lrfnetd.service started at boot and is active (READY=1)" wait_until 30 \
  sh -c '[ "$(systemctl is-active lrfnetd)" = active ]'
check "lrfnetd runs sandboxed as lrfnet" sandboxed lrfnetd.service
check "lrfnetd's watchdog is armed" sh -c '[ "$(systemctl show -P WatchdogUSec lrfnetd)" = 30s ]'

# A scanner (the emulator, an unprivileged transient service) and one tracker instance.
systemd-run --quiet --unit=scanner --property=DynamicUser=yes \
  /usr/bin/lrfnet emulate --synthetic tim561 --port 2112 --log-level warn
cat >/etc/lrfnet/tracker-gate-1.yaml <<'EOF'
sensor:
  address: "127.0.0.1:2112"
  uplink: "127.0.0.1:5800"
EOF
mkdir -p /etc/systemd/system/lrfnet-tracker@.service.d
# A short watchdog, so the hung-link check below takes seconds.
printf '[Service]\nWatchdogSec=3s\n' >/etc/systemd/system/lrfnet-tracker@.service.d/test.conf
systemctl daemon-reload
check "scanner emulator is up" wait_until 20 sh -c '[ "$(systemctl is-active scanner)" = active ]'
check "systemctl start lrfnet-tracker@gate-1 returns once the first scan arrived (READY=1)" \
  systemctl start lrfnet-tracker@gate-1
check "lrfnet-tracker@gate-1 is active" sh -c \
  '[ "$(systemctl is-active lrfnet-tracker@gate-1)" = active ]'
check "the tracker runs sandboxed as lrfnet" sandboxed lrfnet-tracker@gate-1.service
check "the tracker reads the kernel clock state in its sandbox (adjtimex allowed)" wait_until 10 \
  sh -c 'journalctl -q --no-pager -u lrfnet-tracker@gate-1 | grep "gateway clock: " |
         grep -qv "gateway clock: unknown"'
check "lrfnetd hears sensor gate-1" wait_until 20 journal_has lrfnetd "sensor gate-1: first datagram"
check "lrfnetd records into its state directory, as lrfnet" wait_until 20 sh -c \
  '[ -s /var/lib/lrfnet/lrfnet.rec ] && [ "$(stat -c %U /var/lib/lrfnet/lrfnet.rec)" = lrfnet ]'
check "systemctl reload lrfnetd rereads the config (SIGHUP)" sh -c \
  'systemctl reload lrfnetd && sleep 1 && journalctl -q --no-pager -u lrfnetd | grep -q "SIGHUP: config reloaded"'

# The scanner link hangs (the device process stopped, its TCP connection open): no scans, no
# WATCHDOG=1, so systemd kills the tracker and starts it again; it is back once the device is.
restarts=$(prop lrfnet-tracker@gate-1 NRestarts)
systemctl kill --signal=SIGSTOP scanner
check "a hung scanner link: the watchdog kills the tracker and systemd restarts it" wait_until 30 \
  sh -c "[ \"\$(systemctl show -P NRestarts lrfnet-tracker@gate-1)\" -gt $restarts ]"
check "the journal says why (watchdog timeout)" journal_has lrfnet-tracker@gate-1 "Watchdog timeout"
systemctl kill --signal=SIGCONT scanner
check "the tracker is active again once the scanner is back" wait_until 60 \
  sh -c '[ "$(systemctl is-active lrfnet-tracker@gate-1)" = active ]'
check "lrfnetd itself was never restarted" sh -c '[ "$(systemctl show -P NRestarts lrfnetd)" = 0 ]'
check "no unit failed" sh -c '[ -z "$(systemctl list-units --failed --plain --no-legend)" ]'

check "systemctl stop lrfnetd stops it cleanly (the recording closed)" sh -c \
  'systemctl stop lrfnetd && [ "$(systemctl show -P Result lrfnetd)" = success ] &&
   journalctl -q --no-pager -u lrfnetd | grep -q "summary: sensors=1"'
echo "done" >>"$out"
systemctl poweroff --no-block
