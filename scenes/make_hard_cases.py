#!/usr/bin/env python3
"""Writes the hard-case scenes of issue 5: `python3 make_hard_cases.py [OUT_DIR]` (default: this script's folder).

- hdr-boxes.obj/.mtl: emission spanning 1e-6 .. 1e6 in one scene. Three closed cubes of side 10 (inward
  normals), 20 units apart so no cube sees another; each cube's ceiling is a light (Ke 1e6, 1 and 1e-6 W/m^2),
  every surface has Kd 0.5.
- slab.obj/.mtl: the form-factor singularity. A closed 1 x 1 x 0.001 slab (inward normals): its floor and ceiling
  are parallel unit squares 0.001 apart (nearly touching), its four sides are 1 x 0.001 slivers sharing an edge
  with each of them. The ceiling is a light (Ke 1), every surface Kd 0.5. Every form factor between its six
  faces follows from two closed forms (parallel and perpendicular rectangles), see tests/tests/verification.rs.

Data source: none needed (analytic test scenes).
"""

import os
import sys


def cube(x0, y0, z0, s, mat_walls, mat_ceiling, v_offset):
    """Vertices and faces of a closed axis-aligned box with inward normals; the ceiling (y = max) gets
    mat_ceiling. Returns (vertex lines, face lines)."""
    return box(x0, y0, z0, s, s, s, mat_walls, mat_ceiling, v_offset)


def box(x0, y0, z0, sx, sy, sz, mat_walls, mat_ceiling, v_offset):
    xs, ys, zs = (x0, x0 + sx), (y0, y0 + sy), (z0, z0 + sz)
    verts = []
    for k in range(8):
        verts.append((xs[k & 1], ys[(k >> 1) & 1], zs[(k >> 2) & 1]))
    # Vertex index of corner (i, j, k), 1-based with the offset.
    def v(i, j, k):
        return v_offset + 1 + i + 2 * j + 4 * k
    # Counter-clockwise seen from inside (right-hand rule gives the inward normal).
    faces = [
        ("floor y=min, normal +y", mat_walls, [v(0, 0, 0), v(0, 0, 1), v(1, 0, 1), v(1, 0, 0)]),
        ("ceiling y=max, normal -y", mat_ceiling, [v(0, 1, 0), v(1, 1, 0), v(1, 1, 1), v(0, 1, 1)]),
        ("x=min, normal +x", mat_walls, [v(0, 0, 0), v(0, 1, 0), v(0, 1, 1), v(0, 0, 1)]),
        ("x=max, normal -x", mat_walls, [v(1, 0, 0), v(1, 0, 1), v(1, 1, 1), v(1, 1, 0)]),
        ("z=min, normal +z", mat_walls, [v(0, 0, 0), v(1, 0, 0), v(1, 1, 0), v(0, 1, 0)]),
        ("z=max, normal -z", mat_walls, [v(0, 0, 1), v(0, 1, 1), v(1, 1, 1), v(1, 0, 1)]),
    ]
    vlines = ["v %g %g %g" % p for p in verts]
    flines = []
    for comment, mat, idx in faces:
        flines.append((comment, mat, "f " + " ".join(str(i) for i in idx)))
    return vlines, flines


def write(name, header, mtl, boxes):
    out = [header, "mtllib %s.mtl" % name]
    offset = 0
    body = []
    for b in boxes:
        vl, fl = box(*b, v_offset=offset)
        out += vl
        offset += 8
        body += fl
    face = 0
    current = None
    out.append("o %s" % name)
    for comment, mat, line in body:
        if mat != current:
            out.append("usemtl %s" % mat)
            current = mat
        out.append("# face %d: %s" % (face, comment))
        out.append(line)
        face += 1
    with open(os.path.join(OUT, name + ".obj"), "w") as f:
        f.write("\n".join(out) + "\n")
    with open(os.path.join(OUT, name + ".mtl"), "w") as f:
        f.write(mtl)


if len(sys.argv) > 2 or (len(sys.argv) == 2 and sys.argv[1].startswith("-")):
    sys.exit("usage: make_hard_cases.py [OUT_DIR]  (writes hdr-boxes and slab; default OUT_DIR: this script's folder)")
OUT = sys.argv[1] if len(sys.argv) == 2 else os.path.dirname(os.path.abspath(__file__))
if not os.path.isdir(OUT):
    sys.exit("make_hard_cases.py: %s is not a folder" % OUT)

write(
    "hdr-boxes",
    "# Emission spanning 1e-6 .. 1e6 W/m^2 in one scene: three closed cubes of side 10, 20 apart (none sees\n"
    "# another), inward normals; ceilings are lights 'bright' (Ke 1e6), 'unit' (Ke 1), 'dim' (Ke 1e-6); Kd 0.5.\n"
    "# Written by make_hard_cases.py. Data source: none needed (analytic test scene).",
    "# Materials of hdr-boxes.obj (written by make_hard_cases.py). Data source: none needed.\n"
    "newmtl wall\nKd 0.5 0.5 0.5\n\n"
    "newmtl bright\nKd 0.5 0.5 0.5\nKe 1e6 1e6 1e6\n\n"
    "newmtl unit\nKd 0.5 0.5 0.5\nKe 1 1 1\n\n"
    "newmtl dim\nKd 0.5 0.5 0.5\nKe 1e-6 1e-6 1e-6\n",
    [
        (0, 0, 0, 10, 10, 10, "wall", "bright"),
        (30, 0, 0, 10, 10, 10, "wall", "unit"),
        (60, 0, 0, 10, 10, 10, "wall", "dim"),
    ],
)

write(
    "slab",
    "# The form-factor singularity: a closed 1 x 1 x 0.001 slab, inward normals. Floor and ceiling are parallel\n"
    "# unit squares 0.001 apart; the four sides are 1 x 0.001 slivers sharing an edge with both. Ceiling Ke 1,\n"
    "# every surface Kd 0.5. Written by make_hard_cases.py. Data source: none needed (analytic test scene).",
    "# Materials of slab.obj (written by make_hard_cases.py). Data source: none needed.\n"
    "newmtl wall\nKd 0.5 0.5 0.5\n\n"
    "newmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\n",
    [(0, 0, 0, 1, 0.001, 1, "wall", "light")],
)
