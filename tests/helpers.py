"""Small shared helpers for the test-suite (no fixtures: plain functions)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "scenes"


def variant():
    """Select the default variant and register our plugins (once)."""
    from arches_render.render.plugins import ensure_registered
    return ensure_registered()


def random_points(n, lo, hi, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, size=(n, 3))


def render_as_header_says(scene_file, header: dict, aovs: bool = True):
    """Render ``scene_file`` again with the identity an EXR ``header`` gives (camera, size, spp, seed, stream).

    A frame's header is only worth checking against the pixels: the same bits
    from this render prove the header names the camera, samples and stream the
    frame was rendered with. Returns ``(rgb, layers)`` of
    :func:`arches_render.render.jobs.run_job`.
    """
    from arches_render.render.jobs import RenderJob, run_job

    def vec(key):
        return tuple(float(v) for v in header[key].split())

    width, height = (int(v) for v in header["resolution"].split("x"))
    camera = (vec("camera_origin"), vec("camera_target"), vec("camera_up"), float(header["camera_fov"]))
    return run_job(RenderJob(scene=str(Path(scene_file).resolve()), width=width, height=height,
                             spp=int(header["spp"]), seed=int(header["seed"]), stream=int(header["stream"]),
                             geometry=header["geometry"], aovs=aovs, camera=camera))


def exr_layers(image) -> dict:
    """The layers of a read EXR (:class:`arches_render.imaging.exr.ExrImage`) as a render returns them:
    ``{name: (array, channel letters)}``."""
    return {name: (a, image.layer_channels[name]) for name, a in image.layers.items()}
