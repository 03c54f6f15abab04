"""Writes the mesh files of codegen/tests/import/mesh_inertia.xml (run from this directory).

box.stl (binary), box_ascii.stl, box.obj (quads): a box of half sizes 0.5 0.25 0.125 about the
origin. u_shape.obj: a U (a slab 2 x 1 x 0.5 and two pillars 0.5 x 1 x 0.5 on its ends), offset
from the origin, triangles turned outwards; its hull is the box 2 x 1 x 1.
Every coordinate is exact in single precision (MuJoCo stores vertices as float).
"""
import struct

H = (0.5, 0.25, 0.125)
corners = [tuple((1 if (k >> i) & 1 else -1) * H[i] for i in range(3)) for k in range(8)]
quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
tris = [t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]

with open("box.stl", "wb") as f:
    f.write(b"rbss test box".ljust(80, b" ") + struct.pack("<I", len(tris)))
    for t in tris:
        f.write(struct.pack("<3f", 0, 0, 0))
        for i in t:
            f.write(struct.pack("<3f", *corners[i]))
        f.write(b"\0\0")
with open("box_ascii.stl", "w") as f:
    f.write("solid box\n")
    for t in tris:
        f.write("  facet normal 0 0 0\n    outer loop\n")
        for i in t:
            f.write("      vertex %r %r %r\n" % corners[i])
        f.write("    endloop\n  endfacet\n")
    f.write("endsolid box\n")
with open("box.obj", "w") as f:
    f.write("# a box of half sizes 0.5 0.25 0.125, quads\n")
    for c in corners:
        f.write("v %r %r %r\n" % c)
    for q in quads:
        f.write("f %s\n" % " ".join("%d//1" % (i + 1) for i in q))

# The U: cells of 0.5 in x (4) and z (2), 1 in y; filled cells, then their outer faces.
OFF = (0.25, -0.5, 0.125)
filled = {(i, 0) for i in range(4)} | {(0, 1), (3, 1)}
verts, index, faces = [], {}, []


def vid(i, j, k):
    key = (i, j, k)
    if key not in index:
        index[key] = len(verts)
        verts.append((OFF[0] + 0.5 * i, OFF[1] + 1.0 * j, OFF[2] + 0.5 * k))
    return index[key]


def quad(a, b, c, d):  # counter-clockwise seen from outside
    faces.append((a, b, c))
    faces.append((a, c, d))


for (i, k) in sorted(filled):
    v = lambda di, dj, dk: vid(i + di, dj, k + dk)
    quad(v(0, 0, 0), v(1, 0, 0), v(1, 0, 1), v(0, 0, 1))  # -y
    quad(v(0, 1, 0), v(0, 1, 1), v(1, 1, 1), v(1, 1, 0))  # +y
    if (i - 1, k) not in filled:
        quad(v(0, 0, 0), v(0, 0, 1), v(0, 1, 1), v(0, 1, 0))  # -x
    if (i + 1, k) not in filled:
        quad(v(1, 0, 0), v(1, 1, 0), v(1, 1, 1), v(1, 0, 1))  # +x
    if (i, k - 1) not in filled:
        quad(v(0, 0, 0), v(0, 1, 0), v(1, 1, 0), v(1, 0, 0))  # -z
    if (i, k + 1) not in filled:
        quad(v(0, 0, 1), v(1, 0, 1), v(1, 1, 1), v(0, 1, 1))  # +z
with open("u_shape.obj", "w") as f:
    f.write("# a U: slab [0,2]x[0,1]x[0,0.5], pillars x in [0,0.5] and [1.5,2], z in [0.5,1]; offset %r\n" % (OFF,))
    for p in verts:
        f.write("v %r %r %r\n" % p)
    for t in faces:
        f.write("f %d %d %d\n" % tuple(i + 1 for i in t))
