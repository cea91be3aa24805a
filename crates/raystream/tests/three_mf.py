"""lib3mf (the 3MF Consortium's own library) as the reference for raystream's 3MF reading and
writing, for tests/render.rs.
Usage: python three_mf.py OUTDIR [WRITTEN.3mf]
Writes with lib3mf, in OUTDIR:
- parts.3mf: in centimetres; a cube with no colours, a tetrahedron coloured by its object's
  base material, a second one whose triangles name a colour group's colours (one a colour a
  corner, one its object's), and a components object holding the first twice (once mirrored)
  and the second once; the build places the cube, the components object and the second
  tetrahedron, each by its transform;
- plain.3mf: a cube with no properties, in inches.
Then reads each back with lib3mf and prints one JSON object: for each file, its path and its
triangles as the build places them, in millimetres (corners, f64 from lib3mf's f32 values), each
with its corners' colours (null where it has none), depth first through the build and the
components, in order. With WRITTEN.3mf (raystream's), also its unit and each object's name,
display colour and triangle count, and whether it is manifold and oriented (as a printer's
slicer needs it), as lib3mf reads them."""
import json, os, sys

import lib3mf
import numpy as np

w = lib3mf.get_wrapper()
out = sys.argv[1]
os.makedirs(out, exist_ok=True)

TETRA_V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TETRA_T = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def transform(m4x3):
    t = lib3mf.Transform()
    for r in range(4):
        for c in range(3):
            t.Fields[r][c] = m4x3[r][c]
    return t


def rotation_z(deg, translate, scale=1.0, mirror=False):
    a = np.radians(deg)
    m = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]]) * scale
    if mirror:
        m[:, 0] *= -1
    return [list(m[0]), list(m[1]), list(m[2]), list(translate)]


def mesh(model, name, vertices, triangles):
    o = model.AddMeshObject()
    o.SetName(name)
    for v in vertices:
        p = lib3mf.Position()
        p.Coordinates[0], p.Coordinates[1], p.Coordinates[2] = v
        o.AddVertex(p)
    for t in triangles:
        tri = lib3mf.Triangle()
        tri.Indices[0], tri.Indices[1], tri.Indices[2] = t
        o.AddTriangle(tri)
    return o


def write_parts(path):
    m = w.CreateModel()
    m.SetUnit(lib3mf.ModelUnit.CentiMeter)
    base = m.AddBaseMaterialGroup()
    base.AddMaterial("bone", w.RGBAToColor(227, 217, 201, 255))
    red = base.AddMaterial("red", w.RGBAToColor(200, 30, 20, 255))
    a = mesh(m, "A", [tuple(2.0 * x for x in v) for v in TETRA_V], TETRA_T)
    a.SetObjectLevelProperty(base.GetResourceID(), red)
    group = m.AddColorGroup()
    colours = [group.AddColor(w.RGBAToColor(*c, 255))
               for c in [(255, 0, 0), (0, 255, 0), (0, 0, 255), (250, 250, 10), (10, 120, 240)]]
    b = mesh(m, "B", [(5 + x, y, z) for x, y, z in TETRA_V], TETRA_T)
    # Its object's colour for the last triangle; a colour a corner on the first.
    b.SetObjectLevelProperty(group.GetResourceID(), colours[4])
    for k in range(3):
        p = lib3mf.TriangleProperties()
        p.ResourceID = group.GetResourceID()
        ids = colours[:3] if k == 0 else [colours[k + 1]] * 3
        p.PropertyIDs[0], p.PropertyIDs[1], p.PropertyIDs[2] = ids
        b.SetTriangleProperties(k, p)
    c = m.AddComponentsObject()
    c.SetName("C")
    c.AddComponent(a, transform(rotation_z(0, (0, 0, 3))))
    c.AddComponent(a, transform(rotation_z(90, (-4, 1, 0), mirror=True)))
    c.AddComponent(b, transform(rotation_z(30, (0, -6, 1), scale=0.5)))
    # First, a cube with no colours (grey, then, beside the coloured parts).
    m.AddBuildItem(cube(m), transform(rotation_z(10, (-20, 0, 0))))
    m.AddBuildItem(c, transform(rotation_z(45, (10, 20, 30))))
    m.AddBuildItem(b, transform(rotation_z(-20, (0, 0, -5), scale=1.5)))
    m.QueryWriter("3mf").WriteToFile(path)


def cube(m):
    v = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    t = [(0, 2, 1), (1, 2, 3), (4, 5, 6), (5, 7, 6), (0, 1, 4), (1, 5, 4),
         (2, 6, 3), (3, 6, 7), (0, 4, 2), (2, 4, 6), (1, 3, 5), (3, 7, 5)]
    return mesh(m, "cube", v, t)


def write_plain(path):
    m = w.CreateModel()
    m.SetUnit(lib3mf.ModelUnit.Inch)
    m.AddBuildItem(cube(m), w.GetIdentityTransform())
    m.QueryWriter("3mf").WriteToFile(path)


MM = {lib3mf.ModelUnit.MicroMeter: 0.001, lib3mf.ModelUnit.MilliMeter: 1.0,
      lib3mf.ModelUnit.CentiMeter: 10.0, lib3mf.ModelUnit.Inch: 25.4,
      lib3mf.ModelUnit.Foot: 304.8, lib3mf.ModelUnit.Meter: 1000.0}


def matrix(t):
    """A lib3mf transform (row vectors) as a 4x4 column-vector matrix, f64."""
    f = np.array([[t.Fields[r][c] for c in range(3)] for r in range(4)], dtype=np.float64)
    m = np.eye(4)
    m[:3, :3] = f[:3, :3].T
    m[:3, 3] = f[3]
    return m


def colour_of(model, resource, prop):
    kind = model.GetPropertyTypeByID(resource)
    if kind == lib3mf.PropertyType.BaseMaterial:
        c = model.GetBaseMaterialGroupByID(resource).GetDisplayColor(prop)
    elif kind == lib3mf.PropertyType.Colors:
        c = model.GetColorGroupByID(resource).GetColor(prop)
    else:
        return None
    return [c.Red, c.Green, c.Blue]


def triangles(path):
    m = w.CreateModel()
    m.QueryReader("3mf").ReadFromFile(path)
    scale = np.diag([MM[m.GetUnit()]] * 3 + [1.0])
    found = []

    def visit(obj, world):
        if obj.IsComponentsObject():
            comps = m.GetComponentsObjectByID(obj.GetResourceID())
            for k in range(comps.GetComponentCount()):
                c = comps.GetComponent(k)
                visit(c.GetObjectResource(), world @ matrix(c.GetTransform()))
            return
        mo = m.GetMeshObjectByID(obj.GetResourceID())
        vs = [np.array(list(v.Coordinates) + [1.0], dtype=np.float64) for v in mo.GetVertices()]
        mirrored = np.linalg.det(world[:3, :3]) < 0
        for k, t in enumerate(mo.GetTriangleIndices()):
            corners = [list((world @ vs[i])[:3]) for i in t.Indices]
            p = mo.GetTriangleProperties(k)
            cols = None
            if p.ResourceID != 0:
                cols = [colour_of(m, p.ResourceID, p.PropertyIDs[i]) for i in range(3)]
                if None in cols:
                    cols = None
            if mirrored:
                corners = [corners[0], corners[2], corners[1]]
                cols = cols and [cols[0], cols[2], cols[1]]
            found.append({"corners": corners, "colours": cols})

    items = m.GetBuildItems()
    while items.MoveNext():
        item = items.GetCurrent()
        visit(item.GetObjectResource(), scale @ matrix(item.GetObjectTransform()))
    return found


def written(path):
    m = w.CreateModel()
    m.QueryReader("3mf").ReadFromFile(path)
    objects = []
    it = m.GetMeshObjects()
    while it.MoveNext():
        o = it.GetCurrent()
        resource, prop, has = o.GetObjectLevelProperty()
        objects.append({"name": o.GetName(), "triangles": o.GetTriangleCount(),
                        "colour": colour_of(m, resource, prop) if has else None,
                        "manifold": o.IsManifoldAndOriented()})
    return {"unit_mm": MM[m.GetUnit()], "objects": objects}


files = {"parts": os.path.join(out, "parts.3mf"), "plain": os.path.join(out, "plain.3mf")}
write_parts(files["parts"])
write_plain(files["plain"])
result = {name: {"path": p, "triangles": triangles(p)} for name, p in files.items()}
if len(sys.argv) > 2:
    result["written"] = written(sys.argv[2])
print(json.dumps(result))
