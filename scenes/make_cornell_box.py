#!/usr/bin/env python3
"""Writes cornell-box.obj and cornell-box-closed.obj from the published Cornell box data.

Source: Cornell University Program of Computer Graphics, "Cornell Box Data",
https://www.graphics.cornell.edu/online/box/data.html (millimetres, vertices in published order).
The vertices are read from the repository's reference copy of that page, `../../shared/data/cornell-box.md`.
Run from this folder: `python3 make_cornell_box.py`. The MTL file and the TOML file are written by hand.
"""

import os

SOURCE = "Cornell Program of Computer Graphics, Cornell Box Data, graphics.cornell.edu/online/box/data.html"

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "cornell-box.md")


def published():
    """The published quads, read from the reference data's table (`shared/data/cornell-box.md`, beside the
    repository): surface name (without its parenthesised note) -> list of quads, each a list of (x, y, z)."""
    quads = {}
    with open(DATA) as f:
        for line in f:
            if not (line.startswith("| ") and "(" in line):
                continue
            surface, _material, vertices = [c.strip() for c in line.strip().strip("|").split("|")]
            surface = surface.split(" (")[0]
            for quad in vertices.split(";"):
                points = [v.strip().lstrip("(") for v in quad.split(")") if v.strip()]
                quads.setdefault(surface, []).append([tuple(float(c) for c in p.split(",")) for p in points])
    return quads


PUBLISHED = published()
FLOOR = PUBLISHED["floor"][0]
LIGHT = PUBLISHED["light"][0]
CEILING_Y = PUBLISHED["ceiling"][0][0][1]
BACK = PUBLISHED["back wall"][0]
GREEN = PUBLISHED["right wall"][0]
RED = PUBLISHED["left wall"][0]
SHORT = [("short block top", PUBLISHED["short block top"][0])]
SHORT += [("short block side", q) for q in PUBLISHED["short block sides"]]
TALL = [("tall block top", PUBLISHED["tall block top"][0])]
TALL += [("tall block side", q) for q in PUBLISHED["tall block sides"]]


def ceiling_pieces():
    """The published ceiling (556 x 559.2) with a rectangular opening for the light: four convex pieces.

    Each piece keeps the published ceiling's winding (x_max, z0) (x_max, z1) (x_min, z1) (x_min, z0),
    whose normal points down into the room.
    """
    (lx1, _, lz0), (_, _, lz1), (lx0, _, _) = LIGHT[0], LIGHT[1], LIGHT[2]
    rects = [
        ("ceiling front of light", 0, 556, 0, lz0),
        ("ceiling behind light", 0, 556, lz1, 559.2),
        ("ceiling left of light", lx1, 556, lz0, lz1),
        ("ceiling right of light", 0, lx0, lz0, lz1),
    ]
    y = CEILING_Y
    return [(name, [(x1, y, z0), (x1, y, z1), (x0, y, z1), (x0, y, z0)]) for name, x0, x1, z0, z1 in rects]


def edges(poly):
    """Edges of a footprint polygon in the (x, z) plane."""
    pts = [(p[0], p[2]) for p in poly]
    return [(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]


def z_at(edge, x):
    (xa, za), (xb, zb) = edge
    return za + (zb - za) * (x - xa) / (xb - xa)


def floor_without_footprints():
    """The floor minus the two blocks' footprints, as convex pieces (vertical slab decomposition).

    Breakpoints are the footprints' vertex x coordinates. Between breakpoints, the floor strip
    z in [0, 559.2] minus the footprints is a stack of trapezoids bounded by the edges that span the slab.
    Left of the first breakpoint and right of the last one there is no footprint, so the piece is the
    floor clipped to that x range (the right one keeps the published slanted floor edge).
    """
    holes = [SHORT[0][1], TALL[0][1]]
    hole_edges = [e for h in holes for e in edges(h) if e[0][0] != e[1][0]]
    xs = sorted({p[0] for h in holes for p in h})
    pieces = []
    # Left end: x in [0, xs[0]], a rectangle.
    pieces.append([(0, 0), (0, 559.2), (xs[0], 559.2), (xs[0], 0)])
    for xa, xb in zip(xs, xs[1:]):
        xm = 0.5 * (xa + xb)
        spanning = [e for e in hole_edges if min(e[0][0], e[1][0]) <= xa and max(e[0][0], e[1][0]) >= xb]
        bottom = ((xa, 0), (xb, 0))
        top = ((xa, 559.2), (xb, 559.2))
        chain = sorted([bottom, top] + spanning, key=lambda e: z_at(e, xm))
        for lo, hi in zip(chain[0::2], chain[1::2]):
            quad = [(xa, z_at(lo, xa)), (xa, z_at(hi, xa)), (xb, z_at(hi, xb)), (xb, z_at(lo, xb))]
            dedup = []
            for p in quad:
                if not dedup or abs(p[0] - dedup[-1][0]) > 1e-9 or abs(p[1] - dedup[-1][1]) > 1e-9:
                    dedup.append(p)
            if abs(dedup[0][0] - dedup[-1][0]) < 1e-9 and abs(dedup[0][1] - dedup[-1][1]) < 1e-9:
                dedup.pop()
            pieces.append(dedup)
    # Right end: x in [xs[-1], 552.8], bounded by the published slanted edge (552.8, 0)-(549.6, 559.2).
    pieces.append([(xs[-1], 0), (xs[-1], 559.2), (549.6, 559.2), (552.8, 0)])
    out = []
    for p in pieces:
        out.append(("floor piece", [(x, 0, z) for x, z in p]))
    return out


def fmt(v):
    s = ("%.9f" % v).rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def write(path, header, groups):
    lines = ["# " + h for h in header]
    lines.append("mtllib cornell-box.mtl")
    count = 0
    for obj, mat, faces in groups:
        lines.append("")
        lines.append("o " + obj)
        lines.append("usemtl " + mat)
        for name, poly in faces:
            lines.append("# face %d: %s" % (count, name))
            for p in poly:
                lines.append("v " + " ".join(fmt(c) for c in p))
            lines.append("f " + " ".join(str(-len(poly) + i) for i in range(len(poly))))
            count += 1
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return count


COMMON_HEADER = [
    "Cornell box. Data source: " + SOURCE + ".",
    "Geometry in millimetres as published; every face keeps the published vertex order (counter-clockwise seen",
    "from the side the normal points to: into the room, out of the blocks). y is up, the open side is z = 0.",
    "Changes to the published data: the ceiling is split into four convex pieces around the light (the light",
    "lies in the ceiling plane, so the two must not overlap); the red wall, non-planar by about 3 mm as",
    "published, is the last face so that with --no-subdivide patch k = OBJ face k for every other face (the",
    "loader splits the red wall into two triangles with a warning).",
    "Generated by make_cornell_box.py. Face indices (0-based, OBJ order) are in the comments.",
]


def main():
    body = [
        ("floor", "white", [("floor", FLOOR)]),
        ("light", "light", [("light", LIGHT)]),
        ("ceiling", "white", ceiling_pieces()),
        ("back_wall", "white", [("back wall", BACK)]),
        ("green_wall", "green", [("green wall (x = 0)", GREEN)]),
        ("short_block", "white", SHORT),
        ("tall_block", "white", TALL),
        ("red_wall", "red", [("red wall (x ~ 550, non-planar by ~3 mm as published)", RED)]),
    ]
    n = write("cornell-box.obj", COMMON_HEADER, body)
    print("cornell-box.obj:", n, "faces")
    front = [(0, 0, 0), (552.8, 0, 0), (556, 548.8, 0), (0, 548.8, 0)]
    closed = [("floor", "white", floor_without_footprints())] + body[1:] + [
        ("front_wall", "white", [("front wall (z = 0, closes the box, normal +z into the room)", front)])
    ]
    header = COMMON_HEADER + [
        "CLOSED VARIANT for closure tests (every row of F sums to 1): the open side z = 0 is closed by a white",
        "front wall (added, not published), and the floor excludes the blocks' footprints (the blocks have no",
        "bottom faces, so floor under them would see only back faces). The floor is cut into convex pieces by a",
        "vertical slab decomposition at the footprints' vertex x coordinates.",
    ]
    n = write("cornell-box-closed.obj", header, closed)
    print("cornell-box-closed.obj:", n, "faces")


if __name__ == "__main__":
    main()
