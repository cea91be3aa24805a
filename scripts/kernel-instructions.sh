#!/usr/bin/env bash
# Instructions the ray-query kernel executes per query on lavapipe, counted by valgrind's
# callgrind: a figure that repeats to the instruction from run to run (lavapipe's times vary by
# ±30 % on the 2-core development machine), for screening kernel changes where no GPU is lent.
# It counts work, not GPU time: BENCHMARKS.md ("Kernel instructions on lavapipe") sets its
# ratios beside the H200's for changes measured on both. It predicts changes in the amount of
# work (leaf size) to a few %, and misses what a GPU pays for latency (the entry grid's skipped
# top levels) or occupancy (the if-if loop), so a change it favours still goes to a GPU.
#
# Usage: scripts/kernel-instructions.sh [BINARY...]   (default: target/release/raystream)
# Env: SIZE (ray sets' image size, default 160x120), SETS ("mesh:kind" words, default below),
#      ARGS (more `trace` arguments, e.g. "--entry-grid 0"). Needs valgrind (apt-get install
#      valgrind) and lavapipe. Prints one line a binary and set: binary, mesh, rays, query,
#      instructions a query, instructions a ray.
set -euo pipefail
cd "$(dirname "$0")/.."
bins=("$@")
[ ${#bins[@]} -gt 0 ] || bins=(target/release/raystream)
size=${SIZE:-160x120}
sets=${SETS:-"turbine_blade:primary stanford_lucy_100k:primary stanford_lucy_100k:shadow turbine_blade:diffuse"}
py=${RAYSTREAM_PYTHON:-.venv/bin/python}
command -v valgrind > /dev/null || { echo "kernel-instructions.sh: valgrind is not installed" >&2; exit 1; }
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for s in $sets; do
  mesh=${s%%:*}; kind=${s#*:}
  m=../shared/data/meshes/$mesh.ply
  $py ../shared/tools/rays.py gen "$m" --kind "$kind" --size "$size" -o "$out/$mesh-$kind.bin" > /dev/null
  rays=$(( $(stat -c %s "$out/$mesh-$kind.bin") / 32 ))
  query=closest; any=()
  [ "$kind" = shadow ] && { query=any; any=(--any); }
  for b in "${bins[@]}"; do
    # --repeat 1 runs the query three times: warm-up, timed, and the one-query stream.
    # shellcheck disable=SC2086
    valgrind --tool=callgrind --smc-check=all-non-file --callgrind-out-file="$out/cg" \
      "$b" trace "$m" --rays "$out/$mesh-$kind.bin" -o "$out/hits.bin" --device gpu \
      --repeat 1 -q "${any[@]}" ${ARGS:-} > /dev/null 2> "$out/log" \
      || { cat "$out/log" >&2; exit 1; }
    # The kernel is lavapipe's JIT code, the costliest function of no object ("[???]").
    jit=$(callgrind_annotate "$out/cg" 2> /dev/null | grep -F '[???]' | head -1 | awk '{gsub(",", "", $1); print $1}')
    [ -n "$jit" ] || { echo "kernel-instructions.sh: no JIT code in callgrind's profile of $b" >&2; exit 1; }
    per_query=$(( jit / 3 ))
    echo "$b $mesh $kind $rays $query $per_query $(( per_query / rays ))"
  done
done
