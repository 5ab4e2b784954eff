"""Small shared helpers for the test-suite (no fixtures: plain functions)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "scenes"


def golden_checks():
    """``(shipped, (width, height), spp_of)``: the shipped scenes with goldens, the
    resolution of their check renders and ``spp_of(name)``, their samples per pixel
    (``golden/checks.toml``; read by the golden tests and ``benchmarks/golden_seeds.py``)."""
    from arches_render import tomlfile
    checks = tomlfile.load(REPO / "golden" / "checks.toml")

    def spp_of(name: str) -> int:
        return int(checks["spp_of"].get(name, checks["spp"]))

    return sorted(p.stem for p in SCENES.glob("*.toml")), tuple(checks["resolution"]), spp_of


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


# Field against mesh: the mesh is the field polygonized at its voxel, so the two are
# not the same image in expectation (silhouettes move by up to a voxel, facets shade
# a little differently: on the default scene the mesh is 0.6 % brighter, 4.6 sigma
# at 32 spp). These allowances are that discretization, measured on every shipped
# scene at 96 x 54 and 32 spp (worst: a mean shift of -1.09 % at 0.24 % noise in the
# tunnel; the basalt columns' sharp creases need their scene's 0.03 m voxel, at 0.06 the
# mesh's chamfers made windows 10-18 % darker); everything else is noise, known per pixel
# from the moments (the two renders use independent seeds, test_render.FIELD_SEED).
MESH_MEAN_TOL = 0.01
MESH_WINDOW_TOL = 0.05
MESH_POWER = 0.9


def assert_field_matches_mesh(field, mesh):
    """Assert that a traced field's render agrees with its mesh's (both ``PixelMoments``).

    The luminance of every 8x8 window agrees within ``MESH_WINDOW_TOL`` plus 5.5 sigma
    of its noise, the image mean within ``MESH_MEAN_TOL`` plus 4.2 sigma; and the
    renders have the samples for it to matter: a 25 % change would fail in at least
    ``MESH_POWER`` of the windows a quarter as bright as the image (the rest lie in
    noisy shadow; the goldens prove every such window at their own spp).
    """
    from arches_render.imaging.welch import DARK_WINDOW, PATCH_CHANGE, window_stats
    d, sd, mu = window_stats(mesh, field)
    excess = np.abs(d) - 5.5 * sd - MESH_WINDOW_TOL * mu
    y, x = np.unravel_index(int(np.argmax(excess)), excess.shape)
    assert excess[y, x] <= 0, (f"8x8 window at (y={y}, x={x}) differs by {d[y, x] / mu[y, x]:+.1%} "
                               f"(noise {sd[y, x] / mu[y, x]:.1%})")
    total = mesh.mean4[..., 3].sum()
    shift = field.mean4[..., 3].sum() / total - 1
    sigma = np.sqrt(mesh.mean_variance()[..., 3].sum() + field.mean_variance()[..., 3].sum()) / total
    assert abs(shift) <= MESH_MEAN_TOL + 4.2 * sigma, f"image mean shift {shift:+.3%} (noise {sigma:.3%})"
    bright = mu >= DARK_WINDOW * mu.mean()
    seen = np.mean((MESH_WINDOW_TOL * mu + 5.5 * sd < PATCH_CHANGE * mu)[bright])
    assert seen >= MESH_POWER, f"a 25 % patch change would fail in only {seen:.1%} of the bright windows"
