#!/usr/bin/env bash
# The whole test suite: installs what is missing, builds (Release), runs ctest.
#   tools/test.sh [extra ctest arguments, e.g. -R Parallel]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/tools/setup.sh"
cd "$root"
exec ctest --test-dir build --output-on-failure --no-tests=error -j "$(nproc 2>/dev/null || echo 2)" "$@"
