#!/usr/bin/env bash
# Shows that the cores install and are usable by find_package from the installed prefix alone:
#   1. the cores-only build (tools/check_cores.sh: -DPOISE_CORES_ONLY=ON where Fast DDS, OpenCV,
#      CLI11 and GoogleTest cannot be found) is installed into a temporary prefix;
#   2. examples/embed is configured with only that prefix on CMAKE_PREFIX_PATH, built and run,
#      and its "ok" line is required; pkg-config must read the installed poise-cores.pc.
#   tools/test_install.sh [WORK_DIR [CORES_BUILD_DIR]]
#   (defaults: a new temporary directory, removed afterwards; the cores built there by check_cores.sh)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
work="${1:-}"
if [[ -z "$work" ]]; then
  work="$(mktemp -d)"
  trap 'rm -rf "$work"' EXIT
fi
cores="${2:-$work/build}"
mkdir -p "$work"
fail() { echo "test_install: $*" >&2; exit 1; }
launcher=()
if [[ -n "${CMAKE_CXX_COMPILER_LAUNCHER:-}" ]]; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER="$CMAKE_CXX_COMPILER_LAUNCHER")
fi
if [[ ! -f "$cores/build.ninja" ]]; then
  "$root/tools/check_cores.sh" "$cores" || fail "the cores-only build failed"
fi
rm -rf "$work/prefix" "$work/embed"
cmake --install "$cores" --prefix "$work/prefix" >"$work/install.log" 2>&1 \
  || { cat "$work/install.log" >&2; fail "cmake --install failed"; }
[[ -f "$work/prefix/lib/cmake/poise/poiseConfig.cmake" ]] || fail "no poiseConfig.cmake installed"
[[ -f "$work/prefix/lib/pkgconfig/poise-cores.pc" ]] || fail "no poise-cores.pc installed"
# the example sees the installed prefix and nothing of the source or build tree
cmake -S "$root/examples/embed" -B "$work/embed" -G Ninja -DCMAKE_PREFIX_PATH="$work/prefix" \
  -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF "${launcher[@]}" >"$work/embed.log" 2>&1 \
  || { cat "$work/embed.log" >&2; fail "examples/embed does not configure against the installed prefix"; }
grep -q "^poise_DIR:PATH=$work/prefix/" "$work/embed/CMakeCache.txt" \
  || fail "examples/embed found poise somewhere other than $work/prefix"
cmake --build "$work/embed" >>"$work/embed.log" 2>&1 \
  || { tail -40 "$work/embed.log" >&2; fail "examples/embed does not build against the installed prefix"; }
out="$("$work/embed/poise_embed")" || { echo "$out" >&2; fail "examples/embed failed"; }
echo "$out"
grep -q '^ok ' <<<"$out" || fail "examples/embed did not print ok"
PKG_CONFIG_PATH="$work/prefix/lib/pkgconfig" pkg-config --libs --cflags poise-cores >/dev/null \
  || fail "pkg-config cannot read poise-cores.pc"
echo "test_install: cores built without Fast DDS/OpenCV, installed, used by find_package from $work/prefix"
