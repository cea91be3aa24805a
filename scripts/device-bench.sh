#!/usr/bin/env bash
# Every GPU figure of BENCHMARKS.md in one run, on a machine that has no Rust (the lent GPU; see
# DEVELOPERS.md): a release binary, the meshes, the abdomen CT, rays.py and its wheels travel in
# a data folder made by `scripts/device-bench.sh --pack DIR`. Then, there:
#   scripts/device-bench.sh DIR OUTDIR [SIZE] [DVR_SIZE]
# For each mesh and ray kind: rays.py gen writes the standard set; raystream trace on the GPU
# (fused and split kernels) and on the CPU, and Embree (rays.py embree), trace the same file on
# the same machine; rays.py check must pass on the GPU's hits. Then bench (per-kernel times,
# nodes and triangles per ray), the default scene's frame rate, and the volume modes' frame rates.
# Then the volume benchmark: the abdomen CT resampled to 512³, 1024×1024 frames of an orbit,
# ct-bone, without and with shadows, with and without empty-space skipping, GPU and CPU.
# PARTS (default "trace render volume"; also "build": the kd-tree build at 1 to every thread, BASE against this binary;
# "cpuframes": the CPU renderer's frames at 4, 8 and every thread, BASE against this binary, then in waves of CPU_WAVES samples;
# "simplify": iso --simplify on the chest CT's bones at 2, 8 and every thread, this binary and BASE where given; "entry": the entry grid's sizes (GRIDS) A/B; "scene": meshes and the CT in one scene; "ab": this binary against
# BASE=another on the primary, shadow and diffuse sets; "abframes": the same on whole frames (the default scene, a dvr orbit,
# a denoised cinematic frame); "floor": where a query's wall time goes (the floor kernel beside the
# query, with and without timestamps); "pixels": the default scene's camera rays by rows or blocks; "waves": its
# frame in waves of WAVES samples; "checks": its kernels with and without wgpu's run-time checks; "appends": its
# shade_hits reserving queue slots a lane or a subgroup at a time) picks the parts; TRACERS (default "gpu block
# checked ifif wg split sorted costs cpu embree"; also "split-atomic": the split kernels' lists filled a lane at a time (RAYSTREAM_GPU_APPENDS=atomic);
# "planes-f32": the fused kernel without its f64 planes (RAYSTREAM_GPU_PLANES=f32);
# wg = the fused kernel at 32, 128 and 256 threads a workgroup; checked = the fused
# kernel with wgpu's run-time checks (RAYSTREAM_GPU_CHECKS=on; off by default); block = the fused kernel with
# RAYSTREAM_GPU_WAIT=block, blocking waits against the spinning ones a hardware GPU has by default; sorted = the diffuse and random
# sets reordered by sort-rays.py; costs = the fused kernel on trees built with --sah-traversal-cost 2, 4, 8) the tracers of
# the trace part. The fused and if-if trace lines and bench's lines carry the
# kernels' SIMD efficiency and residency peak (gpu_stats); every GPU trace line but split's also carries stream_ms (the
# wall time per query of 10 queries queued in one submission).
# Results: OUTDIR/results.jsonl (one JSON object per line, each tagged), images in OUTDIR.
set -uo pipefail
cd "$(dirname "$0")/.."

if [ "${1:-}" = --pack ]; then
  d=${2:?--pack DIR [BASE_REV]}; base_rev=${3:-}
  mkdir -p "$d/meshes" "$d/ct"
  # The Vulkan loader (.gl) and rays.py's Embree wheels (.whl) for the device, once a checkout.
  if [ ! -d .gl ]; then
    grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo /.gl/ >> .git/info/exclude
    mkdir -p .gl /tmp/amd64/partial
    o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64)
    apt-get "${o[@]}" update -qq && (cd .gl && apt-get "${o[@]}" download libvulkan1 libegl1 libglvnd0) \
      || { rm -rf .gl; echo "--pack: could not download the Vulkan loader into .gl" >&2; exit 1; }
  fi
  if [ ! -d .whl ]; then
    grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo /.whl/ >> .git/info/exclude
    mkdir -p .whl
    for p in embreex==4.4.0.post1 trimesh==5.2.0; do
      python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 -d .whl $p \
        || { rm -rf .whl; echo "--pack: could not download $p into .whl" >&2; exit 1; }
    done
  fi
  cargo build --release --quiet
  # Binaries travel gzipped (a carry holds 64 MiB in all); the run unpacks them, unless an
  # unpacked one is there already (from a trial run here): remove those, or the old ones run.
  rm -f "$d/raystream" "$d/base"
  strip -o "$d/raystream" target/release/raystream && gzip -9f "$d/raystream"
  # BASE_REV: another commit's release build beside it, for the "ab" and "abframes" parts
  # (built in a worktree of its own, into target/base).
  if [ -n "$base_rev" ]; then
    wt=$(mktemp -d)/base
    git worktree add --detach "$wt" "$base_rev" >/dev/null || { echo "--pack: no commit $base_rev" >&2; exit 1; }
    CARGO_TARGET_DIR=$PWD/target/base cargo build --release --quiet --manifest-path "$wt/Cargo.toml"
    git worktree remove --force "$wt"
    rmdir "$(dirname "$wt")"
    strip -o "$d/base" target/base/release/raystream && gzip -9f "$d/base"
    git rev-parse --short "$base_rev" > "$d/base.rev"
  fi
  git rev-parse --short HEAD > "$d/raystream.rev"
  cp ../shared/data/meshes/{stanford_bunny.ply,stanford_lucy_100k.ply,turbine_blade.ply} "$d/meshes/"
  cp ../shared/data/volumes/nifti/abdomen_pelvis_ct_totalseg.nii.gz "$d/ct/"
  # The chest CT with its aorta's path and the fly-through's transfer function (question 20).
  cp ../shared/data/volumes/nifti/chest_ct_stents_totalseg.nii.gz examples/chest_aorta.mrk.json \
    examples/angioscopy.toml "$d/ct/"
  cp ../shared/tools/rays.py scripts/sort-rays.py "$d/"
  du -sh "$d"
  exit 0
fi

d=${1:?data folder}; out=${2:?output folder}; size=${3:-1920x1080}; dvr_size=${4:-1024x1024}
py=${RAYSTREAM_PYTHON:-python3}
# --pack's binaries arrive gzipped; a base binary packed beside this one is the default BASE.
for b in raystream base; do
  [ -f "$d/$b.gz" ] && [ ! -x "$d/$b" ] && gunzip -c "$d/$b.gz" > "$d/$b" && chmod +x "$d/$b"
done
[ -z "${BASE:-}" ] && [ -x "$d/base" ] && BASE=$d/base
bin=$d/raystream
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"
res=$out/results.jsonl
# One JSON line, tagged with what produced it.
tag() { $py -c 'import json,sys
t=json.loads(sys.argv[1])
for l in sys.stdin:
    l=l.strip()
    if l.startswith("{"):
        o=json.loads(l); o.update(t); print(json.dumps(o), flush=True)' "$1" | tee -a "$res"; }

revs=""
[ -f "$d/raystream.rev" ] && revs="$revs, \"commit\": \"$(cat "$d/raystream.rev")\""
[ -f "$d/base.rev" ] && revs="$revs, \"base_commit\": \"$(cat "$d/base.rev")\""
echo "{\"machine\": \"$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)\", \"date\": \"$(date -u +%FT%TZ)\"$revs}" | tee -a "$res"
parts=${PARTS:-trace render volume}
tracers=${TRACERS:-gpu block checked ifif wg split sorted costs cpu embree}
has() { [[ " $1 " == *" $2 "* ]]; }
# MESHES and KINDS (default: all three meshes, all four kinds) narrow the trace part.
has "$parts" trace && for m in ${MESHES:-stanford_bunny stanford_lucy_100k turbine_blade}; do
  mesh=$d/meshes/$m.ply
  for kind in ${KINDS:-primary diffuse shadow random}; do
    rays=$tmp/$m-$kind.rays
    $py "$d/rays.py" gen "$mesh" --kind $kind --size "$size" -o "$rays" > /dev/null || { echo "gen failed: $m $kind"; continue; }
    any=(); [ $kind = shadow ] && any=(--any)
    t="{\"mesh\": \"$m\", \"kind\": \"$kind\""
    for k in fused split ifif; do
      [ $k != fused ] && ! has "$tracers" $k && continue
      stats=(--stats); [ $k = split ] && stats=()
      $bin trace "$mesh" --rays "$rays" -o "$tmp/gpu-$k.hits" "${any[@]}" --device gpu --kernels $k --repeat 10 --json --quiet \
        "${stats[@]}" | tag "$t, \"tracer\": \"raystream-gpu-$k\"}"
    done
    # The split kernels with their lists filled a lane at a time (RAYSTREAM_GPU_APPENDS=atomic;
    # a subgroup at a time by default where the adapter has subgroups): the same hits, faster?
    has "$tracers" split-atomic && { RAYSTREAM_GPU_APPENDS=atomic $bin trace "$mesh" --rays "$rays" -o "$tmp/gpu-split-atomic.hits" \
      "${any[@]}" --device gpu --kernels split --repeat 10 --json --quiet | tag "$t, \"tracer\": \"raystream-gpu-split-atomic\"}"
      cmp -s "$tmp/gpu-fused.hits" "$tmp/gpu-split-atomic.hits" || echo "$m $kind: SPLIT-ATOMIC HITS DIFFER from fused"; }
    # The fused kernel with huge triangles' planes left in f32 (RAYSTREAM_GPU_PLANES=f32; f64 by
    # default where the adapter has it): what the f64 path's code costs (registers) where it
    # never runs; the hits differ only where it does (about 4 tests in 10^5).
    has "$tracers" planes-f32 && { RAYSTREAM_GPU_PLANES=f32 $bin trace "$mesh" --rays "$rays" -o "$tmp/gpu-planes-f32.hits" \
      "${any[@]}" --device gpu --repeat 10 --json --quiet | tag "$t, \"tracer\": \"raystream-gpu-planes-f32\"}"
      cmp -s "$tmp/gpu-fused.hits" "$tmp/gpu-planes-f32.hits" || echo "$m $kind: f32 planes give other hits than f64 ones"; }
    # Leaf size: the SAH builder pricing a traversal step dearer (shallower trees, fuller leaves).
    has "$tracers" costs && for kt in 2 4 8; do
      $bin trace "$mesh" --rays "$rays" -o "$tmp/gpu-kt.hits" "${any[@]}" --device gpu --sah-traversal-cost $kt --repeat 10 --json \
        --quiet | tag "$t, \"tracer\": \"raystream-gpu-fused\", \"sah_traversal_cost\": $kt}"
    done
    # Threads per workgroup of the query kernel (64 is the fused line's): 32, 128 and 256.
    has "$tracers" wg && for wg in 32 128 256; do
      RAYSTREAM_GPU_WORKGROUP=$wg $bin trace "$mesh" --rays "$rays" -o "$tmp/gpu-wg.hits" "${any[@]}" --device gpu --repeat 10 \
        --json --quiet | tag "$t, \"tracer\": \"raystream-gpu-fused\"}"
      cmp -s "$tmp/gpu-fused.hits" "$tmp/gpu-wg.hits" || echo "$m $kind: WORKGROUP $wg HITS DIFFER from fused"
    done
    # Incoherent sets reordered (direction octant, then origin Morton code): SIMD efficiency and speed.
    has "$tracers" sorted && [[ $kind == diffuse || $kind == random ]] && $py "$d/sort-rays.py" "$rays" "$tmp/sorted.rays" && {
      $bin trace "$mesh" --rays "$tmp/sorted.rays" -o "$tmp/sorted.hits" --device gpu --repeat 10 --json --quiet --stats \
        | tag "$t, \"tracer\": \"raystream-gpu-fused\", \"order\": \"octant-morton\"}"
      $py "$d/rays.py" check "$mesh" "$tmp/sorted.rays" "$tmp/sorted.hits" --json | tag "$t, \"check\": \"gpu-fused-sorted\"}"
      rm -f "$tmp/sorted.rays"; }
    # The fused kernel compiled with wgpu's run-time checks (RAYSTREAM_GPU_CHECKS=on; the
    # default drops them): the same hits, how much slower?
    has "$tracers" checked && { RAYSTREAM_GPU_CHECKS=on $bin trace "$mesh" --rays "$rays" -o "$tmp/gpu-checked.hits" "${any[@]}" \
      --device gpu --repeat 10 --json --quiet | tag "$t, \"tracer\": \"raystream-gpu-fused-checked\"}"
      cmp -s "$tmp/gpu-fused.hits" "$tmp/gpu-checked.hits" || echo "$m $kind: CHECKED HITS DIFFER from fused"; }
    # The fused kernel again with blocking waits (RAYSTREAM_GPU_WAIT=block; a hardware GPU's
    # spin by default), for the A/B.
    has "$tracers" block && RAYSTREAM_GPU_WAIT=block $bin trace "$mesh" --rays "$rays" -o "$tmp/gpu-block.hits" "${any[@]}" --device gpu \
      --repeat 10 --json --quiet | tag "$t, \"tracer\": \"raystream-gpu-fused-block\"}"
    $py "$d/rays.py" check "$mesh" "$rays" "$tmp/gpu-fused.hits" "${any[@]}" --json | tag "$t, \"check\": \"gpu-fused\"}"
    has "$tracers" split && { cmp -s "$tmp/gpu-fused.hits" "$tmp/gpu-split.hits" && echo "$m $kind: split hits == fused hits byte for byte" \
      || echo "$m $kind: SPLIT HITS DIFFER from fused"; }
    has "$tracers" ifif && { cmp -s "$tmp/gpu-fused.hits" "$tmp/gpu-ifif.hits" && echo "$m $kind: ifif hits == fused hits byte for byte" \
      || echo "$m $kind: IFIF HITS DIFFER from fused"; }
    has "$tracers" cpu && { $bin trace "$mesh" --rays "$rays" -o "$tmp/cpu.hits" "${any[@]}" --device cpu --repeat 5 --json --quiet \
      | tag "$t, \"tracer\": \"raystream-cpu\"}"
    cmp -s "$tmp/cpu.hits" "$tmp/gpu-fused.hits" && echo "$m $kind: GPU hits == CPU hits byte for byte" \
      || echo "$m $kind: GPU hits differ from CPU hits in $(cmp -l "$tmp/cpu.hits" "$tmp/gpu-fused.hits" | wc -l) bytes"; }
    has "$tracers" embree && $py "$d/rays.py" embree "$mesh" "$rays" "${any[@]}" --repeat 5 --json | tag "$t, \"tracer\": \"embree\"}"
    rm -f "$rays" "$tmp"/*.hits
  done
  has "$tracers" cpu && $bin bench "$mesh" --device gpu,cpu --kernels fused,ifif,split --size "$size" --repeat 5 --json --quiet \
    --save-rays "$tmp/bench-$m" | tag "{\"mesh\": \"$m\", \"bench\": true}"
  # bench's own sets traced by `trace`: are they slow on the GPU by themselves, or only inside bench?
  has "$tracers" cpu && for kind in diffuse shadow; do
    any=(); [ $kind = shadow ] && any=(--any)
    $bin trace "$mesh" --rays "$tmp/bench-$m/$kind.rays" -o "$tmp/bench.hits" "${any[@]}" --device gpu --repeat 10 --json --quiet \
      | tag "{\"mesh\": \"$m\", \"kind\": \"$kind\", \"tracer\": \"raystream-gpu-fused\", \"rays_from\": \"bench\"}"
  done
  rm -rf "$tmp/bench-$m" "$tmp/bench.hits"
done

# Two binaries alternated (BASE=the other binary; its lines tagged "binary": "base", this one's
# "new"): the primary, shadow and diffuse sets (AB_KINDS narrows them), trace --repeat 20, two
# rounds; one rays.py check each.
has "$parts" ab && for m in stanford_bunny stanford_lucy_100k turbine_blade; do
  mesh=$d/meshes/$m.ply
  for kind in ${AB_KINDS:-primary shadow diffuse}; do
    rays=$tmp/$m-$kind.rays
    $py "$d/rays.py" gen "$mesh" --kind $kind --size "$size" -o "$rays" > /dev/null || { echo "gen failed: $m $kind"; continue; }
    any=(); [ $kind = shadow ] && any=(--any)
    for round in 1 2; do
      for which in base new; do
        b=$bin; [ $which = base ] && b=${BASE:?BASE=the other binary}
        $b trace "$mesh" --rays "$rays" -o "$tmp/ab-$which.hits" "${any[@]}" --device gpu --repeat 20 --json --quiet \
          | tag "{\"mesh\": \"$m\", \"kind\": \"$kind\", \"tracer\": \"raystream-gpu-fused\", \"binary\": \"$which\", \"round\": $round}"
      done
    done
    $py "$d/rays.py" check "$mesh" "$rays" "$tmp/ab-new.hits" "${any[@]}" --json | tag "{\"mesh\": \"$m\", \"kind\": \"$kind\", \"check\": \"gpu-fused\"}"
    cmp -s "$tmp/ab-base.hits" "$tmp/ab-new.hits" && echo "$m $kind: base and new hits byte for byte" || echo "$m $kind: BASE AND NEW HITS DIFFER"
    rm -f "$rays" "$tmp"/*.hits
  done
done

# "floor": where a query's wall time goes. trace --stats --repeat 20 of the primary and shadow
# sets (FLOOR_KINDS) of each mesh: the query's wall, kernel and streamed time beside the floor
# kernel's on the same rays (each ray read, a miss written, no traversal) and an empty
# submission's round trip; then the same with RAYSTREAM_GPU_TIMESTAMPS=off (what the
# timestamps' writes, resolve and readback add to the wall time); two rounds
# (summarize-device-bench.py's floor table).
# The kd-tree build on the host's cores (CPU only; no GPU): the chest CT's bones (578,256
# triangles) and the turbine blade, BASE and this binary alternated at 1, 2, 4, 8 and every
# thread, three rounds (`info --json`'s kdtree.build_ms): what splitting large nodes' references
# in parallel runs (the twenty-fourth session's, 2026-12-05) gains beyond the development machine's two cores.
has "$parts" build && [ -n "${BASE:-}" ] && {
  $bin iso "$d/ct/chest_ct_stents_totalseg.nii.gz" -o "$tmp/chest_bones.ply" --quiet
  for round in 1 2 3; do for th in 1 2 4 8 "$(nproc)"; do for which in base new; do
    b=$bin; [ $which = base ] && b=$BASE
    for m in "$tmp/chest_bones.ply" "$d/meshes/turbine_blade.ply"; do
      RAYON_NUM_THREADS=$th $b info "$m" --json \
        | tag "{\"part\": \"build\", \"binary\": \"$which\", \"threads\": $th, \"round\": $round, \"mesh\": \"$(basename "$m" .ply)\"}"
    done
  done; done; done
}
# "simplify": `iso CHEST --smooth S --simplify MM` on the host's cores (CPU only; no GPU): the
# chest CT's bones smoothed 10× at 4 and 1 mm and raw at 0.3 mm, this binary (and BASE, where
# given) at 2, 8 and every thread, two rounds: the whole command's ms and the triangles kept
# (summarize-device-bench.py's simplify table). meshoptimizer's collapses run on one thread
# (two tries' side by side), the measure on every thread: what more cores gain.
has "$parts" simplify && {
  for round in 1 2; do for th in 2 8 "$(nproc)"; do for which in base new; do
    b=$bin
    if [ $which = base ]; then [ -n "${BASE:-}" ] || continue; b=$BASE; fi
    for spec in "10 4" "10 1" "0 0.3"; do
      read -r sm mm <<< "$spec"
      s0=$(date +%s%N)
      kept=$(RAYON_NUM_THREADS=$th $b iso "$d/ct/chest_ct_stents_totalseg.nii.gz" --smooth "$sm" \
        --simplify "$mm" -o "$tmp/simplified.ply" 2>&1 | grep -o '→ [0-9]* triangles' | grep -o '[0-9]*')
      s1=$(date +%s%N)
      echo "{\"ms\": $(( (s1 - s0) / 1000000 )), \"triangles\": ${kept:-null}}" \
        | tag "{\"part\": \"simplify\", \"binary\": \"$which\", \"threads\": $th, \"round\": $round, \"smooth\": $sm, \"bound_mm\": $mm}"
    done
  done; done; done
}
# "cpuframes": the CPU renderer's frame (the default scene, 4 spp, depth 4, median of 3), this
# binary against BASE at 4, 8 and every thread, alternated twice: its serial passes are what more
# threads do not shorten. The PNGs are compared.
has "$parts" cpuframes && [ -n "${BASE:-}" ] && {
for round in 1 2; do for th in 4 8 "$(nproc)"; do for which in base new; do
  b=$bin; [ $which = base ] && b=$BASE
  RAYON_NUM_THREADS=$th $b render --device cpu --size "$size" --max-depth 4 --repeat 3 -o "$tmp/cpuframes-$which.png" 2>&1 \
    | sed "s/^/[cpuframes $which, $th threads, round $round] /" | tee -a "$out/render.log"
done; done; done
cmp "$tmp/cpuframes-base.png" "$tmp/cpuframes-new.png" && echo "[cpuframes] the same PNG" | tee -a "$out/render.log"
# Then this binary's frame on every thread in waves of CPU_WAVES samples (RAYSTREAM_CPU_WAVE;
# 2^18 the default), alternated twice: the wave that suits 16 cores. The PNGs must be equal.
cpu_waves=${CPU_WAVES:-65536 262144 1048576 4194304}
for round in 1 2; do for w in $cpu_waves; do
  RAYSTREAM_CPU_WAVE=$w $bin render --device cpu --size "$size" --max-depth 4 --repeat 3 -o "$tmp/cpuwave-$w.png" 2>&1 \
    | sed "s/^/[cpuwave $w, round $round] /" | tee -a "$out/render.log"
done; done
for w in $cpu_waves; do
  cmp -s "$tmp/cpuwave-${cpu_waves%% *}.png" "$tmp/cpuwave-$w.png" && echo "[cpuwave $w] the same PNG" \
    || echo "[cpuwave $w] THE PNG DIFFERS"
done | tee -a "$out/render.log"
}
has "$parts" floor && for m in stanford_bunny stanford_lucy_100k turbine_blade; do
  mesh=$d/meshes/$m.ply
  for kind in ${FLOOR_KINDS:-primary shadow}; do
    rays=$tmp/$m-$kind.rays
    $py "$d/rays.py" gen "$mesh" --kind $kind --size "$size" -o "$rays" > /dev/null || { echo "gen failed: $m $kind"; continue; }
    any=(); [ $kind = shadow ] && any=(--any)
    for round in 1 2; do
      for stamps in on off; do
        RAYSTREAM_GPU_TIMESTAMPS=$stamps $bin trace "$mesh" --rays "$rays" -o "$tmp/floor.hits" "${any[@]}" --device gpu \
          --repeat 20 --json --quiet --stats | tag "{\"mesh\": \"$m\", \"kind\": \"$kind\", \"tracer\": \"raystream-gpu-fused\", \"part\": \"floor\", \"timestamps\": \"$stamps\", \"round\": $round}"
      done
    done
    rm -f "$rays" "$tmp"/*.hits
  done
done

# "abframes": this binary against BASE=another on whole frames, alternated twice: the default
# scene (PNG), a 36-frame dvr orbit of the CT (bench) and a denoised cinematic frame; the PNGs
# compared with rays.py imgdiff. For changes of the frame's host side (readbacks, buffers).
has "$parts" abframes && {
ct=$d/ct/abdomen_pelvis_ct_totalseg.nii.gz
for round in 1 2; do
  for which in base new; do
    b=$bin; [ $which = base ] && b=${BASE:?BASE=the other binary}
    $b render --device gpu --size "$size" --max-depth 4 --repeat 20 -o "$tmp/abframes-$which.png" 2>&1 \
      | sed "s/^/[abframes scene $which, round $round] /" | tee -a "$out/render.log"
    $b bench "$ct" --mode dvr --preset ct-bones --resample 512 --size "$dvr_size" --json --quiet --device gpu --frames 36 \
      | tag "{\"volume\": \"ct-bones\", \"binary\": \"$which\", \"round\": $round}"
    $b render "$ct" --mode cinematic --preset ct-aaa --spp 16 --denoise --device gpu --size "$dvr_size" --repeat 5 \
      -o "$tmp/abframes-denoised-$which.png" 2>&1 | sed "s/^/[abframes denoised $which, round $round] /" | tee -a "$out/render.log"
  done
done
for k in "" denoised-; do
  $py "$d/rays.py" imgdiff "$tmp/abframes-${k}base.png" "$tmp/abframes-${k}new.png" 2>&1 | sed "s/^/[abframes ${k}imgdiff] /" \
    | tee -a "$out/render.log"
done
}

# The entry grid (--entry-grid N, 128 the default; 0: every walk from the root): the primary,
# shadow and diffuse sets with GRIDS (default "0 64 128 256") alternated, two rounds (work counts
# in the first), each line tagged "entry_grid_res"; the hits must not change. Then the default
# scene with and without the grid, alternated twice; the PNGs must be equal.
has "$parts" entry && {
grids=${GRIDS:-0 64 128 256}
# Lucy and the turbine first: their primary rays are where Warp still leads (BENCHMARKS.md).
for m in stanford_lucy_100k turbine_blade stanford_bunny; do
  mesh=$d/meshes/$m.ply
  for kind in primary shadow diffuse; do
    rays=$tmp/$m-$kind.rays
    $py "$d/rays.py" gen "$mesh" --kind $kind --size "$size" -o "$rays" > /dev/null || { echo "gen failed: $m $kind"; continue; }
    any=(); [ $kind = shadow ] && any=(--any)
    for round in 1 2; do
      stats=(); [ $round = 1 ] && stats=(--stats)
      for g in $grids; do
        $bin trace "$mesh" --rays "$rays" -o "$tmp/entry-$g.hits" "${any[@]}" --device gpu --entry-grid $g --repeat 20 --json \
          --quiet "${stats[@]}" | tag "{\"mesh\": \"$m\", \"kind\": \"$kind\", \"tracer\": \"raystream-gpu-fused\", \"entry_grid_res\": $g, \"round\": $round}"
      done
    done
    for g in $grids; do
      cmp -s "$tmp/entry-${grids%% *}.hits" "$tmp/entry-$g.hits" || echo "$m $kind: ENTRY GRID $g HITS DIFFER"
    done
    $py "$d/rays.py" check "$mesh" "$rays" "$tmp/entry-128.hits" "${any[@]}" --json | tag "{\"mesh\": \"$m\", \"kind\": \"$kind\", \"check\": \"gpu-fused\"}"
    rm -f "$rays" "$tmp"/*.hits
  done
done
for round in 1 2; do
  for g in 0 128; do
    $bin render --device gpu --size "$size" --max-depth 4 --repeat 20 --entry-grid $g -o "$tmp/entry-$g.png" 2>&1 \
      | sed "s/^/[entry grid $g, round $round] /" | tee -a "$out/render.log"
  done
done
cmp "$tmp/entry-0.png" "$tmp/entry-128.png" && echo "[entry] the same PNG" | tee -a "$out/render.log"
}

# The default scene's camera rays row by row or in blocks of pixels (RAYSTREAM_GPU_PIXELS), at
# 1 and 4 samples a pixel, alternated twice: frame times and kernels; the PNGs must be equal.
has "$parts" pixels && for spp in 1 4; do
  for round in 1 2; do
    for order in rows blocks; do
      RAYSTREAM_GPU_PIXELS=$order $bin render --device gpu --size "$size" --spp $spp --max-depth 4 --repeat 20 \
        -o "$tmp/pixels-$order.png" 2>&1 | sed "s/^/[pixels $order, $spp spp, round $round] /" | tee -a "$out/render.log"
    done
  done
  cmp "$tmp/pixels-rows.png" "$tmp/pixels-blocks.png" && echo "[pixels] $spp spp: the same PNG" | tee -a "$out/render.log"
done

# The default scene (4 spp, depth 4, 20 frames) with environment variable VAR set to A and to B,
# alternated twice, lines tagged "[NAME VALUE, round R]"; the two PNGs must be equal.
render_ab() {
  local name=$1 var=$2 a=$3 b=$4 round v
  for round in 1 2; do
    for v in "$a" "$b"; do
      env "$var=$v" $bin render --device gpu --size "$size" --max-depth 4 --repeat 20 -o "$tmp/$name-$v.png" 2>&1 \
        | sed "s/^/[$name $v, round $round] /" | tee -a "$out/render.log"
    done
  done
  cmp "$tmp/$name-$a.png" "$tmp/$name-$b.png" && echo "[$name] the same PNG" | tee -a "$out/render.log"
}

# The default scene with its kd-tree kernels checked and unchecked (RAYSTREAM_GPU_CHECKS).
has "$parts" checks && render_ab checks RAYSTREAM_GPU_CHECKS on off

# The default scene with shade_hits reserving queue slots a lane or a subgroup at a time
# (RAYSTREAM_GPU_APPENDS; subgroup by default where the adapter has subgroups).
has "$parts" appends && render_ab appends RAYSTREAM_GPU_APPENDS atomic subgroup

# The default scene in waves of WAVES samples (RAYSTREAM_GPU_WAVE; default 2^20 to 2^23), 4 spp,
# two rounds; the PNGs must be equal; then the CPU's frame against the GPU's (rays.py imgdiff).
has "$parts" waves && {
waves=${WAVES:-1048576 2097152 4194304 8388608}
for round in 1 2; do
  for wave in $waves; do
    RAYSTREAM_GPU_WAVE=$wave $bin render --device gpu --size "$size" --max-depth 4 --repeat 20 -o "$tmp/wave-$wave.png" 2>&1 \
      | sed "s/^/[wave $wave, round $round] /" | tee -a "$out/render.log"
  done
done
first=${waves%% *}
for wave in $waves; do
  cmp "$tmp/wave-$first.png" "$tmp/wave-$wave.png" && echo "[waves] $wave: the same PNG as $first" | tee -a "$out/render.log"
done
$bin render --device cpu --size "$size" --max-depth 4 -o "$tmp/default-cpu.png" 2>&1 | sed "s/^/[cpu] /" | tee -a "$out/render.log"
$py "$d/rays.py" imgdiff "$tmp/default-cpu.png" "$tmp/wave-${waves##* }.png" 2>&1 | sed "s/^/[imgdiff] /" | tee -a "$out/render.log"
}

ct=$d/ct/abdomen_pelvis_ct_totalseg.nii.gz
# The default scene (the abdomen CT's bones) at depth 4; the CPU on all cores for the ratio.
has "$parts" render && {
$bin render --device gpu --size "$size" --max-depth 4 --repeat 20 -o "$out/default-gpu.png" 2>&1 | tee -a "$out/render.log"
$bin render --device cpu --size "$size" --max-depth 4 --repeat 3 -o "$out/default-cpu.png" 2>&1 | tee -a "$out/render.log"
# A turntable of it (36 frames, the camera and lights set per frame, the scene uploaded once):
# frames/s over an orbit rather than one view repeated.
$bin render --device gpu --size "$size" --max-depth 4 --turntable 36 -o "$tmp/turntable" 2>&1 \
  | sed "s/^/[turntable] /" | tee -a "$out/render.log"
# The host's submissions: a wave's depths in one submission (--submit wave, the default) against
# one per depth with the counts read back after each, alternated twice, at 4 spp and 1 spp.
for spp in 4 1; do for round in 1 2; do for submit in depth wave; do
  $bin render --device gpu --size "$size" --spp $spp --max-depth 4 --repeat 20 --submit $submit \
    -o "$tmp/submit-$submit.png" 2>&1 | sed "s/^/[submit $submit, $spp spp] /" | tee -a "$out/render.log"
done; done
cmp "$tmp/submit-depth.png" "$tmp/submit-wave.png" && echo "[submit] $spp spp: the same PNG" | tee -a "$out/render.log"
done
# Volume modes straight from the CT.
for mode in dvr mip iso; do
  $bin render "$ct" --mode $mode --device gpu --size "$dvr_size" --repeat 20 -o "$out/$mode-gpu.png" 2>&1 | tee -a "$out/render.log"
  $bin render "$ct" --mode $mode --device cpu --size "$dvr_size" --repeat 3 -o "$out/$mode-cpu.png" 2>&1 | tee -a "$out/render.log"
done
$bin render "$ct" --mode dvr --no-skip --device gpu --size "$dvr_size" --repeat 20 -o "$tmp/noskip.png" 2>&1 | tee -a "$out/render.log"
$bin render "$ct" --mode dvr --shadows --device gpu --size "$dvr_size" --repeat 20 -o "$out/dvr-shadows-gpu.png" 2>&1 | tee -a "$out/render.log"
# EXR: the default's float film read back instead of 8-bit sRGB (frames/s beside the PNG's);
# a parallel MIP's and a slice's HU on both devices, for scripts/exr-diff.py at home (the
# GPU's hardware filter weights against the CPU's f32 trilinear).
$bin render --device gpu --size "$size" --max-depth 4 --repeat 20 -o "$out/default-gpu.exr" 2>&1 | tee -a "$out/render.log"
for mode in mip slice; do for dev in gpu cpu; do
  $bin render "$ct" --mode $mode --parallel --device $dev --size "$dvr_size" --repeat 3 -o "$out/$mode-hu-$dev.exr" 2>&1 | tee -a "$out/render.log"
done; done
}
# Meshes and the CT in one scene (examples/spine_rods.toml, from the checkout), GPU and CPU.
has "$parts" scene && {
for dev in gpu cpu; do
  n=10; [ $dev = cpu ] && n=2
  $bin render examples/spine_rods.toml --device $dev --size "$size" --spp 4 --max-depth 4 --repeat $n -o "$out/spine-rods-$dev.png" 2>&1 | tee -a "$out/render.log"
done
$bin render examples/spine_rods.toml --device gpu --size "$size" --spp 4 --max-depth 4 --repeat 10 --submit depth \
  -o "$tmp/spine-depth.png" 2>&1 | sed "s/^/[submit depth] /" | tee -a "$out/render.log"
$py "$d/rays.py" imgdiff "$out/spine-rods-cpu.png" "$out/spine-rods-gpu.png" --json | tag '{"imgdiff": "spine_rods"}'
# The same scene with its CT in the colours of a label map of its halves (open question 17):
# every visible volume sample reads its eight voxels' labels (medium.wgsl's painted).
$bin info "$ct" --json | $py scripts/halves-label-map.py "$tmp/halves.mha"
sed "s|^\[volume\]|[volume]\nsegmentation = \"$tmp/halves.mha\"|; s|\.\./crates/raystream/assets|$PWD/crates/raystream/assets|" \
  examples/spine_rods.toml > "$tmp/spine-segments.toml"
$bin render "$tmp/spine-segments.toml" --device gpu --size "$size" --spp 4 --max-depth 4 --repeat 10 \
  -o "$out/spine-segments-gpu.png" 2>&1 | sed "s/^/[scene segments] /" | tee -a "$out/render.log"
}
has "$parts" volume && {
# Trilinear, as every run before 2026-12-03 measured it, then the cubic B-spline (the default
# of dvr, iso and cinematic since; open question 14): its cost on a GPU's texture units.
v=(bench "$ct" --mode dvr --resample 512 --size "$dvr_size" --json --quiet --interpolation linear)
$bin "${v[@]}" --device gpu --frames 36 | tag '{"volume": "ct-bone"}'
$bin "${v[@]}" --device gpu --frames 36 --no-skip | tag '{"volume": "ct-bone no-skip"}'
$bin "${v[@]}" --device gpu --frames 36 --preset ct-bones | tag '{"volume": "ct-bones"}'
$bin "${v[@]}" --device cpu --frames 2 | tag '{"volume": "ct-bone"}'
c=(bench "$ct" --mode dvr --resample 512 --size "$dvr_size" --json --quiet --interpolation cubic)
$bin "${c[@]}" --device gpu --frames 36 | tag '{"volume": "ct-bone cubic"}'
$bin "${c[@]}" --device gpu --frames 36 --preset ct-bones | tag '{"volume": "ct-bones cubic"}'
$bin "${c[@]}" --device cpu --frames 2 | tag '{"volume": "ct-bone cubic"}'
# The interpolating cubic B-spline: the same fetches from the coefficients' texture (the
# same cost per sample; its brick table differs).
$bin bench "$ct" --mode dvr --resample 512 --size "$dvr_size" --json --quiet --interpolation cubic-interpolating --device gpu --frames 36 | tag '{"volume": "ct-bone cubic-interpolating"}'
$bin bench "$ct" --mode mip --resample 512 --size "$dvr_size" --json --quiet --device gpu --frames 36 | tag '{"volume": "mip"}'
# Segment colours (open question 16): every voxel in one of two segments (the CT's halves), so
# every visible sample reads its eight voxels' labels; against ct-bones cubic above.
$bin info "$ct" --json | $py scripts/halves-label-map.py "$tmp/halves.mha"
$bin "${c[@]}" --device gpu --frames 36 --preset ct-bones --segmentation "$tmp/halves.mha" | tag '{"volume": "ct-bones cubic segments"}'
# Projections kept to a segment (open question 19): one march reading the kept CT and its
# weights from the two channels of one Rg16Float texture, against a plain one's R16Float.
a=(bench "$ct" --mode average --resample 512 --size "$dvr_size" --json --quiet --device gpu --frames 36)
$bin "${a[@]}" | tag '{"volume": "average"}'
$bin "${a[@]}" --segmentation "$tmp/halves.mha" --segment 1 | tag '{"volume": "average kept to segments"}'
$bin bench "$ct" --mode mip --resample 512 --size "$dvr_size" --json --quiet --device gpu --frames 36 --segmentation "$tmp/halves.mha" --segment 1 | tag '{"volume": "mip kept to segments"}'
$bin render "$ct" --mode dvr --shadows --preset ct-bones --device gpu --size "$dvr_size" -o "$out/dvr-bones-shadows-gpu.png" 2>&1 | tee -a "$out/render.log"
# Animations (open question 18): a 36-frame dvr turntable as a folder of PNGs, one APNG and one
# GIF; the wall time of each whole command, so that the encoding shows beside the GPU's frames.
for f in png apng gif; do
  o="$tmp/turntable-dvr"; [ $f = apng ] && o="$tmp/turntable-dvr.png"; [ $f = gif ] && o="$tmp/turntable-dvr.gif"
  t0=$(date +%s%N)
  $bin render "$ct" --mode dvr --preset ct-bones --device gpu --size "$dvr_size" --turntable 36 --format $f -o "$o" 2>&1 \
    | sed "s/^/[animation $f] /" | tee -a "$out/render.log"
  echo "[animation $f] wall $(( ($(date +%s%N) - t0) / 1000000 )) ms" | tee -a "$out/render.log"
done
# Cinematic rendering (64 paths a pixel, 4 scatterings): an orbit of 4 frames at 512³, one
# picture of 256 paths a pixel, and one of 16 denoised.
$bin bench "$ct" --mode cinematic --preset ct-bones --resample 512 --size "$dvr_size" --json --quiet --device gpu --frames 4 --interpolation linear | tag '{"volume": "cinematic ct-bones"}'
$bin bench "$ct" --mode cinematic --preset ct-bones --resample 512 --size "$dvr_size" --json --quiet --device gpu --frames 4 --interpolation cubic | tag '{"volume": "cinematic ct-bones cubic"}'
$bin render "$ct" --mode cinematic --preset ct-aaa --spp 256 --device gpu --size "$dvr_size" -o "$out/cinematic-gpu.png" 2>&1 | tee -a "$out/render.log"
# Denoised: 16 paths a pixel, traced, guided and filtered on the GPU (its line names what the
# guides and the filter took).
$bin render "$ct" --mode cinematic --preset ct-aaa --spp 16 --denoise --device gpu --size "$dvr_size" -o "$out/cinematic-denoised-gpu.png" 2>&1 | tee -a "$out/render.log"
# A fly-through of the chest CT's aorta (open question 20): 36 frames from inside the lumen,
# on the GPU and (4 frames) on the CPU; the median frame time is on each line.
chest=$d/ct/chest_ct_stents_totalseg.nii.gz
[ -f "$chest" ] && for dev in gpu cpu; do
  n=36; [ $dev = cpu ] && n=4
  $bin render "$chest" --mode dvr --tf "$d/ct/angioscopy.toml" --path "$d/ct/chest_aorta.mrk.json" --fly $n \
    --device $dev --size "$dvr_size" -o "$tmp/fly-$dev" 2>&1 | sed "s/^/[fly $dev] /" | tee -a "$out/render.log"
done
}
(cd "$out" && shopt -s nullglob && f=(./*.png ./*.exr) && [ ${#f[@]} -gt 0 ] \
  && tar cf images.tar "${f[@]}" && rm -f "${f[@]}")
echo done
