"""raysweep: a Python client for the raysweep daemon, in Mitsuba's and Eradiate's words.

    import raysweep as rs

    client = rs.connect("http://127.0.0.1:8350")          # or $RAYSWEEP_URL
    scene = client.load_file("plate.json")                # uploads meshes, volumes, bitmaps
    params = scene.traverse()                             # like mi.traverse(scene)
    params["plate.bsdf.reflectance.value"] = 0.3
    params.update()                                       # one atomic PATCH
    film = scene.render(spp=64, wavelength=550)           # like mi.render(scene, spp=64)
    ds = scene.sweep(grid={"wavelength": [450, 550, 650]}, spp=64)   # an xarray.Dataset
    job = scene.submit(grid={...})                        # a future: job.result(), job.cancel()

The manual is docs/python.md; the HTTP API docs/daemon.md.
"""

from ._data import aolp, dolp
from .client import Client, connect
from .errors import ConnectionFailed, JobFailed, RaysweepError, SweepWarning, UnknownKeyError
from .jobs import Job, as_completed, grid_contexts
from .scene import Scene, SceneParameters

__version__ = "0.2.0"

__all__ = [
    "Client",
    "ConnectionFailed",
    "Job",
    "JobFailed",
    "RaysweepError",
    "Scene",
    "SceneParameters",
    "SweepWarning",
    "UnknownKeyError",
    "aolp",
    "as_completed",
    "connect",
    "dolp",
    "grid_contexts",
    "render",
    "traverse",
]


def traverse(scene, match=None):
    """``scene.traverse(match)``, spelt as Mitsuba's ``mi.traverse(scene)``."""
    return scene.traverse(match)


def render(scene, **kwargs):
    """``scene.render(**kwargs)``, spelt as Mitsuba's ``mi.render(scene, spp=..., seed=..., sensor=...)``."""
    return scene.render(**kwargs)
