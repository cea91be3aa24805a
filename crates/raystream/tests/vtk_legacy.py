"""VTK itself (the vtk wheel's legacy readers and writers) as the reference for raystream's
legacy VTK files, for tests/volume.rs.
Usage: python vtk_legacy.py MODEL.vtk SURFACE.ply OUTDIR
Reads MODEL.vtk (`iso`'s) with vtkPolyDataReader and prints what it holds; writes SURFACE.ply
(read by vtkPLYReader) as polygonal data in file versions 4.2 and 5.1, ASCII and binary, titled
as 3D Slicer titles its RAS models, and a small volume as image data, ASCII and binary; prints
one JSON object."""
import json, os, sys
from vtkmodules.vtkCommonCore import VTK_SHORT
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkIOLegacy import vtkPolyDataReader, vtkPolyDataWriter, vtkStructuredPointsWriter
from vtkmodules.vtkIOPLY import vtkPLYReader
from vtkmodules.util.numpy_support import vtk_to_numpy

model, surface, out = sys.argv[1:4]
os.makedirs(out, exist_ok=True)

r = vtkPolyDataReader()
r.SetFileName(model)
r.Update()
m = r.GetOutput()
polys = vtk_to_numpy(m.GetPolys().GetConnectivityArray())
normals = m.GetPointData().GetNormals()
read = {"points": m.GetNumberOfPoints(), "polygons": m.GetNumberOfPolys(),
        "point_sum": float(vtk_to_numpy(m.GetPoints().GetData()).astype("float64").sum()),
        "index_sum": int(polys.astype("int64").sum()),
        "normals": 0 if normals is None else normals.GetNumberOfTuples(),
        "title": r.GetHeader()}

p = vtkPLYReader()
p.SetFileName(surface)
p.Update()
written = []
for version in (42, 51):
    for binary in (False, True):
        name = f"v{version}_{'binary' if binary else 'ascii'}.vtk"
        w = vtkPolyDataWriter()
        w.SetInputData(p.GetOutput())
        w.SetFileName(os.path.join(out, name))
        w.SetFileVersion(version)
        w.SetHeader("3D Slicer output. SPACE=RAS")
        if binary:
            w.SetFileTypeToBinary()
        else:
            w.SetFileTypeToASCII()
        w.Write()
        written.append(name)

im = vtkImageData()
im.SetDimensions(5, 4, 3)
im.SetSpacing(0.5, 0.25, 2.0)
im.SetOrigin(-10.0, 20.0, 30.5)
im.AllocateScalars(VTK_SHORT, 1)
a = vtk_to_numpy(im.GetPointData().GetScalars())
a[:] = [(i * 37) % 2001 - 1000 for i in range(a.size)]
images = []
for binary in (False, True):
    name = f"image_{'binary' if binary else 'ascii'}.vtk"
    w = vtkStructuredPointsWriter()
    w.SetInputData(im)
    w.SetFileName(os.path.join(out, name))
    if binary:
        w.SetFileTypeToBinary()
    else:
        w.SetFileTypeToASCII()
    w.Write()
    images.append(name)

print(json.dumps({"read": read, "written": written, "images": images,
                  "image_values": [int(v) for v in a]}))
