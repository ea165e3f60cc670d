#!/usr/bin/env bash
# Measures fan-out on this machine: one radcast-server (2,500-patch Cornell box, lights changing
# once a second via --animate) and one load tester, both on loopback. Prints a Markdown table:
# viewers vs frame latency, server CPU and memory. Then the idle memory per viewer (a static
# scene, no updates). Usage: scripts/load-curve.sh [VIEWERS...]   (default: 100 1000 10000)
set -euo pipefail
cd "$(dirname "$0")/.."
counts=("${@:-100 1000 10000}")
[ $# -gt 0 ] || counts=(100 1000 10000)
cargo build --release -q -p radcast-server -p radcast-client
server=target/release/radcast-server
client=target/release/radcast-client
ulimit -n "$(ulimit -Hn)"

start_server() { # PORT ARGS...
  local port=$1; shift
  # Every viewer comes from 127.0.0.1: lift the per-address caps (defaults 1,000 / 1,100).
  "$server" --addr "127.0.0.1:$port" --patches 2500 --no-cache --token load-test \
    --max-viewers-per-ip 20000 --max-connections-per-ip 21000 "$@" >/dev/null 2>&1 &
  pid=$!
  for _ in $(seq 300); do curl -sf "http://127.0.0.1:$port/healthz" >/dev/null && return; sleep 0.1; done
  echo "server did not start" >&2; exit 1
}
cpu_ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }
rss_kib() { awk '/VmRSS/ {print $2}' "/proc/$1/status"; }
hwm_kib() { awk '/VmHWM/ {print $2}' "/proc/$1/status"; }
wait_final() { # PORT
  for _ in $(seq 600); do curl -sf "http://127.0.0.1:$1/api/solution" | grep -q '"is_final":true' && return; sleep 0.1; done
}

echo "| viewers | connected | failed | latency p50 ms | p90 ms | p99 ms | max ms | frames/viewer | server CPU % | tester CPU % | server peak RSS MiB |"
echo "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
hz=$(getconf CLK_TCK)
for n in "${counts[@]}"; do
  start_server 18080 --animate
  wait_final 18080
  before=$(cpu_ticks "$pid"); t0=$(date +%s.%N)
  report=$("$client" load --url ws://127.0.0.1:18080/ws --clients "$n" --ramp 5 --duration 20 --json)
  after=$(cpu_ticks "$pid"); t1=$(date +%s.%N)
  peak=$(hwm_kib "$pid")
  kill -INT "$pid"; wait "$pid" 2>/dev/null || true
  python3 - "$report" "$before" "$after" "$t0" "$t1" "$hz" "$peak" <<'PY'
import json, sys
r = json.loads(sys.argv[1]); before, after, t0, t1, hz, peak = map(float, sys.argv[2:])
l = r["latency_ms"]; fpv = r["frames_per_viewer"]
cpu = 100 * (after - before) / hz / (t1 - t0)
tester = r.get("load_tester_cpu_percent") or 0
print(f"| {r['clients']} | {r['connected']} | {r['failed']} | {l['p50']:.1f} | {l['p90']:.1f} | {l['p99']:.1f} | {l['max']:.1f} | {fpv[0]}..{fpv[1]} | {cpu:.0f} | {tester:.0f} | {peak/1024:.0f} |")
PY
done

# Idle viewers: a static scene (no --animate), so memory is what a connection itself holds.
n=${counts[-1]}
start_server 18081
wait_final 18081
base=$(rss_kib "$pid")
"$client" load --url ws://127.0.0.1:18081/ws --clients "$n" --ramp 5 --duration 10 --json >/dev/null &
loader=$!
sleep 12  # measuring while all viewers are connected (ramp 5 s, then 10 s connected)
held=$(rss_kib "$pid")
wait "$loader"
kill -INT "$pid"; wait "$pid" 2>/dev/null || true
echo
echo "Idle: $n viewers on a static scene: server RSS $((base / 1024)) MiB before, $((held / 1024)) MiB with them connected: $(( (held - base) * 1024 / n )) bytes per idle viewer."
