#!/usr/bin/env bash
# Builds poise with -DPOISE_WITH_CAMERA=OFF where OpenCV and AprilTag cannot be found
# (CMAKE_DISABLE_FIND_PACKAGE_*) and checks the result:
#   - `poise` links no OpenCV or AprilTag library (ldd), and the number of shared libraries it
#     loads is printed beside that of the full build (when BUILD_DIR/bin/poise exists);
#   - the camera commands are gone (`poise camera`, `poise tags`), the estimators are there, and the
#     selective EKF still takes vision poses over DDS (`poise run --list`: selective_ekf, no
#     camera/sim_camera component).
# Tests are not built in that configuration (they need the camera).
#   tools/check_no_camera.sh [--configure-only] [OUT_DIR [FULL_BUILD_DIR]]   (default build-nocamera/ and build/)
# --configure-only stops after the configure step (seconds instead of ~5 min uncached: what
# tools/test.sh runs, to keep the whole CI run inside its time budget).
# CMAKE_CXX_COMPILER_LAUNCHER (e.g. ccache) is honoured.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
configure_only=0
if [[ "${1:-}" == "--configure-only" ]]; then
  configure_only=1
  shift
fi
out="${1:-$root/build-nocamera}"
full="${2:-$root/build}"
fail() { echo "check_no_camera: $*" >&2; exit 1; }
launcher=()
if [[ -n "${CMAKE_CXX_COMPILER_LAUNCHER:-}" ]]; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER="$CMAKE_CXX_COMPILER_LAUNCHER")
fi
start=$SECONDS
mkdir -p "$out"
cmake -S "$root" -B "$out" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPOISE_WITH_CAMERA=OFF -DPOISE_BUILD_TESTS=OFF \
  -DCMAKE_DISABLE_FIND_PACKAGE_OpenCV=ON -DCMAKE_DISABLE_FIND_PACKAGE_apriltag=ON --no-warn-unused-cli \
  "${launcher[@]}" >"$out/check_no_camera.configure.log" 2>&1 \
  || { tail -30 "$out/check_no_camera.configure.log" >&2; fail "poise does not configure with POISE_WITH_CAMERA=OFF and no OpenCV/AprilTag"; }
if [[ $configure_only == 1 ]]; then
  echo "check_no_camera: POISE_WITH_CAMERA=OFF configures without OpenCV/AprilTag ($((SECONDS - start)) s; build not checked: run without --configure-only)"
  exit 0
fi
cmake --build "$out" -j "$(nproc 2>/dev/null || echo 2)" >"$out/check_no_camera.build.log" 2>&1 \
  || { tail -40 "$out/check_no_camera.build.log" >&2; fail "poise does not build with POISE_WITH_CAMERA=OFF (see $out/check_no_camera.build.log)"; }
poise="$out/bin/poise"
if hits=$(ldd "$poise" | grep -E 'libopencv|libapriltag'); then
  fail "poise built with POISE_WITH_CAMERA=OFF still links:"$'\n'"$hits"
fi
list="$("$poise" run --list)" || fail "poise run --list failed"
grep -q '^selective_ekf ' <<<"$list" || fail "the selective EKF component is missing"
grep -q '^sim_imu ' <<<"$list" || fail "the simulated IMU component is missing"
if grep -qE '^(camera|sim_camera) ' <<<"$list"; then fail "a camera component is still registered"; fi
for cmd in camera tags; do
  said="$("$poise" "$cmd" 2>&1 || true)"
  grep -q "unknown subcommand '$cmd'" <<<"$said" || fail "poise $cmd still exists"
done
n_off=$(ldd "$poise" | wc -l)
msg="check_no_camera: POISE_WITH_CAMERA=OFF builds in $((SECONDS - start)) s; poise loads $n_off shared libraries (ldd), no OpenCV/AprilTag"
if [[ -x "$full/bin/poise" ]]; then
  msg+="; the full build's poise: $(ldd "$full/bin/poise" | wc -l)"
fi
echo "$msg"
