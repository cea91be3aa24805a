#!/usr/bin/env python3
"""Isosurface benchmark beside VTK: resamples the abdomen CT to N³ (SimpleITK, linear), writes it
as NIfTI, and times VTK's vtkFlyingEdges3D and vtkMarchingCubes on it at the same threshold
(median of --repeat runs, all cores). `scripts/bench-iso.sh` runs `raystream bench` on the same
file in the same run.
Usage: bench-iso.py CT.nii.gz OUT.nii --size 512 --iso 300 --repeat 3"""
import argparse, json, statistics, time
import SimpleITK as sitk

ap = argparse.ArgumentParser()
ap.add_argument("ct"); ap.add_argument("out")
ap.add_argument("--size", type=int, default=512); ap.add_argument("--iso", type=float, default=300)
ap.add_argument("--repeat", type=int, default=3); ap.add_argument("--write-only", action="store_true")
a = ap.parse_args()

im = sitk.ReadImage(a.ct)
size = [a.size] * 3
spacing = [sz * sp / a.size for sz, sp in zip(im.GetSize(), im.GetSpacing())]
res = sitk.Resample(im, size, sitk.Transform(), sitk.sitkLinear, im.GetOrigin(), spacing,
                    im.GetDirection(), -1024, sitk.sitkInt16)
sitk.WriteImage(res, a.out)
if a.write_only:
    raise SystemExit

import numpy as np, vtk
from vtk.util import numpy_support
arr = sitk.GetArrayFromImage(res)  # z, y, x
img = vtk.vtkImageData()
img.SetDimensions(a.size, a.size, a.size)
img.SetSpacing(*spacing)
img.GetPointData().SetScalars(numpy_support.numpy_to_vtk(arr.ravel(), deep=True))
for name, cls in [("vtkFlyingEdges3D", vtk.vtkFlyingEdges3D), ("vtkMarchingCubes", vtk.vtkMarchingCubes)]:
    times = []
    for _ in range(a.repeat + 1):
        f = cls(); f.SetInputData(img); f.SetValue(0, a.iso); f.ComputeNormalsOn()
        t = time.perf_counter(); f.Update(); times.append((time.perf_counter() - t) * 1e3)
    ms = statistics.median(times[1:])
    print(json.dumps({"impl": name, "vtk": vtk.vtkVersion.GetVTKVersion(), "dims": size,
                      "iso_hu": a.iso, "iso_ms": round(ms, 1),
                      "mvoxels_per_s": round(a.size ** 3 / ms / 1e3, 1),
                      "triangles": f.GetOutput().GetNumberOfCells(),
                      "threads": vtk.vtkSMPTools.GetEstimatedNumberOfThreads()}))
