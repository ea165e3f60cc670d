#!/bin/sh
# Links against leaves as the scene grows: generated furnished rooms, hierarchical radiosity at
# one error knob. Prints a Markdown table (docs/BENCHMARKS.md). Usage: scripts/hierarchy-scaling.sh [ERROR] [PIECES...]
set -eu
cd "$(dirname "$0")/.."
error=${1:-0.3}
[ $# -gt 0 ] && shift
pieces=${*:-"30 100 300 1000"}
cargo build --quiet --release -p radcast-cli
echo "| pieces | faces | leaves | links | links/leaf | seconds | peak MB |"
echo "|---:|---:|---:|---:|---:|---:|---:|"
for n in $pieces; do
    scene=scenes/generated/room-$n.obj
    [ -f "$scene" ] || ./target/release/radcast generate --pieces "$n" --out "$scene" 2>/dev/null
    faces=$(grep -c '^f ' "$scene")
    ./target/release/radcast solve "$scene" --method hierarchical --error "$error" --json 2>/dev/null | python3 -c "
import json, sys
d = json.load(sys.stdin)
print(f\"| $n | $faces | {d['elements']} | {d['links']} | {d['links'] / d['elements']:.1f} | {d['seconds']['total']:.2f} | {d['peak_memory_bytes'] / 1e6:.0f} |\")"
done
