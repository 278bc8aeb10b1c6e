#!/usr/bin/env bash
# The main job on the embedded default (no hardware): installs what is missing, builds, runs
# `poise demo`. Extra arguments go to `poise demo` (e.g. --duration 30).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/tools/setup.sh"
exec "$root/build/bin/poise" demo "$@"
