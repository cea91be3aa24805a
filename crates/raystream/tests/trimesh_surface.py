"""The surface measures of meshes as trimesh takes them, for
`info_measures_a_surface_as_trimesh_does` (tests/render.rs).

Usage: trimesh_surface.py MESH...

Each mesh is read by trimesh for its geometry alone (its corners merged by position, as
`info` merges them), and measured by trimesh: area, volume, whether it is watertight and
wound one way, its pieces joined through edges (its face adjacency's connected components,
with scipy), its Euler characteristic, its vertices and edges, the edges of one triangle and
of more than two, and its holes (the loops of its outline); and each piece so, alone (its
faces taken out as a mesh of their own), in `pieces`. Prints one JSON object, by file name.
"""

import json
import os
import sys

import numpy as np
import trimesh
from trimesh import graph


def measures(m):
    uses = np.unique(m.edges_sorted, axis=0, return_counts=True)[1]
    pieces = graph.connected_components(m.face_adjacency, nodes=np.arange(len(m.faces)))
    return {
        "triangles": len(m.faces),
        "area": float(m.area),
        "volume": float(m.volume),
        "watertight": bool(m.is_watertight),
        "winding_consistent": bool(m.is_winding_consistent),
        "shells": len(pieces),
        "euler": int(m.euler_number),
        "vertices": len(m.vertices),
        "edges": len(uses),
        "boundary_edges": int((uses == 1).sum()),
        "non_manifold_edges": int((uses > 2).sum()),
        "holes": 0 if m.is_watertight else len(m.outline().entities),
    }, pieces


out = {}
for path in sys.argv[1:]:
    read = trimesh.load(path, force="mesh", process=False)
    m = trimesh.Trimesh(read.vertices, read.faces)
    whole, pieces = measures(m)
    whole["pieces"] = []
    for p in pieces:
        piece = trimesh.Trimesh(m.vertices, m.faces[np.sort(p)])
        piece.remove_unreferenced_vertices()
        whole["pieces"].append(measures(piece)[0])
    out[os.path.basename(path)] = whole
print(json.dumps(out))
