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
# With a base binary packed beside this one (`device-bench.sh --pack DIR BASE_REV`), first what
# BENCHMARKS.md lists as not yet timed on a GPU: the two binaries' ray queries and whole frames
# alternated, where a query's wall time goes, and the queues filled a lane or a subgroup at a time.
if [ -f "$d/base.gz" ] || [ -x "$d/base" ]; then
  part 0-ab PARTS=ab
  part 0-floor PARTS=floor
  part 0-appends PARTS=appends
  part 0-split PARTS=trace TRACERS="split split-atomic" MESHES=turbine_blade
  part 0-planes PARTS=trace TRACERS="planes-f32" KINDS="primary shadow diffuse"
  part 0-abframes PARTS=abframes
  part 0-build PARTS=build
  part 0-cpuframes PARTS=cpuframes
fi
part 1-trace PARTS=trace TRACERS="gpu checked block costs ifif wg"
part 2-render PARTS=render
part 3-trace PARTS=trace TRACERS="split sorted cpu embree"
part 4-volume PARTS="volume scene"
# CPU only, last: iso --simplify on the host's cores (and BASE's, where packed).
part 5-simplify PARTS=simplify
echo done > "$out/done"
