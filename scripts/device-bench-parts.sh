#!/usr/bin/env bash
# scripts/device-bench.sh's parts one after another, most wanted first (BENCHMARKS.md's open
# questions), each into its own folder under OUTDIR, then OUTDIR/done: started in the
# background (setsid) on the lent GPU, so that calls of the device tool, 10 minutes each, can
# copy whatever parts have finished (DEVELOPERS.md).
#   scripts/device-bench-parts.sh DATA OUTDIR [SIZE] [DVR_SIZE]
set -uo pipefail
cd "$(dirname "$0")/.."
d=${1:?data folder}; out=${2:?output folder}; sizes=("${@:3}")
mkdir -p "$out"
part() { local name=$1; shift; env "$@" bash scripts/device-bench.sh "$d" "$out/$name" "${sizes[@]}" > "$out/$name.log" 2>&1; }
part 1-trace PARTS=trace TRACERS="gpu checked block costs ifif wg"
part 2-render PARTS=render
part 3-trace PARTS=trace TRACERS="split sorted cpu embree"
part 4-volume PARTS="volume scene"
echo done > "$out/done"
