#!/usr/bin/env python3
"""Reorders a RAYS.bin (8 little-endian float32 per ray: origin, t_min, direction, t_max) for
coherence, the literature's remedy for divergent secondary rays: by direction octant, then by
the Morton code of the origin (10 bits an axis, over the origins' bounding box). The rays are
the same; only their order changes, so a GPU's subgroups get neighbouring rays that head the
same way.

    scripts/sort-rays.py IN.rays OUT.rays

Used by scripts/device-bench.sh (the TRACERS entry "sorted") to measure whether reordering pays
on a GPU (`raystream trace --stats` on both orders). numpy only: it travels to the lent GPU with
rays.py's wheels. Written here because it is an offline experiment, not a product feature: on the
2-core CPU the sort cost more than it saved (BENCHMARKS.md).
"""
import sys

import numpy as np


def spread_bits(v: np.ndarray) -> np.ndarray:
    """10-bit integers with two zero bits inserted after each bit (for 3-D Morton codes)."""
    v = v.astype(np.uint64) & 0x3FF
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    v = (v | (v << 2)) & 0x09249249
    return v


def order(rays: np.ndarray) -> np.ndarray:
    """The permutation: octant of the direction (3 bits) above the origin's 30-bit Morton code."""
    o, d = rays[:, 0:3], rays[:, 4:7]
    lo, hi = o.min(axis=0), o.max(axis=0)
    q = np.clip((o - lo) / np.maximum(hi - lo, 1e-30) * 1023.0, 0, 1023).astype(np.uint64)
    morton = spread_bits(q[:, 0]) | (spread_bits(q[:, 1]) << 1) | (spread_bits(q[:, 2]) << 2)
    octant = ((d[:, 0] < 0).astype(np.uint64) << 2) | ((d[:, 1] < 0).astype(np.uint64) << 1) | (
        d[:, 2] < 0
    ).astype(np.uint64)
    return np.argsort((octant << 30) | morton, kind="stable")


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit("usage: sort-rays.py IN.rays OUT.rays")
    src, dst = sys.argv[1], sys.argv[2]
    raw = np.fromfile(src, dtype="<f4")
    if raw.size % 8:
        sys.exit(f"{src}: {raw.size * 4} bytes is not a multiple of 32 (8 float32 per ray)")
    rays = raw.reshape(-1, 8)
    rays[order(rays)].tofile(dst)


if __name__ == "__main__":
    main()
