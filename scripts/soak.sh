#!/usr/bin/env bash
# The soak: one radcast-server on the default scene (no solve flags: the Cornell box to 5%),
# VIEWERS viewers (default 1,000) for MINUTES minutes (default 10), an edit every 100 ms (the
# light's emission and moves of the short block, in turn), all on loopback. Prints the server's
# resident memory once a minute (it must stay flat), the load tester's report (every viewer
# must end on the server's final version; no version may go back), and the server's count of
# edit batches and faults. Usage: scripts/soak.sh [MINUTES] [VIEWERS] [PROTOCOL]
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-10}
viewers=${2:-1000}
protocol=${3:-3}
cargo build --release -q -p radcast-server -p radcast-client
ulimit -n "$(ulimit -Hn)"
port=18090
token=soak
target/release/radcast-server --addr "127.0.0.1:$port" --no-cache --token "$token" \
  --max-viewers-per-ip 20000 --max-connections-per-ip 21000 >/tmp/radcast-soak-server.log 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null || true' EXIT
for _ in $(seq 600); do
  curl -sf "http://127.0.0.1:$port/api/solution" | grep -q '"is_final":true' && break
  sleep 0.1 # polling for the first solve, not synchronisation
done
rss_mib() { awk '/VmRSS/ {printf "%.0f", $2 / 1024}' "/proc/$pid/status"; }
echo "server RSS after the first solve: $(rss_mib) MiB"
seconds=$((minutes * 60))
(
  for minute in $(seq "$minutes"); do
    sleep 60 # one sample a minute
    echo "minute $minute: server RSS $(rss_mib) MiB"
  done
) &
sampler=$!
target/release/radcast-client --protocol "$protocol" load --url "ws://127.0.0.1:$port/ws" \
  --clients "$viewers" --ramp 10 --duration "$seconds" \
  --edit light --edit-every 0.1 --move short_block --token "$token"
wait "$sampler" || true
echo "server RSS at the end: $(rss_mib) MiB"
curl -s "http://127.0.0.1:$port/metrics" | grep -E '^radcast_(edit_batches_total|faults_total|solution_version|viewers_dropped_total)' || true
echo "healthz: $(curl -s "http://127.0.0.1:$port/healthz")"
