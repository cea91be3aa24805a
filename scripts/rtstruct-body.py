"""Writes an RT Structure Set of a CT series' body outline (over -500 HU) and bones (over
300 HU) with rt-utils, for the structure-set benchmark (BENCHMARKS.md):

    rtstruct-body.py SERIES_DIR OUT.dcm

Put OUT.dcm in a folder beside SERIES_DIR, as an export lays them out.
"""

import sys

import numpy as np
from rt_utils import RTStructBuilder
from rt_utils.image_helper import load_sorted_image_series

series, out = sys.argv[1:3]
rt = RTStructBuilder.create_new(dicom_series_path=series)
images = load_sorted_image_series(series)
hu = np.stack(
    [ds.pixel_array * float(ds.RescaleSlope) + float(ds.RescaleIntercept) for ds in images],
    axis=-1,
)
body, bone = hu > -500, hu > 300
rt.add_roi(mask=body, name="BODY", color=[255, 200, 150])
rt.add_roi(mask=bone, name="Bone", color=[240, 240, 220])
rt.save(out)
print(f"{out}: BODY {body.sum()} voxels, Bone {bone.sum()} voxels")
