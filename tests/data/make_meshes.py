#!/usr/bin/env python3
"""Regenerates the mesh fixtures: tests/data/quad.obj, tests/data/quad_le.ply
and the malformed files in tests/corpus/bad/meshes/ (see the README there).
Run from the repository root: python3 tests/data/make_meshes.py"""
import os
import struct

DATA = "tests/data"
BAD = "tests/corpus/bad/meshes"

# The quad of Mitsuba's rectangle: [-1,1]^2 at z = 0, normal +z,
# uv = ((x+1)/2, (y+1)/2); one polygon, fan-triangulated to (0,1,2), (0,2,3).
QUAD = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]


def write(path, data):
    mode = "wb" if isinstance(data, bytes) else "w"
    with open(path, mode) as f:
        f.write(data)


def ply_header(fmt, nv, nf, extra=""):
    return ("ply\nformat %s 1.0\ncomment raysweep test mesh\n"
            "element vertex %d\nproperty float x\nproperty float y\n"
            "property float z\nproperty float nx\nproperty float ny\n"
            "property float nz\nproperty float u\nproperty float v\n"
            "%selement face %d\nproperty list uchar int vertex_indices\n"
            "end_header\n" % (fmt, nv, extra, nf)).encode()


def quad_le(idx=(0, 1, 2, 3), x0=None):
    body = b""
    for i, (x, y, z) in enumerate(QUAD):
        if i == 0 and x0 is not None:
            x = x0
        body += struct.pack("<8f", x, y, z, 0, 0, 1, (x + 1) / 2, (y + 1) / 2)
    body += struct.pack("<B4i", 4, *idx)
    return ply_header("binary_little_endian", 4, 1) + body


def quad_ascii(nf=1, faces="4 0 1 2 3\n"):
    s = ply_header("ascii", 4, nf).decode()
    for (x, y, z) in QUAD:
        s += "%g %g %g 0 0 1 %g %g\n" % (x, y, z, (x + 1) / 2, (y + 1) / 2)
    return s + faces


OBJ = """# quad: [-1,1]^2 at z = 0, normal +z
o quad
v -1 -1 0
v 1 -1 0
v 1 1 0
v -1 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
s off
f 1/1/1 2/2/1 3/3/1 4/4/1
"""

write(os.path.join(DATA, "quad.obj"), OBJ)
write(os.path.join(DATA, "quad_le.ply"), quad_le())

good = quad_le()
bad = {
    "truncated_binary.ply": good[:len(good) - 10],
    "truncated_ascii.ply": quad_ascii(nf=2),
    "index_out_of_range.ply": quad_ascii(faces="4 0 1 2 7\n"),
    "index_out_of_range_binary.ply": quad_le(idx=(0, 1, 2, 4)),
    "negative_index_binary.ply": quad_le(idx=(0, -1, 2, 3)),
    "nonfinite_binary.ply": quad_le(x0=float("inf")),
    "bad_header.ply": quad_ascii().replace("element vertex 4",
                                           "element vertex four"),
    "no_end_header.ply": "ply\nformat ascii 1.0\nelement vertex 1\n"
                         "property float x\n",
    "big_endian.ply": good.replace(b"binary_little_endian",
                                   b"binary_big_endian"),
    "huge_count.ply": ply_header("binary_little_endian", 3000000000, 1),
    "no_faces.ply": quad_ascii(nf=0, faces=""),
    "index_out_of_range.obj": OBJ.replace("f 1/1/1 2/2/1 3/3/1 4/4/1",
                                          "f 1/1/1 2/2/1 3/3/1 5/4/1"),
    "bad_number.obj": OBJ.replace("v 1 -1 0", "v 1 -1.x 0"),
    "nonfinite.obj": OBJ.replace("v 1 1 0", "v 1 1e999 0"),
    "zero_index.obj": OBJ.replace("f 1/1/1", "f 0/1/1"),
    "no_faces.obj": OBJ.replace("f 1/1/1 2/2/1 3/3/1 4/4/1\n", ""),
    "two_corner_face.obj": OBJ.replace("f 1/1/1 2/2/1 3/3/1 4/4/1",
                                       "f 1/1/1 2/2/1"),
}
for name, data in bad.items():
    write(os.path.join(BAD, name), data)
