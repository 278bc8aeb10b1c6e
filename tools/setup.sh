#!/usr/bin/env bash
# Installs what poise needs on Debian 12 (only what is missing), then configures and builds it in
# Release. Idempotent and fast when everything is already there.
#
#   tools/setup.sh [--build-dir DIR] [--no-build] [--no-tests | --cores-only] [--no-camera] [--sanitize] [--jobs N]
#   --no-tests    no test-only packages (GoogleTest, Cyclone DDS, clang, Node.js, ...), no tests built
#   --cores-only  only the estimator cores (Eigen + yaml-cpp; -DPOISE_CORES_ONLY=ON; README "Installing")
#   --no-camera   no OpenCV/AprilTag (-DPOISE_WITH_CAMERA=OFF, implies --no-tests; docs/DEPLOY.md)
#
# Needs root (or sudo) only when packages are missing.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
build_dir="$root/build"
do_build=1
tests=ON
cores_only=OFF
camera=ON
sanitize=OFF
jobs="$(nproc 2>/dev/null || echo 2)"

while [ $# -gt 0 ]; do
  case "$1" in
    --build-dir) build_dir="$2"; shift 2 ;;
    --no-build) do_build=0; shift ;;
    --no-tests) tests=OFF; shift ;;
    --cores-only) cores_only=ON; tests=OFF; shift ;;
    --no-camera) camera=OFF; tests=OFF; shift ;;
    --sanitize) sanitize=ON; shift ;;
    --jobs) jobs="$2"; shift 2 ;;
    -h|--help) sed -n '2,12p' "$0"; exit 0 ;;
    *) echo "setup.sh: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done

# Debian 12 packages. Build: compiler, CMake, Ninja, Fast DDS + generator, Eigen, OpenCV,
# AprilTag, yaml-cpp, CLI11, HDF5, zstd, nlohmann-json (the one JSON writer), libsystemd (sd_notify
# for the poise@.service unit), websocketpp + standalone asio (header-only: the Foxglove WebSocket
# server, docs/FOXGLOVE.md). Tests: GoogleTest, Cyclone DDS (interop), iproute2
# (network namespaces), openssl (DDS Security), clang (fuzzing), Node.js + npm (MCAP validators,
# Foxglove clients),
# dpkg-dev (dpkg-shlibdeps for the Debian packages), systemd (systemd-analyze verify), and the
# GY-87 firmware's toolchain and emulator (tests/firmware, docs/FIRMWARE.md): arduino-mk with
# Debian's AVR core, gcc-avr, avr-libc, simavr + libsimavr-dev + libelf-dev; ccache (tools/test.sh
# compiles the cores twice: the second time is a cache hit).
packages=(build-essential cmake ninja-build pkg-config libeigen3-dev libyaml-cpp-dev)
if [ "$cores_only" = OFF ]; then
  packages+=(libfastrtps-dev libfastcdr-dev fastddsgen fastdds-tools
             libcli11-dev libhdf5-dev libzstd-dev nlohmann-json3-dev libsystemd-dev
             libwebsocketpp-dev libasio-dev)
  if [ "$camera" = ON ]; then
    packages+=(libopencv-dev libapriltag-dev)
  fi
fi
if [ "$tests" = ON ]; then
  packages+=(libgtest-dev libgmock-dev cyclonedds-dev cyclonedds-tools iproute2 iputils-ping openssl clang
             dpkg-dev systemd arduino-mk arduino-core-avr gcc-avr binutils-avr avr-libc simavr
             libsimavr-dev libelf-dev ccache)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
# Node.js/npm may come from Debian or be preinstalled elsewhere: check the commands.
if [ "$tests" = ON ]; then
  if ! command -v node >/dev/null 2>&1; then missing+=(nodejs); fi
  if ! command -v npm >/dev/null 2>&1; then missing+=(npm); fi
fi

if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${#missing[@]} missing package(s): ${missing[*]}" >&2
  sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null 2>&1 || { echo "setup: need root or sudo to install packages" >&2; exit 1; }
    sudo_cmd=(sudo)
  fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  echo "setup: packages installed" >&2
else
  echo "setup: all packages present" >&2
fi

[ "$do_build" -eq 1 ] || exit 0

generator=()
if [ ! -f "$build_dir/CMakeCache.txt" ]; then
  generator=(-G Ninja)
fi
cmake -S "$root" -B "$build_dir" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release \
  -DPOISE_SANITIZE="$sanitize" -DPOISE_BUILD_TESTS="$tests" -DPOISE_CORES_ONLY="$cores_only" \
  -DPOISE_WITH_CAMERA="$camera" >/dev/null
echo "setup: building in $build_dir ($jobs jobs)" >&2
cmake --build "$build_dir" -j "$jobs"
if [ "$cores_only" = ON ]; then
  echo "setup: done; the cores are built in $build_dir (cmake --install $build_dir --prefix PREFIX)" >&2
else
  echo "setup: done; the poise binary is $build_dir/bin/poise" >&2
fi
