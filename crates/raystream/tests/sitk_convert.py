"""Writes the abdomen CT, resampled onto an oblique grid, in every format raystream reads
(.nrrd, .nhdr + gzip data, .mha, .mhd + raw, .nii, .nii.gz, legacy VTK .vtk) with SimpleITK, and prints SimpleITK's
reading of each written file as JSON lines: the reference for tests/volume.rs.
Usage: python sitk_convert.py INPUT.nii.gz OUTDIR"""
import json, os, sys
import SimpleITK as sitk

src, out = sys.argv[1], sys.argv[2]
os.makedirs(out, exist_ok=True)
im = sitk.ReadImage(src)
# An oblique, anisotropic grid: rotate the direction by 20° about LPS z and 10° about x.
rot = sitk.VersorTransform((0, 0, 1), 0.35)
d = rot.GetMatrix()
small = sitk.Resample(im, [40, 36, 30], sitk.Transform(), sitk.sitkLinear,
                      im.TransformContinuousIndexToPhysicalPoint([20, 15, 40]),
                      [2.5, 3.0, 3.5], d, -1024, sitk.sitkInt16)
for name, kw in [("oblique.nrrd", {}), ("oblique.nhdr", {"useCompression": True}),
                 ("oblique.mha", {"useCompression": True}), ("oblique.mhd", {}),
                 ("oblique.nii", {}), ("oblique.nii.gz", {}),
                 # ITK's legacy VTK writer keeps no direction: read back, the grid is axial.
                 ("oblique.vtk", {})]:
    path = os.path.join(out, name)
    sitk.WriteImage(small, path, **kw)
    back = sitk.ReadImage(path)
    a = sitk.GetArrayViewFromImage(back)
    print(json.dumps({"file": name, "dims": back.GetSize(), "spacing": back.GetSpacing(),
                      "origin": back.GetOrigin(), "direction": back.GetDirection(),
                      "range": [float(a.min()), float(a.max())], "sum": float(a.sum())}))
