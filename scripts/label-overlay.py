#!/usr/bin/env python3
"""Draw a label map (`raystream measure --mask`) over its CT's axial slices, as README's
docs/mask.png shows it: each slice windowed (W 400, L 40), label 1 tinted cyan and label 2
magenta, cropped about the labels and set side by side.
Usage: .venv/bin/python scripts/label-overlay.py CT MASK OUT.png [SLICES] [HALF_MM]
SLICES: how many axial slices, evenly through those with labels (default 5); HALF_MM: the
crop's half-width about the labels' centre (default 37.5)."""
import sys
import numpy as np
import SimpleITK as sitk
from PIL import Image

ct_path, mask_path, out = sys.argv[1:4]
count = int(sys.argv[4]) if len(sys.argv) > 4 else 5
half_mm = float(sys.argv[5]) if len(sys.argv) > 5 else 37.5
ct, mask = sitk.ReadImage(ct_path), sitk.ReadImage(mask_path)
if ct.GetSize() != mask.GetSize():
    sys.exit(f"{mask_path}: not on {ct_path}'s grid")
hu, labels = sitk.GetArrayFromImage(ct), sitk.GetArrayFromImage(mask)  # [k][j][i]
zs = [z for z in range(labels.shape[0]) if labels[z].any()]
if not zs:
    sys.exit(f"{mask_path}: no labels")
half = int(round(half_mm / ct.GetSpacing()[0]))
tiles = []
for z in [zs[int((len(zs) - 1) * (t + 0.5) / count)] for t in range(count)]:
    g = (np.clip((hu[z] + 160.0) / 400.0, 0, 1) * 255)[..., None].repeat(3, -1)
    for label, tint in ((1, (0, 255, 255)), (2, (255, 0, 255))):
        on = labels[z] == label
        g[on] = 0.5 * g[on] + 0.5 * np.array(tint)
    ys, xs = np.nonzero(labels[z])
    cy, cx = int(ys.mean()), int(xs.mean())
    g = np.pad(g, ((half, half), (half, half), (0, 0)))
    crop = g[cy:cy + 2 * half, cx:cx + 2 * half].astype(np.uint8)
    tiles.append(Image.fromarray(crop).resize((4 * 2 * half, 4 * 2 * half), Image.NEAREST))
side = tiles[0].width
sheet = Image.new("RGB", (count * side + 4 * (count - 1), side), "white")
for t, tile in enumerate(tiles):
    sheet.paste(tile, (t * (side + 4), 0))
sheet.save(out)
