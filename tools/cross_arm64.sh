#!/usr/bin/env bash
# Cross-builds the estimator cores and their unit tests for arm64 with Debian's cross toolchain and
# runs the tests under qemu-user-static (tests/cores_only.cmake lists them):
#   tools/cross_arm64.sh [BUILD_DIR]      (default build-arm64/; prints the build and test times)
# Installs what is missing (root or sudo): the arm64 architecture (dpkg --add-architecture arm64),
# crossbuild-essential-arm64, qemu-user-static (Eigen is header-only: libeigen3-dev). The arm64
# libraries (libyaml-cpp-dev, libyaml-cpp0.7, libgtest-dev, libgmock-dev) are fetched with
# apt-get download and unpacked into BUILD_DIR/sysroot (cmake/toolchain-arm64.cmake), never
# installed system-wide. The build uses every core; on a shared machine run the
# script under the build lock (flock /tmp/poise-build.lock tools/cross_arm64.sh).
# CMAKE_CXX_COMPILER_LAUNCHER (e.g. ccache) is honoured.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/build-arm64}"
fail() { echo "cross_arm64: $*" >&2; exit 1; }

sudo_cmd=()
[[ "$(id -u)" -eq 0 ]] || sudo_cmd=(sudo)
if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  "${sudo_cmd[@]}" dpkg --add-architecture arm64
  "${sudo_cmd[@]}" apt-get update -qq
fi
# Host tools only (amd64 packages; Eigen is header-only).
missing=()
for p in crossbuild-essential-arm64 qemu-user-static libeigen3-dev cmake ninja-build file; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [[ ${#missing[@]} -gt 0 ]]; then
  echo "cross_arm64: installing ${missing[*]}" >&2
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null \
    || fail "cannot install ${missing[*]}"
fi
# The arm64 libraries go into a sysroot under the build dir, never into the system: installing
# libyaml-cpp-dev:arm64 with apt would remove the amd64 libyaml-cpp-dev (not Multi-Arch: same).
mkdir -p "$out"
sysroot="$out/sysroot"
arm64_packages=(libyaml-cpp-dev:arm64 libyaml-cpp0.7:arm64 libgtest-dev:arm64 libgmock-dev:arm64)
if [[ ! -f "$sysroot/.complete" ]]; then
  rm -rf "$sysroot" "$out/debs"
  mkdir -p "$sysroot" "$out/debs"
  (cd "$out/debs" && apt-get download "${arm64_packages[@]}" >/dev/null) \
    || fail "cannot download ${arm64_packages[*]} (apt-get download; run apt-get update after adding arm64)"
  for deb in "$out"/debs/*.deb; do
    dpkg-deb -x "$deb" "$sysroot"
  done
  touch "$sysroot/.complete"
fi

launcher=()
if [[ -n "${CMAKE_CXX_COMPILER_LAUNCHER:-}" ]]; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER="$CMAKE_CXX_COMPILER_LAUNCHER" -DCMAKE_C_COMPILER_LAUNCHER="$CMAKE_CXX_COMPILER_LAUNCHER")
fi
start=$SECONDS
cmake -S "$root" -B "$out" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPOISE_CORES_ONLY=ON -DPOISE_CORES_TESTS=ON \
  -DCMAKE_TOOLCHAIN_FILE="$root/cmake/toolchain-arm64.cmake" -DPOISE_ARM64_SYSROOT="$sysroot" \
  "${launcher[@]}" >"$out/cross_arm64.configure.log" 2>&1 \
  || { cat "$out/cross_arm64.configure.log" >&2; fail "the arm64 configure failed"; }
grep -q "^yaml-cpp_DIR:PATH=$sysroot/" "$out/CMakeCache.txt" || fail "yaml-cpp was not taken from the arm64 sysroot"
cmake --build "$out" -j "$(nproc 2>/dev/null || echo 2)" >"$out/cross_arm64.build.log" 2>&1 \
  || { tail -40 "$out/cross_arm64.build.log" >&2; fail "the arm64 build failed"; }
built=$((SECONDS - start))
arch="$(file -b "$out/poise_core_attitude_test" 2>/dev/null || readelf -h "$out/poise_core_attitude_test" | grep Machine)"
grep -qiE 'aarch64|ARM aarch64|AArch64' <<<"$arch" || fail "the test executables are not arm64: $arch"
echo "cross_arm64: cores and tests built for arm64 in ${built} s ($arch)"
start=$SECONDS
ctest --test-dir "$out" --output-on-failure --no-tests=error -j "$(nproc 2>/dev/null || echo 2)" \
  || fail "arm64 core tests failed under qemu (ctest --test-dir $out)"
echo "cross_arm64: $(ctest --test-dir "$out" -N | grep -c 'Test *#') core tests passed on arm64 under qemu-user in $((SECONDS - start)) s"
