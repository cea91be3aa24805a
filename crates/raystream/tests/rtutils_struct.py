"""Writes an RT Structure Set of a label map's labels with rt-utils (an independent writer:
OpenCV traces each slice's boundary, through the centres of its boundary pixels, into polygons).

    rtutils_struct.py SERIES_DIR LABELS.nii.gz OUT.dcm [--blank-series] NAME=L[+L…]:R,G,B …

Each structure is the voxels whose label is one of L…, drawn on the CT series in SERIES_DIR
(the label map is on that series' grid); its slices are matched to the series' images by
position, not by order, for rt-utils sorts them itself. `--blank-series` blanks the series
UID it references, as some anonymisers do, leaving its Frame of Reference.
"""

import sys

import numpy as np
import SimpleITK as sitk
from rt_utils import RTStructBuilder
from rt_utils.image_helper import load_sorted_image_series

series_dir, labels_path, out = sys.argv[1:4]
specs = sys.argv[4:]
blank = "--blank-series" in specs
specs = [s for s in specs if s != "--blank-series"]
image = sitk.ReadImage(labels_path)
labels = sitk.GetArrayFromImage(image)  # k, j, i
rt = RTStructBuilder.create_new(dicom_series_path=series_dir)
images = load_sorted_image_series(series_dir)
# The label map's slice under each of rt-utils' sorted images.
ks = []
for ds in images:
    i, j, k = image.TransformPhysicalPointToIndex([float(v) for v in ds.ImagePositionPatient])
    assert (i, j) == (0, 0), (i, j)
    ks.append(k)
for spec in specs:
    name, rest = spec.split("=")
    values, colour = rest.split(":")
    held = np.isin(labels, [int(v) for v in values.split("+")])
    # rt-utils takes mask[row, column, image]: row j, column i.
    mask = np.stack([held[k] for k in ks], axis=-1)
    rt.add_roi(mask=mask, name=name, color=[int(c) for c in colour.split(",")])
if blank:
    for frame in rt.ds.ReferencedFrameOfReferenceSequence:
        for study in frame.RTReferencedStudySequence:
            for series in study.RTReferencedSeriesSequence:
                series.SeriesInstanceUID = ""
rt.save(out)
print(out)
