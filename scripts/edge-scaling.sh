#!/usr/bin/env bash
# Measures the NATS fan-out on this machine (docs/SCALING.md): a nats-server of its own (with
# monitoring), one origin (2,500-patch Cornell box, lights changing once a second via
# --animate) and two edges, all on loopback with the load tester. Prints Markdown rows:
#  1. the edge path's added latency: 100 viewers on the origin and 100 on an edge at once;
#  2. VIEWERS (default 10000) on the origin alone, then spread over the two edges.
# Latency is from the origin's publish stamp in each frame to the viewer's decode.
# Usage: scripts/edge-scaling.sh [VIEWERS]
set -euo pipefail
cd "$(dirname "$0")/.."
viewers=${1:-10000}
cargo build --release -q -p radcast-server -p radcast-client
server=target/release/radcast-server
client=target/release/radcast-client
ulimit -n "$(ulimit -Hn)"
store=$(mktemp -d)
logs=${LOGS:-$(mktemp -d)}
echo "logs: $logs" >&2
pids=()
trap 'kill "${pids[@]}" 2>/dev/null; rm -rf "$store"' EXIT

nats-server -a 127.0.0.1 -p 14222 -m 18222 -js -sd "$store" >/dev/null 2>&1 &
nats_pid=$!; pids+=("$nats_pid")
caps=(--max-viewers-per-ip 20000 --max-connections-per-ip 21000 --max-viewers 20000)
"$server" --addr 127.0.0.1:18080 --patches 2500 --no-cache --token load-test --animate \
  --nats nats://127.0.0.1:14222 --name cornell "${caps[@]}" >"$logs/origin.log" 2>&1 &
origin_pid=$!; pids+=("$origin_pid")
"$server" --edge --nats nats://127.0.0.1:14222 --addr 127.0.0.1:18081 "${caps[@]}" >"$logs/edge-a.log" 2>&1 &
edge_a=$!; pids+=("$edge_a")
"$server" --edge --nats nats://127.0.0.1:14222 --addr 127.0.0.1:18082 "${caps[@]}" >"$logs/edge-b.log" 2>&1 &
edge_b=$!; pids+=("$edge_b")
for port in 18080 18081 18082; do
  for _ in $(seq 600); do curl -sf "http://127.0.0.1:$port/healthz" | grep -q ok && break; sleep 0.1; done
done

hz=$(getconf CLK_TCK)
cpu_ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }
nats_bytes() { curl -sf http://127.0.0.1:18222/varz | python3 -c 'import json,sys; v=json.load(sys.stdin); print(v["in_bytes"] + v["out_bytes"])'; }

# One measured run: LABEL, then load-tester arguments. Prints a row.
run() {
  local label=$1; shift
  local before=() after=() t0 t1 b0 b1 report
  for p in "$origin_pid" "$edge_a" "$edge_b" "$nats_pid"; do before+=("$(cpu_ticks "$p")"); done
  b0=$(nats_bytes); t0=$(date +%s.%N)
  report=$("$client" load "$@" --ramp 5 --duration 20 --json)
  echo "$report" | python3 -c 'import json,sys; r=json.load(sys.stdin); r["failures"] and print("failures:", r["failures"], file=sys.stderr)' 
  t1=$(date +%s.%N); b1=$(nats_bytes)
  for p in "$origin_pid" "$edge_a" "$edge_b" "$nats_pid"; do after+=("$(cpu_ticks "$p")"); done
  python3 - "$label" "$report" "$t0" "$t1" "$hz" "$b0" "$b1" "${before[@]}" "${after[@]}" <<'PY'
import json, sys
label, report = sys.argv[1], json.loads(sys.argv[2])
t0, t1, hz, b0, b1 = map(float, sys.argv[3:8])
ticks = list(map(float, sys.argv[8:]))
before, after = ticks[:4], ticks[4:]
cpu = [100 * (a - b) / hz / (t1 - t0) for a, b in zip(after, before)]
l = report["latency_ms"]
tester = report.get("load_tester_cpu_percent") or 0
print(f"| {label} | {report['connected']}/{report['clients']} | {l['p50']:.1f} | {l['p99']:.1f} | "
      f"{cpu[0]:.0f} | {cpu[1]:.0f} | {cpu[2]:.0f} | {cpu[3]:.0f} | {tester:.0f} | {(b1 - b0) / (t1 - t0) / 1024:.0f} |")
PY
}

echo "| run | connected | latency p50 ms | p99 ms | origin CPU % | edge A CPU % | edge B CPU % | NATS CPU % | tester CPU % | NATS KiB/s |"
echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
# 1. Added latency of the edge path: the same frames, read direct and through an edge, at once.
run "100 on the origin (with 100 on edge A at once)" --url ws://127.0.0.1:18080/ws --clients 100 &
direct=$!
run "100 on edge A (with 100 on the origin at once)" --url ws://127.0.0.1:18081/ws --clients 100
wait "$direct"
# 2. Many viewers: on one server, then over two edges.
run "$viewers on the origin" --url ws://127.0.0.1:18080/ws --clients "$viewers"
run "$viewers over edges A and B" --url ws://127.0.0.1:18081/ws,ws://127.0.0.1:18082/ws --clients "$viewers"
