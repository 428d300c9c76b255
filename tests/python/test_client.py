#!/usr/bin/env python3
"""The raysweep Python package (python/, docs/python.md) against a real daemon.

Run by tests/integration/test_python.sh, which installs the package into a
venv as the README says, starts raysweepd on free ports and sets
RAYSWEEP_URL (the daemon), RSW_TOKEN_URL and RSW_TOKEN (a second daemon
with --token-file), RSW_ROOT (the repository) and RSW_BIN (build/bin).
Standard library unittest; ends with "test_client: N passed, N failed".

The plate of docs/examples/plate.json (a Lambertian rectangle under a
normal-incidence directional sun of irradiance 1, seen by a 1x1 distant
sensor) has the closed form L = rho E cos(theta_s) / pi, and BRF = rho
(docs/client.md): the renders below are checked against it to 1e-5.
"""

import io
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest
import warnings

import numpy as np

import raysweep as rs
from raysweep import _progress

ROOT = os.environ.get("RSW_ROOT", os.path.join(os.path.dirname(__file__), "..", ".."))
BIN = os.environ.get("RSW_BIN", os.path.join(ROOT, "build", "bin"))
URL = os.environ.get("RAYSWEEP_URL", "http://127.0.0.1:8350")
PLATE = os.path.join(ROOT, "docs", "examples", "plate.json")
HDISTANT = os.path.join(ROOT, "proto", "examples", "hdistant_lambertian.json")
RHO_KEY = "plate.bsdf.reflectance.value"


def plate_dict(rho=0.5, spp=4):
    """docs/examples/plate.json as a dict, with its reflectance and sample count."""
    with open(PLATE) as f:
        d = json.load(f)
    d["plate"]["bsdf"]["reflectance"] = rho
    d["camera"]["sampler"]["sample_count"] = spp
    return d


def cli_push(path):
    """The scene id `raysweep scene push` answers for ``path``."""
    out = subprocess.run([os.path.join(BIN, "raysweep"), "--server", URL, "scene", "push", path],
                         check=True, capture_output=True, text=True)
    return out.stdout.strip()


class Base(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.client = rs.connect(URL)
        cls.tmp = tempfile.mkdtemp(prefix="rsw-python-")

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def plate(self, rho=0.5, **kw):
        """A fresh plate scene: its reflectance in the document gives it an id of its own."""
        return self.client.load_dict(plate_dict(rho, **kw))


class TestConnect(Base):
    def test_info(self):
        self.assertEqual(self.client.info["name"], "raysweepd")
        self.assertIn("mono", self.client.info["variants"])

    def test_unreachable(self):
        import socket
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        s.close()  # nothing listens there now
        with self.assertRaises(rs.ConnectionFailed) as cm:
            rs.connect(f"http://127.0.0.1:{port}")
        self.assertIn(f"127.0.0.1:{port}", str(cm.exception))
        self.assertIsInstance(cm.exception, ConnectionError)

    def test_token(self):
        url, token = os.environ.get("RSW_TOKEN_URL"), os.environ.get("RSW_TOKEN")
        if not url:
            self.skipTest("no daemon with a token (RSW_TOKEN_URL)")
        with self.assertRaises(rs.RaysweepError) as cm:
            rs.connect(url, token="")
        self.assertEqual(cm.exception.status, 401)
        with self.assertRaises(rs.RaysweepError) as cm:
            rs.connect(url, token="wrong-" + token)
        self.assertEqual(cm.exception.status, 401)
        c = rs.connect(url, token=token)
        self.assertEqual(c.load_dict(plate_dict()).sensors, ["camera"])

    def test_bad_url(self):
        with self.assertRaises(ValueError):
            rs.connect("127.0.0.1:8350")

    def test_route(self):
        # route= (and $RAYSWEEP_ROUTE) is sent as X-Raysweep-Shard on every request, so a balancer
        # keeps all of a client's requests on one replica; a key outside the pattern is refused.
        import http.server
        import threading
        seen = []

        class H(http.server.BaseHTTPRequestHandler):
            def log_message(self, *a):
                pass

            def do_GET(self):
                seen.append(self.headers.get("X-Raysweep-Shard"))
                body = json.dumps({"name": "raysweepd", "variants": ["mono"], "scenes": []}).encode()
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

        srv = http.server.HTTPServer(("127.0.0.1", 0), H)
        t = threading.Thread(target=srv.serve_forever, daemon=True)
        t.start()
        url = f"http://127.0.0.1:{srv.server_address[1]}"
        try:
            rs.connect(url, route="shard-a.1")
            self.assertEqual(seen, ["shard-a.1", "shard-a.1"])  # GET /v1, GET /v1/scenes
            os.environ["RAYSWEEP_ROUTE"] = "from-env"
            try:
                rs.connect(url)
            finally:
                del os.environ["RAYSWEEP_ROUTE"]
            self.assertEqual(seen[2:], ["from-env", "from-env"])
            rs.connect(url)
            self.assertEqual(seen[4:], [None, None])
            for bad in ("two words", "", "x" * 65, "k/1"):
                with self.assertRaises(ValueError, msg=repr(bad)):
                    rs.connect(url, route=bad)
        finally:
            srv.shutdown()
            srv.server_close()


class TestLoad(Base):
    def test_load_file_json_same_id_as_cli(self):
        scene = self.client.load_file(PLATE)
        self.assertEqual(scene.id, cli_push(PLATE))
        self.assertEqual(scene.sensors, ["camera"])
        self.assertEqual(scene.variant, "mono")
        self.assertEqual(scene.label, "plate.json")

    def test_load_dict_uploads_mesh(self):
        # A mesh referenced by a relative name, resolved against base_dir and
        # uploaded; the daemon has no data root in common with us.
        d = plate_dict()
        d["plate"] = {"type": "obj", "filename": "quad.obj", "bsdf": {"type": "diffuse", "reflectance": 0.5}}
        before = json.dumps(d, sort_keys=True)
        scene = self.client.load_dict(d, base_dir=os.path.join(ROOT, "tests", "data"))
        self.assertEqual(json.dumps(d, sort_keys=True), before, "load_dict must not modify its argument")
        film = scene.render(spp=4, xarray=False)
        self.assertAlmostEqual(float(film[0, 0, 0]), 0.5 / math.pi, delta=1e-5)
        # The same scene from a file beside the mesh: the same id as the CLI's push.
        path = os.path.join(self.tmp, "mesh_plate.json")
        shutil.copy(os.path.join(ROOT, "tests", "data", "quad.obj"), self.tmp)
        with open(path, "w") as f:
            json.dump(d, f)
        self.assertEqual(self.client.load_file(path).id, cli_push(path))

    def test_load_dict_missing_file(self):
        d = plate_dict()
        d["plate"] = {"type": "obj", "filename": "no_such_mesh.obj"}
        with self.assertRaises(rs.RaysweepError) as cm:
            self.client.load_dict(d, base_dir=self.tmp)
        self.assertIn("no_such_mesh.obj", str(cm.exception))

    def test_load_file_xml_uploads_volumes(self):
        path = os.path.join(ROOT, "proto", "examples", "atmosphere.xml")
        scene = self.client.load_file(path)
        self.assertEqual(scene.id, cli_push(path))

    def test_xml_error_keeps_line(self):
        # The filename rewrite must not move lines: the daemon's error names line 7.
        shutil.copy(os.path.join(ROOT, "tests", "data", "quad.obj"), self.tmp)
        path = os.path.join(self.tmp, "bad.xml")
        # A parameter the file uses but does not declare is declared on line 1: lines must not move.
        for line6, params in (('<bsdf type="diffuse"/>', {}),
                              ('<bsdf type="diffuse"><float name="reflectance" value="$rho"/></bsdf>', {"rho": 0.5})):
            with open(path, "w") as f:
                f.write('<scene version="3.0.0">\n'
                        '  <shape type="obj">\n'
                        '    <string name="filename" value="quad.obj"/>\n'
                        '  </shape>\n'
                        '  <shape type="rectangle">\n'
                        f'    {line6}\n'
                        '    <bsdf type="difuse_typo"/>\n'
                        '  </shape>\n'
                        '</scene>\n')
            with self.assertRaises(rs.RaysweepError) as cm:
                self.client.load_file(path, **params)
            e = cm.exception
            self.assertEqual(e.status, 422)
            self.assertRegex(str(e.pointer) + " " + str(e.detail), r":7\b")

    def test_problem_members(self):
        d = plate_dict()
        d["plate"]["bsdf"]["type"] = "difuse"
        with self.assertRaises(rs.RaysweepError) as cm:
            self.client.load_dict(d)
        e = cm.exception
        self.assertEqual(e.status, 422)
        self.assertTrue(e.code.startswith("RSW_ERR_"), e.code)
        self.assertTrue(e.title)
        self.assertIn("difuse", e.detail)
        self.assertTrue(e.pointer.startswith("/plate/bsdf"), e.pointer)
        self.assertIn(e.pointer, str(e))

    def test_xml_params(self):
        # Keyword arguments set XML parameters, as Mitsuba's load_file does:
        # rho replaces its <default>, irr (no default) is declared.
        path = os.path.join(self.tmp, "plate.xml")
        with open(path, "w") as f:
            f.write('<scene version="3.0.0">\n'
                    '    <default name="rho" value="0.5"/>\n'
                    '    <sensor type="distant" id="camera">\n'
                    '        <vector name="direction" x="0" y="0" z="-1"/>\n'
                    '        <point name="target" x="0" y="0" z="0"/>\n'
                    '        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>\n'
                    '        <film type="hdrfilm"><integer name="width" value="1"/>'
                    '<integer name="height" value="1"/><rfilter type="box"/></film>\n'
                    '    </sensor>\n'
                    '    <emitter type="directional" id="sun">\n'
                    '        <vector name="direction" x="0" y="0" z="-1"/>\n'
                    '        <float name="irradiance" value="$irr"/>\n'
                    '    </emitter>\n'
                    '    <shape type="rectangle" id="plate">\n'
                    '        <bsdf type="diffuse"><float name="reflectance" value="$rho"/></bsdf>\n'
                    '    </shape>\n'
                    '</scene>\n')
        scene = self.client.load_file(path, variant="mono", rho=0.3, irr=2.0)
        film = scene.render(spp=4, xarray=False)
        self.assertAlmostEqual(float(film[0, 0, 0]), 0.3 * 2.0 / math.pi, delta=1e-5)
        with self.assertRaises(rs.RaysweepError) as cm:
            self.client.load_file(path, variant="mono", rho=0.3)   # $irr undefined
        self.assertIn("irr", str(cm.exception))
        with self.assertRaises(TypeError):
            self.client.load_file(PLATE, rho=0.3)                  # a JSON scene takes none
        # A parameter the file neither declares nor uses is refused, naming it and the closest
        # declared one (it was declared, and $rho silently kept its default)
        with self.assertRaises(TypeError) as cm:
            self.client.load_file(path, variant="mono", rh0=0.3, irr=2.0)
        self.assertIn("'rh0'", str(cm.exception))
        self.assertIn("did you mean 'rho'?", str(cm.exception))


class TestParameters(Base):
    def test_traverse(self):
        scene = self.plate(0.41)
        p = scene.traverse()
        self.assertIn(RHO_KEY, p)
        self.assertNotIn("plate.bsdf.nothing", p)
        self.assertAlmostEqual(p[RHO_KEY], 0.41)
        self.assertIsInstance(p["sun.direction"], np.ndarray)
        np.testing.assert_allclose(p["sun.direction"], [0, 0, -1])
        self.assertEqual(p["plate.to_world"].shape, (4, 4))
        self.assertEqual(p.properties(RHO_KEY)["class"], "spectral")
        self.assertEqual(len(p), len(p.keys()))
        self.assertIn(RHO_KEY, repr(p))
        self.assertEqual(len(scene.traverse("*.reflectance.value")), 1)
        self.assertEqual(rs.traverse(scene).keys(), p.keys())

    def test_typo_did_you_mean(self):
        p = self.plate(0.42).traverse()
        with self.assertRaises(KeyError) as cm:
            p["plate.bsdf.reflectanc.value"]
        self.assertIn("did you mean", str(cm.exception))
        self.assertIn(RHO_KEY, str(cm.exception))
        self.assertEqual(cm.exception.candidates[0], RHO_KEY)
        with self.assertRaises(rs.UnknownKeyError):
            p["plate.bsdf.reflectanc.value"] = 0.3

    def test_server_typo_candidates(self):
        scene = self.plate(0.43)
        with self.assertRaises(rs.UnknownKeyError) as cm:
            scene.update({"plate.bsdf.reflectanc.value": 0.3})
        self.assertEqual(cm.exception.status, 422)
        self.assertEqual(cm.exception.key, "plate.bsdf.reflectanc.value")
        self.assertIn(RHO_KEY, cm.exception.candidates)
        with self.assertRaises(rs.UnknownKeyError) as cm:
            scene.render(spp=4, params={"plate.bsdf.reflectanc.value": 0.3})
        self.assertIn(RHO_KEY, str(cm.exception))

    def test_update_one_patch(self):
        scene = self.plate(0.44)
        p = scene.traverse()
        rev = p.revision
        self.assertIsNone(p.update(), "nothing changed: no PATCH")
        p[RHO_KEY] = 0.3
        p["sun.irradiance.value"] = 2.0
        ans = p.update()
        self.assertEqual(ans["revision"], rev + 1, "two keys, one PATCH, one revision")
        self.assertEqual(ans["changed"], 2)
        self.assertEqual(scene.traverse()[RHO_KEY], 0.3)
        film = scene.render(spp=4, xarray=False)
        self.assertAlmostEqual(float(film[0, 0, 0]), 0.3 * 2.0 / math.pi, delta=1e-5)

    def test_update_refused_changes_nothing(self):
        scene = self.plate(0.45)
        p = scene.traverse()
        p[RHO_KEY] = 0.2
        p["sun.irradiance.value"] = -1.0
        with self.assertRaises(rs.RaysweepError) as cm:
            p.update()
        self.assertEqual(cm.exception.status, 422)
        self.assertIn("sun.irradiance.value", str(cm.exception))
        self.assertAlmostEqual(p[RHO_KEY], 0.45, msg="the table shows the scene's state again")
        fresh = scene.traverse()
        self.assertEqual(fresh.revision, p.revision)
        self.assertAlmostEqual(fresh[RHO_KEY], 0.45)

    def test_spectrum_and_numpy_values(self):
        scene = self.plate(0.46)
        p = scene.traverse()
        p[RHO_KEY] = {"wavelengths": np.array([400.0, 700.0]), "values": np.array([0.2, 0.8])}
        p["sun.direction"] = np.array([0.0, 0.0, -1.0])
        p.update()
        v = scene.traverse()[RHO_KEY]
        np.testing.assert_allclose(v["values"], [0.2, 0.8])
        film = scene.render(spp=4, wavelength=550, xarray=False)
        self.assertAlmostEqual(float(film[0, 0, 0]), 0.5 / math.pi, delta=1e-5)

    def test_long_buffer(self):
        # A buffer of more than 16 numbers comes as its length in the table and
        # is fetched when read (?full=1); a daemon without ?full=1 says so.
        path = os.path.join(self.tmp, "fan.obj")
        n = 8
        with open(path, "w") as f:
            for k in range(n):
                a = 2 * math.pi * k / n
                f.write(f"v {math.cos(a):.6f} {math.sin(a):.6f} 0\n")
            f.write("v 0 0 0\n")
            for k in range(n):
                f.write(f"f {n + 1} {k + 1} {(k + 1) % n + 1}\n")
        d = plate_dict(0.49)
        d["plate"] = {"type": "obj", "id": "fan", "filename": "fan.obj",
                      "bsdf": {"type": "diffuse", "reflectance": 0.5}}
        p = self.client.load_dict(d, base_dir=self.tmp).traverse()
        key = next(k for k in p if k.endswith("vertex_positions"))
        self.assertIn("27", repr(p) + str(p.properties(key)["shape"]))
        try:
            v = p[key]
        except rs.RaysweepError as e:
            self.assertIn("full=1", str(e))
        else:
            rows = np.round(np.reshape(v, (-1, 3)), 5).tolist()
            self.assertEqual(len(rows), n + 1)
            self.assertIn([0.0, 0.0, 0.0], rows)
            self.assertIn([1.0, 0.0, 0.0], rows)

    def test_read_only(self):
        p = self.plate(0.47).traverse()
        with self.assertRaises(rs.RaysweepError):
            p["allow_thread_reordering"] = False

    def test_keep(self):
        p = self.plate(0.48).traverse()
        p.keep("*.value")
        self.assertIn(RHO_KEY, p)
        self.assertNotIn("plate.to_world", p)


class TestRender(Base):
    def test_numpy(self):
        film = self.plate(0.5).render(spp=4, xarray=False)
        self.assertIsInstance(film, np.ndarray)
        self.assertEqual(film.shape, (1, 1, 1))
        self.assertEqual(film.dtype, np.float32)
        self.assertAlmostEqual(float(film[0, 0, 0]), 0.5 / math.pi, delta=1e-5)

    def test_dataarray_quantities(self):
        da = rs.render(self.plate(0.5), spp=4, wavelength=600, quantities=["brf"], variance=True)
        self.assertEqual(da.dims, ("y", "x", "channel"))
        self.assertEqual(list(da.channel.values), ["Y", "brf.Y", "radiance_stderr.Y"])
        self.assertAlmostEqual(float(da.sel(channel="brf.Y")[0, 0]), 0.5, delta=1e-5)
        self.assertEqual(float(da.wavelength), 600.0)
        self.assertEqual(da.attrs["spp"], 4)
        self.assertEqual(da.attrs["units"], "W m-2 sr-1 nm-1")
        # No environment plugin failed: the attrs say 0 all the same.
        self.assertEqual((da.attrs["plugin_failures"], da.attrs["plugin_failure"]), (0, ""))

    def test_angles(self):
        scene = self.client.load_file(HDISTANT)
        da = scene.render(spp=4, sensor="sensor")
        self.assertEqual(da.vza.dims, ("y", "x"))
        self.assertEqual(da.shape, (32, 32, 1))
        self.assertTrue(((da.vza >= 0) & (da.vza <= 90)).all())
        self.assertEqual(float(da.sza), 30.0)

    def test_bad_sensor(self):
        with self.assertRaises(rs.RaysweepError) as cm:
            self.plate(0.5).render(spp=4, sensor="nope")
        self.assertEqual(cm.exception.pointer, "/sensor")


def stokes_dict(p=0.6, chi=30.0):
    """A 3x2 mono Stokes camera under tests/plugins/polarized_sky.c (DoLP p, AoLP chi) and a sun of E_h = 2."""
    return {"type": "scene", "variant": "mono",
            "camera": {"type": "perspective", "fov": 20,
                       "to_world": [{"lookat": {"origin": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}}],
                       "sampler": {"type": "independent", "sample_count": 4},
                       "film": {"type": "hdrfilm", "width": 3, "height": 2, "pixel_format": "stokes",
                                "component_format": "float32", "rfilter": {"type": "box"}}},
            "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": 2.0},
            "sky": {"type": "polarized_sky", "polarization": p, "polarization_angle": chi}}


class TestRenderCoords(Base):
    def test_render_coords(self):
        # A render's coords drive the scene's templates (and the render's own): the plate under a
        # sun at zenith sza gives rho cos(sza) / pi; a coordinate no template reads is refused.
        d = plate_dict(0.46)
        d["templates"] = {"sun.direction": {"sun": {"zenith": "sza", "azimuth": 0}}}
        scene = self.client.load_dict(d)
        a = scene.render(coords={"sza": np.float64(60)}, xarray=False)
        self.assertAlmostEqual(float(a.ravel()[0]), 0.46 * 0.5 / math.pi, delta=1e-6)
        plain = self.plate(0.46)
        b = plain.render(coords={"vza": 60}, templates={"sun.direction": {"sun": {"zenith": "vza", "azimuth": 0}}},
                         xarray=False)
        self.assertAlmostEqual(float(b.ravel()[0]), 0.46 * 0.5 / math.pi, delta=1e-6)
        with self.assertRaises(rs.RaysweepError) as cm:
            plain.render(coords={"sza": 60})
        self.assertEqual(cm.exception.pointer, "/coords/sza")
        with self.assertRaises(TypeError):
            scene.render(coords={"sza": "sixty"})


@unittest.skipUnless(os.environ.get("RSW_STOKES"), "needs a daemon with tests/plugins (RSW_STOKES=1)")
class TestStokes(Base):
    """Stokes films (docs/polarization.md): every escaped ray sees DoLP p and AoLP chi exactly."""

    def test_render_stokes_dimension(self):
        da = self.client.load_dict(stokes_dict(0.6, 30.0)).render(spp=4, quantities=["brf"])
        self.assertEqual(da.dims, ("y", "x", "stokes", "channel"))
        self.assertEqual(list(da.stokes.values), ["S0", "S1", "S2", "S3"])
        self.assertEqual(list(da.channel.values), ["Y", "brf.Y"])
        want = [1.0, 0.6 * math.cos(math.radians(60)), 0.6 * math.sin(math.radians(60)), 0.0]
        np.testing.assert_allclose(da.sel(channel="Y").isel(y=0, x=0).values, want, atol=1e-6)
        np.testing.assert_allclose(rs.dolp(da).sel(channel="Y").values, 0.6, atol=1e-6)
        np.testing.assert_allclose(rs.aolp(da).values, 30.0, atol=1e-4)  # brf's too: the same vector / E_h
        self.assertEqual(rs.aolp(da).attrs["units"], "degree")
        film = self.client.load_dict(stokes_dict(0.6, -75.0)).render(spp=4, xarray=False)
        self.assertEqual(film.shape, (2, 3, 4))
        np.testing.assert_allclose(rs.aolp(film), -75.0, atol=1e-4)
        np.testing.assert_allclose(rs.dolp(film), 0.6, atol=1e-6)

    def test_render_mono_polarized(self):
        d = stokes_dict(0.6, 30.0)
        d["variant"] = "mono_polarized"
        del d["camera"]["film"]["pixel_format"]
        da = self.client.load_dict(d).render(spp=4, variance=True)
        self.assertEqual(da.dims, ("y", "x", "stokes", "channel"))
        self.assertEqual(list(da.channel.values), ["Y", "radiance_stderr.Y"])
        s = da.sel(channel="Y").values.astype(np.float64)
        np.testing.assert_allclose(rs.dolp(da).sel(channel="Y").values, np.hypot(s[..., 1], s[..., 2]) / s[..., 0],
                                   atol=1e-6)
        self.assertTrue((rs.dolp(da).sel(channel="Y").values <= 0.6 + 1e-6).all())

    def test_sweep_dataset(self):
        ds = self.client.load_dict(stokes_dict(0.4)).sweep(
            grid={"sky.polarization_angle": [-60, 0, 90]}, spp=4, progress=False)
        self.assertEqual(ds.radiance.dims, ("polarization_angle", "y", "x", "stokes"))
        self.assertEqual(ds.dolp.dims, ("polarization_angle", "y", "x"))
        np.testing.assert_allclose(ds.dolp.values, 0.4, atol=1e-6)
        np.testing.assert_allclose(ds.aolp.isel(y=0, x=0).values, [-60, 0, 90], atol=1e-4)
        # The helpers agree with the dataset's own variables.
        np.testing.assert_allclose(rs.aolp(ds).values, ds.aolp.values, atol=1e-4)
        np.testing.assert_allclose(rs.dolp(ds.radiance).values, ds.dolp.values, atol=1e-6)

    def test_helpers_refuse_non_stokes(self):
        with self.assertRaises(rs.RaysweepError):
            rs.dolp(np.zeros((2, 3, 1)))
        da = self.plate(0.5).render(spp=4)
        with self.assertRaises(rs.RaysweepError):
            rs.aolp(da)


@unittest.skipUnless(os.environ.get("RSW_FAILING_SKY"),
                     "needs a daemon with tests/support/plugins/failing_sky.c (RSW_FAILING_SKY=1)")
class TestPluginFailures(Base):
    """A meter under a sky whose every answer is NaN or negative (replaced by black): films and datasets count them."""

    def scene(self):
        return self.client.load_dict({
            "type": "scene", "variant": "mono",
            "meter": {"type": "radiancemeter", "origin": [0, 0, 0], "direction": [1, 0, 0],
                      "film": {"type": "hdrfilm", "width": 1, "height": 1, "component_format": "float32"}},
            "sky": {"type": "failing_sky", "id": "bad_sky"}})

    def assert_failed(self, n, msg):
        self.assertGreater(n, 0)
        self.assertIn("emitter 'bad_sky' (plugin type 'failing_sky'): add_radiance returned I =", msg)

    def test_render_attrs(self):
        da = self.scene().render(spp=4, wavelength=600)
        self.assertEqual(float(da[0, 0, 0]), 0.0)
        self.assertIsInstance(da.attrs["plugin_failures"], int)
        self.assert_failed(da.attrs["plugin_failures"], da.attrs["plugin_failure"])

    def test_dataset_and_films(self):
        job = self.scene().submit(grid={"wavelength": [500, 600]}, spp=2)
        ds = job.result()
        self.assertEqual(ds.plugin_failures.dims, ("wavelength",))
        self.assertEqual(ds.plugin_failures.attrs["units"], "1")
        films = job.films(xarray=True)
        for w in (500, 600):
            n, msg = int(ds.plugin_failures.sel(wavelength=w)), str(ds.plugin_failure.sel(wavelength=w).item())
            self.assert_failed(n, msg)
            ctx = str(ds.context.sel(wavelength=w).item())
            da = films[(ctx, "meter")]
            self.assertEqual((da.attrs["plugin_failures"], da.attrs["plugin_failure"]), (n, msg))


class TestSweep(Base):
    def test_grid_dataset(self):
        scene = self.plate(0.5)
        ds = scene.sweep(grid={"wavelength": [450, 550, 650], RHO_KEY: np.array([0.2, 0.4])}, spp=4,
                         progress=False)
        self.assertEqual(ds.radiance.dims, ("wavelength", "reflectance", "y", "x"))
        np.testing.assert_allclose(ds.reflectance.values, [0.2, 0.4])
        got = ds.radiance.isel(y=0, x=0).values
        want = np.broadcast_to(np.array([0.2, 0.4]) / math.pi, (3, 2))
        np.testing.assert_allclose(got, want, atol=1e-5)
        self.assertEqual(ds.attrs["scene"], scene.id)
        # Plugin failures per film: there, and 0 ("") for a scene without plugins.
        self.assertEqual(ds.plugin_failures.dims, ("wavelength", "reflectance"))
        self.assertEqual(ds.plugin_failures.dtype, np.uint64)
        self.assertTrue((ds.plugin_failures.values == 0).all())
        self.assertTrue((ds.plugin_failure.values == "").all())

    def test_grid_coordinate_with_templates(self):
        # sza is a plain coordinate: a template turns it into the sun's direction.
        ds = self.plate(0.5).sweep(grid={"sza": [0, 30, 60]}, spp=4, quantities=["brf"],
                                   templates={"sun.direction": {"sun": {"zenith": "sza", "azimuth": 0}}})
        got = ds.radiance.isel(y=0, x=0).values
        np.testing.assert_allclose(got, 0.5 * np.cos(np.radians([0, 30, 60])) / math.pi, atol=1e-5)
        np.testing.assert_allclose(ds.brf.isel(y=0, x=0).values, 0.5, atol=1e-5)

    def test_contexts_and_job_params(self):
        ds = self.plate(0.5).sweep(
            contexts=[{"wavelength": w, "coords": {"wavelength": w}} for w in (400, 700)], spp=4,
            params={RHO_KEY: {"wavelengths": [400, 700], "values": [0.2, 0.8]}})
        np.testing.assert_allclose(ds.radiance.isel(y=0, x=0).values, np.array([0.2, 0.8]) / math.pi, atol=1e-5)

    def test_bands(self):
        ds = self.plate(0.5).sweep(
            contexts=[{"id": "only"}], spp=4, quantities=["brf"],
            bands=[{"id": "B4", "srf": {"type": "gaussian", "mean": 665, "fwhm": 30}}])
        self.assertIn("brf_srf", ds)
        self.assertAlmostEqual(float(ds.brf_srf.squeeze()), 0.5, delta=1e-5)
        # Plugin failures are the node films': over the node wavelengths.
        self.assertEqual(ds.plugin_failures.dims, ("context", "wavelength"))
        self.assertTrue((ds.plugin_failures.values == 0).all())

    def test_grid_search_key(self):
        # An Eradiate search TYPE:ID:PATH names a parameter too; its coord is the path's last name.
        d = plate_dict(0.5)
        d["plate"]["bsdf"]["id"] = "white"
        ds = self.client.load_dict(d).sweep(grid={"bsdf:white:reflectance.value": [0.1, 0.3]}, spp=4)
        np.testing.assert_allclose(ds.radiance.isel(y=0, x=0).values, np.array([0.1, 0.3]) / math.pi, atol=1e-5)
        self.assertIn("reflectance", ds.dims)

    def test_grid_and_job_value(self):
        # A grid axis also given job-wide: every context sets its own, so the job-wide value would
        # change nothing (it was silently overridden)
        with self.assertRaises(TypeError) as cm:
            self.plate(0.5).sweep(grid={RHO_KEY: [0.1, 0.2]}, params={RHO_KEY: 0.5})
        self.assertIn("also a grid axis", str(cm.exception))
        with self.assertRaises(TypeError):
            self.plate(0.5).sweep(grid={"wavelength": [500, 600]}, wavelength=550)

    def test_grid_typo(self):
        with self.assertRaises(KeyError) as cm:
            self.plate(0.5).sweep(grid={"plate.bsdf.reflectanc.value": [0.1]})
        self.assertIn(RHO_KEY, str(cm.exception))

    def test_grid_contexts_shape(self):
        ctx = rs.grid_contexts({"wavelength": [500, 600], "a.b.value": [1, 2, 3]})
        self.assertEqual(len(ctx), 6)
        self.assertEqual(ctx[0], {"id": "c00000", "coords": {"wavelength": 500, "b": 1}, "wavelength": 500,
                                  "params": {"a.b.value": 1}})
        self.assertEqual(ctx[5]["coords"], {"wavelength": 600, "b": 3})
        with self.assertRaises(TypeError):
            rs.grid_contexts({"wavelength": 500})
        # numpy scalars are numbers; numpy vectors are refused saying so (it was numpy's
        # "can only convert an array of size 1 to a Python scalar")
        ctx = rs.grid_contexts({"a.b.value": np.array([0.25, 0.5]), "wavelength": [np.int64(500)]})
        self.assertEqual([c["params"]["a.b.value"] for c in ctx], [0.25, 0.5])
        self.assertIs(type(ctx[0]["wavelength"]), int)
        with self.assertRaises(TypeError) as cm:
            rs.grid_contexts({"sun.direction": [np.array([0.0, 0, -1]), np.array([0.5, 0, -1])]})
        self.assertIn("contexts=[...]", str(cm.exception))
        self.assertIn("[0.0, 0.0, -1.0]", str(cm.exception))

    def test_progress_text_bar(self):
        out = io.StringIO()
        bar = _progress.TextBar(4, "job-x", out, live=False)
        bar.update(2, 4)
        bar.update(4, 4)
        bar.close("succeeded")
        self.assertRegex(out.getvalue(), r"job-x \[#{30}\] 4/4 .*succeeded")
        self.assertIsNone(_progress.make_bar(False, 4, "x"))
        self.assertIsNone(_progress.make_bar(None, 4, "x", stream=io.StringIO()), "no bar off a terminal")

    def test_progress_follows_events(self):
        # A bar fed by the job's events reaches the total.
        seen = []

        class Bar:
            def __init__(self, total, desc, unit):
                self.total = total

            def update(self, n):
                seen.append(n)

            def refresh(self):
                pass

            def set_postfix_str(self, s, refresh=False):
                pass

            def close(self):
                pass

            n = property(lambda self: sum(seen))

        self.plate(0.5).sweep(grid={"wavelength": [450, 500, 550, 600]}, spp=4, progress=Bar)
        self.assertEqual(sum(seen), 4)


class TestJobs(Base):
    def long_job(self, scene, n=40, spp=20000):
        return scene.submit(grid={"wavelength": list(range(400, 400 + 5 * n, 5))}, spp=spp)

    def test_future(self):
        scene = self.plate(0.5)
        jobs = [scene.submit(grid={"wavelength": [500 + k]}, spp=4) for k in range(3)]
        done = list(rs.as_completed(jobs, timeout=60))
        self.assertEqual(sorted(j.id for j in done), sorted(j.id for j in jobs))
        for j in jobs:
            self.assertTrue(j.done())
            self.assertFalse(j.cancelled())
            self.assertIsNone(j.exception())
            ds = j.result()
            self.assertEqual(ds.attrs["job"], j.id)
        films = jobs[0].films()
        (key, film), = films.items()
        self.assertEqual(key, ("c00000", "camera"))
        self.assertAlmostEqual(float(film[0, 0, 0]), 0.5 / math.pi, delta=1e-5)

    def test_cancel(self):
        hd = self.client.load_file(HDISTANT)
        job = self.long_job(hd)
        self.assertTrue(job.cancel())
        job.wait(timeout=60)
        self.assertEqual(job.state, "cancelled")
        self.assertTrue(job.cancelled())
        with self.assertRaises(rs.JobFailed) as cm:
            job.result()
        self.assertEqual(cm.exception.state, "cancelled")
        self.assertFalse(job.cancel(), "an ended job cannot be cancelled")

    def test_sweep_warnings(self):
        # A sweep whose axis changes nothing (no template reads 'sza') says so at once, as a
        # SweepWarning naming the caller's line, not only in the dataset's attributes.
        scene = self.plate(0.48)
        with self.assertWarns(rs.SweepWarning) as cm:
            ds = scene.sweep(grid={"sza": [0, 60]}, progress=False)
        w = cm.warning
        self.assertEqual((w.code, w.coordinate), ("coordinate_unused", "sza"))
        self.assertIn("coordinate_unused (sza)", str(w))
        self.assertEqual(os.path.basename(cm.filename), os.path.basename(__file__))
        self.assertIn("coordinate_unused", ds.attrs["warnings"])
        with self.assertWarns(rs.SweepWarning) as cm:
            job = scene.submit(grid={"sza": [0, 60]})
        self.assertEqual(os.path.basename(cm.filename), os.path.basename(__file__))
        self.assertEqual(cm.warning.job, job.id)
        job.wait(timeout=60)
        # With the template that reads it: no warning.
        with warnings.catch_warnings():
            warnings.simplefilter("error", rs.SweepWarning)
            scene.sweep(grid={"sza": [0, 60]}, templates={"sun.direction": {"sun": {"zenith": "sza", "azimuth": 0}}},
                        progress=False)

    def test_failed_renders_say_why(self):
        # A sun below the horizon has no horizontal irradiance to divide brf by: the daemon
        # fails those renders and says why; the exception carries its words, not only a count.
        d = plate_dict(0.47)
        d["templates"] = {"sun.direction": {"sun": {"zenith": "sza", "azimuth": 0}}}
        scene = self.client.load_dict(d)
        with self.assertRaises(rs.JobFailed) as cm:
            scene.sweep(grid={"sza": [30, 95, 120]}, quantities=["brf"], progress=False)
        e = cm.exception
        self.assertEqual(e.state, "failed")
        self.assertEqual([(c, s) for c, s, _ in e.failures], [("c00001", "camera"), ("c00002", "camera")])
        self.assertIn("at or below the horizon", e.failures[0][2])
        self.assertIn("2 of 3 renders failed; c00001/camera: quantities: brdf and brf", str(e))
        self.assertIn("(1 more in .failures)", str(e))

    def test_wait_timeout(self):
        hd = self.client.load_file(HDISTANT)
        job = self.long_job(hd)
        t = time.monotonic()
        with self.assertRaises(TimeoutError):
            job.result(timeout=0.3)
        self.assertLess(time.monotonic() - t, 5)
        job.cancel()
        job.wait(timeout=60)

    def test_ctrl_c_cancels(self):
        # A script sweeping a long job gets SIGINT: it cancels the job and says so.
        hd = self.client.load_file(HDISTANT)
        code = ("import raysweep as rs, sys\n"
                f"s = rs.connect({URL!r}).scene({hd.id!r})\n"
                "s.sweep(grid={'wavelength': list(range(400, 600, 5))}, spp=20000, progress=False)\n")
        before = {j.id for j in self.client.jobs()}
        # SIGINT back to its default in the script: a shell's background
        # job (tests/fresh/run.sh's `setsid bash -c ... &`) starts with it
        # ignored, and Python then never raises KeyboardInterrupt.
        proc = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE, text=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        new = []
        for _ in range(1200):  # up to a minute: a loaded machine imports xarray slowly
            new = [j for j in self.client.jobs() if j.id not in before and j.status["scene"] == hd.id]
            if new and new[0].state == "running":
                break
            time.sleep(0.05)
        self.assertTrue(new, "the script's job never appeared")
        proc.send_signal(signal.SIGINT)
        # Generous waits: the fresh-root run shares 2 cores with other tests.
        _, err = proc.communicate(timeout=180)
        self.assertNotEqual(proc.returncode, 0)
        self.assertIn(f"cancelled job {new[0].id}", err)
        self.assertIn("KeyboardInterrupt", err)
        job = self.client.job(new[0].id)
        job.wait(timeout=180)
        self.assertEqual(job.state, "cancelled")

    def test_ctrl_c_as_submit_returns(self):
        # A SIGINT that comes as the submit returns is run by the handler
        # the deferral puts back (CPython runs the one in place when it
        # checks): the job is still cancelled. Simulated by raising SIGINT
        # right after the deferral's __exit__; it failed before the fix.
        from unittest import mock
        from raysweep import scene as scene_mod
        hd = self.client.load_file(HDISTANT)
        cancelled = []

        class FakeJob:
            id = "job-fake"

            def cancel(self):
                cancelled.append(self.id)

            def result(self, **kw):
                raise AssertionError("the job's result was waited for")

        hd.submit = lambda **kw: FakeJob()
        plain_exit = scene_mod._deferred_interrupt.__exit__

        def exit_then_sigint(self, *exc):
            plain_exit(self, *exc)
            signal.raise_signal(signal.SIGINT)
            return False

        old = signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            with mock.patch.object(scene_mod._deferred_interrupt, "__exit__", exit_then_sigint):
                with self.assertRaises(KeyboardInterrupt):
                    hd.sweep(grid={"wavelength": [500]}, progress=False)
        finally:
            signal.signal(signal.SIGINT, old)
        self.assertEqual(cancelled, ["job-fake"])

    def test_dataset_bytes_workaround(self):
        # What docs/python.md says: BytesIO has no engine; netCDF4 memory= does.
        import xarray as xr
        job = self.plate(0.5).submit(grid={"wavelength": [500, 600]}, spp=4)
        job.wait(timeout=60)
        data = job.dataset_bytes()
        self.assertEqual(data[:4], b"\x89HDF")
        try:
            import h5netcdf  # noqa: F401
        except ImportError:
            with self.assertRaises(ValueError):
                xr.open_dataset(io.BytesIO(data))
        import netCDF4
        nc = netCDF4.Dataset("in-memory.nc", memory=data)
        ds = xr.open_dataset(xr.backends.NetCDF4DataStore(nc)).load()
        nc.close()
        self.assertEqual(dict(ds.sizes)["wavelength"], 2)
        path = job.save_dataset(os.path.join(self.tmp, "job.nc"))
        with xr.open_dataset(path) as ds2:
            np.testing.assert_array_equal(ds2.radiance.values, ds.radiance.values)


class TestDatasetFiles(Base):
    """Datasets are streamed to files, not read whole into memory."""

    def big_job(self):
        # 151 films of 32x32 (docs' hdistant example): a dataset of about 1 MB
        scene = self.client.load_file(HDISTANT)
        job = scene.submit(grid={"wavelength": list(range(400, 702, 2))}, spp=1)
        job.wait(timeout=120)
        return job

    def test_save_dataset_streams(self):
        import tracemalloc
        from raysweep import _data
        job = self.big_job()
        data = job.dataset_bytes()
        old = getattr(_data, "_CHUNK", None)
        _data._CHUNK = 64 << 10
        try:
            tracemalloc.start()
            path = job.save_dataset(os.path.join(self.tmp, "big.nc"))
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
        finally:
            _data._CHUNK = old
        with open(path, "rb") as f:
            self.assertEqual(f.read(), data)
        # Read whole, the answer alone would take len(data).
        self.assertGreater(len(data), 512 << 10)
        self.assertLess(peak, len(data) // 2, f"saving a {len(data)}-byte dataset peaked at {peak} bytes")
        self.assertEqual([n for n in os.listdir(self.tmp) if n.endswith(".part")], [])

    def test_dataset_through_a_temporary_file(self):
        import xarray as xr
        import netCDF4
        job = self.big_job()
        data = job.dataset_bytes()
        nc = netCDF4.Dataset("in-memory.nc", memory=data)
        ref = xr.open_dataset(xr.backends.NetCDF4DataStore(nc)).load()
        nc.close()
        tmp = os.path.join(self.tmp, "tmpdir")
        os.makedirs(tmp)
        old = tempfile.tempdir
        tempfile.tempdir = tmp
        try:
            ds = job.dataset()
        finally:
            tempfile.tempdir = old
        xr.testing.assert_identical(ds, ref)
        self.assertEqual(os.listdir(tmp), [], "the temporary file is removed")

    def test_cut_short(self):
        from raysweep import _data

        class Answer(io.BytesIO):
            headers = {"Content-Length": "100"}

        class Cut:
            def open(self, *a, **kw):
                return Answer(b"\x89HDF" + b"x" * 40)

        dest = os.path.join(self.tmp, "cut.nc")
        with self.assertRaises(rs.ConnectionFailed) as cm:
            _data.stream_to_file(Cut(), "/v1/jobs/j/dataset", dest)
        self.assertIn("after 44 of its 100 bytes", str(cm.exception))
        self.assertFalse(os.path.exists(dest))
        self.assertEqual([n for n in os.listdir(self.tmp) if n.startswith(".cut.nc")], [])


class TestWithoutXarray(Base):
    def test_numpy_only(self):
        # Hide xarray: render gives numpy, sweep a dict of numpy films.
        code = ("import sys; sys.modules['xarray'] = None\n"
                "import numpy as np, raysweep as rs, json\n"
                f"c = rs.connect({URL!r})\n"
                f"d = json.load(open({PLATE!r}))\n"
                "s = c.load_dict(d)\n"
                "f = s.render(spp=4)\n"
                "assert isinstance(f, np.ndarray) and f.shape == (1, 1, 1), type(f)\n"
                "r = s.sweep(grid={'wavelength': [500, 600]}, spp=4)\n"
                "assert sorted(r) == [('c00000', 'camera'), ('c00001', 'camera')], r\n"
                "try:\n"
                "    j = s.submit(grid={'wavelength': [500]}, spp=4)\n"
                "    j.wait()\n"
                "    j.dataset()\n"
                "except ImportError as e:\n"
                "    assert 'xarray' in str(e)\n"
                "else:\n"
                "    raise AssertionError('dataset() without xarray')\n"
                "print('ok')\n")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        self.assertEqual(out.returncode, 0, out.stderr[-1500:])
        self.assertEqual(out.stdout.strip(), "ok")


def main():
    suite = unittest.defaultTestLoader.loadTestsFromModule(sys.modules[__name__])
    if len(sys.argv) > 1:
        suite = unittest.defaultTestLoader.loadTestsFromNames(sys.argv[1:], sys.modules[__name__])
    t = time.monotonic()
    res = unittest.TextTestRunner(stream=sys.stdout, verbosity=2).run(suite)
    failed = len(res.failures) + len(res.errors) + len(res.unexpectedSuccesses)
    passed = res.testsRun - failed - len(res.skipped)
    print(f"test_client: {time.monotonic() - t:.1f} s")
    print(f"test_client: {passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
