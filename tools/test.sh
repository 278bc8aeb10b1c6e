#!/usr/bin/env bash
# The whole test suite: installs what is missing, builds (Release), checks that the estimator
# cores build alone (tools/check_cores.sh), installs them and builds examples/embed against the
# installed prefix (tools/test_install.sh), builds, installs, checks and purges the Debian packages
# (tools/test_deb.sh; needs root; with the installed unit run under a private systemd,
# tools/test_service.sh), configures poise without OpenCV/AprilTag
# (tools/check_no_camera.sh --configure-only; without that flag the script builds it, ~5 min uncached),
# cross-builds the cores and their tests for arm64 and runs them
# under qemu (tools/cross_arm64.sh), runs ctest.
#   tools/test.sh [extra ctest arguments, e.g. -R Parallel]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/tools/setup.sh" --no-build  # packages first: ccache is one of them
# The cores are compiled twice with the same command (build/ and check_cores.sh's build-cores/):
# through ccache the second is a cache hit. A launcher the caller chose is kept.
if [[ -z "${CMAKE_CXX_COMPILER_LAUNCHER:-}" ]] && command -v ccache >/dev/null 2>&1; then
  export CMAKE_CXX_COMPILER_LAUNCHER=ccache CMAKE_C_COMPILER_LAUNCHER=ccache
fi
"$root/tools/setup.sh"
cd "$root"
"$root/tools/check_cores.sh" "$root/build-cores"  # the cores build without Fast DDS / OpenCV / clocks
"$root/tools/test_install.sh" "$root/build-install" "$root/build-cores"  # install + find_package(poise)
"$root/tools/test_deb.sh" "$root/build"  # cpack .debs, dpkg -i, /usr/bin/poise, systemd-analyze verify
"$root/tools/check_no_camera.sh" --configure-only "$root/build-nocamera" "$root/build"  # -DPOISE_WITH_CAMERA=OFF configures (the build: ~5 min uncached, run the script without --configure-only)
"$root/tools/cross_arm64.sh" "$root/build-arm64"  # arm64 cores + unit tests under qemu-user (~3 min)
exec ctest --test-dir build --output-on-failure --no-tests=error -j "$(nproc 2>/dev/null || echo 2)" "$@"
