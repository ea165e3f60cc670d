#!/bin/sh
# Cost against scene size for one family of generated scenes: hierarchical radiosity at the
# default settings (or at --error E), each solve measured against a path-traced reference of
# its own scene. Prints a Markdown table (docs/BENCHMARKS.md).
# The self-check is off, so the knob is fixed (0.03 unless --error E) and the time is the solve's.
# RADCAST=path/to/radcast runs that build instead of this checkout's (to compare two commits).
# Usage: scripts/hierarchy-scaling.sh room|town|corpus [--error E] SIZE|NAME...
#   room: SIZE pieces of furniture (radcast generate --pieces); town: about SIZE triangles of
#   soup under a sky (radcast generate --town); corpus: the real models of scripts/corpus.py
#   by NAME (monastery, monastery-piece, monastery-village, living-room, teddy).
set -eu
cd "$(dirname "$0")/.."
family=$1
shift
knob=""
if [ "${1:-}" = "--error" ]; then
    knob="--error $2"
    shift 2
fi
case $family in
    room) flag=--pieces ;;
    town) flag=--town ;;
    corpus) flag="" ;;
    *) echo "usage: $0 room|town|corpus [--error E] SIZE|NAME..." >&2; exit 2 ;;
esac
if [ -z "${RADCAST:-}" ]; then
    cargo build --quiet --release -p radcast-cli
fi
radcast=${RADCAST:-./target/release/radcast}
echo "| $family | triangles | knob used | leaves | links | links/leaf | shadow rays | refine s | solve s | total s | peak MB | smooth RMS | flat RMS | energy |"
echo "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
for n in "$@"; do
    if [ "$family" = corpus ]; then
        scene=scenes/corpus/$n.obj
        reference=scenes/corpus/reference/$n.json
        [ -f "$reference" ] || python3 scripts/corpus.py --references >/dev/null
    else
        scene=scenes/generated/$family-$n.obj
        reference=scenes/generated/$family-$n.reference.json
        [ -f "$scene" ] || $radcast generate $flag "$n" --out "$scene" 2>/dev/null
        [ -f "$reference" ] || $radcast reference "$scene" --probes 1000 --samples 16384 --out "$reference" 2>/dev/null
    fi
    # shellcheck disable=SC2086 # $knob is empty or two words.
    $radcast solve "$scene" --method hierarchical $knob --check off --reference "$reference" --json 2>/dev/null | python3 -c "
import json, sys
d = json.load(sys.stdin)
s, e = d['seconds'], d['error']
print(f\"| $n | {d['triangles']:,} | {d['knob_used']} | {d['elements']:,} | {d['links']:,} | {d['links'] / d['elements']:.1f} | {d['rays'] / 1e6:.1f}M \"
      f\"| {s['form_factors']:.1f} | {s['solve']:.2f} | {s['total']:.1f} | {d['peak_memory_bytes'] / 1e6:.0f} \"
      f\"| {100 * e['smooth']['rms']:.2f}% | {100 * e['flat']['rms']:.2f}% | {100 * e['smooth']['energy']:+.2f}% |\")"
done
