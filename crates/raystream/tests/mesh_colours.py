"""Coloured meshes for `mesh_colours_read_as_their_writers_wrote_them` (tests/render.rs); the
VTK files name their space in field data (a `SPACE` string array, `RAS`), as 3D Slicer does.

Usage: mesh_colours.py OUT_DIR

Writes a small sphere coloured per point and per cell, as VTK writes PLY, VTK XML polygonal
data (ASCII, binary, appended, compressed) and legacy VTK (4.2 and 5.1, ASCII and binary);
per point in RGBA; with vertex and line cells before its polygons (whose cell ids then start
past them); an OBJ with `v x y z r g b`; a PLY with float colours and one with 16-bit ones;
and a GLB with COLOR_0 as trimesh writes it. Prints JSON: for each file, each coloured
point's position and colour, or each triangle cell's centroid and colour, as VTK reads the
file back (for the OBJ, the PLYs of other types and the GLB, as the colours were written:
VTK's OBJ reader truncates 0.5 to 127, and a GLB's COLOR_0 is linear light, its sRGB given).
"""

import json
import os
import sys

import numpy as np
import trimesh
import vtk
from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

out = sys.argv[1]
os.makedirs(out, exist_ok=True)

source = vtk.vtkSphereSource()
source.SetCenter(10.0, -20.0, 30.0)
source.SetRadius(5.0)
source.SetThetaResolution(16)
source.SetPhiResolution(12)
source.Update()
sphere = source.GetOutput()
points = vtk_to_numpy(sphere.GetPoints().GetData()).astype(np.float64)
n_cells = sphere.GetNumberOfCells()


def point_colours(components=3):
    """A colour a point, from its position (every channel used, 0 and 255 among them)."""
    rel = (points - points.min(axis=0)) / np.ptp(points, axis=0)
    c = np.zeros((len(points), components), np.uint8)
    c[:, :3] = np.round(rel * 255)
    if components == 4:
        c[:, 3] = 77
    return c


def cell_colours(n):
    ids = np.arange(n)
    return np.stack([ids * 37 % 256, ids * 91 % 256, 255 - ids % 256], axis=1).astype(np.uint8)


def coloured(per_point, components=3):
    """The sphere in colours, its field data naming its space as 3D Slicer's do (`RAS`)."""
    pd = vtk.vtkPolyData()
    pd.DeepCopy(sphere)
    space = vtk.vtkStringArray()
    space.SetName("SPACE")
    space.InsertNextValue("RAS")
    pd.GetFieldData().AddArray(space)
    if per_point:
        a = numpy_to_vtk(point_colours(components), deep=1)
        a.SetName("Colors")
        pd.GetPointData().SetScalars(a)
    else:
        a = numpy_to_vtk(cell_colours(n_cells), deep=1)
        a.SetName("FaceColors")
        pd.GetCellData().SetScalars(a)
    return pd


def with_verts_and_lines():
    """The sphere's triangles after 5 vertex cells and 3 lines, colours a cell."""
    pd = vtk.vtkPolyData()
    pd.SetPoints(sphere.GetPoints())
    verts = vtk.vtkCellArray()
    for i in range(5):
        verts.InsertNextCell(1, [i])
    lines = vtk.vtkCellArray()
    for i in range(3):
        lines.InsertNextCell(2, [i, i + 1])
    pd.SetVerts(verts)
    pd.SetLines(lines)
    pd.SetPolys(sphere.GetPolys())
    a = numpy_to_vtk(cell_colours(8 + n_cells), deep=1)
    a.SetName("Colors")
    pd.GetCellData().SetScalars(a)
    return pd


def read_back(path):
    """The file as VTK reads it: its points' colours, or its triangles' (with centroids)."""
    if path.endswith(".ply"):
        r = vtk.vtkPLYReader()
    elif path.endswith(".vtp"):
        r = vtk.vtkXMLPolyDataReader()
    else:
        r = vtk.vtkPolyDataReader()
        r.ReadAllScalarsOn()
    r.SetFileName(path)
    r.Update()
    pd = r.GetOutput()
    pts = vtk_to_numpy(pd.GetPoints().GetData()).astype(np.float64)
    ps = pd.GetPointData().GetScalars()
    if ps is not None:
        c = vtk_to_numpy(ps)[:, :3]
        return {"points": np.hstack([pts, c]).tolist()}
    cs = vtk_to_numpy(pd.GetCellData().GetScalars())[:, :3]
    rows = []
    for i in range(pd.GetNumberOfCells()):
        cell = pd.GetCell(i)
        if cell.GetCellType() != vtk.VTK_TRIANGLE:
            continue
        ids = [cell.GetPointId(k) for k in range(3)]
        rows.append(pts[ids].mean(axis=0).tolist() + cs[i].tolist())
    return {"cells": rows}


files = {}


def written(name, entry):
    files[name] = entry


for per_point, stem in [(True, "points"), (False, "cells")]:
    pd = coloured(per_point)
    for name, binary in [(f"{stem}.ply", True), (f"{stem}_ascii.ply", False)]:
        w = vtk.vtkPLYWriter()
        w.SetFileName(os.path.join(out, name))
        w.SetInputData(pd)
        w.SetArrayName("Colors" if per_point else "FaceColors")
        w.SetColorModeToDefault()
        if binary:
            w.SetFileTypeToBinary()
        else:
            w.SetFileTypeToASCII()
        w.Write()
        written(name, read_back(os.path.join(out, name)))
    for mode in ["ascii", "binary", "appended", "zlib"]:
        name = f"{stem}_{mode}.vtp"
        w = vtk.vtkXMLPolyDataWriter()
        w.SetFileName(os.path.join(out, name))
        w.SetInputData(pd)
        if mode == "ascii":
            w.SetDataModeToAscii()
        elif mode == "binary":
            w.SetDataModeToBinary()
        else:
            w.SetDataModeToAppended()
        if mode == "zlib":
            w.SetCompressorTypeToZLib()
        else:
            w.SetCompressorTypeToNone()
        w.Write()
        written(name, read_back(os.path.join(out, name)))
    for version in [42, 51]:
        for binary in [False, True]:
            name = f"{stem}_{version}_{'binary' if binary else 'ascii'}.vtk"
            w = vtk.vtkPolyDataWriter()
            w.SetFileName(os.path.join(out, name))
            w.SetInputData(pd)
            w.SetFileVersion(version)
            if binary:
                w.SetFileTypeToBinary()
            w.Write()
            written(name, read_back(os.path.join(out, name)))

for name in ["rgba.vtp", "rgba.vtk"]:
    pd = coloured(True, components=4)
    w = vtk.vtkXMLPolyDataWriter() if name.endswith(".vtp") else vtk.vtkPolyDataWriter()
    w.SetFileName(os.path.join(out, name))
    w.SetInputData(pd)
    w.Write()
    written(name, read_back(os.path.join(out, name)))

for name in ["verts_lines.vtp", "verts_lines.vtk"]:
    w = vtk.vtkXMLPolyDataWriter() if name.endswith(".vtp") else vtk.vtkPolyDataWriter()
    w.SetFileName(os.path.join(out, name))
    w.SetInputData(with_verts_and_lines())
    w.Write()
    written(name, read_back(os.path.join(out, name)))

# The sphere's triangles, for the files written here.
tris = vtk_to_numpy(sphere.GetPolys().GetConnectivityArray()).reshape(-1, 3)
c = point_colours()
expected = {"points": np.hstack([points, c]).tolist()}

with open(os.path.join(out, "points.obj"), "w") as f:
    for p, col in zip(points, c):
        f.write("v %.9g %.9g %.9g %.6f %.6f %.6f\n" % (*p, *(col / 255.0)))
    for t in tris:
        f.write("f %d %d %d\n" % tuple(t + 1))
written("points.obj", expected)
r = vtk.vtkOBJReader()
r.SetFileName(os.path.join(out, "points.obj"))
r.Update()
obj_vtk = vtk_to_numpy(r.GetOutput().GetPointData().GetArray("RGB")).astype(int)
assert len(obj_vtk) == len(c) and np.abs(obj_vtk - c).max() <= 1, "VTK reads the OBJ's colours"


def ply_of_type(name, kind, scale):
    with open(os.path.join(out, name), "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex %d\n" % len(points))
        f.write("property double x\nproperty double y\nproperty double z\n")
        f.write("".join(f"property {kind} {ch}\n" for ch in ["red", "green", "blue"]))
        f.write("element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(tris))
        for p, col in zip(points, c):
            v = col.astype(np.float64) * scale
            vals = [("%.6f" % x) if kind == "float" else str(int(round(x))) for x in v]
            f.write("%.9g %.9g %.9g %s\n" % (*p, " ".join(vals)))
        for t in tris:
            f.write("3 %d %d %d\n" % tuple(t))
    written(name, expected)


ply_of_type("points_float.ply", "float", 1 / 255.0)
ply_of_type("points_ushort.ply", "ushort", 257.0)

# glTF: COLOR_0 is linear light; the sRGB of each is what a viewer shows.
m = trimesh.Trimesh(vertices=points, faces=tris, process=False)
linear = np.zeros((len(points), 4), np.uint8)
linear[:, :3] = c
linear[:, 3] = 255
m.visual = trimesh.visual.ColorVisuals(m, vertex_colors=linear)
m.export(os.path.join(out, "points.glb"))


def to_srgb8(x):
    x = np.clip(x, 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(s * 255).astype(int)


written("points.glb", {"points": np.hstack([points, to_srgb8(c / 255.0)]).tolist()})

print(json.dumps({"files": files}))
