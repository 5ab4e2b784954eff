"""Memory estimates of requests, checked against what the machine has before the work starts.

A render farm hands this tool resolutions, sample counts, grids and voxel sizes it
did not choose. A request whose memory does not fit must be refused up front, with
the estimate, instead of being killed by the kernel's OOM killer an hour later
(exit 137, no message, maybe a half-written file). Two parts:

Available memory
    :func:`available_bytes`: the smallest of the system's available memory
    (``MemAvailable`` of ``/proc/meminfo``, through psutil), the room left under the
    process's cgroup limit (v2 ``memory.max - memory.current``, or v1
    ``memory.limit_in_bytes - memory.usage_in_bytes``: containers and batch
    schedulers set these) and ``$ARCHES_RENDER_MEMORY`` (a cap in bytes, or with a
    ``K``/``M``/``G``/``T`` suffix, e.g. ``ARCHES_RENDER_MEMORY=8G`` on a shared
    node).
Estimates
    Byte counts of the arrays the code really allocates, per operation (their
    docstrings list them); ``tests/test_robust_resources.py`` measures the peak
    resident memory of real runs in fresh processes and checks that each estimate
    covers it without being more than a few times larger.

:func:`check_memory` raises :class:`ResourceError` (a ``ValueError``; the CLI
prints its one line and exits with status 2).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import psutil

__all__ = ["ENV", "ResourceError", "available_bytes", "check_memory", "format_bytes",
           "render_bytes", "polygonize_bytes", "heightmap_bytes"]

#: Environment variable capping the memory arches-render plans to use.
ENV = "ARCHES_RENDER_MEMORY"

#: What a Mitsuba process holds before the request's own arrays (interpreter,
#: Mitsuba, Dr.Jit, LLVM, the scene's kernels): measured 300-330 MB on a small scene.
BASE_BYTES = 400 << 20


#: The polygonizer's sample batches: 2^21 points as int64 indices, float64 positions,
#: Dr.Jit float32 coordinates and values (:func:`arches_render.mesh.polygonize.sample_grid`).
POLY_BATCH_BYTES = 150 << 20


class ResourceError(ValueError):
    """A request whose memory estimate exceeds the memory available (one-line message)."""


def format_bytes(n: float) -> str:
    """``n`` bytes as ``'1.5 GB'`` (powers of 1000, like ``free -h --si``)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(n) >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} B"


def _parse_size(text: str) -> int | None:
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([kKmMgGtT]?)i?[bB]?\s*", text or "")
    if not m:
        return None
    scale = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}[m.group(2).lower()]
    return int(float(m.group(1)) * scale)


def _read_int(path: str) -> int | None:
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _cgroup_room() -> int | None:
    """Bytes left under this process's cgroup memory limit (``None``: no limit found)."""
    try:
        lines = Path("/proc/self/cgroup").read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        _, controllers, rel = line.split(":", 2)
        if controllers == "":  # cgroup v2
            base = f"/sys/fs/cgroup{rel}".rstrip("/")
            limit, used = _read_int(f"{base}/memory.max"), _read_int(f"{base}/memory.current")
        elif "memory" in controllers.split(","):
            base = f"/sys/fs/cgroup/memory{rel}".rstrip("/")
            limit = _read_int(f"{base}/memory.limit_in_bytes")
            used = _read_int(f"{base}/memory.usage_in_bytes")
        else:
            continue
        if limit is not None and used is not None and limit < (1 << 60):
            return max(limit - used, 0)
    return None


def available_bytes() -> int:
    """Memory this process may still allocate, in bytes (see the module docstring).

    Returns
    -------
    int
        ``min(MemAvailable, cgroup room, $ARCHES_RENDER_MEMORY)``.
    """
    room = [psutil.virtual_memory().available]
    cg = _cgroup_room()
    if cg is not None:
        room.append(cg)
    cap = os.environ.get(ENV)
    if cap:
        size = _parse_size(cap)
        if size is None:
            raise ResourceError(f"${ENV} must be a size in bytes, e.g. 8G or 512M (got {cap!r})")
        room.append(size)
    return int(min(room))


def check_memory(nbytes: float, what: str) -> None:
    """Refuse ``what`` when its estimate ``nbytes`` exceeds :func:`available_bytes`.

    Parameters
    ----------
    nbytes : float
        The estimate.
    what : str
        The request, e.g. ``'rendering 16384x16384 with 20 channels'``.

    Raises
    ------
    ResourceError
        ``WHAT needs about X of memory, more than the Y available (...)``.
    """
    avail = available_bytes()
    if nbytes > avail:
        raise ResourceError(f"{what} needs about {format_bytes(nbytes)} of memory, more than the "
                            f"{format_bytes(avail)} available (system, cgroup limit and ${ENV}): "
                            f"lower the resolution, grid or voxel count")


def render_bytes(width: int, height: int, channels: int) -> int:
    """Estimated memory of rendering a ``width x height`` image of ``channels`` film channels.

    Per pixel and channel: the film's float32 storage and its weight (Mitsuba), the
    float32 tensor ``mi.render`` returns and its numpy view, the float64 sum of the
    passes, the float64 pass image and its product with the pass size, the float32
    mean, the layers split from it and the EXR writer's float32 copy: about 48 bytes
    (:func:`arches_render.render.renderer.render_layers`,
    :func:`arches_render.render.output.write_render`). The wavefront itself costs
    nothing per sample: the LLVM kernels generate samples inside the loop (measured
    RSS is the same at 1 and 16 spp per pass). Plus :data:`BASE_BYTES`.

    Parameters
    ----------
    width, height : int
    channels : int
        Beauty (3) plus the AOV channels plus 1 (the film's weight).

    Returns
    -------
    int
    """
    return BASE_BYTES + int(width) * int(height) * int(channels) * 48


def polygonize_bytes(voxels: float, surface_voxels: float | None = None) -> int:
    """Estimated memory of polygonizing a dense grid of ``voxels`` samples (marching cubes).

    The float32 volume (4 B/voxel), scikit-image's Lewiner marching cubes, which
    keeps per voxel a few index slices (measured about 4 B/voxel more on a sphere),
    the batches of sampled points (:data:`POLY_BATCH_BYTES`), and per vertex of the output (about ``2 x surface voxels``) the float32
    positions, normals and the float64 copies of the normal estimate and winding
    check (about 200 B). ``surface_voxels`` defaults to a sphere's share of a cube
    grid, ``6 n^(2/3)``.

    Parameters
    ----------
    voxels : float
        Grid samples ``nx ny nz``.
    surface_voxels : float, optional

    Returns
    -------
    int
    """
    if surface_voxels is None:
        surface_voxels = 6.0 * float(voxels) ** (2.0 / 3.0)
    return BASE_BYTES + POLY_BATCH_BYTES + int(8 * float(voxels) + 400 * float(surface_voxels))


def heightmap_bytes(nx: int, ny: int) -> int:
    """Estimated memory of an ``nx x ny`` fBm heightmap and the heightfield node made of it.

    :func:`arches_render.field.heightmaps.fbm_heightmap` holds the float64 sample
    coordinates, the octave sum, one octave's noise and its temporaries (about 8
    float64 arrays of the grid); the node keeps a float32 copy on the device and
    its min/max mipmap (about 12 B per sample). About 80 B per sample.
    """
    return int(nx) * int(ny) * 80
