"""One amplify run: the DEM, the tree being built and what the presets add to it.

:class:`Amplification` holds the state a preset of :mod:`.presets` works on (the
DEM, the falloff ``R`` and threshold ``T``, the landform scales, the resistance
``rho``, the tree's children, the stats), with the helpers the landform functions
share: landform sizes in metres, Poisson spacings capped at :data:`MAX_PRIMITIVES`
primitives, and the writing of carving primitives as ``skeletal_set`` nodes.
:class:`NodeTables` writes the tree as scene-file tables and their data files;
:class:`StepTimer` times the steps a preset reports and checks their order.

Carving energies. A carving primitive of falloff ``R_i`` and energy ``-e_i`` in rock
of field value ``T`` removes the ball where ``e_i g(d / R_i) > T``. Each erosion
sample asks for a cavity of radius ``r_i`` (``e``-proportional); we set
``R_i = r_i / 0.6`` and ``e_i = T / g(0.6) / n_i`` where ``n_i = sum_j g(|c_i - c_j| / R_j)``
is the overlap of the samples at ``c_i``: the paper only says energies are
proportional to ``e``; without the ``1 / n_i`` a Poisson-dense set of overlapping
primitives would carve the *sum* of its neighbours (tens of times too deep).

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.spatial import cKDTree

from arches_render.scene.nodes import NodeBuilder

from .falloff import g
from .shallow_erosion import ErosionPrimitives
from .skeletal_files import save_npz

__all__ = ["Amplification", "NodeTables", "StepTimer", "SEA_STEPS", "MAX_PRIMITIVES"]

_CAVITY_AT = 0.6  # cavity radius / falloff radius of a carving primitive
SEA_STEPS = 3  # steps of sea erosion, as in the paper's Fig. 11
#: Most primitives one run makes (the paper's largest tree, Fig. 17, has 165,773).
MAX_PRIMITIVES = 250_000


class StepTimer:
    """Progress and timings of a fixed list of named steps.

    Parameters
    ----------
    labels : sequence of str
        The steps, in order (unique).
    progress : callable, optional
        ``progress(done, total, label)`` after each step.

    Attributes
    ----------
    timings : dict
        ``{label: seconds}`` of the steps done.
    """

    def __init__(self, labels, progress=None):
        self.labels, self.progress = list(labels), progress
        self.timings: dict = {}
        self._last = time.perf_counter()

    @property
    def done(self) -> int:
        """Number of steps done."""
        return len(self.timings)

    def step(self, label: str) -> None:
        """Close step ``label``, which must be the next one of the list (else a bug: raises)."""
        expected = self.labels[self.done] if self.done < len(self.labels) else None
        if label != expected:
            raise RuntimeError(f"step {label!r} out of order: expected {expected!r} (steps {self.labels})")
        now = time.perf_counter()
        self.timings[label] = round(now - self._last, 4)
        self._last = now
        if self.progress:
            self.progress(self.done, len(self.labels), label)


class NodeTables:
    """Node tables and their data files, built by the scene loader's builder.

    The tree is written as scene-file tables (``[nodes.*]``) and built through the
    loader's :class:`~arches_render.scene.nodes.NodeBuilder` from the very same tables
    and data files, so the scene file holds exactly the tree that was generated.
    """

    def __init__(self, work_dir: Path, prefix: str):
        self.dir, self.prefix = Path(work_dir), prefix
        self.files: list = []
        self.builder = NodeBuilder({}, self.dir / "amplified.toml", self.dir)

    @property
    def tables(self) -> dict:
        """The ``[nodes.*]`` tables defined so far."""
        return self.builder.defs

    def file(self, suffix, write):
        """Write a data file ``PREFIX.SUFFIX`` with ``write(path)``; return its relative name."""
        rel = f"{self.prefix}.{suffix}"
        path = self.dir / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        write(path)
        self.files.append(rel)
        return rel

    def add(self, name, table):
        """Define the table ``name`` and return its node."""
        self.builder.define(name, table)
        return self.builder.named(name)


@dataclass
class Amplification:
    """One amplify run: the DEM, the tree being built and what the presets add to it."""

    tree: NodeTables
    heights: np.ndarray
    extent: tuple
    cell: float
    R: float
    T: float
    rng: np.random.Generator
    scales: dict = field(default_factory=dict)
    precision: float = 0.1
    terrain: object = None
    timer: StepTimer | None = None
    sea_steps: int = SEA_STEPS
    sea_spacing: float | None = None
    fallen_blocks: bool = True
    #: node -> the same node without its accessories (the fallen blocks' host)
    bare: dict = field(default_factory=dict)
    sea_level: float | None = None
    rho: Callable | None = None
    children: list = field(default_factory=lambda: ["terrain"])
    focus: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)

    @property
    def relief(self):
        """``(zlo, zhi, Z)``: lowest and highest elevation, relief (at least 4 cells)."""
        zlo, zhi = float(self.heights.min()), float(self.heights.max())
        return zlo, zhi, max(zhi - zlo, 4 * self.cell)

    @property
    def size(self):
        """``(W, D)``: the tile's width and depth in metres."""
        x0, y0, x1, y1 = self.extent
        return x1 - x0, y1 - y0

    @property
    def mesh_step(self) -> int:
        """Subsampling of the DEM mesh: at most ~1024 vertices along a side."""
        ny, nx = self.heights.shape
        return max(1, int(math.ceil(max(nx, ny) / 1024)))

    @property
    def feature(self) -> float:
        """Landform size ``F`` in metres (:func:`.preset_choice.landform_scales`), at least 2 precisions."""
        return max(float(self.scales.get("feature_m", 0.2 * self.relief[2])), 2.0 * self.precision)

    def scale(self, key, default):
        """A landform size of :attr:`scales` (metres), ``default`` where it is 0 or missing."""
        v = float(self.scales.get(key, 0.0))
        return v if v > 0 else float(default)

    def spacing_for(self, area, spacing, per_sample=1.0):
        """Poisson spacing for ``area`` m^2 so that the expected count stays under :data:`MAX_PRIMITIVES`.

        ``per_sample``: primitives a sample makes. A larger spacing is noted in ``stats``.
        """
        need = per_sample * float(area) / float(spacing) ** 2
        if need <= MAX_PRIMITIVES:
            return float(spacing)
        wider = float(spacing) * math.sqrt(need / MAX_PRIMITIVES)
        self.stats["sparse_note"] = (f"Poisson spacing widened from {spacing:.3g} m to {wider:.3g} m "
                                     f"(at most {MAX_PRIMITIVES} primitives)")
        return wider

    def carve(self, name, arrays):
        """Write ``arrays`` (one dict or a list merged into one set) as a ``skeletal_set`` node.

        Returns ``(name, primitives, centres)`` or ``None`` when there is nothing to carve.
        """
        parts = [x for x in (arrays if isinstance(arrays, list) else [arrays]) if x is not None]
        if not parts:
            return None
        merged = {k: np.concatenate([x[k] for x in parts]) for k in ("a", "b", "radius", "energy")}
        rel = self.tree.file(f"{name}.npz", lambda p: save_npz(p, **merged))
        # One set for all steps (one grid, one loop per ray step). No star noise on carving
        # sets: the Poisson samples and rho already make the walls irregular, and the noise
        # would triple the cost of every ray step near the terrain.
        self.tree.add(name, {"type": "skeletal_set", "file": rel, "combine": "sum"})
        return name, int(len(merged["radius"])), 0.5 * (merged["a"] + merged["b"])

    def carving_arrays(self, prims: ErosionPrimitives):
        """Arrays ``a, b, radius, energy`` of negative primitives carving the cavities of ``prims``."""
        T = self.T
        keep = prims.radius >= self.precision  # smaller cavities are below the precision
        a, b, r = prims.center[keep], prims.end[keep], prims.radius[keep]
        if len(r) == 0:
            return None
        R = r / _CAVITY_AT
        mid = 0.5 * (a + b)
        # n_i = sum_j g(|c_i - c_j| / R_j), the primitive itself included (g(0) = 1).
        pairs = cKDTree(mid).query_pairs(float(R.max()), output_type="ndarray")
        d = np.linalg.norm(mid[pairs[:, 0]] - mid[pairs[:, 1]], axis=1)
        overlap = (1.0 + np.bincount(pairs[:, 0], g(d, R[pairs[:, 1]]), minlength=len(r))
                   + np.bincount(pairs[:, 1], g(d, R[pairs[:, 0]]), minlength=len(r)))
        return dict(a=a, b=b, radius=R, energy=-T / g(_CAVITY_AT, 1.0) / overlap)

    def add_carving(self, name, prims, count_key):
        """Carve ``prims`` as node ``name`` (a child of the world), counted as ``stats[count_key]``."""
        out = self.carve(name, self.carving_arrays(prims))
        if out:
            self.children.append(out[0])
            self.stats[count_key] = out[1]
            self.focus.append(out[2])
