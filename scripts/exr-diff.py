#!/usr/bin/env python3
"""Compares two EXR images that `raystream render -o OUT.exr` wrote (say, the GPU's and the
CPU's HU of one MIP or slice): channel by channel, whether the same pixels are NaN, and the
absolute differences of the rest (median, 99th percentile, largest).

  .venv/bin/python scripts/exr-diff.py A.exr B.exr [--json]

Needs `pip install OpenEXR numpy`. Exits 1 if the channels or the NaN pixels differ.
"""
import argparse
import json
import sys

import numpy as np
import OpenEXR


def channels(path):
    with OpenEXR.File(path) as f:
        return {name: np.asarray(c.pixels, dtype=np.float64) for name, c in f.channels().items()}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    a, b = channels(args.a), channels(args.b)
    if a.keys() != b.keys():
        print(f"channels differ: {sorted(a)} vs {sorted(b)}", file=sys.stderr)
        return 1
    out, ok = {}, True
    for name in sorted(a):
        x, y = a[name], b[name]
        if x.shape != y.shape:
            print(f"{name}: sizes differ: {x.shape} vs {y.shape}", file=sys.stderr)
            return 1
        nan_x, nan_y = np.isnan(x), np.isnan(y)
        same_nan = bool((nan_x == nan_y).all())
        ok &= same_nan
        both = ~nan_x & ~nan_y
        d = np.abs(x[both] - y[both])
        d = d[np.isfinite(d)]
        out[name] = {
            "pixels": int(x.size),
            "nan": int(nan_x.sum()),
            "same_nan": same_nan,
            "median": float(np.median(d)) if d.size else 0.0,
            "p99": float(np.percentile(d, 99)) if d.size else 0.0,
            "max": float(d.max()) if d.size else 0.0,
        }
    if args.json:
        print(json.dumps({"a": args.a, "b": args.b, "channels": out}))
    else:
        for name, r in out.items():
            print(f"{name}: {r['pixels']} pixels, {r['nan']} NaN ({'the same' if r['same_nan'] else 'NOT the same'}), "
                  f"|diff| median {r['median']:.4g}, p99 {r['p99']:.4g}, max {r['max']:.4g}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
