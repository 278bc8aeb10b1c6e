#!/usr/bin/env bash
# Builds the Debian packages of a configured and built full build (cpack -G DEB: poise, poise-dev
# and poise-dds-dev), installs them on this machine with dpkg -i, and checks them from the installed
# places only:
#   - /usr/bin/poise --version and /usr/bin/poise run --list run;
#   - the shipped host/filter/QoS files are under /usr/share/poise;
#   - poise@.service verifies with systemd-analyze verify (no warning at all) and is Type=notify
#     when poise was built with libsystemd; the system user poise exists;
#   - the Depends fields were computed (dpkg-shlibdeps: libfastrtps, libyaml-cpp, ...);
#   - examples/embed configures, builds and runs against /usr alone: the cores (poise-dev) and
#     poise::dds (poise-dds-dev: a participant on loopback, an IMU sample round trip);
#   - the installed unit runs the shipped robot.yaml from /etc/poise under a real (private)
#     systemd with its sandbox, as the user poise: exposure OK, READY=1, a pty, SCHED_FIFO,
#     estimates published, the watchdog fed and restarting it when components stop
#     (tools/test_service.sh --installed).
# Then purges both packages (and checks the user and files are gone), leaving the machine as it was.
# Needs root, cpack, dpkg-shlibdeps (dpkg-dev) and systemd-analyze (systemd); without them it
# skips, or fails under CI=true / POISE_REQUIRE_ALL=1.
#   tools/test_deb.sh [BUILD_DIR [WORK_DIR]]   (default build/ and a temporary directory)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$(cd "${1:-$root/build}" && pwd)"
source "$root/tools/test_lib.sh"
make_work_dir "${2:-}"
installed=0
cleanup() {  # leaves the machine as it was: the packages purged, a temporary work dir removed
  if [[ $installed -eq 1 ]]; then
    dpkg --purge poise-dds-dev poise-dev poise >"$work/purge.log" 2>&1 || cat "$work/purge.log" >&2
  fi
  if [[ $temporary -eq 1 ]]; then rm -rf "$work"; fi
}
trap cleanup EXIT
fail() { echo "test_deb: FAILED: $*" >&2; exit 1; }
skip() { skip_or_fail test_deb 0 "$*"; }
[[ "$(id -u)" -eq 0 ]] || skip "dpkg -i needs root"
for tool in cpack dpkg-deb dpkg-shlibdeps systemd-analyze; do
  command -v "$tool" >/dev/null 2>&1 || skip "$tool is missing (tools/setup.sh installs dpkg-dev and systemd)"
done
[[ -f "$build/CPackConfig.cmake" && -x "$build/bin/poise" ]] \
  || fail "$build is not a built full build (tools/setup.sh)"
for p in poise poise-dev poise-dds-dev; do
  if dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q installed; then
    fail "package $p is already installed; remove it first (dpkg --purge $p): this test installs its own"
  fi
done

start=$SECONDS
rm -rf "$work/pkg"
cpack --config "$build/CPackConfig.cmake" -B "$work/pkg" >"$work/cpack.log" 2>&1 \
  || { tail -40 "$work/cpack.log" >&2; fail "cpack -G DEB failed"; }
shopt -s nullglob
runtime_deb=("$work"/pkg/poise_*.deb)
dev_deb=("$work"/pkg/poise-dev_*.deb)
dds_deb=("$work"/pkg/poise-dds-dev_*.deb)
[[ ${#runtime_deb[@]} -eq 1 && ${#dev_deb[@]} -eq 1 && ${#dds_deb[@]} -eq 1 ]] \
  || { ls "$work/pkg" >&2; fail "expected poise_*.deb, poise-dev_*.deb and poise-dds-dev_*.deb"; }
echo "test_deb: cpack took $((SECONDS - start)) s"
for deb in "${runtime_deb[0]}" "${dev_deb[0]}" "${dds_deb[0]}"; do
  echo "test_deb: $(basename "$deb"): $(du -k "$deb" | cut -f1) KiB, installed $(dpkg-deb -f "$deb" Installed-Size) KiB"
done
depends="$(dpkg-deb -f "${runtime_deb[0]}" Depends)"
echo "test_deb: poise Depends: $depends"
for lib in libfastrtps libfastcdr libyaml-cpp libc6 libstdc++6; do
  grep -q "$lib" <<<"$depends" || fail "poise's Depends lacks $lib: dpkg-shlibdeps did not compute it"
done
with_systemd=0
if grep -q 'libsystemd' <<<"$depends"; then with_systemd=1; fi  # linked by sd_notify support
if [[ $with_systemd -eq 0 && ( "${CI:-}" == true || "${POISE_REQUIRE_ALL:-}" == 1 ) ]]; then
  fail "poise was built without libsystemd (no sd_notify; tools/setup.sh installs libsystemd-dev)"
fi

installed=1
dpkg -i "${runtime_deb[0]}" "${dev_deb[0]}" "${dds_deb[0]}" >"$work/install.log" 2>&1 \
  || { cat "$work/install.log" >&2; fail "dpkg -i failed"; }

version="$(/usr/bin/poise --version)" || fail "/usr/bin/poise --version failed"
[[ "$version" == "poise 0.1.0" ]] || fail "/usr/bin/poise --version printed '$version'"
list="$(/usr/bin/poise run --list)" || fail "/usr/bin/poise run --list failed"
grep -q '^parallel_kf ' <<<"$list" || fail "/usr/bin/poise run --list does not list parallel_kf"
for f in hosts/robot.yaml filters/parallel_kf.yaml qos/poise_profiles.xml drivers/imu.yaml; do
  [[ -f "/usr/share/poise/$f" ]] || fail "/usr/share/poise/$f is not installed"
done
unit=/usr/lib/systemd/system/poise@.service
[[ -f "$unit" ]] || fail "$unit is not installed"
grep -qx 'ExecStart=/usr/bin/poise run /etc/poise/%i.yaml' "$unit" || fail "$unit does not run /usr/bin/poise run /etc/poise/%i.yaml"
if [[ $with_systemd -eq 1 ]]; then
  grep -qx 'Type=notify' "$unit" || fail "$unit is not Type=notify although poise was built with libsystemd"
fi
verify="$(systemd-analyze verify poise@test.service 2>&1)" || { echo "$verify" >&2; fail "systemd-analyze verify poise@test.service failed"; }
[[ -z "$verify" ]] || { echo "$verify" >&2; fail "systemd-analyze verify poise@test.service warned"; }
getent passwd poise >/dev/null || fail "the postinst did not create the system user poise"
for f in /usr/share/poise/hosts/*.yaml; do  # the example hosts under /etc/poise, from the package
  cmp -s "$f" "/etc/poise/examples/$(basename "$f")" || fail "/etc/poise/examples/$(basename "$f") is not the shipped $f"
done

# poise-dev: the example sees /usr only (no build tree, no prefix path)
cmake -S "$root/examples/embed" -B "$work/embed" -G Ninja -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF \
  >"$work/embed.log" 2>&1 || { cat "$work/embed.log" >&2; fail "examples/embed does not configure against /usr"; }
grep -q '^poise_DIR:PATH=/usr/lib/' "$work/embed/CMakeCache.txt" || fail "examples/embed found poise outside /usr/lib"
cmake --build "$work/embed" >>"$work/embed.log" 2>&1 || { tail -40 "$work/embed.log" >&2; fail "examples/embed does not build against /usr"; }
"$work/embed/poise_embed" | grep -q '^ok ' || fail "examples/embed against /usr did not print ok"
[[ -x "$work/embed/poise_embed_dds" ]] || fail "examples/embed did not find poise::dds in /usr (poise-dds-dev)"
POISE_DDS_PROFILE=poise_loopback "$work/embed/poise_embed_dds" | grep -q '^ok dds' \
  || fail "examples/embed's DDS program against /usr did not print ok dds"
pkg-config --cflags --libs poise-cores | grep -q -- '-lpoise_core' || fail "pkg-config poise-cores does not work from /usr"

# the service as installed: the shipped robot.yaml in /etc/poise, run by the installed unit with
# its sandbox under a real (private) systemd, as the user poise; watchdog (tools/test_service.sh)
rc=0
"$root/tools/test_service.sh" --installed "$build" "$work/service" || rc=$?
if [[ $rc -eq 77 ]]; then
  echo "test_deb: the service walk-through cannot run here (see above); the rest passed" >&2
elif [[ $rc -ne 0 ]]; then
  fail "the service walk-through (tools/test_service.sh --installed) failed"
fi

installed=0
dpkg --purge poise-dds-dev poise-dev poise >"$work/purge.log" 2>&1 || { cat "$work/purge.log" >&2; fail "dpkg --purge failed"; }
[[ ! -e /usr/bin/poise && ! -e "$unit" && ! -e /usr/share/poise && ! -e /usr/include/poise && ! -e /usr/lib/cmake/poise && ! -e /etc/poise/examples ]] \
  || fail "files remain after dpkg --purge"
! getent passwd poise >/dev/null || fail "the system user poise remains after dpkg --purge"
echo "test_deb: poise, poise-dev and poise-dds-dev built, installed, checked from /usr and purged in $((SECONDS - start)) s"
