#!/usr/bin/env bash
# Isosurface extraction, raystream beside VTK on the same 512³ volume and threshold, one run.
# Needs .venv with SimpleITK and vtk (pip install SimpleITK vtk) and a release build.
set -euo pipefail
cd "$(dirname "$0")/.."
size=${SIZE:-512}
vol=${TMPDIR:-/tmp}/abdomen_${size}.nii
.venv/bin/python scripts/bench-iso.py ../shared/data/volumes/nifti/abdomen_pelvis_ct_totalseg.nii.gz "$vol" --size "$size" --iso 300 --repeat 3
target/release/raystream bench "$vol" --iso 300 --repeat 3 --json
