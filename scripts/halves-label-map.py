#!/usr/bin/env python3
"""A label map of a volume's two halves, for measuring segment colours where no real
segmentation of the volume is at hand (scripts/device-bench.sh, part `volume`).

Usage: raystream info CT --json | halves-label-map.py OUT.mha

Writes a MetaImage (8-bit labels, standard library only) on an axis-aligned 2 mm grid that
covers the CT's box in LPS millimetres: label 1 where x (LPS) lies below the box's middle, 2
above it. Every CT voxel then lies in a segment, so every visible sample takes the colour
lookup: what it costs is the figure wanted, not the picture.
"""
import itertools
import json
import sys

info = json.load(sys.stdin)
dims, spacing, origin = info["dims"], info["spacing"], info["origin"]
d = info["direction"]  # row-major, columns = the axes' directions
corners = []
for c in itertools.product(*[(0, n - 1) for n in dims]):
    step = [c[a] * spacing[a] for a in range(3)]
    corners.append([origin[r] + sum(d[3 * r + a] * step[a] for a in range(3)) for r in range(3)])
lo = [min(p[r] for p in corners) - 2.0 for r in range(3)]
hi = [max(p[r] for p in corners) + 2.0 for r in range(3)]
n = [int((hi[r] - lo[r]) / 2.0) + 1 for r in range(3)]
middle = 0.5 * (lo[0] + hi[0])
row = bytes(1 + (lo[0] + 2.0 * i > middle) for i in range(n[0]))
with open(sys.argv[1], "wb") as f:
    f.write(
        (
            "ObjectType = Image\nNDims = 3\n"
            f"DimSize = {n[0]} {n[1]} {n[2]}\nElementSpacing = 2 2 2\n"
            f"Offset = {lo[0]} {lo[1]} {lo[2]}\nTransformMatrix = 1 0 0 0 1 0 0 0 1\n"
            "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n"
        ).encode()
    )
    f.write(row * (n[1] * n[2]))
