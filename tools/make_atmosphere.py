#!/usr/bin/env python3
"""The example plane-parallel atmosphere of proto/examples, the way Eradiate
builds one (its ids: medium_atmosphere, shape_atmosphere, surface,
illumination, measure), and its per-wavelength parameter maps.

    tools/make_atmosphere.py                 write proto/examples/atmosphere.json,
                                             atmosphere.xml and its .vol grids
    tools/make_atmosphere.py --out-dir DIR   the same files into DIR
    tools/make_atmosphere.py --params WL     print the parameter map of the
                                             atmosphere at WL nm (JSON): the
                                             body of a PATCH, or a job
                                             context's "params"
    tools/make_atmosphere.py --job WL... [--spp N]
                                             print a job body (JSON): one
                                             context per wavelength, "wWL",
                                             each overriding the three
                                             arrays with its own profiles
    tools/make_atmosphere.py --layers N      another number of layers (the
                                             examples use 2400)

The atmosphere (0-120 km, N layers of equal thickness, 50 m for 2,400):
  molecules  Rayleigh scattering, no absorption, extinction falling with an
             8 km scale height: sigma_m(z, wl) = B (550 / wl)^4.05 e^(-z/H),
             B = 1.2e-5 m^-1 (Rayleigh optical thickness 0.096 at 550 nm),
             averaged over each layer exactly:
             B (550/wl)^4.05 H (e^(-z0/H) - e^(-z1/H)) / (z1 - z0);
  aerosols   0-2 km, optical thickness 0.2 at 550 nm, Angstrom exponent
             1.3, single-scattering albedo 0.9, Henyey-Greenstein g = 0.7.
Per layer: sigma_t = sigma_m + sigma_a, albedo = (sigma_m + 0.9 sigma_a) /
sigma_t, and the blendphase weight (the share of the hg component in the
scattering) w = 0.9 sigma_a / (sigma_m + 0.9 sigma_a); Mitsuba's
blendphase is (1 - w) phase_0 + w phase_1 with phase_0 = rayleigh,
phase_1 = hg.

The medium is Eradiate's `piecewise` on a [1, 1, N] `gridvolume` over the
box [-W/2, W/2]^2 x [0, 120 km] (W = 1,000 km: the scene is in metres and
Embree traces in single precision, so the box is kept narrower than
Eradiate's default 1e6 km; a view 75 degrees off nadir crosses 120 km of
atmosphere within 450 km of the target). The atmosphere's shape is a
`cube` with the `null` BSDF and the medium as its interior, 100 m deeper
than the medium (its bottom face must not coincide with the surface); the
surface is an RPV rectangle (Eradiate's defaults rho_0 0.183, k 0.780,
g -0.1) at z = 0 as wide as the box. The sun is a `directional` emitter 30
degrees from the zenith (irradiance 1); the measure an `hdistant` 32 x 32
at 1,000 spp aimed at a 1 km square target; the integrator Eradiate's
`piecewise_volpath`.

Numbers are written with repr() (shortest round-trip), so a value read
back from the JSON is the double computed here: a PATCH of the map for a
wavelength equals loading the scene written for it, bitwise. The XML's
grids are Mitsuba .vol files (float32, x fastest).
"""
import argparse
import json
import math
import os
import struct
import sys

TOP = 120e3  # m
WIDTH = 1e6  # m
SHAPE_OFFSET = 100.0  # m below the ground
H = 8e3  # molecular scale height, m
B550 = 1.2e-5  # molecular extinction at the ground, 550 nm, m^-1
AER_TOP = 2e3  # m
AER_TAU550 = 0.2
AER_ANGSTROM = 1.3
AER_SSA = 0.9
AER_G = 0.7
RPV = {"rho_0": 0.183, "k": 0.780, "g": -0.1}
SUN_ZENITH = 30.0  # degrees

MEDIUM = "medium_atmosphere"


def profiles(n, wl):
    """sigma_t [m^-1], albedo and blend weight of each of n layers at wl nm."""
    dz = TOP / n
    bm = B550 * (550.0 / wl) ** 4.05
    ba = AER_TAU550 / AER_TOP * (550.0 / wl) ** AER_ANGSTROM
    sigma_t, albedo, weight = [], [], []
    for i in range(n):
        z0, z1 = i * dz, (i + 1) * dz
        sm = bm * H * (math.exp(-z0 / H) - math.exp(-z1 / H)) / dz
        # the aerosol's share of the layer (layers straddling 2 km)
        frac = min(max((AER_TOP - z0) / dz, 0.0), 1.0)
        sa = ba * frac
        ss = sm + AER_SSA * sa
        sigma_t.append(sm + sa)
        albedo.append(ss / (sm + sa))
        weight.append(AER_SSA * sa / ss)
    return sigma_t, albedo, weight


def param_keys():
    """The parameter keys of the three per-layer arrays (traversal names:
    the medium's id, its slots sigma_t / albedo / phase_function, the
    grid's `data`)."""
    return {
        "sigma_t": MEDIUM + ".sigma_t.data",
        "albedo": MEDIUM + ".albedo.data",
        "weight": MEDIUM + ".phase_function.weight.data",
    }


def params_map(n, wl):
    st, al, w = profiles(n, wl)
    k = param_keys()
    return {k["sigma_t"]: st, k["albedo"]: al, k["weight"]: w}


def volume_to_world():
    """The unit cube onto the medium's box (scale, then translate)."""
    return [{"scale": [WIDTH, WIDTH, TOP]}, {"translate": [-WIDTH / 2, -WIDTH / 2, 0.0]}]


def grid(values):
    """A [1, 1, N] grid along z: `shape` is Mitsuba's tensor shape [Z, Y, X];
    nearest-cell lookups, so a layer's value holds across the layer (the
    blendphase evaluates its weight at the scattering point)."""
    return {
        "type": "gridvolume",
        "data": values,
        "shape": [len(values), 1, 1],
        "filter_type": "nearest",
        "to_world": volume_to_world(),
    }


def scene_json(n, wl):
    st, al, w = profiles(n, wl)
    sz = math.radians(SUN_ZENITH)
    half_h = (TOP + SHAPE_OFFSET) / 2
    return {
        "type": "scene",
        "variant": "mono",
        MEDIUM: {
            "type": "piecewise",
            "sigma_t": grid(st),
            "albedo": grid(al),
            "phase": {
                "type": "blendphase",
                "phase_0": {"type": "rayleigh"},
                "phase_1": {"type": "hg", "g": AER_G},
                "weight": grid(w),
            },
        },
        "shape_atmosphere": {
            "type": "cube",
            "to_world": [{"scale": [WIDTH / 2, WIDTH / 2, half_h]}, {"translate": [0.0, 0.0, TOP - half_h]}],
            "bsdf": {"type": "null"},
            "interior": {"type": "ref", "id": MEDIUM},
        },
        "surface": {
            "type": "rectangle",
            "to_world": [{"scale": [WIDTH / 2, WIDTH / 2, 1.0]}],
            "bsdf": dict({"type": "rpv"}, **RPV),
        },
        "illumination": {
            "type": "directional",
            "direction": [math.sin(sz), 0.0, -math.cos(sz)],
            "irradiance": 1.0,
        },
        "measure": {
            "type": "hdistant",
            "to_world": [{"lookat": {"origin": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0]}}],
            "target": {"type": "rectangle", "to_world": [{"scale": [500.0, 500.0, 1.0]}]},
            "sampler": {"type": "independent", "sample_count": 1000},
            "film": {
                "type": "hdrfilm",
                "width": 32,
                "height": 32,
                "component_format": "float32",
                "rfilter": {"type": "box"},
            },
        },
        "integrator": {"type": "piecewise_volpath", "max_depth": -1},
    }


def dump_json(doc):
    """One key per line down to the objects, arrays on one line (the grids
    are long), numbers as repr() (round-trip)."""

    def enc(v, ind):
        pad = "  " * ind
        if isinstance(v, dict):
            if all(not isinstance(x, (dict, list)) or (isinstance(x, list) and len(x) <= 16) for x in v.values()) and len(v) <= 4:
                return "{" + ", ".join(json.dumps(k) + ": " + enc(x, 0) for k, x in v.items()) + "}"
            items = [pad + "  " + json.dumps(k) + ": " + enc(x, ind + 1) for k, x in v.items()]
            return "{\n" + ",\n".join(items) + "\n" + pad + "}"
        if isinstance(v, list):
            return "[" + ", ".join(enc(x, ind + 1) for x in v) + "]"
        if isinstance(v, float):
            if not math.isfinite(v):
                raise ValueError("non-finite number")
            return repr(v)
        return json.dumps(v)

    return enc(doc, 0) + "\n"


def write_vol(path, values, bbox):
    """Mitsuba's .vol grid: 'VOL', version 3, encoding 1 (float32), the
    resolution x, y, z, the channels, the bbox (6 float32), the data with x
    fastest. Little endian."""
    with open(path, "wb") as f:
        f.write(b"VOL" + bytes([3]))
        f.write(struct.pack("<iiiii", 1, 1, 1, len(values), 1))
        f.write(struct.pack("<6f", *bbox))
        f.write(struct.pack("<%df" % len(values), *values))


def scene_xml(n):
    sz = math.radians(SUN_ZENITH)
    half_h = (TOP + SHAPE_OFFSET) / 2
    w2 = WIDTH / 2

    def vol(name, fname):
        return (
            '        <volume type="gridvolume" name="%s">\n'
            '            <string name="filename" value="%s"/>\n'
            '            <string name="filter_type" value="nearest"/>\n'
            '            <transform name="to_world">\n'
            '                <scale value="%r, %r, %r"/>\n'
            '                <translate value="%r, %r, 0"/>\n'
            "            </transform>\n"
            "        </volume>\n" % (name, fname, WIDTH, WIDTH, TOP, -w2, -w2)
        )

    return (
        '<scene version="3.0.0" variant="mono">\n'
        "    <!-- Written by tools/make_atmosphere.py: the twin of atmosphere.json at 550 nm,\n"
        "         with its %d-layer grids in Mitsuba .vol files (float32). -->\n"
        '    <integrator type="piecewise_volpath">\n'
        '        <integer name="max_depth" value="-1"/>\n'
        "    </integrator>\n"
        '    <medium type="piecewise" id="%s">\n'
        "%s%s"
        '        <phase type="blendphase">\n'
        '            <phase type="rayleigh" name="phase_0"/>\n'
        '            <phase type="hg" name="phase_1">\n'
        '                <float name="g" value="%r"/>\n'
        "            </phase>\n"
        "    %s"
        "        </phase>\n"
        "    </medium>\n"
        '    <shape type="cube" id="shape_atmosphere">\n'
        '        <transform name="to_world">\n'
        '            <scale value="%r, %r, %r"/>\n'
        '            <translate value="0, 0, %r"/>\n'
        "        </transform>\n"
        '        <bsdf type="null"/>\n'
        '        <ref name="interior" id="%s"/>\n'
        "    </shape>\n"
        '    <shape type="rectangle" id="surface">\n'
        '        <transform name="to_world">\n'
        '            <scale value="%r, %r, 1"/>\n'
        "        </transform>\n"
        '        <bsdf type="rpv">\n'
        '            <float name="rho_0" value="%r"/>\n'
        '            <float name="k" value="%r"/>\n'
        '            <float name="g" value="%r"/>\n'
        "        </bsdf>\n"
        "    </shape>\n"
        '    <emitter type="directional" id="illumination">\n'
        '        <vector name="direction" value="%r, 0, %r"/>\n'
        '        <float name="irradiance" value="1"/>\n'
        "    </emitter>\n"
        '    <sensor type="hdistant" id="measure">\n'
        '        <transform name="to_world">\n'
        '            <lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/>\n'
        "        </transform>\n"
        '        <shape type="rectangle" name="target">\n'
        '            <transform name="to_world">\n'
        '                <scale value="500, 500, 1"/>\n'
        "            </transform>\n"
        "        </shape>\n"
        '        <sampler type="independent">\n'
        '            <integer name="sample_count" value="1000"/>\n'
        "        </sampler>\n"
        '        <film type="hdrfilm">\n'
        '            <integer name="width" value="32"/>\n'
        '            <integer name="height" value="32"/>\n'
        '            <string name="component_format" value="float32"/>\n'
        '            <rfilter type="box"/>\n'
        "        </film>\n"
        "    </sensor>\n"
        "</scene>\n"
        % (
            n,
            MEDIUM,
            vol("sigma_t", "atmosphere_sigma_t.vol"),
            vol("albedo", "atmosphere_albedo.vol"),
            AER_G,
            vol("weight", "atmosphere_weight.vol").replace("\n        ", "\n            "),
            w2,
            w2,
            half_h,
            TOP - half_h,
            MEDIUM,
            w2,
            w2,
            RPV["rho_0"],
            RPV["k"],
            RPV["g"],
            math.sin(sz),
            -math.cos(sz),
        )
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out-dir", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "proto", "examples"))
    ap.add_argument("--layers", type=int, default=2400)
    ap.add_argument("--wavelength", type=float, default=550.0, help="nm, for the scene files (default 550)")
    ap.add_argument("--params", type=float, metavar="WL", help="print the parameter map at WL nm and exit")
    ap.add_argument("--job", type=float, nargs="+", metavar="WL", help="print a job body over these wavelengths and exit")
    ap.add_argument("--spp", type=int, default=0, help="the job's samples per pixel (default: the sensor's)")
    a = ap.parse_args()
    if a.layers < 1:
        sys.exit("make_atmosphere.py: --layers must be at least 1")
    for name, wl in [("--wavelength", a.wavelength), ("--params", a.params)] + [("--job", w) for w in a.job or []]:
        if wl is not None and not (wl > 0 and math.isfinite(wl)):
            sys.exit("make_atmosphere.py: %s must be a positive number of nm" % name)
    if a.spp < 0:
        sys.exit("make_atmosphere.py: --spp must be positive")
    if a.job:
        ctx = [{"id": "w%g" % wl, "wavelength": wl, "params": params_map(a.layers, wl)} for wl in a.job]
        job = {"defaults": {"spp": a.spp}, "contexts": ctx} if a.spp else {"contexts": ctx}
        sys.stdout.write(json.dumps(job) + "\n")
        return
    if a.params is not None:
        sys.stdout.write(json.dumps(params_map(a.layers, a.params)) + "\n")
        return
    os.makedirs(a.out_dir, exist_ok=True)
    with open(os.path.join(a.out_dir, "atmosphere.json"), "w") as f:
        f.write(dump_json(scene_json(a.layers, a.wavelength)))
    st, al, w = profiles(a.layers, a.wavelength)
    bbox = (-WIDTH / 2, -WIDTH / 2, 0.0, WIDTH / 2, WIDTH / 2, TOP)
    for name, v in (("sigma_t", st), ("albedo", al), ("weight", w)):
        write_vol(os.path.join(a.out_dir, "atmosphere_%s.vol" % name), v, bbox)
    with open(os.path.join(a.out_dir, "atmosphere.xml"), "w") as f:
        f.write(scene_xml(a.layers))


if __name__ == "__main__":
    main()
