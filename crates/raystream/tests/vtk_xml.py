"""VTK itself (the vtk wheel's XML writers) as the reference for raystream's reading of VTK's
XML formats, for tests/volume.rs.
Usage: python vtk_xml.py CT.nii.gz OUTDIR
Cuts a block of the CT (SimpleITK), gives it an oblique direction and writes it as ref.nii;
writes the same voxels and grid as VTK XML image data (.vti) in every way VTK writes them:
ASCII, inline binary and appended (raw and base64), uncompressed and under each compressor
(zlib, LZ4, LZMA), with 32- and 64-bit headers, little- and big-endian, with a block size that
splits the data into many blocks. Writes a sphere (vtkSphereSource, with normals) as PLY and
as polygonal data (.vtp) the same ways, and as triangle strips (vtkStripper). Prints one JSON
object naming the files written."""
import json, os, sys

import numpy as np
import SimpleITK as sitk
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkFiltersCore import vtkStripper
from vtkmodules.vtkFiltersSources import vtkSphereSource
from vtkmodules.vtkIOPLY import vtkPLYWriter
from vtkmodules.vtkIOXML import vtkXMLImageDataWriter, vtkXMLPolyDataWriter
from vtkmodules.util.numpy_support import numpy_to_vtk

src, out = sys.argv[1:3]
os.makedirs(out, exist_ok=True)

im = sitk.ReadImage(src)[30:70, 20:56, 40:70]
# An oblique direction (20° about z, then 10° about x), kept as it is: only the grid turns.
a, b = np.radians(20.0), np.radians(10.0)
rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
d = rx @ rz
im.SetDirection(d.ravel().tolist())
im.SetOrigin((-12.5, 40.25, 310.0))
sitk.WriteImage(im, os.path.join(out, "ref.nii"))

img = vtkImageData()
img.SetDimensions(im.GetSize())
img.SetSpacing(im.GetSpacing())
img.SetOrigin(im.GetOrigin())
img.SetDirectionMatrix(*d.ravel().tolist())
voxels = numpy_to_vtk(sitk.GetArrayFromImage(im).ravel(), deep=1)
voxels.SetName("HU")
img.GetPointData().SetScalars(voxels)

ply = vtkSphereSource()
ply.SetCenter(10.0, -20.5, 300.25)
ply.SetRadius(30.0)
ply.SetThetaResolution(24)
ply.SetPhiResolution(16)
ply.Update()
w = vtkPLYWriter()
w.SetInputConnection(ply.GetOutputPort())
w.SetFileTypeToBinary()
w.SetFileName(os.path.join(out, "sphere.ply"))
assert w.Write() == 1
stripper = vtkStripper()
stripper.SetInputConnection(ply.GetOutputPort())
stripper.Update()


def variants():
    yield "ascii", lambda w: w.SetDataModeToAscii()
    for mode in ("binary", "raw", "base64"):
        for comp in ("none", "zlib", "lz4", "lzma"):
            for header in (32, 64):
                for endian in ("le", "be"):
                    # Every mode and compressor; the header and byte order on some of them.
                    if (header, endian) != (32, "le") and comp not in ("none", "zlib"):
                        continue

                    def setup(w, mode=mode, comp=comp, header=header, endian=endian):
                        if mode == "binary":
                            w.SetDataModeToBinary()
                        else:
                            w.SetDataModeToAppended()
                            w.SetEncodeAppendedData(mode == "base64")
                        {"none": w.SetCompressorTypeToNone, "zlib": w.SetCompressorTypeToZLib,
                         "lz4": w.SetCompressorTypeToLZ4, "lzma": w.SetCompressorTypeToLZMA}[comp]()
                        if comp != "none":
                            w.SetBlockSize(4096)  # many blocks, the last one short
                        (w.SetHeaderTypeToUInt32 if header == 32 else w.SetHeaderTypeToUInt64)()
                        (w.SetByteOrderToLittleEndian if endian == "le" else w.SetByteOrderToBigEndian)()
                    yield f"{mode}_{comp}_{header}_{endian}", setup


images, surfaces = [], []
for name, setup in variants():
    w = vtkXMLImageDataWriter()
    w.SetInputData(img)
    setup(w)
    w.SetFileName(os.path.join(out, f"ct_{name}.vti"))
    assert w.Write() == 1
    images.append(f"ct_{name}.vti")
    for what, data in (("surface", ply.GetOutput()), ("strips", stripper.GetOutput())):
        w = vtkXMLPolyDataWriter()
        w.SetInputData(data)
        setup(w)
        w.SetFileName(os.path.join(out, f"{what}_{name}.vtp"))
        assert w.Write() == 1
        surfaces.append(f"{what}_{name}.vtp")

# An extent that starts away from 0 (a cropped image, as vtkExtractVOI leaves it): its first
# voxel lies where VTK puts it, Origin + Direction · (Spacing ⊙ the extent's low corner).
crop = vtkImageData()
crop.SetExtent(3, 8, 2, 6, 1, 4)
crop.SetSpacing(0.5, 0.75, 2.0)
crop.SetOrigin(-7.0, 11.0, 130.0)
crop.SetDirectionMatrix(*d.ravel().tolist())
ramp = numpy_to_vtk(np.arange(6 * 5 * 4, dtype=np.int16), deep=1)
ramp.SetName("ramp")
crop.GetPointData().SetScalars(ramp)
w = vtkXMLImageDataWriter()
w.SetInputData(crop)
w.SetFileName(os.path.join(out, "cropped.vti"))
assert w.Write() == 1

print(json.dumps({"images": images, "surfaces": surfaces,
                  "strips": stripper.GetOutput().GetNumberOfStrips(),
                  "cropped": {"first": crop.GetPoint(0), "last": crop.GetPoint(6 * 5 * 4 - 1)}}))
