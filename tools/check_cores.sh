#!/usr/bin/env bash
# Builds the estimator cores alone (-DPOISE_CORES_ONLY=ON with Fast DDS, Fast CDR, OpenCV, CLI11,
# GoogleTest and nlohmann-json made unfindable: only Eigen and yaml-cpp found) and fails if
# any core reaches Fast DDS, OpenCV or a clock:
#   - every core is linked into one program (a call into anything else fails to link);
#   - no core translation unit includes a Fast DDS, Fast CDR or OpenCV header (ninja's header deps);
#   - no core object references a clock (clock_gettime, gettimeofday, time, std::chrono clocks).
#   tools/check_cores.sh [BUILD_DIR]   (default build-cores/; CMAKE_CXX_COMPILER_LAUNCHER is honoured)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/build-cores}"
fail() { echo "check_cores: $*" >&2; exit 1; }
no_find=()
for pkg in fastrtps fastcdr OpenCV CLI11 GTest nlohmann_json; do
  no_find+=(-DCMAKE_DISABLE_FIND_PACKAGE_"$pkg"=ON)
done
cmake -S "$root" -B "$out" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPOISE_CORES_ONLY=ON --no-warn-unused-cli "${no_find[@]}" >/dev/null \
  || fail "the cores do not configure with only Eigen and yaml-cpp"
cmake --build "$out" -j "$(nproc 2>/dev/null || echo 2)" >/dev/null \
  || fail "the cores do not build and link alone (see: cmake --build $out)"
if hits=$(ninja -C "$out" -t deps | grep -E '/(fastdds|fastrtps|fastcdr|opencv4?)/'); then
  fail "a core includes a middleware or OpenCV header:"$'\n'"$hits"
fi
clock_re='clock_gettime|gettimeofday|(steady|system|high_resolution)_clock::now|^ +U time$'
if hits=$(find "$out" -name '*.a' -print0 | xargs -0 nm -C --undefined-only 2>/dev/null | grep -E "$clock_re"); then
  fail "a core reads a clock:"$'\n'"$hits"
fi
echo "check_cores: $(find "$out" -name 'libpoise_*.a' | wc -l) core libraries build alone; no Fast DDS, OpenCV or clock"
