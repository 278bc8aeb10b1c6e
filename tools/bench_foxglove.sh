#!/usr/bin/env bash
# The foxglove_bridge's cost (docs/FOXGLOVE.md "Cost"): a 1 kHz simulated IMU and three filters
# (parallel KF, selective EKF, Gauss-Newton) in one process (`poise run`), the bridge alone in a
# second process (`poise foxglove`), one client subscribed to every channel (the test client,
# tests/foxglove/client/client.mjs, over @foxglove/ws-protocol). Prints the bridge process's CPU
# (utime + stime from /proc/PID/stat) as % of one core over DURATION seconds, and the host's.
#
#   tools/bench_foxglove.sh [DURATION_S]      (default 30; build in ./build or $BUILD)
# Needs node + npm (the client's packages are installed into the build tree on first use).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${BUILD:-$root/build}"
duration="${1:-30}"
poise="$build/bin/poise"
client="$build/tests/foxglove/client"
domain="${POISE_BENCH_DOMAIN:-217}"
port="${POISE_BENCH_PORT:-18765}"
[ -x "$poise" ] || { echo "bench_foxglove: $poise not built" >&2; exit 1; }
[ -f "$client/client.mjs" ] || { echo "bench_foxglove: $client not configured (build with tests)" >&2; exit 1; }
if [ ! -f "$client/node_modules/@foxglove/ws-protocol/package.json" ]; then
  npm install --prefix "$client" --no-audit --no-fund --loglevel=error >/dev/null
fi
tmp="$(mktemp -d)"
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$tmp"; }
trap cleanup EXIT
cat > "$tmp/host.yaml" <<YAML
components:
  - type: sim_imu
    params: {link: $tmp/imu, scenario: tour, rate_hz: 1000}
  - type: imu_driver
    name: imu0
    params: {port: $tmp/imu}
  - type: parallel_kf
  - type: selective_ekf
  - type: gauss_newton
YAML
export POISE_DDS_PROFILE=poise_loopback
"$poise" run "$tmp/host.yaml" --domain "$domain" --quiet & host=$!; pids+=("$host")
"$poise" foxglove --domain "$domain" --set port="$port" --set address=127.0.0.1 --quiet 2>"$tmp/bridge.log" &
bridge=$!; pids+=("$bridge")
sleep 3
node "$client/client.mjs" bench "ws://127.0.0.1:$port" "$((duration + 4))" > "$tmp/client.log" & pids+=("$!")
sleep 2
ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }
hz="$(getconf CLK_TCK)"
b0="$(ticks "$bridge")"; h0="$(ticks "$host")"; t0="$(date +%s.%N)"
sleep "$duration"
b1="$(ticks "$bridge")"; h1="$(ticks "$host")"; t1="$(date +%s.%N)"
wait "${pids[2]}" || true
awk -v b="$((b1 - b0))" -v h="$((h1 - h0))" -v hz="$hz" -v t0="$t0" -v t1="$t1" 'BEGIN {
  s = t1 - t0;
  printf "foxglove_bridge (poise foxglove): %.1f %% of one core over %.0f s\n", 100 * b / hz / s, s;
  printf "host (1 kHz sim IMU + driver + parallel_kf + selective_ekf + gauss_newton): %.1f %% of one core\n", 100 * h / hz / s;
}'
cat "$tmp/client.log"
