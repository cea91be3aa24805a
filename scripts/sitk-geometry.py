#!/usr/bin/env python3
"""Print SimpleITK's geometry of a volume file or DICOM folder as one JSON line: the source of
the expected values in crates/raystream-io/src/volume/tests.rs.
Usage: .venv/bin/pip install SimpleITK; .venv/bin/python scripts/sitk-geometry.py PATH..."""
import json, os, sys
import SimpleITK as sitk

for path in sys.argv[1:]:
    if os.path.isdir(path):
        r = sitk.ImageSeriesReader()
        r.SetFileNames(r.GetGDCMSeriesFileNames(path))
        im = r.Execute()
    else:
        im = sitk.ReadImage(path)
    a = sitk.GetArrayViewFromImage(im)
    print(json.dumps({"file": path, "dims": im.GetSize(), "spacing": im.GetSpacing(),
                      "origin": im.GetOrigin(), "direction": im.GetDirection(),
                      "range": [float(a.min()), float(a.max())]}))
