#!/usr/bin/env bash
# The service walk-through under a real systemd (docs/DEPLOY.md "The sandbox and the watchdog,
# tested"): the shipped unit poise@.service, with every sandboxing option it has, run by a private
# systemd (tools/service_sandbox.sh: PID 1 of its own namespaces, /etc and /usr as overlays):
#   1. the unit's exposure (`systemd-analyze security --offline`) is "OK" or better (<= 4.9), and
#      `systemd-analyze verify` has nothing to say;
#   2. the shipped robot.yaml copied to /etc/poise/sbx.yaml (its port the pty of a simulated IMU
#      component placed in front, plus the synthetic camera and the selective EKF, and a
#      `realtime:` section) starts: READY=1 comes, as the user poise, with no capabilities, no new
#      privileges, a seccomp filter and a read-only /;
#   3. the sandboxed process opened a pty, runs SCHED_FIFO with its memory locked, made its
#      shared-memory segments, and publishes: `poise echo`, outside the sandbox, receives its
#      attitude, pose and altitude estimates as the service's user (shared memory and UDP) and
#      its attitude as another user (nobody, UDP);
#   4. the watchdog is fed while every component produces: after more than WatchdogSec it is
#      still running, never restarted;
#   5. when the simulated IMU's scenario ends, nothing produces any more: no WATCHDOG=1 comes,
#      systemd kills it (watchdog timeout) and restarts it.
#   tools/test_service.sh [--installed] [BUILD_DIR [WORK_DIR]]
# Default: BUILD_DIR's runtime component is installed into the sandbox's /usr (`cmake --install
# --component runtime --prefix /usr`, into the overlay) and packaging/postinst run there (the
# user poise, /etc/poise), as the package would. --installed: the unit and /usr/bin/poise of the
# installed package (tools/test_deb.sh, after dpkg -i). POISE_TEST_DOMAIN: the DDS domain (default:
# a free one of the test domains 100-232, locked as the C++ tests' DomainLease does).
# Needs root, util-linux (unshare, nsenter, setpriv, chrt) and systemd; exit 77 when this machine
# cannot run it (the reason on stderr), or 1 under CI=true / POISE_REQUIRE_ALL=1.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
installed=0
if [[ "${1:-}" == --installed ]]; then
  installed=1
  shift
fi
build="$(cd "${1:-$root/build}" && pwd)"
source "$root/tools/test_lib.sh"
make_work_dir "${2:-}"
domain="${POISE_TEST_DOMAIN:-}"
if [[ -z "$domain" ]]; then  # a free test domain, held as poise::testing::DomainLease holds one
  locks="${TMPDIR:-/tmp}/poise-test-domains"
  mkdir -p "$locks"
  for d in $(seq 100 232); do
    exec 9>"$locks/$d.lock"
    if flock -n 9; then domain=$d; break; fi
  done
  [[ -n "$domain" ]] || { echo "test_service: every test domain is in use" >&2; exit 1; }
fi
sim_s=20        # the simulated IMU's scenario length: the components stop producing then
watchdog_s=10   # the unit's WatchdogSec= (checked below)
sbx="$root/tools/service_sandbox.sh"
state="$work/sandbox"
unit_name=poise@sbx.service
booted=0
cleanup() {
  if [[ $booted -eq 1 ]]; then
    "$sbx" exec "$state" systemctl stop "$unit_name" >/dev/null 2>&1 || true
    "$sbx" halt "$state" || true
  fi
  if [[ $temporary -eq 1 ]]; then rm -rf "$work"; fi
}
trap cleanup EXIT
fail() {
  echo "test_service: FAILED: $*" >&2
  if [[ $booted -eq 1 ]]; then
    echo "--- the service's output (/run/poise-sbx.log in the sandbox):" >&2
    "$sbx" exec "$state" tail -40 /run/poise-sbx.log >&2 || true
  fi
  exit 1
}
skip() { skip_or_fail test_service 77 "$*"; }
[[ "$(id -u)" -eq 0 ]] || skip "needs root (a private systemd in new namespaces)"
for tool in systemd-analyze unshare nsenter setpriv chrt; do
  command -v "$tool" >/dev/null 2>&1 || skip "$tool is missing (Debian systemd, util-linux)"
done
if [[ $installed -eq 1 ]]; then
  poise=/usr/bin/poise
else
  poise="$build/bin/poise"
  [[ -x "$poise" && -f "$build/cmake_install.cmake" ]] || fail "$build is not a built full build"
fi
[[ -x "$poise" ]] || fail "$poise does not exist"

start=$SECONDS
boot_err="$work/boot.err"
rc=0
case "$build" in  # the sandbox has empty /tmp and /var/tmp: keep the build tree visible
  /tmp/* | /var/tmp/*) export SANDBOX_KEEP="$build" ;;
esac
"$sbx" boot "$state" >/dev/null 2>"$boot_err" || rc=$?
if [[ $rc -eq 77 ]]; then skip "$(tail -1 "$boot_err")"; fi
[[ $rc -eq 0 ]] || { cat "$boot_err" >&2; fail "the private systemd did not boot"; }
booted=1
in_sbx() { "$sbx" exec "$state" "$@"; }
echo "test_service: private systemd up in $((SECONDS - start)) s"

if [[ $installed -eq 0 ]]; then  # what the package does, into the sandbox's own /usr and /etc
  in_sbx cmake --install "$build" --component runtime --prefix /usr >"$work/install.log" 2>&1 \
    || { cat "$work/install.log" >&2; fail "cmake --install --component runtime --prefix /usr failed"; }
  in_sbx sh "$root/packaging/postinst" configure || fail "packaging/postinst configure failed"
fi
unit=/usr/lib/systemd/system/poise@.service
in_sbx test -f "$unit" || fail "$unit is not installed"
units=/run/poise-sandbox/units  # the only place the sandbox's manager loads units from
in_sbx cp "$unit" "$units/"

# 1. the exposure score, and a unit this systemd reads without a word
security="$(in_sbx systemd-analyze security --offline=true --threshold=49 "$unit" 2>&1)" \
  || { grep -v '✓' <<<"$security" >&2; fail "the unit's exposure is above 4.9 (OK)"; }
score="$(grep -o 'Overall exposure level.*' <<<"$security" | sed 's/ *[^ -~]*$//')"
echo "test_service: $score"
verify="$(in_sbx systemd-analyze verify "$unit_name" 2>&1)" || { echo "$verify" >&2; fail "systemd-analyze verify failed"; }
[[ -z "$verify" ]] || { echo "$verify" >&2; fail "systemd-analyze verify warned"; }

# 2. the host file in /etc/poise: the shipped robot.yaml, its port the simulated IMU's pty
in_sbx sh -c "sed -e 's|port: /dev/ttyACM0|port: /tmp/poise-sim-imu|' \
  -e 's|^components:|realtime: {priority: 10, lock_memory: true}\ncomponents:\n  - {type: sim_imu, params: {link: /tmp/poise-sim-imu, scenario: tour, rate_hz: 100, duration_s: $sim_s}}\n  - {type: sim_camera, name: camera0, params: {fps: 10}}\n  - {type: selective_ekf, params: {q_body_camera: [0, 1, 0, 0]}}|' \
  /usr/share/poise/hosts/robot.yaml >/etc/poise/sbx.yaml" || fail "cannot write /etc/poise/sbx.yaml"
in_sbx grep -q 'config_file: ../drivers/imu.yaml' /etc/poise/sbx.yaml || fail "the host file lost its ../drivers path"
# the test's domain, and a log file (the sandbox runs no journald)
dropin="[Service]\nEnvironment=POISE_DOMAIN=$domain\nStandardOutput=append:/run/poise-sbx.log\nStandardError=append:/run/poise-sbx.log\n"
# LimitRTPRIO=/LimitMEMLOCK= raise hard limits, which needs CAP_SYS_RESOURCE in the manager. A
# container without it (e.g. this development machine) cannot: the service then gets
# CAP_SYS_NICE and CAP_IPC_LOCK instead, which let SCHED_FIFO and mlockall through whatever the
# limits, so what is checked is that the rest of the sandbox (seccomp filter, no RestrictRealtime,
# NoNewPrivileges) leaves them working.
expected_caps=0000000000000000
manager_caps="$(awk '$1 == "CapEff:" {print $2}' "/proc/$(cat "$state/pid")/status")"
if (( (16#$manager_caps & (1 << 24)) == 0 )); then
  echo "test_service: the manager has no CAP_SYS_RESOURCE (CapEff $manager_caps): LimitRTPRIO/LimitMEMLOCK cannot be raised here; the service gets CAP_SYS_NICE CAP_IPC_LOCK instead"
  dropin="${dropin}AmbientCapabilities=CAP_SYS_NICE CAP_IPC_LOCK\nCapabilityBoundingSet=CAP_SYS_NICE CAP_IPC_LOCK\n"
  expected_caps=0000000000804000
fi
in_sbx sh -c "mkdir -p $units/$unit_name.d && printf '$dropin' >$units/$unit_name.d/test.conf"
in_sbx systemctl daemon-reload
t0=$SECONDS
in_sbx systemctl start "$unit_name" || fail "$unit_name did not start (no READY=1 within TimeoutStartSec)"
echo "test_service: $unit_name ready (READY=1) after $((SECONDS - t0)) s: $(in_sbx systemctl show "$unit_name" -p StatusText --value)"
show() { in_sbx systemctl show "$unit_name" -p "$1" --value; }
pid="$(show MainPID)"
[[ "$pid" -gt 0 ]] || fail "no main process"
[[ "$(show WatchdogUSec)" == "${watchdog_s}s" ]] || fail "the unit's WatchdogSec= is $(show WatchdogUSec), not ${watchdog_s} s"

# 2b. the sandbox is in force
status="$(in_sbx cat "/proc/$pid/status")"
field() { awk -v k="$1:" '$1 == k {print $2}' <<<"$status"; }
[[ "$(field Uid)" == "$(in_sbx id -u poise)" ]] || fail "not running as the user poise"
[[ "$(field NoNewPrivs)" == 1 ]] || fail "NoNewPrivs is not set"
[[ "$(field Seccomp)" == 2 ]] || fail "no seccomp filter"
[[ "$(field CapBnd)" == "$expected_caps" && "$(field CapEff)" == "$expected_caps" ]] \
  || fail "capabilities: bounding $(field CapBnd), effective $(field CapEff) instead of $expected_caps"
in_sbx awk '$5 == "/" && $6 ~ /(^|,)ro(,|$)/ {found = 1} END {exit !found}' "/proc/$pid/mountinfo" || fail "/ is not read-only for the service"
in_sbx awk '$5 == "/etc" && $6 ~ /(^|,)ro(,|$)/ {found = 1} END {exit !found}' "/proc/$pid/mountinfo" || fail "/etc is not read-only for the service"
echo "test_service: sandbox in force: uid poise, NoNewPrivs 1, Seccomp 2, capabilities $expected_caps, / and /etc read-only"

# 3. a pty, real time, and what it publishes, seen from outside as another user
ptys="$(in_sbx ls -l "/proc/$pid/fd" | grep -c -E '/dev/(ptmx|pts/)' || true)"
[[ "$ptys" -ge 2 ]] || fail "the sandboxed process has no pty open (sim_imu's master, the driver's side)"
policy="$(in_sbx chrt -p "$pid")"
grep -q 'SCHED_FIFO' <<<"$policy" && grep -q 'priority: 10' <<<"$policy" \
  || fail "not SCHED_FIFO priority 10 in the sandbox: $policy"
locked_kb="$(field VmLck)"
[[ "${locked_kb:-0}" -gt 0 ]] || fail "no memory locked (lock_memory: true)"
echo "test_service: ptys open $ptys, $(tr '\n' ' ' <<<"$policy"), VmLck $locked_kb kB"
# Fast DDS's shared-memory segments are writable by their owner only, so over SHM a process talks
# to processes of its own user: a subscriber as the service's user (uid, outside the sandbox, the
# default profile: shared memory and UDP) and one as another user (nobody) on UDP alone
# (POISE_DDS_PROFILE=poise_udp; docs/DEPLOY.md "Clients on the same host").
service_uid="$(field Uid)"
shm_files="$(find /dev/shm -maxdepth 1 -name 'fastrtps_*' -uid "$service_uid" | wc -l)"
[[ "$shm_files" -ge 1 ]] || fail "the sandboxed process made no shared-memory segment in /dev/shm"
echo "test_service: the sandboxed process's shared-memory segments in /dev/shm: $shm_files"
subscribe() {  # UID GID PROFILE TOPIC: 3 samples of TOPIC, or fail
  local who="$1" group="$2" profile="$3" topic="$4" got n
  got="$(setpriv --reuid="$who" --regid="$group" --clear-groups env POISE_DOMAIN="$domain" POISE_DDS_PROFILE="$profile" \
           HOME=/nonexistent "$poise" echo "$topic" --count 3 --timeout 20 --json 2>&1)" \
    || { echo "$got" >&2; fail "nothing on $topic for uid $who ($profile)"; }
  n="$(grep -c '^{' <<<"$got" || true)"
  [[ "$n" -eq 3 ]] || { echo "$got" >&2; fail "$n samples of $topic instead of 3 (uid $who, $profile)"; }
}
for topic in attitude/parallel_kf pose/selective_ekf altitude; do
  subscribe "$service_uid" "$(field Gid)" poise_default "$topic"
done
echo "test_service: poise echo (outside the sandbox, uid $service_uid = poise, shared memory + UDP): 3 samples each of attitude/parallel_kf, pose/selective_ekf, altitude"
subscribe "$(id -u nobody)" "$(id -g nobody)" poise_udp attitude/parallel_kf
echo "test_service: poise echo (outside the sandbox, user nobody, UDP): 3 samples of attitude/parallel_kf"

# 4. fed while every component produces: beyond WatchdogSec, still the first run
while [[ $((SECONDS - t0)) -lt $((watchdog_s + 4)) ]]; do sleep 1; done
[[ "$(show ActiveState)" == active && "$(show NRestarts)" == 0 ]] \
  || fail "not running $((SECONDS - t0)) s after the start (WatchdogSec=$watchdog_s): $(show ActiveState), restarts $(show NRestarts)"
fed1="$(show WatchdogTimestampMonotonic)"
sleep 6
fed2="$(show WatchdogTimestampMonotonic)"
[[ "$fed2" -gt "$fed1" ]] || fail "no WATCHDOG=1 in 6 s although every component produces"
echo "test_service: $((SECONDS - t0)) s after the start still the first run, watchdog fed (last at $fed1 then $fed2 us)"

# 5. the simulated IMU's scenario ends: nothing produces, no WATCHDOG=1, systemd restarts it
deadline=$((t0 + sim_s + 2 * watchdog_s + 20))
while [[ "$(show NRestarts)" == 0 && $SECONDS -lt $deadline ]]; do sleep 1; done
[[ "$(show NRestarts)" -ge 1 ]] || fail "not restarted by the watchdog $((SECONDS - t0)) s after the start (scenario over at $sim_s s)"
in_sbx grep -q 'poise: watchdog: .* produced nothing' /run/poise-sbx.log || fail "the service did not say which component stopped"
echo "test_service: restarted $((SECONDS - t0)) s after the start (scenario over at $sim_s s, WatchdogSec=$watchdog_s): $(in_sbx grep -m1 'poise: watchdog:' /run/poise-sbx.log | cut -c1-160)"
in_sbx systemctl stop "$unit_name"
echo "test_service: passed in $((SECONDS - start)) s"
