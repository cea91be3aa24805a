#!/usr/bin/env python3
"""Fuzzes raystream's inputs: mutated files and scenes through the release binary.

  .venv/bin/python scripts/fuzz-inputs.py files [--runs N] [--seed S] [--device cpu|gpu] [--only SEEDS]
  .venv/bin/python scripts/fuzz-inputs.py scenes [--runs N] [--seed S]

files:  tiny meshes (OBJ, PLY ascii/LE/BE, STL ascii/binary, coloured PLY, OBJ and VTK, glTF as .glb (a textured one too; their JSON also mutated as a document) and as .gltf; an OBJ with normals and an MTL
        library and a PNG texture, any of them mutated; a PLY with normals), tiny volumes
        (NIfTI, NRRD and MetaImage, attached and detached, via SimpleITK; a DICOM Encapsulated STL raystream wrote; 4-D ones, and
        3D Slicer's interleaved 4-D NRRD, read at a --phase or as a --cine) and real DICOM slices from
        ../shared (JPEG-LS and 12-bit JPEG among them; three of a series in a ZIP, as a PACS
        hands a study out) and, with pydicom, an enhanced CT, each cut, bit-flipped, spliced or given absurd numbers, then `raystream info`
        and `raystream render --aov prim` (meshes also shaded; volumes, and an RT Structure Set laid on its CT, also `--mode` mip, minip, average, slice,
        dvr or cinematic (half of those --denoise, some with --anisotropy and --exposure), some
        with --interpolation linear, cubic or cubic-interpolating, some with --slab, to an EXR, a turntable of EXRs or an animation (APNG, GIF); some tinted by themselves as a label map, some
        rendered (dvr, iso, mip, minip, average, cinematic) in the colours of their own segments or kept to some,
        or their segments made surfaces with `raystream iso --segment` (some simplified, some keeping their largest islands, some named
        by a mutated colour table) or rendered). Each run must exit 0 or 2, never panic, and an error
        must name the file. Paths (text and 3D Slicer markups) are mutated too, rendered as a
        curved planar reformation (--path, straightened or stretched) or flown through (--fly) in an intact volume, measured along
        (`raystream measure`, sometimes grading a stenosis, plotting the profile or writing a label map) and tracked through (`raystream
        centreline`, some of a dark lumen).
scenes: a scene with glass, a mirror, a mesh and a light, with one to three numbers replaced by
        absurd ones (0, -1, ±inf, nan, 1e30 ...), rendered on the CPU and the GPU: either both
        refuse it (exit 2, naming the file) or rays.py imgdiff finds them within the GPU tests'
        bounds (mean < 0.5/255, at most 0.1 % of pixels over 2/255). Half of them drop the
        file's camera for the framing one, turned by a random --orbit, some with --parallel; a
        third hold the built-in CT as their [volume], read linearly or by the cubic B-spline,
        half of those in the colours of a label map of its halves (or kept to one).

Prints each failure with its input (kept under the work folder) and a count at the end; exits 1
if any failed. Run from the repository root after `cargo build --release`. The 2026-11-23
sessions found with it: the NaN framing camera beyond ~1e8 units, unchecked scene values, the
far-off secondary-ray offset, the hidden cause of DICOM gaps (all fixed); see BENCHMARKS.md and
README for the limits that stay.
"""
import argparse
import base64
import json
import os
import random
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import zipfile
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, "target/release/raystream")
SHARED = os.path.join(ROOT, "..", "shared")
ABSURD = [b"4294967295", b"1000000", b"-1", b"0", b"nan", b"inf", b"1e39",
          b"99999999999999999999", b"2147483648", b"-2147483649"]


def png(width, height, rgba):
    """A PNG of 8-bit RGBA texels (row by row), written by hand: no imaging library needed."""
    chunk = lambda kind, data: (struct.pack(">I", len(data)) + kind + data
                                + struct.pack(">I", zlib.crc32(kind + data)))
    rows = b"".join(b"\0" + rgba[4 * width * y:4 * width * (y + 1)] for y in range(height))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))


def seeds(d):
    """Small valid inputs of every format, written into d."""
    v = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
    f = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    w = lambda name, data: open(os.path.join(d, name), "wb").write(data)
    w("t.obj", "".join(f"v {x} {y} {z}\n" for x, y, z in v).encode()
      + "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in f).encode())
    # Legacy VTK polygonal data: ASCII (version 4.2, a quad and a strip) and binary (5.1).
    pts = " ".join(f"{x} {y} {z}" for x, y, z in v)
    w("tp.vtk", (f"# vtk DataFile Version 4.2\n3D Slicer output. SPACE=RAS\nASCII\nDATASET POLYDATA\n"
                 f"POINTS 4 float\n{pts}\nPOLYGONS 2 8\n3 0 2 1\n3 0 1 3\nTRIANGLE_STRIPS 1 5\n4 0 3 2 1\n"
                 f"POINT_DATA 4\nNORMALS Normals float\n" + " ".join(["0 0 1"] * 4) + "\n").encode())
    w("tb.vtk", b"# vtk DataFile Version 5.1\nvtk output\nBINARY\nDATASET POLYDATA\nPOINTS 4 double\n"
      + struct.pack(">12d", *[c for p in v for c in p]) + b"\nPOLYGONS 5 12\nOFFSETS vtktypeint64\n"
      + struct.pack(">5q", 0, 3, 6, 9, 12) + b"\nCONNECTIVITY vtktypeint64\n"
      + struct.pack(">12q", *[i for t in f for i in t]) + b"\n")
    # Coloured: a PLY with vertex colours (bytes) and face colours (floats), an OBJ with
    # `v x y z r g b`, legacy VTK with cell colours after a string field (binary, as VTK writes
    # them: a length byte before the string) and point colours in ASCII.
    w("tc.ply", (b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
                 b"property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
                 b"property uchar blue\nelement face 4\nproperty list uchar int vertex_indices\n"
                 b"property float red\nproperty float green\nproperty float blue\nend_header\n")
      + b"".join(struct.pack("<3f3B", *p, 40 * i, 200, 255 - 40 * i) for i, p in enumerate(v))
      + b"".join(struct.pack("<B3i3f", 3, *t, 0.25 * i, 0.5, 1.0) for i, t in enumerate(f)))
    w("tc.obj", "".join(f"v {x} {y} {z} {x} 0.5 {z}\n" for x, y, z in v).encode()
      + "".join(f"f {a+1} {b+1} {c+1}\n" for a, b, c in f).encode())
    w("tcb.vtk", b"# vtk DataFile Version 4.2\nvtk output\nBINARY\nDATASET POLYDATA\n"
      b"FIELD FieldData 1\nSPACE 1 1 string\n\xc3LPS\nPOINTS 4 float\n"
      + struct.pack(">12f", *[c for p in v for c in p]) + b"\nVERTICES 1 2\n"
      + struct.pack(">2i", 1, 0) + b"\nPOLYGONS 4 16\n"
      + b"".join(struct.pack(">4i", 3, *t) for t in f)
      + b"\nCELL_DATA 5\nCOLOR_SCALARS c 3\n" + bytes(range(15)) + b"\n")
    w("tca.vtk", (f"# vtk DataFile Version 4.2\nvtk output\nASCII\nDATASET POLYDATA\n"
                  f"POINTS 4 float\n{pts}\nPOLYGONS 4 16\n"
                  + "".join(f"3 {a} {b} {c}\n" for a, b, c in f)
                  + "POINT_DATA 4\nCOLOR_SCALARS c 4\n" + "0.5 0.25 1 1\n" * 4
                  + "VECTORS v float\n" + "0 0 1\n" * 4).encode())
    # A model tagged with its patient space, as 3D Slicer saves one.
    w("ts.stl", b"solid 3D Slicer output. SPACE=RAS\n" + "".join(
        "facet normal 0 0 0\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y, z in (v[a], v[b], v[c]))
        + "endloop\nendfacet\n" for a, b, c in f).encode() + b"endsolid\n")
    hdr = lambda fmt: (f"ply\nformat {fmt} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                       "property float z\nelement face 4\nproperty list uchar int vertex_indices\n"
                       "end_header\n").encode()
    w("t_ascii.ply", hdr("ascii") + "".join(f"{x} {y} {z}\n" for x, y, z in v).encode()
      + "".join(f"3 {a} {b} {c}\n" for a, b, c in f).encode())
    for name, e in [("le", "<"), ("be", ">")]:
        b = hdr("binary_little_endian" if e == "<" else "binary_big_endian")
        b += b"".join(struct.pack(e + "3f", *p) for p in v)
        b += b"".join(struct.pack(e + "B3i", 3, *t) for t in f)
        w(f"t_{name}.ply", b)
    # An OBJ with per-corner normals, texture coordinates and materials from its library, one
    # with a texture (fuzzed on its own, or the library or the texture instead: see
    # fuzz_files), and a PLY with normals.
    w("tm.obj", b"mtllib tm.mtl\n" + "".join(f"v {x} {y} {z}\n" for x, y, z in v).encode()
      + b"vn 0 0 -1\nvn 0 -1 0\nvn -1 0 0\nvn 1 1 1\nvt 0 0\nvt 1 0\nvt 0.5 1.5\n" + b"".join(
          f"usemtl {m}\nf {a+1}/1/{k+1} {b+1}/2/{k+1} {c+1}/3/{k+1}\n".encode()
          for k, ((a, b, c), m) in enumerate(zip(f, ["red", "glass", "red", "mirror"]))))
    w("tm.mtl", b"newmtl red\nKd 0.8 0.1 0.1\nKs 0.3 0.3 0.3\nNs 30\nillum 2\nmap_Kd -s 2 1 -o 0.5 0 -clamp on -mm 0 1 tm.png\n"
      b"newmtl glass\nKd 0 0 0\nd 0.2\nNi 1.5\nillum 7\nnewmtl mirror\nKs 0.8 0.8 0.8\nillum 3\n")
    w("tm.png", png(3, 2, bytes(range(0, 240, 10))))
    w("tn.ply", (hdr("ascii").decode().replace(
        "property float z\n", "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n")
        + "".join(f"{x} {y} {z} {x} {y} {z - 0.5}\n" for x, y, z in v)
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in f)).encode())
    s = "solid t\n"
    for t in f:
        s += " facet normal 0 0 0\n  outer loop\n" + "".join(
            "   vertex {} {} {}\n".format(*v[i]) for i in t) + "  endloop\n endfacet\n"
    w("t_ascii.stl", (s + "endsolid t\n").encode())
    b = b"\0" * 80 + struct.pack("<I", len(f))
    for t in f:
        b += struct.pack("<12fH", 0, 0, 0, *v[t[0]], *v[t[1]], *v[t[2]], 0)
    w("t_bin.stl", b)
    # 3MF: the tetrahedron as a coloured object placed twice through components (one in another
    # model part), and a colour group by triangle.
    core = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
    mat = "http://schemas.microsoft.com/3dmanufacturing/material/2015/02"
    prod = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06"
    verts = "".join(f'<vertex x="{x}" y="{y}" z="{z}"/>' for x, y, z in v)
    tris = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}" pid="4" p1="{k % 2}"/>' for k, (a, b, c) in enumerate(f))
    root = (f'<model unit="centimeter" xmlns="{core}" xmlns:m="{mat}" xmlns:p="{prod}"><resources>'
            '<basematerials id="1"><base name="a" displaycolor="#E3D9C9FF"/></basematerials>'
            '<m:colorgroup id="4"><m:color color="#FF0000"/><m:color color="#00FF00FF"/></m:colorgroup>'
            f'<object id="2" pid="1" pindex="0"><mesh><vertices>{verts}</vertices><triangles>{tris}</triangles></mesh></object>'
            '<object id="3"><components><component objectid="2" transform="1 0 0 0 1 0 0 0 1 0 0 3"/>'
            '<component p:path="/3D/o.model" objectid="1" transform="-1 0 0 0 1 0 0 0 1 0 0 0"/></components></object>'
            '</resources><build><item objectid="3" transform="0 1 0 -1 0 0 0 0 1 5 5 5"/><item objectid="2"/></build></model>')
    plain = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in f)
    other = (f'<model unit="millimeter" xmlns="{core}"><resources><object id="1"><mesh><vertices>{verts}</vertices>'
             f'<triangles>{plain}</triangles></mesh></object></resources><build/></model>')
    rels = ('<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
            '<Relationship Target="/3D/3dmodel.model" Id="r0" '
            'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>')
    with zipfile.ZipFile(os.path.join(d, "t.3mf"), "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("_rels/.rels", rels)
        z.writestr("3D/3dmodel.model", root)
        z.writestr("3D/o.model", other)
    # Colour STLs: Materialise's (COLOR= and MATERIAL= in the header, a triangle its own colour
    # or the part's) and VisCAM's (bit 15 set: its own colour).
    for name, header, attrs in (
            ("tcm.stl", b"COLOR=\x28\x5a\xc8\xff,MATERIAL=" + bytes(range(12)), (0x001f, 0x8000, 0x7c00, 0)),
            ("tcv.stl", b"VisCAM", (0xfc00, 0, 0x83e0, 0xffff))):
        b = header.ljust(80, b" ") + struct.pack("<I", len(f))
        for t, a in zip(f, attrs * len(f)):
            b += struct.pack("<12fH", 0, 0, 0, *v[t[0]], *v[t[1]], *v[t[2]], a)
        w(name, b)
    # glTF: the tetrahedron as a GLB (positions, normals, u16 indices, a material, a node that
    # moves and scales it under a parent) and as a .gltf with its buffer as a data URI.
    pos = b"".join(struct.pack("<3f", *p) for p in v)
    nrm = b"".join(struct.pack("<3f", x, y, z - 0.5) for x, y, z in v)
    idx = b"".join(struct.pack("<3H", *t) for t in f)
    buf = pos + nrm + idx
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"translation": [1, 0, 0], "children": [1]}, {"scale": [2, 2, 2], "mesh": 0}],
           "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.2, 0.1, 1]}}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2,
                                       "material": 0}]}],
           "buffers": [{"byteLength": len(buf)}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                           {"buffer": 0, "byteOffset": 48, "byteLength": 48},
                           {"buffer": 0, "byteOffset": 96, "byteLength": 24}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                          "min": [0, 0, 0], "max": [1, 1, 1]},
                         {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
                         {"bufferView": 2, "componentType": 5123, "count": 12, "type": "SCALAR"}]}
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    glb = (b"glTF" + struct.pack("<II", 2, 12 + 8 + len(j) + 8 + len(buf)) + struct.pack("<I", len(j))
           + b"JSON" + j + struct.pack("<I", len(buf)) + b"BIN\0" + buf)
    w("t.glb", glb)
    # And textured: texture coordinates and a PNG in the binary chunk.
    uv = b"".join(struct.pack("<2f", x, y) for x, y, _ in v)
    tex = png(3, 2, bytes(range(0, 240, 10)))
    tbuf = buf + uv + tex + b"\0" * (-len(tex) % 4)
    tdoc = json.loads(json.dumps(doc))
    tdoc["buffers"] = [{"byteLength": len(tbuf)}]
    tdoc["bufferViews"] += [{"buffer": 0, "byteOffset": len(buf), "byteLength": len(uv)},
                            {"buffer": 0, "byteOffset": len(buf) + len(uv), "byteLength": len(tex)}]
    tdoc["accessors"].append({"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC2"})
    tdoc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = 3
    tdoc["images"] = [{"bufferView": 4, "mimeType": "image/png"}]
    tdoc["samplers"] = [{"wrapS": 33071, "wrapT": 10497}]
    tdoc["textures"] = [{"source": 0, "sampler": 0}]
    tdoc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    tj = json.dumps(tdoc).encode()
    tj += b" " * (-len(tj) % 4)
    w("tt.glb", b"glTF" + struct.pack("<II", 2, 12 + 8 + len(tj) + 8 + len(tbuf)) + struct.pack("<I", len(tj))
      + b"JSON" + tj + struct.pack("<I", len(tbuf)) + b"BIN\0" + tbuf)
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(buf).decode()
    w("t.gltf", json.dumps(doc, indent=1).encode())
    try:
        import numpy as np
        import SimpleITK as sitk
        img = sitk.GetImageFromArray((np.arange(120).reshape(4, 5, 6) * 10 - 500).astype(np.int16))
        img.SetSpacing((0.7, 0.8, 2.5))
        img.SetOrigin((-10, 20, 30))
        img.SetDirection((0, 1, 0, 1, 0, 0, 0, 0, -1))
        for n in ["v.nii", "v.nii.gz", "v.nrrd", "v.mha", "v.mhd", "v.nhdr", "v.vtk"]:
            sitk.WriteImage(img, os.path.join(d, n))
        # The same voxels as raw bytes named by their size and type, and as ASCII legacy VTK.
        vox = sitk.GetArrayFromImage(img).astype("<i2")
        w("vr_6x5x4_int16.raw", vox.tobytes())
        w("va.vtk", b"# vtk DataFile Version 3.0\nascii ramp\nASCII\nDATASET STRUCTURED_POINTS\n"
          b"DIMENSIONS 6 5 4\nSPACING 0.7 0.8 2.5\nORIGIN -10 20 30\nPOINT_DATA 120\n"
          b"SCALARS v short 1\nLOOKUP_TABLE default\n"
          + " ".join(str(v) for v in vox.ravel()).encode() + b"\n")
        # VTK XML image data: appended base64 zlib blocks (VTK's default), inline base64, and a
        # sphere as polygonal data, as the vtk wheel writes them (where it is installed).
        try:
            from vtkmodules.vtkCommonDataModel import vtkImageData
            from vtkmodules.vtkFiltersSources import vtkSphereSource
            from vtkmodules.vtkIOXML import vtkXMLImageDataWriter, vtkXMLPolyDataWriter
            from vtkmodules.util.numpy_support import numpy_to_vtk
            vi = vtkImageData()
            vi.SetDimensions(6, 5, 4)
            vi.SetSpacing(0.7, 0.8, 2.5)
            vi.SetOrigin(-10, 20, 30)
            vi.SetDirectionMatrix(0, 1, 0, 1, 0, 0, 0, 0, -1)
            arr = numpy_to_vtk(vox.ravel().astype(np.int16), deep=1)
            arr.SetName("v")
            vi.GetPointData().SetScalars(arr)
            for n, binary in (("vx.vti", False), ("vb.vti", True)):
                wr = vtkXMLImageDataWriter()
                wr.SetInputData(vi)
                if binary:
                    wr.SetDataModeToBinary()
                    wr.SetCompressorTypeToNone()
                else:
                    wr.SetBlockSize(64)
                wr.SetFileName(os.path.join(d, n))
                wr.Write()
            sph = vtkSphereSource()
            sph.SetThetaResolution(6)
            sph.SetPhiResolution(4)
            wr = vtkXMLPolyDataWriter()
            wr.SetInputConnection(sph.GetOutputPort())
            wr.SetCompressorTypeToLZ4()
            wr.SetFileName(os.path.join(d, "tx.vtp"))
            wr.Write()
            # Coloured per cell, with 3D Slicer's SPACE field, appended and compressed.
            from vtkmodules.vtkCommonCore import vtkStringArray
            sph.Update()
            pd = sph.GetOutput()
            cols = numpy_to_vtk((np.arange(3 * pd.GetNumberOfCells()) * 7 % 256).astype(np.uint8)
                                .reshape(-1, 3), deep=1)
            cols.SetName("c")
            pd.GetCellData().SetScalars(cols)
            space = vtkStringArray()
            space.SetName("SPACE")
            space.InsertNextValue("LPS")
            pd.GetFieldData().AddArray(space)
            wr = vtkXMLPolyDataWriter()
            wr.SetInputData(pd)
            wr.SetDataModeToAppended()
            wr.SetFileName(os.path.join(d, "tc.vtp"))
            wr.Write()
        except ImportError:
            print("no vtk: VTK XML files left out", file=sys.stderr)
        # A multi-label map with TotalSegmentator's label table in a header extension (--ml).
        sitk.WriteImage(sitk.Cast((img > -300) + (img > 300), sitk.sitkUInt8), os.path.join(d, "ml0.nii"))
        raw = open(os.path.join(d, "ml0.nii"), "rb").read()
        os.remove(os.path.join(d, "ml0.nii"))
        xml = (b'<?xml version="1.0" encoding="UTF-8"?> <CaretExtension> <VolumeInformation Index="0">'
               b'<LabelTable>\n<Label Key="1" Red="1.0" Green="0.0" Blue="0.0" Alpha="1"><![CDATA[liver]]>'
               b'</Label>\n<Label Key="2" Red="0.0" Green="1.0" Blue="0.0" Alpha="1"><![CDATA[aorta]]>'
               b'</Label>\n</LabelTable></VolumeInformation></CaretExtension>')
        xml += b" " * ((-(len(xml) + 8)) % 16)
        at = int(np.frombuffer(raw[108:112], "<f4")[0])
        w("ml.nii", raw[:108] + np.array([352 + 8 + len(xml)], "<f4").tobytes() + raw[112:348]
          + b"\x01\0\0\0" + np.array([len(xml) + 8, 0], "<i4").tobytes() + xml + raw[at:])
        # A mask of v.nii, as TotalSegmentator writes one of its folder's.
        sitk.WriteImage(sitk.Cast(img > 0, sitk.sitkUInt8), os.path.join(d, "mk.nii.gz"))
        # 4-D: two phases, as SimpleITK writes them, and 3D Slicer's interleaved NRRD.
        for n in ["v4.nii.gz", "v4.nrrd", "v4.mha"]:
            sitk.WriteImage(sitk.JoinSeries([img, img + 100]), os.path.join(d, n))
        a = (np.arange(120).reshape(4, 5, 6) * 10 - 500).astype("<i2")
        w("v4s.nrrd", b"NRRD0004\ntype: short\ndimension: 4\nspace: left-posterior-superior\n"
          b"sizes: 2 6 5 4\nspace directions: none (0,0.7,0) (0.8,0,0) (0,0,-2.5)\n"
          b"kinds: list domain domain domain\nendian: little\nencoding: raw\n"
          b"space origin: (-10,20,30)\n\n" + np.stack([a, a + 100], axis=-1).tobytes())
        # A 3D Slicer segmentation of v.nii: two overlapping segments on two layers.
        lab = np.zeros((4, 5, 6), "u1")
        lab[1:3, 1:4, 1:5] = 1
        top = np.zeros_like(lab)
        top[2:4, 2:5, 2:6] = 1
        w("vs.seg.nrrd", b"NRRD0004\ntype: unsigned char\ndimension: 4\nspace: left-posterior-superior\n"
          b"sizes: 2 6 5 4\nspace directions: none (0,0.7,0) (0.8,0,0) (0,0,-2.5)\n"
          b"kinds: list domain domain domain\nencoding: raw\nspace origin: (-10,20,30)\n"
          b"Segment0_ID:=a\nSegment0_Name:=liver\nSegment0_Color:=0.8 0.3 0.2\nSegment0_LabelValue:=1\n"
          b"Segment0_Layer:=0\nSegment1_ID:=b\nSegment1_Name:=tumour\nSegment1_Color:=1 1 0\n"
          b"Segment1_LabelValue:=1\nSegment1_Layer:=1\n\n" + np.stack([lab, top], axis=-1).tobytes())
        # A ball as a DICOM Encapsulated STL, written by raystream itself.
        z, y, x = np.mgrid[0:8, 0:8, 0:8]
        ball = (((x - 3.5) ** 2 + (y - 3.5) ** 2 + (z - 3.5) ** 2) < 9).astype("<i2") * 1000
        w("ball.nrrd", b"NRRD0004\ntype: short\ndimension: 3\nspace: left-posterior-superior\n"
          b"sizes: 8 8 8\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nkinds: domain domain domain\n"
          b"endian: little\nencoding: raw\nspace origin: (0,0,0)\n\n" + ball.tobytes())
        subprocess.run([BIN, "iso", os.path.join(d, "ball.nrrd"), "-q", "-o", os.path.join(d, "m3d.dcm")],
                       check=True)
    except ImportError:
        print("no SimpleITK: volumes other than DICOM left out", file=sys.stderr)
    # Paths for curved planar reformation through v.nii (LPS mm), as text and Slicer markups.
    path = [(-9.0, 20.5, 29.0), (-8.0, 22.0, 27.0), (-7.5, 23.5, 24.0)]
    w("c.txt", "".join(f"{x} {y} {z}\n" for x, y, z in path).encode())
    w("c.mrk.json", json.dumps({"markups": [{"type": "Curve", "coordinateSystem": "LPS",
                                             "controlPoints": [{"position": p} for p in path]}]}).encode())
    try:
        w("mf.dcm", enhanced_ct())
        w("sg.dcm", segmentation())
        w("sr.dcm", report())
        w("sgr.dcm", label_map_rle())
        # An RT Structure Set and the CT series it was drawn on (copied beside it each run).
        os.makedirs(os.path.join(d, "rsct"))
        for k, b in enumerate(structure_set_ct()):
            w(os.path.join("rsct", f"ct{k}.dcm"), b)
        w("rs.dcm", structure_set())
    except ImportError:
        print("no pydicom: the enhanced (multi-frame) CT, Segmentation and report seeds left out",
              file=sys.stderr)
    ts = os.path.join(SHARED, "data/volumes/dicom/ct_slice_transfer_syntaxes")
    names = sorted(os.listdir(ts))
    # Every codec the reader decodes: its own (JPEG-LS, 12-bit JPEG), the one it checks first
    # (RLE), and dicom-pixeldata's lossless JPEG and JPEG 2000.
    for n in names[:4] + [n for n in names if re.search(r"\.4\.(51|57|70|80|81|90|91)_|\.1\.2\.5_", n)]:
        shutil.copy(os.path.join(ts, n), os.path.join(d, n))
        os.chmod(os.path.join(d, n), 0o644)
    # A ZIP of a series' first slices as a PACS hands a study out, in a CD's folders beside a
    # DICOMDIR, stored and deflated (the archive is mutated whole).
    series = os.path.join(SHARED, "data/volumes/dicom/abdomen_ct_j2k_totalseg")
    with zipfile.ZipFile(os.path.join(d, "st.zip"), "w") as z:
        for k, n in enumerate(sorted(os.listdir(series))[:3]):
            z.write(os.path.join(series, n), f"DICOM/ST000/SE000/IM{k:04}",
                    compress_type=zipfile.ZIP_DEFLATED if k % 2 else zipfile.ZIP_STORED)
        z.writestr("DICOMDIR", b"not read")


def item(**kw):
    """A pydicom data set (a sequence item) holding `kw`."""
    from pydicom.dataset import Dataset
    d = Dataset()
    for k, v in kw.items():
        setattr(d, k, v)
    return d


def file_bytes(ds, compress=None):
    """The data set `ds` as a DICOM file's bytes: its file meta, Explicit VR Little Endian, or
    its pixel data `compress`ed in that transfer syntax (its instance UID kept, so that runs
    reproduce)."""
    import io
    from pydicom.dataset import FileMetaDataset
    from pydicom.uid import ExplicitVRLittleEndian
    ds.file_meta = FileMetaDataset()
    ds.file_meta.TransferSyntaxUID = ExplicitVRLittleEndian
    if compress:
        ds.compress(compress, generate_instance_uid=False)
    ds.file_meta.MediaStorageSOPClassUID = ds.SOPClassUID
    ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
    out = io.BytesIO()
    ds.save_as(out, enforce_file_format=True)
    return out.getvalue()


def enhanced_ct():
    """A 3-frame 8x6 enhanced CT: per-frame positions and rescales, shared plane and spacing."""
    from pydicom.dataset import Dataset
    from pydicom.sequence import Sequence

    ds = Dataset()
    ds.SOPClassUID, ds.SOPInstanceUID = "1.2.840.10008.5.1.4.1.1.2.1", "2.25.7"
    ds.Modality, ds.SeriesInstanceUID, ds.NumberOfFrames = "CT", "2.25.8", 3
    ds.Rows, ds.Columns, ds.SamplesPerPixel = 6, 8, 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 0
    ds.SharedFunctionalGroupsSequence = Sequence([item(
        PixelMeasuresSequence=Sequence([item(PixelSpacing=[0.7, 0.8], SliceThickness=2)]),
        PlaneOrientationSequence=Sequence([item(ImageOrientationPatient=[1, 0, 0, 0, 1, 0])]))])
    ds.PerFrameFunctionalGroupsSequence = Sequence([item(
        PlanePositionSequence=Sequence([item(ImagePositionPatient=[-10, 20, 30 + 2 * k])]),
        PixelValueTransformationSequence=Sequence([item(
            RescaleIntercept=-1024 - k, RescaleSlope=1, RescaleType="HU")]))
        for k in (2, 0, 1)])
    ds.PixelData = struct.pack("<144H", *[(i * 37) % 3000 for i in range(144)])
    return file_bytes(ds)


def seg_frames(kind, bits, sop_class, uid, frames):
    """A DICOM Segmentation's header: two segments, 7x5 frames of `bits` bits at the planes
    `frames` gives (their z index, and their segment where a frame is one's), shared
    orientation and spacing."""
    from pydicom.dataset import Dataset
    from pydicom.sequence import Sequence

    ds = Dataset()
    ds.SOPClassUID, ds.SOPInstanceUID = sop_class, f"2.25.{uid}"
    ds.Modality, ds.SeriesInstanceUID, ds.NumberOfFrames = "SEG", f"2.25.{uid + 1}", len(frames)
    ds.Rows, ds.Columns, ds.SamplesPerPixel = 5, 7, 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = bits, bits, bits - 1, 0
    ds.SegmentationType = kind
    ds.SegmentSequence = Sequence([item(SegmentNumber=n, SegmentLabel=f"s{n}") for n in (1, 2)])
    ds.SharedFunctionalGroupsSequence = Sequence([item(
        PixelMeasuresSequence=Sequence([item(PixelSpacing=[0.7, 0.8], SpacingBetweenSlices=2)]),
        PlaneOrientationSequence=Sequence([item(ImageOrientationPatient=[1, 0, 0, 0, 1, 0])]))])

    def frame(k, n):
        f = item(PlanePositionSequence=Sequence([item(ImagePositionPatient=[-10, 20, 30 + 2 * k])]))
        if n:
            f.SegmentIdentificationSequence = Sequence([item(ReferencedSegmentNumber=n)])
        return f
    ds.PerFrameFunctionalGroupsSequence = Sequence([frame(k, n) for k, n in frames])
    return ds


def segmentation():
    """A DICOM Segmentation of two binary segments: 3 frames of 7x5 (the bits run on across
    bytes), two on one plane."""
    ds = seg_frames("BINARY", 1, "1.2.840.10008.5.1.4.1.1.66.4", 9, ((0, 1), (2, 1), (2, 2)))
    ds.PixelData = bytes((i * 37) % 256 for i in range(14))
    return file_bytes(ds)


def label_map_rle():
    """A DICOM 2024 Label Map Segmentation, 8 bits, its 3 frames of 7x5 RLE Lossless
    compressed (a fragment a frame)."""
    from pydicom.uid import RLELossless

    ds = seg_frames("LABELMAP", 8, "1.2.840.10008.5.1.4.1.1.66.7", 13, ((0, 0), (1, 0), (2, 0)))
    ds.PixelData = bytes((i * 7) % 3 for i in range(105))
    return file_bytes(ds, RLELossless)


def structure_set_ct():
    """A 3-slice 8x6 CT series (its files' bytes) for the structure set to lie on."""
    from pydicom.dataset import Dataset

    out = []
    for k in range(3):
        ds = Dataset()
        ds.SOPClassUID, ds.SOPInstanceUID = "1.2.840.10008.5.1.4.1.1.2", f"2.25.4{k}"
        ds.Modality, ds.SeriesInstanceUID, ds.FrameOfReferenceUID = "CT", "2.25.30", "2.25.31"
        ds.Rows, ds.Columns, ds.SamplesPerPixel = 6, 8, 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
        ds.RescaleIntercept, ds.RescaleSlope = 0, 1
        ds.ImagePositionPatient = [-10, 20, 30 + 2 * k]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.PixelSpacing = [0.8, 0.7]
        ds.PixelData = struct.pack("<48h", *[(i * 53 + k * 11) % 2000 - 1000 for i in range(48)])
        out.append(file_bytes(ds))
    return out


def structure_set():
    """An RT Structure Set on structure_set_ct's series: a body outline over every slice, and
    a ring (a polygon and its hole) inside it on one slice, with a colour and kind each."""
    from pydicom.dataset import Dataset
    from pydicom.sequence import Sequence

    def polygon(points, k):
        return item(ContourGeometricType="CLOSED_PLANAR", NumberOfContourPoints=len(points),
                    ContourData=[c for x, y in points for c in (-10 + 0.7 * x, 20 + 0.8 * y, 30 + 2 * k)])
    ds = Dataset()
    ds.SOPClassUID, ds.SOPInstanceUID = "1.2.840.10008.5.1.4.1.1.481.3", "2.25.32"
    ds.Modality, ds.SeriesInstanceUID = "RTSTRUCT", "2.25.33"
    ds.StructureSetLabel = "fuzz"
    ds.ReferencedFrameOfReferenceSequence = Sequence([item(
        FrameOfReferenceUID="2.25.31", RTReferencedStudySequence=Sequence([item(
            RTReferencedSeriesSequence=Sequence([item(SeriesInstanceUID="2.25.30")]))]))])
    ds.StructureSetROISequence = Sequence([
        item(ROINumber=1, ROIName="Body", ReferencedFrameOfReferenceUID="2.25.31"),
        item(ROINumber=2, ROIName="Lumen", ReferencedFrameOfReferenceUID="2.25.31")])
    body = [(0.5, 0.5), (6.5, 0.5), (6.5, 4.5), (0.5, 4.5)]
    ds.ROIContourSequence = Sequence([
        item(ReferencedROINumber=1, ROIDisplayColor=[255, 200, 150],
             ContourSequence=Sequence([polygon(body, k) for k in range(3)])),
        item(ReferencedROINumber=2, ROIDisplayColor=[0, 255, 255], ContourSequence=Sequence([
            polygon([(1, 1), (5, 1), (5, 4), (1, 4)], 1), polygon([(2, 2), (4, 2), (3, 3)], 1)]))])
    ds.RTROIObservationsSequence = Sequence([
        item(ObservationNumber=n, ReferencedROINumber=n, RTROIInterpretedType=t)
        for n, t in ((1, "EXTERNAL"), (2, "ORGAN"))])
    return file_bytes(ds)


def report():
    """A DICOM Imaging Measurement Report (TID 1500): a measurement group with a tracking
    identifier, a finding, a diameter with its derivation and its line (SCOORD3D), and a
    segment's volume."""
    from pydicom.dataset import Dataset
    from pydicom.sequence import Sequence

    def code(v, s, m):
        return Sequence([item(CodeValue=v, CodingSchemeDesignator=s, CodeMeaning=m)])

    def node(rel, kind, concept, **kw):
        return item(RelationshipType=rel, ValueType=kind, ConceptNameCodeSequence=code(*concept), **kw)

    mm = code("mm", "UCUM", "millimeter")
    diameter = node("CONTAINS", "NUM", ("81827009", "SCT", "Diameter"),
                    MeasuredValueSequence=Sequence([item(NumericValue="7.25", MeasurementUnitsCodeSequence=mm)]),
                    ContentSequence=Sequence([
                        node("HAS CONCEPT MOD", "CODE", ("121401", "DCM", "Derivation"),
                             ConceptCodeSequence=code("56851009", "SCT", "Maximum")),
                        node("INFERRED FROM", "SCOORD3D", ("260753009", "SCT", "Source"),
                             ReferencedFrameOfReferenceUID="2.25.3", GraphicType="POLYLINE",
                             GraphicData=[0.0, 1.0, 2.0, 3.0, 4.0, 5.0])]))
    volume = node("CONTAINS", "NUM", ("118565006", "SCT", "Volume"),
                  MeasuredValueSequence=Sequence([item(NumericValue="1.5",
                                                       MeasurementUnitsCodeSequence=code("ml", "UCUM", "ml"))]))
    group = node("CONTAINS", "CONTAINER", ("125007", "DCM", "Measurement Group"),
                 ContinuityOfContent="SEPARATE", ContentSequence=Sequence([
                     node("HAS OBS CONTEXT", "TEXT", ("112039", "DCM", "Tracking Identifier"), TextValue="g1"),
                     node("CONTAINS", "CODE", ("121071", "DCM", "Finding"),
                          ConceptCodeSequence=code("59820001", "SCT", "Blood vessel")),
                     node("CONTAINS", "IMAGE", ("121191", "DCM", "Referenced Segment"),
                          ReferencedSOPSequence=Sequence([item(
                              ReferencedSOPClassUID="1.2.840.10008.5.1.4.1.1.66.4",
                              ReferencedSOPInstanceUID="2.25.9", ReferencedSegmentNumber=1)])),
                     diameter, volume]))
    ds = Dataset()
    ds.SOPClassUID, ds.SOPInstanceUID = "1.2.840.10008.5.1.4.1.1.88.34", "2.25.11"
    ds.Modality, ds.SeriesInstanceUID = "SR", "2.25.12"
    ds.CompletionFlag, ds.VerificationFlag = "COMPLETE", "UNVERIFIED"
    ds.ValueType, ds.ContinuityOfContent = "CONTAINER", "SEPARATE"
    ds.ConceptNameCodeSequence = code("126000", "DCM", "Imaging Measurement Report")
    ds.ContentTemplateSequence = Sequence([item(MappingResource="DCMR", TemplateIdentifier="1500")])
    ds.ContentSequence = Sequence([
        node("HAS OBS CONTEXT", "TEXT", ("121013", "DCM", "Device Observer Name"), TextValue="fuzz"),
        node("CONTAINS", "CONTAINER", ("126010", "DCM", "Imaging Measurements"),
             ContinuityOfContent="SEPARATE", ContentSequence=Sequence([group]))])
    return file_bytes(ds)


def mutate(b, text):
    b = bytearray(b)
    k = random.randrange(6)
    if k == 0 and len(b) > 1:
        return bytes(b[:random.randrange(len(b))])
    if k == 1:
        for _ in range(random.randint(1, 8)):
            b[random.randrange(len(b))] = random.randrange(256)
        return bytes(b)
    if k == 2:
        i = random.randrange(len(b) + 1)
        return bytes(b[:i] + os.urandom(random.randint(1, 16)) + b[i:])
    if k == 3 and text:
        nums = list(re.finditer(rb"-?\d+(\.\d+)?", bytes(b)))
        if nums:
            m = random.choice(nums)
            return bytes(b[:m.start()] + random.choice(ABSURD) + b[m.end():])
    if k == 4 and len(b) >= 4:
        i = random.randrange(min(len(b) - 3, 2048))
        b[i:i + 4] = random.choice([b"\xff\xff\xff\xff", b"\xff\xff\xff\x7f", b"\0\0\0\x80"])
        return bytes(b)
    i = random.randrange(min(len(b), 4096))
    b[i] ^= 1 << random.randrange(8)
    return bytes(b)


def mutate_3mf(b):
    """A 3MF package with one of its parts (a model's XML, the relationships) mutated as text,
    then zipped again (a byte changed in the archive mostly breaks its checksums)."""
    import io
    with zipfile.ZipFile(io.BytesIO(b)) as z:
        parts = {n: z.read(n) for n in z.namelist()}
    name = random.choice(sorted(parts))
    parts[name] = mutate(parts[name], True)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in parts.items():
            z.writestr(n, data)
    return out.getvalue()


def mutate_glb(b):
    """A GLB's JSON changed as a document, not as bytes: one to three keys deleted, array
    entries repeated, or values replaced by absurd ones (a missing MIME type, an index out of
    range, a wrong enum), the binary chunk kept."""
    n = struct.unpack("<I", b[12:16])[0]
    doc, rest = json.loads(b[20:20 + n]), b[20 + n:]

    def paths(o, at=()):
        yield at
        items = o.items() if isinstance(o, dict) else enumerate(o) if isinstance(o, list) else ()
        for k, v in items:
            yield from paths(v, at + (k,))
    for _ in range(random.randint(1, 3)):
        at = random.choice([q for q in paths(doc) if q])
        parent = doc
        for k in at[:-1]:
            parent = parent[k]
        k, r = at[-1], random.random()
        if r < 0.35 and isinstance(parent, dict):
            del parent[k]
        elif r < 0.5 and isinstance(parent, list):
            parent.append(json.loads(json.dumps(parent[k])))
        else:
            parent[k] = random.choice([-1, 0, 1, 2, 7, 1e9, 4294967295, "x", None, [], {}, 0.5,
                                       33648, 5125, "VEC4", "data:,"])
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    return (b"glTF" + struct.pack("<II", 2, 20 + len(j) + len(rest)) + struct.pack("<I", len(j))
            + b"JSON" + j + rest)


def islands(shells=True):
    """Now and then `--keep-largest` or `--min-island`, with a sensible or an absurd number,
    and `--fill-cavities` or `--colour-shells`."""
    pick = random.random()
    fill = ["--fill-cavities"] if random.random() < 0.3 else []
    # (--colour-shells parts a threshold's surface; with --segment it is a usage error.)
    fill += ["--colour-shells"] if shells and random.random() < 0.2 else []
    if pick < 0.2:
        return fill + ["--keep-largest", random.choice(["1", "2", "1000000", "18446744073709551615"])]
    if pick < 0.4:
        return fill + ["--min-island", random.choice(["0.000001", "0.5", "1e9", "1e300"])]
    return fill


def run(args, name):
    """None if the run behaved, else what went wrong. An error must name `name` (or one of
    them, a tuple: an input and the colour table or output an error may be about)."""
    try:
        r = subprocess.run(["bash", "-c", "ulimit -v 8000000; exec \"$@\"", "_", BIN] + args,
                           capture_output=True, timeout=120)
    except subprocess.TimeoutExpired:
        return "timeout"
    err = r.stderr.decode(errors="replace")
    if r.returncode not in (0, 2) or "panicked" in err:
        return f"exit {r.returncode}: {err[-400:]}"
    names = name if isinstance(name, tuple) else (name,)
    if r.returncode == 2 and not any(n in err for n in names):
        return f"error without the file's name: {err[-400:]}"
    return None


def settle(why, p, d):
    """A case's outcome: 1 and its failure printed (its folder kept to look at), or 0 and its
    folder removed."""
    if why:
        print(f"FAIL {p}: {why}")
        return 1
    shutil.rmtree(d)
    return 0


def fuzz_files(work, n, device, only=None):
    sd = os.path.join(work, "seeds")
    os.makedirs(sd)
    seeds(sd)
    names = [s for s in sorted(os.listdir(sd)) if s not in ("v.raw", "tm.mtl", "tm.png", "rsct")]
    if only:
        names = [s for s in names if s in only]
        if not names:
            sys.exit(f"--only names no seed: {', '.join(only)}")
    bad = 0
    for i in range(n):
        s = random.choice(names)
        d = os.path.join(work, f"case{i}")
        os.makedirs(d)
        p = os.path.join(d, s)
        text = s.endswith((".obj", ".stl", ".ply", ".mha", ".mhd", ".nhdr", ".nrrd", ".txt", ".json", ".gltf")) \
            or s in ("va.vtk", "tp.vtk")
        data = open(os.path.join(sd, s), "rb").read()
        if s == "tm.obj":
            # The OBJ, its material library or its texture, mutated; the others as they are.
            lib = open(os.path.join(sd, "tm.mtl"), "rb").read()
            tex = open(os.path.join(sd, "tm.png"), "rb").read()
            r = random.random()
            if r < 0.4:
                data = mutate(data, True)
            elif r < 0.7:
                lib = mutate(lib, True)
            else:
                tex = mutate(tex, False)
            open(os.path.join(d, "tm.mtl"), "wb").write(lib)
            open(os.path.join(d, "tm.png"), "wb").write(tex)
            open(p, "wb").write(data)
        elif s.endswith(".3mf") and random.random() < 0.8:
            open(p, "wb").write(mutate_3mf(data))
        else:
            glb = s.endswith(".glb") and random.random() < 0.5
            open(p, "wb").write(mutate_glb(data) if glb else mutate(data, text))
        if s in ("v.mhd", "v.nhdr"):
            shutil.copy(os.path.join(sd, "v.raw"), d)
        if s == "rs.dcm":
            # The structure set's CT beside it, in its folder.
            for f in os.listdir(os.path.join(sd, "rsct")):
                shutil.copy(os.path.join(sd, "rsct", f), d)
        if s == "mk.nii.gz":
            # A folder of masks (TotalSegmentator's): the mutated one after an intact one.
            masks = os.path.join(d, "masks")
            os.makedirs(masks)
            shutil.move(p, os.path.join(masks, s))
            shutil.copy(os.path.join(sd, s), os.path.join(masks, "a.nii.gz"))
            vol = os.path.join(sd, "v.nii")
            why = run(["info", masks, "--json"], (s, "masks")) or (os.path.exists(vol) and run(
                ["info", vol, "--segmentation", masks, "--below", "-950", "--percentile", "15",
                 "--clusters", random.choice(["3d", "2d"]), "--combine", random.choice(["both=1,2", "all=all", "one=a"])],
                (s, "masks")))
            bad += settle(why, p, d)
            continue
        if s.startswith("c."):
            # A curved reformation along the mutated path, through the intact volume.
            vol = os.path.join(sd, "v.nii")
            mode = random.choice([["slice"], ["mip", "--slab", "2"], ["average", "--slab", "5"]])
            out = (["--turntable", "2", "--format", "exr", "-o", os.path.join(d, "frames")]
                   if random.random() < 0.25 else ["-o", os.path.join(d, "o.exr")])
            layout = random.choice([[], ["--cpr", "stretched"]])
            why = os.path.exists(vol) and run(
                ["render", vol, "--path", p, "--mode"] + mode + ["--size", "8x16", "-q",
                 "--device", device, "--orbit", str(random.choice([0, 45, 90]))] + layout + out, s)
            # Sometimes the lumen's edges drawn on it, into a PNG.
            if not why and os.path.exists(vol) and random.random() < 0.3:
                why = run(["render", vol, "--path", p, "--mode", "slice", "--size", "8x16", "-q",
                           "--draw-lumen", random.choice(["-500", "150"]), "--device", device]
                          + layout + ["-o", os.path.join(d, "l.png")], s)
            # Sometimes cross-sections with the lumen and the outer wall drawn.
            if not why and os.path.exists(vol) and random.random() < 0.2:
                why = run(["render", vol, "--path", p, "--mode", "slice", "--size", "16x16", "-q",
                           "--slices", random.choice(["1", "3"]), "--device", device,
                           "-o", os.path.join(d, "w")]
                          + random.choice([["--draw-lumen", "150", "--draw-wall"],
                                           ["--draw-lumen", "-500", "--draw-dark", "--draw-wall"],
                                           ["--draw-lumen", "-950", "--draw-dark", "--draw-wall",
                                            "--draw-wall-edge", "integral"]])
                          + random.choice([[], ["--field", random.choice(["0.01", "20", "1e5"])]]), s)
            # Sometimes a fly-through along it (--fly), at an odd field of view.
            if not why and os.path.exists(vol) and random.random() < 0.2:
                look = random.choice([["dvr"], ["iso"], ["cinematic", "--spp", "2"]])
                why = run(["render", vol, "--path", p, "--mode"] + look
                          + ["--fly", random.choice(["1", "2"]), "--fov", random.choice(["1", "90", "179.9"]),
                             "--size", "8x8", "-q", "--device", device, "-o", os.path.join(d, "fly")], s)
            # And the lumen measured along it (`measure`), with some valid options.
            count = random.choice([[], ["--sections", random.choice(["1", "3", "50"])]])
            # Sometimes a stenosis graded too, its lesion and references placed at random.
            grade = random.choice([[], ["--stenosis"], ["--lesion", random.choice(["0", "5", "1e9"])],
                                   ["--reference", random.choice(["3", "2,30", "1,2,3", "-1"])],
                                   ["--span", random.choice(["0.1", "5", "1e9"])],
                                   ["--lesions", random.choice(["1", "3", "100"])]])
            # Sometimes the outer wall too: a vessel's below the lumen's threshold (its default,
            # -30 HU, where that is below it), an airway's (--dark) with no threshold, at half
            # maximum or by the integral.
            lumen = random.choice(["-500", "0", "150"])
            dark = ["--dark"] if random.random() < 0.2 else []
            wall = random.choice([[], ["--wall"], ["--wall", "--wall-edge", "integral"]] if dark else
                                 [[], ["--wall", str(float(lumen) - random.choice([1, 180]))]]
                                 + ([["--wall"]] if float(lumen) > -30 else []))
            # Sometimes an airway's walls drawn for Pi10 (refused, naming the plot, where there
            # is no Pi10).
            pi10 = (["--plot-pi10", os.path.join(d, "pi.svg")]
                    if dark and wall and random.random() < 0.5 else [])
            why = why or (os.path.exists(vol) and run(
                ["measure", vol, "--path", p, "-q", "--json", "-o", os.path.join(d, "m.csv"),
                 "--lumen", lumen, "--open", random.choice(["0", "2"])] + count + grade + wall
                + (["--angle", random.choice(["0,1,2", "5,1,9", "1,2,1e9", "-1,0,1"])]
                   if random.random() < 0.3 else [])
                + (["--plot", os.path.join(d, "p." + random.choice(["svg", "png", "dcm"]))]
                   if random.random() < 0.5 else [])
                + (["--mask", os.path.join(d, "m." + random.choice(["nii", "nii.gz", "seg.nrrd"]))]
                   if random.random() < 0.3 else [])
                + pi10 + dark, (s, "pi.svg") if pi10 else s))
            # And a centreline tracked through its points.
            why = why or (os.path.exists(vol) and run(
                ["centreline", vol, "--path", p, "-q", "-o", os.path.join(d, "cl.mrk.json"),
                 "--lumen", random.choice(["-500", "0", "150"])]
                + (["--dark"] if random.random() < 0.3 else []), s))
            bad += settle(why, p, d)
            continue
        # A 4-D image's phases: one picked (maybe one it lacks), or all as a cine.
        four_d = s.startswith("v4")
        phase = ["--phase", random.choice("123")] if four_d and random.random() < 0.5 else []
        # Sometimes the body too (--body; refused, naming the file, for a mesh or a volume not
        # in HU), written as a label map.
        body = (["--body", "--mask", os.path.join(d, "body.nii.gz")]
                if random.random() < 0.2 else [])
        # Sometimes its values within itself as a segmentation, with densitometry (a CT is
        # refused as no label map, a mesh as no volume).
        within = (["--segmentation", p]
                  + random.choice([["--below", "-950"], ["--below", "-950,0"], ["--below=-856"]])
                  + random.choice([[], ["--clusters"], ["--clusters", "2d"],
                                   ["--below-mask", os.path.join(d, "laa.nii.gz")]])
                  + ["--percentile", random.choice(["15", "0,100", "2.5"])]
                  + random.choice([[], ["--adjust-to", "1=tlc:male:180"], ["--adjust-to", "all=5000"]])
                  + random.choice([[], ["--agatston"],
                                   ["--agatston", "--agatston-mask", os.path.join(d, "cac.nii.gz")]])
                  if random.random() < 0.15 else [])
        why = run(["info", p, "--json"] + phase + body + within, s) or run(
            ["render", p, "--aov", "prim", "--size", "8x8", "-q", "--device", device,
             "-o", os.path.join(d, "o.png")], s)
        if not why and s.endswith((".obj", ".ply", ".glb", ".gltf")):
            # Shaded, so that normals and materials are used.
            shells = ["--colour-shells", "--legend"] if random.random() < 0.3 else []
            why = run(["render", p, "--size", "8x8", "--spp", "1", "-q", "--device", device]
                      + shells + ["-o", os.path.join(d, "s.png")], s)
        if not why and not s.endswith((".obj", ".stl", ".ply", ".glb", ".gltf")) and random.random() < 0.3:
            # Its bones as a surface, some of their islands kept.
            # (--body-only: a CT kept to its body; refused, naming it, for a volume not in HU.)
            body = ["--body-only"] if random.random() < 0.3 else []
            why = run(["iso", p, "-q"] + islands() + body + phase + ["-o", os.path.join(d, "b.stl")], (s, "b.stl"))
        if not why and not s.endswith((".obj", ".stl", ".ply", ".glb", ".gltf")):
            # A volume also goes straight through a windowed mode, its HU into an EXR.
            mode = random.choice(["mip", "minip", "average", "slice", "dvr", "cinematic"])
            extra = ["--slab", "3"] if mode != "slice" and random.random() < 0.5 else []
            if mode == "cinematic":
                extra += ["--spp", "2", "--max-depth", "2"]
                if random.random() < 0.5:
                    extra.append("--denoise")
                if random.random() < 0.3:
                    extra += ["--anisotropy", random.choice(["0.5", "-0.3", "0.95"]),
                              "--exposure", random.choice(["1", "-2.5"])]
            # Any interpolation, whatever the mode's default (a 1-voxel-thin axis has
            # neighbours only by clamping).
            if random.random() < 0.4:
                extra += ["--interpolation", random.choice(["linear", "cubic", "cubic-interpolating"])]
            # Some as a turntable (or a cine) of EXR frames into a folder, or as one animation.
            frames = ["--cine"] if four_d and not phase else ["--turntable", "2"]
            pick = random.random()
            if pick < 0.2:
                out = frames + ["--format", "exr", "-o", os.path.join(d, "frames")]
            elif pick < 0.3:
                kind = random.choice(["apng", "gif"])
                out = frames + ["--format", kind, "--fps", random.choice(["1", "12", "50"]),
                                "-o", os.path.join(d, "a." + ("png" if kind == "apng" else "gif"))]
            else:
                out = ["-o", os.path.join(d, "o.exr")] + phase
            # Sometimes kept to the body (with --cine a usage error).
            if "--cine" not in out and random.random() < 0.3:
                extra.append("--body-only")
            why = run(["render", p, "--mode", mode, "--size", "8x8", "-q", "--device", device,
                       "--view", random.choice(["inferior", "left", "anterior"])] + extra + out, s)
            # Sometimes a slice of it tinted by itself as a label map (a Segmentation is one;
            # a CT is refused as none).
            if not why and random.random() < 0.2:
                outline = ["--outline"] if random.random() < 0.5 else []
                outline += random.choice([[], [], ["--below=0.5", "--legend"], ["--below=-950"]])
                why = run(["render", p, "--mode", "slice", "--size", "8x8", "-q", "--device",
                           device, "--segmentation", p] + outline + phase + ["-o", os.path.join(d, "t.png")], s)
            # Sometimes rendered in the colours of its own segments, or kept to some of them
            # (a CT is refused as no label map; the projections take only --segment).
            if not why and random.random() < 0.2:
                m = random.choice(["dvr", "iso", "mip", "minip", "average", "cinematic"])
                keep = (["--segment", random.choice(["all", "1", "2,1"])]
                        if m in ("mip", "minip", "average") or random.random() < 0.5 else [])
                more = ["--spp", "2", "--max-depth", "1"] if m == "cinematic" else []
                why = run(["render", p, "--mode", m, "--size", "8x8", "-q", "--device", device,
                           "--segmentation", p] + keep + more + phase
                          + ["-o", os.path.join(d, "c.png")], s)
            # Sometimes its segments as surfaces, written (some simplified) or rendered (a CT is
            # refused as no label map).
            if not why and random.random() < 0.3:
                segments = ["--segment", random.choice(["all", "1", "2,1", "Lumen", "body", "tumour"]),
                            "--smooth", random.choice(["0", "3"])] + phase
                if random.random() < 0.3:
                    # Names and colours from a mutated colour table (3D Slicer's or ITK-SNAP's).
                    table = random.choice([
                        b"# Color table\n0 Background 0 0 0 0\n1 lumen 0 255 255 255\n2 wall 255 0 255 255\n",
                        b'0 0 0 0 0 0 0 "Clear Label"\n1 0 255 255 1 1 1 "lumen"\n2 255 0 255 1 1 1 "wall"\n'])
                    ctbl = os.path.join(d, "t.ctbl")
                    with open(ctbl, "wb") as f:
                        f.write(mutate(table, True))
                    segments += ["--colour-table", ctbl]
                segments += islands(shells=False)
                if random.random() < 0.5:
                    simplify = ["--simplify", random.choice(["0.1", "1"])] if random.random() < 0.5 else []
                    why = run(["iso", p, "-q"] + segments + simplify + ["-o", os.path.join(
                        d, "s." + random.choice(["glb", "obj", "ply", "stl", "vtk", "vtp", "3mf"]))], (s, "t.ctbl", "s.stl"))
                else:
                    why = run(["render", p, "-q", "--size", "8x8", "--spp", "1", "--device", device]
                              + segments + ["-o", os.path.join(d, "s.png")], (s, "t.ctbl"))
        bad += settle(why, p, d)
    return bad


SCENE = """background = [0.1, 0.1, 0.1]
ambient = [0.3, 0.3, 0.3]
[camera]
eye = [0, 1, 5]
target = [0, 0, 0]
fov = 40
[[lights]]
position = [3, 5, 4]
color = [1, 1, 1]
[materials.glass]
diffuse = [0.1, 0.1, 0.1]
transparency = 0.8
reflectivity = 0.1
ior = 1.5
[materials.mirror]
reflectivity = 0.7
[[objects]]
shape = "sphere"
material = "glass"
[[objects]]
shape = "quad"
material = "mirror"
scale = [5, 1, 5]
translate = [0, -1, 0]
[[objects]]
shape = "spot"
translate = [1.5, 0, 0]
scale = 0.5
rotate = [0, 30, 0]
"""


def halves_of(ct, work):
    """A label map of `ct`'s two halves (scripts/halves-label-map.py), made once."""
    out = os.path.join(work, "halves.mha")
    if not os.path.exists(out):
        info = subprocess.run([BIN, "info", ct, "--json"], capture_output=True, check=True).stdout
        subprocess.run([sys.executable, os.path.join(ROOT, "scripts/halves-label-map.py"), out],
                       input=info, check=True)
    return out


def fuzz_scenes(work, n):
    python = os.path.join(ROOT, ".venv/bin/python")
    rays_py = os.path.join(SHARED, "tools/rays.py")
    bad = 0
    for i in range(n):
        s, framing = SCENE, []
        if random.random() < 0.5:
            # The framing camera instead of the file's, turned and projected at random.
            s = re.sub(r"\[camera\]\n(.*\n){3}", "", s)
            framing = [f"--orbit={random.uniform(-360, 360):.3f},{random.uniform(-90, 90):.3f}"]
            framing += ["--parallel"] if random.random() < 0.5 else []
        if random.random() < 0.3:
            # The built-in CT among the meshes, read either way (its numbers mutated too), half
            # of them in the colours of a label map of its halves on another grid, or kept to
            # one half.
            ct = os.path.join(ROOT, "crates/raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz")
            s += (f'[volume]\npath = "{ct}"\npreset = "ct-bones"\nstep = 3.0\n'
                  f'interpolation = "{random.choice(["linear", "cubic", "cubic-interpolating"])}"\n')
            if random.random() < 0.5:
                s += f'segmentation = "{halves_of(ct, work)}"\n'
                s += random.choice(["", 'segment = "all"\n', "segment = [2]\n", 'segment = "1, 2"\n'])
            if random.random() < 0.3:
                s += "body_only = true\n"
        for _ in range(random.randint(1, 3)):
            m = random.choice(list(re.finditer(r"-?\d+(\.\d+)?", s)))
            s = s[:m.start()] + random.choice(
                ["0", "-1", "1e30", "-1e30", "nan", "inf", "-inf", "1e-30", "1e9", "-0.0"]) + s[m.end():]
        name = f"scene{i}.toml"
        p = os.path.join(work, name)
        open(p, "w").write(s)
        def render_both(size):
            """None and whether both devices rendered it, or what went wrong."""
            codes, why = [], None
            for dev in ("cpu", "gpu"):
                png = os.path.join(work, f"scene{i}-{dev}.png")
                if os.path.exists(png):
                    os.remove(png)
                why = why or run(["render", p, "--size", size, "--spp", "2", "--max-depth", "3",
                                  "-q", "--device", dev, "-o", png] + framing, name)
                codes.append(os.path.exists(png))
            if why or codes == [False, False]:
                return why, False
            if codes != [True, True]:
                return "one device rendered it, the other refused it", False
            return None, True

        def compare():
            """The issue's bound on the two images: mean < 0.5/255, at most 0.1 % of pixels
            beyond 2/255; the difference, or None."""
            r = subprocess.run([python, rays_py, "imgdiff",
                                os.path.join(work, f"scene{i}-cpu.png"),
                                os.path.join(work, f"scene{i}-gpu.png"), "--json"],
                               capture_output=True)
            j = json.loads(r.stdout)
            if j["mean_abs_diff"] >= 0.5 or j["frac_gt_2"] > 0.001:
                return j
            return None

        why, both = render_both("24x16")
        j = compare() if both else None
        if j and j["mean_abs_diff"] < 0.5 and j["frac_gt_2"] * 384 < 1.5:
            # One pixel in 384 is past a bound made for frames (0.1 %): judge it again on 96x64
            # (a scene at the f32 edge functions' limit, a strip drawn out to 1e9, differs by
            # such a pixel; BENCHMARKS.md, "A long ground plane").
            why, both = render_both("96x64")
            j = compare() if both else None
            print(f"{name}: one pixel beyond 2/255 at 24x16; at 96x64 "
                  + (why or ("beyond the bound" if j else "within it")))
        if j:
            why = f"GPU vs CPU: mean {j['mean_abs_diff']:.3f}/255, {j['frac_gt_2']:.4f} > 2/255"
        if why:
            bad += 1
            print(f"FAIL {p} {' '.join(framing)}: {why}")
    return bad


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=["files", "scenes"])
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--device", default="cpu", choices=["cpu", "gpu"])
    ap.add_argument("--only", help="files: these seeds alone, comma-separated (tc.ply,tc.vtp)")
    a = ap.parse_args()
    random.seed(a.seed)
    work = tempfile.mkdtemp(prefix="raystream-fuzz-")
    only = a.only.split(",") if a.only else None
    bad = fuzz_files(work, a.runs, a.device, only) if a.what == "files" else fuzz_scenes(work, a.runs)
    if bad:
        print(f"{a.what}: {a.runs} runs, {bad} failed (inputs of failures kept in {work})")
    else:
        shutil.rmtree(work)
        print(f"{a.what}: {a.runs} runs, 0 failed")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
