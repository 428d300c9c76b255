#!/usr/bin/env python3
"""Writes the seed corpora tests/fuzz/corpus/<harness>/ from the project's
own inputs (tests/corpus/bad, proto/examples, tests/data) and a few
hand-written cases. Run from the repository root; it only adds and
overwrites its own seed_* files, so inputs the fuzzers found and that were
copied in stay."""
import glob
import os
import re
import shutil

root = os.getcwd()
out = "tests/fuzz/corpus"


# Seeds that crash today go where they belong: crashes/ (fixed on this
# branch: replayed by make test) or pending/ (fixed by another branch, named
# in the file name; move them to crashes/ once it is merged).
where = {
    ("scene_render", "projective.json"): "crashes/geom_",
    ("scene_render", "xml_small.xml"): "crashes/geom_",
    ("job_body", "wl400.json"): "crashes/",
    ("job_body", "job_params_bad.json"): "crashes/",
    ("job_body", "ctx_params_bad.json"): "crashes/",
}


def put(h, name, data):
    w = where.get((h, name))
    if w:
        kind, prefix = w.split("/")
        d = os.path.join("tests/fuzz", kind, h)
        os.makedirs(d, exist_ok=True)
        with open(os.path.join(d, prefix + name), "wb") as f:
            f.write(data.encode() if isinstance(data, str) else data)
        return
    d = os.path.join(out, h)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, "seed_" + name), "wb") as f:
        f.write(data)


def copy(h, paths, limit=None):
    for p in sorted(paths)[:limit]:
        put(h, os.path.basename(p), open(p, "rb").read())


# ---- readers ----
copy("scene_json", glob.glob("tests/corpus/bad/*.json"), 40)
copy("scene_json", glob.glob("proto/examples/*.json"))
copy("scene_xml", glob.glob("tests/corpus/bad/*.xml"), 45)
copy("scene_xml", glob.glob("proto/examples/*.xml"))
put("scene_xml", "define.xml",
    '<scene version="3.0.0"><default name="w" value="2"/><integrator type="path"/>'
    '<sensor type="perspective"><sampler type="independent"><integer name="sample_count" value="$spp"/>'
    '</sampler><film type="hdrfilm"><integer name="width" value="$w"/><integer name="height" value="2"/>'
    '</film></sensor><shape type="sphere"><float name="radius" value="$r"/></shape></scene>')
copy("mesh_obj", glob.glob("tests/corpus/bad/meshes/*.obj") + ["tests/data/quad.obj"])
put("mesh_obj", "negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf -3/-1/-1 -2/-1/-1 -1/-1/-1\n")
put("mesh_obj", "poly.obj", "# pentagon\nv 0 0 0\nv 1 0 0\nv 1.5 1 0\nv 0.5 2 0\nv -0.5 1 0\no x\ng y\ns 1\nusemtl m\nf 1 2 3 4 5\nl 1 2\n")
put("mesh_obj", "vt_only.obj", "v 0 0 0 1\nv 1 0 0\nv 0 1 0\nvt 0.5\nvt 0 1 0\nf 1/1 2/2 3/1\n")
copy("mesh_ply", glob.glob("tests/corpus/bad/meshes/*.ply") + ["tests/data/quad_le.ply"])
put("mesh_ply", "ascii_uv.ply",
    "ply\nformat ascii 1.0\ncomment c\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\n"
    "property float nx\nproperty float ny\nproperty float nz\nproperty float u\nproperty float v\n"
    "element face 1\nproperty list uchar uint vertex_indices\nelement edge 1\nproperty int a\nend_header\n"
    "0 0 0 0 0 1 0 0\n1 0 0 0 0 1 1 0\n1 1 0 0 0 1 1 1\n0 1 0 0 0 1 0 1\n4 0 1 2 3\n7\n")
import struct
hdr = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "property uchar red\nelement face 1\nproperty list uchar int vertex_index\nend_header\n").encode()
body = b"".join(struct.pack("<fffB", *v) for v in [(0, 0, 0, 1), (1, 0, 0, 2), (0, 1, 0, 3)])
put("mesh_ply", "binary_extra.ply", hdr + body + struct.pack("<Biii", 3, 0, 1, 2))
il = "tests/fuzz/corpus/instance_list"
put("instance_list", "matrix.txt", "# one\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n")
put("instance_list", "leaf.txt", "0 0 1 0 0 1 0.1\n1 2 3 0.5 0.5 0.7071 0.2  # comment\n")
put("instance_list", "mixed.txt", "\n# header\n2 0 0 1 0 2 0 1 0 0 2 1 0 0 0 1\n0 0 0 0 0 -1 1\n")
put("instance_list", "bad_count.txt", "1 2 3 4 5\n")
put("instance_list", "bad_normal.txt", "0 0 0 0 0 0 1\n")
put("instance_list", "projective.txt", "1 0 0 0 0 1 0 0 0 0 1 0 0.5 0 0 1\n")
put("instance_list", "huge.txt", "1e300 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n0 0 0 0 0 1 1e-300\n")
put("instance_list", "nan.txt", "nan 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n")
put("instance_list", "empty.txt", "")
put("instance_list", "crlf.txt", "0 0 0 0 0 1 1\r\n1 1 1 0 1 0 1\r\n")

# ---- scene builder + render: small films ----
for p in sorted(glob.glob("proto/examples/*.json")) + sorted(glob.glob("proto/examples/*.xml")):
    t = open(p).read()
    t = re.sub(r'("width":\s*)\d+', r"\g<1>4", t)
    t = re.sub(r'("height":\s*)\d+', r"\g<1>4", t)
    t = re.sub(r'(name="width" value=")\d+', r"\g<1>4", t)
    t = re.sub(r'(name="height" value=")\d+', r"\g<1>4", t)
    put("scene_render", os.path.basename(p), t)
base = ('{"type":"scene","variant":"%s","s":{"type":"%s","sampler":{"type":"independent","sample_count":1},'
        '"film":{"type":"hdrfilm","width":3,"height":2}},"integrator":{"type":"path","max_depth":%d},'
        '"sun":{"type":"directional","direction":[0,0,-1],"irradiance":1},%s}')
shapes = {
    "obj": '"m":{"type":"obj","filename":"m.obj","bsdf":{"type":"diffuse"}}',
    "ply": '"m":{"type":"ply","filename":"m.ply","to_world":[{"scale":[2,2,1]}],"bsdf":{"type":"roughconductor"}}',
    "inst": '"g":{"type":"shapegroup","leaf":{"type":"rectangle","bsdf":{"type":"bilambertian"}}},'
            '"il":{"type":"instancelist","filename":"i.txt","shapegroup":{"type":"ref","id":"g"}}',
    "sphere": '"b":{"type":"sphere","radius":1e-3,"bsdf":{"type":"dielectric"}}',
    "cyl": '"c":{"type":"cylinder","bsdf":{"type":"twosided","bsdf":{"type":"rpv"}}}',
    "disk": '"d":{"type":"disk","to_world":[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]],"bsdf":{"type":"hapke"}}',
}
sensors = ["hdistant", "perspective", "distant", "radiancemeter"]
i = 0
for k, sh in shapes.items():
    for v in ("mono", "rgb"):
        put("scene_render", "%s_%s.json" % (k, v), base % (v, sensors[i % 4], [1, 3, -1][i % 3], sh))
        i += 1
put("scene_render", "xml_small.xml",
    '<scene version="3.0.0"><integrator type="path"><integer name="max_depth" value="2"/></integrator>'
    '<sensor type="perspective"><transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/>'
    '</transform><film type="hdrfilm"><integer name="width" value="2"/><integer name="height" value="2"/></film>'
    '</sensor><emitter type="constant"/><shape type="ply"><string name="filename" value="m.ply"/>'
    '<transform name="to_world"><scale value="1e-30"/></transform></shape></scene>')
# Phase functions and volumes (top-level objects: create, parameters, prepare).
media = ('"r":{"type":"rectangle"},"ph":{"type":"blendphase","weight":{"type":"gridvolume","shape":[2,1,1],'
         '"data":[0.2,0.8]},"phase_0":{"type":"rayleigh"},"phase_1":{"type":"tabphase","values":"1, 2, 4"}},'
         '"hg":{"type":"hg","g":0.3},"iso":{"type":"isotropic"},"cv":{"type":"constvolume","value":[0.1,0.2,0.3]},'
         '"gv":{"type":"gridvolume","shape":[1,2,2,%s],%s"data":[1,2,3,4,5,6,7,8%s],"wrap_mode":"mirror",'
         '"filter_type":"nearest","to_world":[{"scale":[1,2,3]}]}')
put("scene_render", "media_mono.json", base % ("mono", "hdistant", 2, media % ("2", '"wavelengths":[400,700],', "")))
put("scene_render", "media_rgb.json", base % ("rgb", "perspective", 3, media % ("3", "", ",9,10,11,12")))
# Media and the volumetric integrators (null boundaries, piecewise and
# heterogeneous media, both integrators, both variants).
volpath = '{"type":"scene","variant":"mono","s":{"type":"hdistant","sampler":{"type":"independent","sample_count":2},"film":{"type":"hdrfilm","width":3,"height":2}},"integrator":{"type":"piecewise_volpath","max_depth":4},"sun":{"type":"directional","direction":[0.3,0,-1],"irradiance":1},"sky":{"type":"constant","radiance":0.2},"ground":{"type":"rectangle","to_world":[{"scale":2}]},"atmo":{"type":"cube","bsdf":{"type":"null"},"to_world":[{"scale":[2,2,0.6]},{"translate":[0,0,0.5]}],"interior":{"type":"piecewise","albedo":{"type":"gridvolume","shape":[3,1,1],"data":[0.9,0.5,0.1],"to_world":[{"translate":[-0.5,-0.5,0]},{"scale":[4,4,1]}]},"sigma_t":{"type":"gridvolume","shape":[3,1,1],"data":[1.5,0.4,0.1],"to_world":[{"translate":[-0.5,-0.5,0]},{"scale":[4,4,1]}]},"phase":{"type":"hg","g":0.6}}},"ball":{"type":"sphere","radius":0.3,"center":[0,0,1.5],"bsdf":{"type":"null"},"interior":{"type":"heterogeneous","albedo":0.8,"sigma_t":{"type":"gridvolume","shape":[2,2,2],"data":[0,1,2,3,4,5,6,7],"to_world":[{"translate":[-0.5,-0.5,-0.5]},{"scale":0.6},{"translate":[0,0,1.5]}]}}}}'
put("scene_render", "volpath_mono.json", volpath)
put("scene_render", "volpath_rgb.json",
    volpath.replace('"variant":"mono"', '"variant":"rgb"').replace('"piecewise_volpath"', '"volpath"'))
# Local majorants: the ball's heterogeneous medium with an extremum_grid
# (volpath tracks it over the grid's cells), rgb and mono.
extremum = '"interior":{"type":"heterogeneous","ex":{"type":"extremum_grid","resolution":[2,1,2]},"albedo":0.8,'
put("scene_render", "volpath_extremum_rgb.json",
    volpath.replace('"variant":"mono"', '"variant":"rgb"').replace('"piecewise_volpath"', '"volpath"')
    .replace('"interior":{"type":"heterogeneous","albedo":0.8,', extremum))
put("scene_render", "volpath_extremum_mono.json",
    volpath.replace('"piecewise_volpath"', '"volpath"').replace('"interior":{"type":"heterogeneous","albedo":0.8,',
                                                                 extremum))
put("scene_render", "projective.json", base % ("mono", "hdistant", 2,
    '"r":{"type":"rectangle","to_world":[[1,0,0,0],[0,1,0,0],[0,0,1,0],[1,0,0,1]]}'))

# ---- service: PATCH bodies ----
patches = {
    "reflectance": '{"rectangle.bsdf.reflectance.value": 0.3}',
    "tabulated": '{"rectangle.bsdf.reflectance.value": {"wavelengths":[400,700],"values":[0.1,0.9]}}',
    "irradiance": '{"sun.irradiance.value": 2, "sun.direction": [0, 0, -1]}',
    "to_world": '{"rectangle.to_world": [[2,0,0,0],[0,2,0,0],[0,0,1,0],[0,0,0,1]]}',
    "flat16": '{"ball.to_world": [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}',
    "projective": '{"rectangle.to_world": [1,0,0,0,0,1,0,0,0,0,1,0,1,0,0,1]}',
    "tiny_scale": '{"rectangle.to_world": [[1e-21,0,0,0],[0,1e-21,0,0],[0,0,1,0],[0,0,0,1]]}',
    "huge_scale": '{"rectangle.to_world": [[1e39,0,0,0],[0,1e39,0,0],[0,0,1,0],[0,0,0,1]]}',
    "alpha": '{"ball.bsdf.alpha.value": 0.01, "ball.bsdf.k.value": 3}',
    "unknown": '{"rectangle.bsdf.reflectance.valu": 0.3}',
    "typed_key": '{"bsdf:rectangle.bsdf:reflectance.value": 0.5}',
    "negative": '{"rectangle.bsdf.reflectance.value": -1}',
    "nan": '{"sun.sampling_weight": NaN}',
    "bignum": '{"sun.sampling_weight": 1e400}',
    "bool": '{"allow_thread_reordering": false}',
    "weight": '{"rectangle.silhouette_sampling_weight": 0}',
    "cam": '{"cam.to_world": [[1,0,0,0],[0,1,0,0],[0,0,1,-5],[0,0,0,1]], "hd.direction": [0, 0.5, 1]}',
    "hd_zero": '{"hd.direction": [0, 0, 0]}',
    "trailing": '{} xyz',
    "array": '[1,2,3]',
    "empty": '{}',
    "dup": '{"sun.sampling_weight": 1, "sun.sampling_weight": 2}',
    "utf8": '{"\xff\xfe": 1}',
    "nested": '{"sun.irradiance.value": [[[[[1]]]]]}',
}
for k, v in patches.items():
    put("params", k + ".json", v.encode("latin-1"))

# ---- service: render bodies ----
renders = {
    "empty": "{}",
    "spp": '{"spp": 1}',
    "cam": '{"sensor": "cam", "spp": 2, "seed": 7}',
    "index": '{"sensor": "1", "spp": 1, "wavelength": 700}',
    "params": '{"spp":1,"params":{"rectangle.bsdf.reflectance.value":0.9,"sun.irradiance.value":3}}',
    "projective": '{"spp":1,"params":{"rectangle.to_world":[1,0,0,0,0,1,0,0,0,0,1,0,1,0,0,1]}}',
    "tiny": '{"spp":1,"params":{"ball.to_world":[[1e-30,0,0,0],[0,1e-30,0,0],[0,0,1e-30,0],[0,0,0,1]]}}',
    "big_spp": '{"spp": 1000000}',
    "spp0": '{"spp": 0}',
    "wl": '{"wavelength": 1e400}',
    "wl_neg": '{"wavelength": -5}',
    "timeout": '{"timeout_s": 0.000001, "spp": 16}',
    "unknown": '{"spq": 1}',
    "bad_sensor": '{"sensor": "nope"}',
    "trailing": '{"spp":1} xyz',
    "seed_neg": '{"seed": -1}',
    "seed_big": '{"seed": 18446744073709551616}',
    "not_obj": '"x"',
    "bad_param": '{"params": {"rectangle.bsdf.reflectance.value": "x"}}',
    "nul": '{"sensor": "c\\u0000am"}',
}
for k, v in renders.items():
    put("render_body", k + ".json", v)

# ---- service: job bodies ----
jobs = {
    "one": '{"contexts":[{"id":"a"}]}',
    "two": '{"contexts":[{"id":"a","wavelength":500},{"id":"b","wavelength":600,"spp":2}],"seed":3}',
    "defaults": '{"contexts":[{"id":"a"}],"defaults":{"sensors":["hd"],"spp":1,"wavelength":450}}',
    "spp0": '{"contexts":[{"id":"a"}],"defaults":{"spp":0}}',
    "wl400": '{"contexts":[{"id":"a","wavelength":1e400}]}',
    "params": '{"contexts":[{"id":"a","params":{"sun.irradiance.value":2}}],"params":{"rectangle.bsdf.reflectance.value":0.2}}',
    "job_params_bad": '{"contexts":[{"id":"a"}],"params":{"rectangle.bsdf.reflectance.value":-3}}',
    "job_params_unknown": '{"contexts":[{"id":"a"}],"params":{"nope":1}}',
    "ctx_params_bad": '{"contexts":[{"id":"a","params":{"sun.direction":[0,0,0]}}]}',
    "projective": '{"contexts":[{"id":"a","params":{"rectangle.to_world":[1,0,0,0,0,1,0,0,0,0,1,0,1,0,0,1]}}]}',
    "dup": '{"contexts":[{"id":"a"},{"id":"a"}]}',
    "sensors": '{"contexts":[{"id":"a","sensors":["cam","hd","0"]}]}',
    "bad_sensor": '{"contexts":[{"id":"a","sensors":["zz"]}]}',
    "trailing": '{"contexts":[{"id":"a"}]} xyz',
    "empty": '{"contexts":[]}',
    "bad_id": '{"contexts":[{"id":"a/b"}]}',
    "spectral": '{"contexts":[{"id":"a","params":{"rectangle.bsdf.reflectance.value":{"wavelengths":[400,700],"values":[0.1,0.9]}}}]}',
    "unknown_field": '{"contexts":[{"id":"a"}],"x":1}',
    "coords_grid": '{"contexts":[{"id":"a","coords":{"k":1,"s":"x"}},{"id":"b","coords":{"k":2,"s":"x"}}]}',
    "coords_list": '{"contexts":[{"id":"a","coords":{"k":1}},{"id":"b","coords":{"k":1}}]}',
    "coords_mixed": '{"contexts":[{"id":"a","coords":{"k":1}},{"id":"b","coords":{"k":"s"}}]}',
    "coords_missing": '{"contexts":[{"id":"a","coords":{"k":1}},{"id":"b"}]}',
}
for k, v in jobs.items():
    put("job_body", k + ".json", v)
