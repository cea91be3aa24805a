#!/usr/bin/env bash
# Side-by-side CPU throughput: raystream trace vs Intel Embree (via ../shared/tools/rays.py) on
# the same standard ray sets, in one run. Prints one JSON line per (mesh, kind, tracer) and a
# summary table. Usage: scripts/bench-vs-embree.sh [SIZE] [MESH...]
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-1920x1080}; shift || true
meshes=("$@")
[ ${#meshes[@]} -gt 0 ] || meshes=(../shared/data/meshes/stanford_lucy_100k.ply ../shared/data/meshes/turbine_blade.ply)
py=${RAYSTREAM_PYTHON:-.venv/bin/python}
R="$py ../shared/tools/rays.py"
bin=target/release/raystream
cargo build --release --quiet
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
rows=()
for m in "${meshes[@]}"; do
  name=$(basename "$m")
  for kind in primary shadow diffuse; do
    $R gen "$m" --kind $kind --size "$size" -o "$out/r.bin" > /dev/null
    any=(); [ $kind = shadow ] && any=(--any)
    ours=$($bin trace "$m" --rays "$out/r.bin" -o "$out/h.bin" "${any[@]}" --repeat 5 --json --device cpu)
    $R check "$m" "$out/r.bin" "$out/h.bin" "${any[@]}" | tail -1 | grep -q '^PASS' || { echo "check failed: $name $kind" >&2; exit 1; }
    theirs=$($R embree "$m" "$out/r.bin" "${any[@]}" --repeat 5 --json)
    echo "$ours"; echo "$theirs"
    rows+=("$(python3 - "$name" "$kind" "$ours" "$theirs" <<'PY'
import json, sys
name, kind, a, b = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4])
print(f"| {name} | {kind} | {a['rays']} | {a['mrays_per_s']:.2f} | {b['mrays_per_s']:.2f} | {a['mrays_per_s']/b['mrays_per_s']:.2f} | {a['build_ms']:.0f} | {b['build_ms']:.0f} |")
PY
)")
  done
done
echo
echo "| mesh | rays | count | raystream Mrays/s | Embree Mrays/s | ratio | raystream build ms | Embree build ms |"
echo "|---|---|---|---|---|---|---|---|"
printf '%s\n' "${rows[@]}"
