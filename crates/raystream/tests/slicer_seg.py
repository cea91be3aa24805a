"""slicerio (3D Slicer's own Python reader and writer of .seg.nrrd files) as the reference for
raystream's reading of 3D Slicer segmentations, for tests/volume.rs.
Usage: python slicer_seg.py OUTDIR
Takes the segmentations 3D Slicer wrote that slicerio ships (a chest CT's, one layer; the same
with an overlapping sphere on a second layer) and its CT; writes with slicerio an oblique
segmentation whose segments overlap, and, by hand, one in the format of Slicer before 4.11 (no
label values: a layer for each segment). Prints one JSON object: for each file, its path, its
voxel-to-LPS matrix and each segment's name, colour (0-255), voxels and centroid (LPS mm); the
CT's mean value within each segment of the first file, its share below -950 and -856 HU and its
15th and 2.5th percentiles, its mass (g, at (HU + 1000) / 1000 g/ml) and its Agatston score (its
bones' calcium; scipy.ndimage.label's lesions in each slice), the two lungs' together
and a voxel's volume (ml); each lung's clusters of voxels below
-910 HU (scipy.ndimage.label's), in 3D and within each slice, with the power law of their
sizes."""
import json, os, sys

import nrrd
import numpy as np
import scipy.ndimage
import slicerio

out = sys.argv[1]
os.makedirs(out, exist_ok=True)
data = os.path.join(os.path.dirname(slicerio.__file__), "data")


def describe(path, masks=None):
    """`masks`: each segment's voxels, where slicerio does not find them (it takes every
    segment of a file without label values from the first layer)."""
    s = slicerio.read_segmentation(path)
    m = s["ijkToLPS"]
    segments = []
    for n, seg in enumerate(s["segments"]):
        mask = slicerio.segment_mask(s, seg["id"]) if masks is None else masks[n]
        ijk = np.argwhere(mask).astype("float64")
        centroid = (m[:3, :3] @ ijk.mean(axis=0) + m[:3, 3]).tolist() if len(ijk) else None
        terms = seg.get("terminology", {})
        code = lambda part: terms[part] if part in terms and terms[part][1] else None
        segments.append({
            "name": seg["name"],
            "category": code("category"),
            "type": code("type"),
            "modifier": code("typeModifier"),
            "region": code("anatomicRegion"),
            "region_modifier": code("anatomicRegionModifier"),
            "colour": [int(np.floor(c * 255 + 0.5)) for c in seg["color"]] if "color" in seg else None,
            "voxels": int(mask.sum()),
            "centroid": centroid,
        })
    return {"path": path, "ijk_to_lps": m.tolist(), "segments": segments}, s


files = []
one_layer = os.path.join(data, "Segmentation.seg.nrrd")
d, flat = describe(one_layer)
files.append(d)
files.append(describe(os.path.join(data, "SegmentationOverlapping.seg.nrrd"))[0])

# The CT the segmentation was drawn on: its mean within each segment.
ct_path = os.path.join(data, "CTChest4.nrrd")
ct, _ = nrrd.read(ct_path)
assert ct.shape == flat["voxels"].shape, (ct.shape, flat["voxels"].shape)
values = [ct[slicerio.segment_mask(flat, seg["id"])].astype("float64")
          for seg in flat["segments"]]
means = [float(v.mean()) for v in values]
# Lung densitometry: the share below -950 and -856 HU (per cent), the 15th and 2.5th
# percentiles (numpy's linear interpolation).
below = [[float((v < hu).mean() * 100) for hu in (-950, -856)] for v in values]
percentiles = [np.percentile(v, [15, 2.5]).tolist() for v in values]
# Both lungs together (their masks' union): voxels, share below -950 HU, 15th percentile.
names = [seg["name"] for seg in flat["segments"]]
lungs = ct[slicerio.segment_mask(flat, flat["segments"][names.index("right lung")]["id"])
           | slicerio.segment_mask(flat, flat["segments"][names.index("left lung")]["id"])
           ].astype("float64")
both = [int(lungs.size), float((lungs < -950).mean() * 100), float(np.percentile(lungs, 15))]
# A voxel's volume (ml), and each segment's mass (g) with each voxel's density (HU + 1000) / 1000
# g/ml, as lung weight is found.
voxel_ml = float(abs(np.linalg.det(flat["ijkToLPS"][:3, :3]))) / 1000.0
masses = [float(((v + 1000.0) / 1000.0).sum() * voxel_ml) for v in values]


def agatston(mask):
    """The Agatston score of the CT's voxels in `mask`: in each slice (the third axis), the
    pieces of those at 130 HU or more (scipy.ndimage.label, the eight about each voxel), each of
    1 mm² or more counted as its area times 1 to 4 by its peak (130, 200, 300, 400 HU), times
    the slice spacing over 3 mm; with the volume (mm³), the lesions, the slices and the peak."""
    m = flat["ijkToLPS"][:3, :3]
    pixel = float(np.linalg.norm(np.cross(m[:, 0], m[:, 1])))
    slice_mm = float(abs(np.linalg.det(m))) / pixel
    score = volume = 0.0
    lesions, slices, peak, each = 0, set(), None, []
    for k in range(ct.shape[2]):
        hot = mask[:, :, k] & (ct[:, :, k] >= 130)
        labels, n = scipy.ndimage.label(hot, structure=np.ones((3, 3)))
        if n == 0:
            continue
        sizes = np.bincount(labels.ravel())[1:]
        peaks = scipy.ndimage.maximum(ct[:, :, k], labels, np.arange(1, n + 1))
        for size, top in zip(sizes, peaks):
            if size * pixel < 1.0:
                continue
            weight = 4 if top >= 400 else 3 if top >= 300 else 2 if top >= 200 else 1
            score += size * pixel * weight * slice_mm / 3.0
            volume += size * pixel * slice_mm
            lesions += 1
            slices.add(k)
            peak = float(top) if peak is None else max(peak, float(top))
            each.append([k, int(size), float(top)])
    return {"score": score, "volume_mm3": volume, "lesions": lesions, "slices": len(slices),
            "peak_hu": peak, "each": sorted(each)}


calcium = [agatston(slicerio.segment_mask(flat, seg["id"])) for seg in flat["segments"]]


def clusters(mask, structure):
    """scipy.ndimage.label's clusters of `mask`: their count, each size met with its count,
    and numpy.polyfit's line through (ln X, ln Y), Y the clusters of at least X voxels: D (its
    slope, negated) and r² (numpy.corrcoef's)."""
    labels, count = scipy.ndimage.label(mask, structure=structure)
    sizes, counts = np.unique(np.bincount(labels.ravel())[1:], return_counts=True)
    at_least = counts[::-1].cumsum()[::-1]
    x, y = np.log(sizes), np.log(at_least)
    d = r2 = None
    if len(sizes) > 1:
        d, r2 = float(-np.polyfit(x, y, 1)[0]), float(np.corrcoef(x, y)[0, 1] ** 2)
    return {"count": int(count), "sizes": [[int(a), int(b)] for a, b in zip(sizes, counts)],
            "d": d, "r2": r2}


# The clusters of each lung's voxels below -910 HU: in 3D (scipy's default structure, the six
# face neighbours) and within each slice (the four in the plane of the first two axes).
in_slices = np.zeros((3, 3, 3), bool)
in_slices[:, :, 1] = scipy.ndimage.generate_binary_structure(2, 1)
lung_clusters = {}
for name in ("right lung", "left lung"):
    mask = slicerio.segment_mask(flat, flat["segments"][names.index(name)]["id"]) & (ct < -910)
    lung_clusters[name] = {"3d": clusters(mask, None), "2d": clusters(mask, in_slices)}

# An oblique grid (rotated 30° about z, then 20° about x; uneven spacing), three segments: a
# ball and a slab that overlaps it (slicerio puts it on a second layer), and a cube apart.
shape = (40, 36, 24)
a, b = np.radians(30.0), np.radians(20.0)
rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
m = np.eye(4)
m[:3, :3] = rx @ rz @ np.diag([0.8, 1.1, 2.5])
m[:3, 3] = [-12.5, 40.0, -210.0]
s = slicerio.create_segmentation(shape, m)
i, j, k = np.indices(shape)
ball = (i - 15) ** 2 + (j - 16) ** 2 + ((k - 11) * 2) ** 2 <= 10 ** 2
slab = (i >= 12) & (i < 30) & (j >= 5) & (j < 30) & (k >= 10) & (k < 14)
cube = (i >= 32) & (i < 38) & (j >= 28) & (j < 34) & (k >= 2) & (k < 8)
# The ball is coded as Slicer codes a mass in the right adrenal gland: its type, and the
# anatomic region it lies in with that region's modifier.
mass = {"contextName": "Segmentation category and type - 3D Slicer General Anatomy list",
        "category": ["SCT", "49755003", "Morphologically Altered Structure"],
        "type": ["SCT", "4147007", "Mass"],
        "anatomicContextName": "Anatomic codes - DICOM master list",
        "anatomicRegion": ["SCT", "23451007", "Adrenal gland"],
        "anatomicRegionModifier": ["SCT", "24028007", "Right"]}
for name, mask, colour in (("ball", ball, [1.0, 0.2, 0.2]), ("slab", slab, [0.2, 0.4, 1.0]),
                           ("cube", cube, [0.1, 0.9, 0.3])):
    segment = {"id": name, "name": name, "color": colour}
    if name == "ball":
        segment["terminology"] = mass
    slicerio.add_segment(s, mask, segment)
oblique = os.path.join(out, "oblique.seg.nrrd")
slicerio.write_segmentation(oblique, s)
files.append(describe(oblique)[0])

# Slicer before 4.11: a layer for each segment, its voxels 1, no LabelValue or Layer fields.
legacy = os.path.join(out, "legacy.seg.nrrd")
layers = np.stack([ball, slab]).astype("uint8")
header = {
    "type": "unsigned char", "dimension": 4, "space": "right-anterior-superior",
    "kinds": ["list", "domain", "domain", "domain"],
    "space directions": np.vstack([[np.nan] * 3, (np.diag([-1.0, -1.0, 1.0]) @ m[:3, :3]).T]),
    "space origin": np.diag([-1.0, -1.0, 1.0]) @ m[:3, 3],
    "encoding": "gzip",
    "Segment0_ID": "Ball", "Segment0_Name": "ball", "Segment0_Color": "1 0.2 0.2",
    "Segment1_ID": "Slab", "Segment1_Name": "slab", "Segment1_Color": "0.2 0.4 1",
}
nrrd.write(legacy, layers, header, custom_field_map={})
files.append(describe(legacy, [ball, slab])[0])

print(json.dumps({"files": files, "ct": ct_path, "ct_means": means, "ct_below": below,
                  "ct_percentiles": percentiles, "ct_lungs": both,
                  "ct_voxel_ml": voxel_ml, "ct_masses": masses, "ct_agatston": calcium,
                  "lung_clusters": lung_clusters}))
