"""Material stacks: a 2-D grid of columns, each a stack of (material, thickness) layers.

The discrete half of the hybrid model of Peytavie et al. (2009, section 3.2, figure 3):
the terrain is a 2-D grid of *material stacks*; a stack lists the layers of one
column of side ``s`` (the cell size) from the base ``z0`` upwards, each a material
(:data:`MATERIALS`) and a thickness. Overhangs, arches and caves are air layers
between two solid layers.

Storage (compact, CSR-like; no Python objects per layer): thicknesses are integer
counts of a vertical quantum ``dz`` (``uint16``), materials are ``uint8`` ids, and
``offsets[c] : offsets[c + 1]`` indexes the layers of column ``c = j nx + i``
(``uint32``). A layer thus costs 3 bytes and a column 4 bytes; the *effective voxel
resolution* is ``nx x ny x n_levels`` with ``n_levels = (z1 - z0) / dz <= 65535``.
Canonical form: no zero-thickness layer, adjacent layers of one material merged,
no trailing air (the air above the top layer is implicit).

Column ``(i, j)`` covers ``[x0 + i s, x0 + (i + 1) s] x [y0 + j s, y0 + (j + 1) s]``;
level ``l`` covers ``[z0 + l dz, z0 + (l + 1) dz]``.

References
----------
Peytavie, A., Galin, E., Grosjean, J., Merillou, S. (2009). Arches: a framework for
modeling complex terrains. Computer Graphics Forum 28(2), 457-467 (section 3.2).
Benes, B., Forsbach, R. (2001). Layered data representation for visual simulation
of terrain erosion. SCCG 2001.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arches_render.atomic import atomic_path
from arches_render.field import evaluate
from arches_render.npzfile import write_npz
from arches_render.scene.array_files import Spec, read_arrays


# The kernels (numba: 0.13 s to import) are imported on first use, not by every process
# that reads the scene node types (``layers`` registers its nodes through this module).
def _kernels():
    from . import stack_kernels
    return stack_kernels


#: Material ids. Stable materials (bedrock, sandstone, water) never flow; granular
#: ones (sand, rock) flow by their angle of repose (section 3.4).
MATERIALS = {"air": 0, "bedrock": 1, "sand": 2, "rock": 3, "water": 4, "sandstone": 5}
MATERIAL_NAMES = {v: k for k, v in MATERIALS.items()}
AIR, BEDROCK, SAND, ROCK, WATER, SANDSTONE = 0, 1, 2, 3, 4, 5
GRANULAR = (SAND, ROCK)
#: Materials forming the ground surface (the skeleton of section 6: sand or bedrock;
#: rocks are included because this renderer has no separate rock instancing here).
SOLID = (BEDROCK, SAND, ROCK, SANDSTONE)
MAX_LEVELS = 65535
#: The arrays of a stack file written by :meth:`MaterialStacks.save`.
STACK_SPECS = {"offsets": Spec(("c",), "integer", lo=0, hi=2 ** 32 - 1),
               "material": Spec(("m",), "integer", lo=0, hi=255),
               "count": Spec(("m",), "integer", lo=0, hi=MAX_LEVELS),
               "grid": Spec((3,), "integer", lo=1, hi=2 ** 31 - 1), "geometry": Spec((5,)),
               "material_names": Spec((None,), "string", required=False)}


def material_id(name) -> int:
    """Material id of ``name`` (str) or the id itself; raises ``ValueError`` otherwise."""
    if isinstance(name, (int, np.integer)) and int(name) in MATERIAL_NAMES:
        return int(name)
    if isinstance(name, str) and name in MATERIALS:
        return MATERIALS[name]
    raise ValueError(f"unknown material {name!r} (allowed: {', '.join(MATERIALS)})")


class MaterialStacks:
    """A grid of material stacks (see module docstring).

    Parameters
    ----------
    shape : (ny, nx)
        Number of columns along y and x.
    cell : float
        Column side ``s`` in metres.
    origin : (x0, y0, z0)
        Corner of column (0, 0) and base of every stack.
    dz : float
        Vertical quantum in metres.
    n_levels : int
        Height of the grid in quanta (``<= 65535``).
    offsets, material, count : numpy.ndarray
        CSR arrays (``uint32`` of ``nx ny + 1``, ``uint8``, ``uint16``).
    """

    def __init__(self, shape, cell, origin, dz, n_levels, offsets, material, count):
        ny, nx = (int(v) for v in shape)
        if nx < 1 or ny < 1:
            raise ValueError(f"stack grid must have at least 1x1 columns (got {nx}x{ny})")
        if not (cell > 0 and dz > 0 and np.isfinite(cell) and np.isfinite(dz)):
            raise ValueError(f"cell and dz must be finite and > 0 (got {cell}, {dz})")
        if not 1 <= int(n_levels) <= MAX_LEVELS:
            raise ValueError(f"n_levels must be in [1, {MAX_LEVELS}] (got {n_levels}): raise dz")
        self.nx, self.ny = nx, ny
        self.cell = float(cell)
        self.origin = tuple(float(v) for v in origin)
        self.dz = float(dz)
        self.n_levels = int(n_levels)
        self.offsets = np.ascontiguousarray(offsets, dtype=np.uint32)
        self.material = np.ascontiguousarray(material, dtype=np.uint8)
        self.count = np.ascontiguousarray(count, dtype=np.uint16)
        if len(self.offsets) != nx * ny + 1 or self.offsets[-1] != len(self.material) \
                or len(self.material) != len(self.count):
            raise ValueError("inconsistent CSR arrays (offsets, material, count)")
        tops = _kernels().column_heights(self.offsets, self.count)
        if tops.size and int(tops.max()) > self.n_levels:
            raise ValueError("a stack is higher than n_levels")

    # ---------------------------------------------------------------- geometry
    @property
    def ncol(self) -> int:
        return self.nx * self.ny

    @property
    def extent(self):
        """``(x0, y0, x1, y1)`` of the grid in metres."""
        x0, y0, _ = self.origin
        return (x0, y0, x0 + self.nx * self.cell, y0 + self.ny * self.cell)

    @property
    def z_range(self):
        """``(z0, z1)``: base and top of the grid in metres."""
        return self.origin[2], self.origin[2] + self.n_levels * self.dz

    def heights(self) -> np.ndarray:
        """Top of the highest non-air layer of every stack (metres, shape ``(ny, nx)``)."""
        tops = _kernels().column_heights(self.offsets, self.count)
        return (self.origin[2] + tops * self.dz).reshape(self.ny, self.nx)

    def column(self, i: int, j: int):
        """Layers of stack ``(i, j)`` as ``[(material name, z_bottom, z_top), ...]`` bottom-up."""
        c = j * self.nx + i
        a, b = int(self.offsets[c]), int(self.offsets[c + 1])
        out, z = [], self.origin[2]
        for m, n in zip(self.material[a:b], self.count[a:b]):
            out.append((MATERIAL_NAMES[int(m)], z, z + int(n) * self.dz))
            z += int(n) * self.dz
        return out

    def volume(self, materials=SOLID) -> float:
        """Volume in m^3 of the given material ids (exact: integer quanta times ``dz s^2``)."""
        return float(self.levels(materials)) * self.dz * self.cell ** 2

    def levels(self, materials=SOLID) -> int:
        """Total thickness in quanta of the given material ids (the conserved mass)."""
        mask = np.isin(self.material, np.atleast_1d(materials))
        return int(self.count[mask].astype(np.int64).sum())

    def intervals(self, materials=SOLID):
        """Merged intervals of the given materials, per column, as CSR in metres.

        Adjacent layers of any of ``materials`` form one interval. Returns
        ``(offsets, bottom, top)``: ``offsets`` of length ``ncol + 1`` (int64) and the
        float64 bounds of each interval, bottom-up within a column.
        """
        sel = np.zeros(256, dtype=np.bool_)
        sel[np.atleast_1d(np.asarray(materials, dtype=np.int64))] = True
        off, lo, hi = _kernels()._merged_intervals(self.offsets, self.material, self.count, sel)
        z0 = self.origin[2]
        return off, z0 + lo * self.dz, z0 + hi * self.dz

    def nbytes(self) -> int:
        """Memory of the CSR arrays in bytes."""
        return self.offsets.nbytes + self.material.nbytes + self.count.nbytes

    def effective_voxels(self) -> int:
        """``nx ny n_levels``: voxels of a dense grid with the same resolution."""
        return self.nx * self.ny * self.n_levels

    def copy(self) -> "MaterialStacks":
        return MaterialStacks((self.ny, self.nx), self.cell, self.origin, self.dz, self.n_levels,
                              self.offsets.copy(), self.material.copy(), self.count.copy())

    def with_arrays(self, offsets, material, count) -> "MaterialStacks":
        """Same grid, new CSR arrays."""
        return MaterialStacks((self.ny, self.nx), self.cell, self.origin, self.dz, self.n_levels,
                              offsets, material, count)

    def digest(self) -> str:
        """SHA-256 of the grid and its arrays (determinism checks)."""
        import hashlib
        h = hashlib.sha256(repr((self.nx, self.ny, self.cell, self.origin, self.dz,
                                 self.n_levels)).encode())
        for a in (self.offsets, self.material, self.count):
            h.update(a.tobytes())
        return h.hexdigest()

    def __eq__(self, other):
        return isinstance(other, MaterialStacks) and self.digest() == other.digest()

    def __repr__(self):
        return (f"MaterialStacks({self.nx}x{self.ny} columns, cell {self.cell} m, dz {self.dz} m, "
                f"{len(self.material)} layers, {self.nbytes()} bytes)")

    # -------------------------------------------------------------- conversion
    @classmethod
    def from_heightfield(cls, heights, cell, origin=(0.0, 0.0), z0=None, z1=None, dz=None,
                         column=(("bedrock", None),)):
        """Stacks whose solid is the ground under a heightfield.

        Parameters
        ----------
        heights : array_like
            ``(ny, nx)`` elevations of the column axes in metres.
        cell : float
            Column side ``s``.
        origin : (x0, y0)
            Corner of column (0, 0).
        z0, z1 : float, optional
            Base and top of the grid; default 1 m below the lowest sample and
            a third of the relief (at least 2 m) above the highest.
        dz : float, optional
            Vertical quantum; default ``(z1 - z0) / 4096``.
        column : sequence of (material, thickness)
            The material column from the surface downwards; a thickness of ``None``
            (only last) fills down to ``z0``; what is left below the column is bedrock.

        Returns
        -------
        MaterialStacks
        """
        H = np.asarray(heights, dtype=np.float64)
        if H.ndim != 2 or not np.all(np.isfinite(H)):
            raise ValueError("heights must be a finite 2-D array")
        lo, hi = float(H.min()), float(H.max())
        z0 = lo - 1.0 if z0 is None else float(z0)
        z1 = hi + max(2.0, (hi - lo) / 3.0) if z1 is None else float(z1)
        if not z1 > z0:
            raise ValueError(f"z1 must exceed z0 (got {z0}, {z1})")
        dz = (z1 - z0) / 4096 if dz is None else float(dz)
        n_levels = int(np.ceil((z1 - z0) / dz - 1e-9))
        top = np.clip(np.rint((H - z0) / dz), 0, n_levels).astype(np.int64).ravel()
        mats, thick = _column_spec(column, dz)
        # Layers top-down: each band takes what is left above z0.
        counts = np.zeros((len(top), len(mats) + 1), dtype=np.int64)
        left = top.copy()
        for k, t in enumerate(thick):
            take = left if t is None else np.minimum(left, t)
            counts[:, len(mats) - 1 - k + 1] = take
            left = left - take
        counts[:, 0] = left                 # bedrock below the column
        mat_row = np.array([BEDROCK] + list(reversed(mats)), dtype=np.uint8)
        off, m, n = _csr_from_dense_counts(counts, mat_row)
        ny, nx = H.shape
        return cls((ny, nx), cell, (origin[0], origin[1], z0), dz, n_levels, off, m, n)

    def to_heightfield(self):
        """The upper envelope as a heightfield: ``(heights, extent)`` of the column axes.

        ``extent = (x_c0, y_c0, x_c1, y_c1)`` spans the first and last column
        centres, the convention of :class:`arches_render.field.Heightfield`.
        """
        x0, y0, _ = self.origin
        s = self.cell
        return self.heights(), (x0 + s / 2, y0 + s / 2, x0 + (self.nx - 0.5) * s, y0 + (self.ny - 0.5) * s)

    @classmethod
    def from_field(cls, node, extent, cell, z_range, dz, step=None, material="bedrock",
                   column=None, batch_columns=4096):
        """Voxelize a field of the language into stacks (the solid is ``f > 0``).

        Each stack's central axis is sampled every ``step`` metres with
        :func:`arches_render.field.evaluate`; a sign change between two samples
        puts a layer boundary at the linear root of ``f`` (section 4.1: "finding
        the roots of f = 0 along the central axis of the material stack").

        Parameters
        ----------
        node : arches_render.field.Node
        extent : (x0, y0, x1, y1)
            Grid extent; it must be a whole number of cells.
        cell : float
            Column side ``s``.
        z_range : (z0, z1)
        dz : float
            Vertical quantum.
        step : float, optional
            Sampling step along the axis; default ``cell / 2``.
        material : str
            Material of the solid (used without ``column``).
        column : sequence of (material, thickness), optional
            Material column applied below the top of each solid run.

        Returns
        -------
        MaterialStacks
        """
        x0, y0, x1, y1 = (float(v) for v in extent)
        nx = int(round((x1 - x0) / cell))
        ny = int(round((y1 - y0) / cell))
        if nx < 1 or ny < 1 or abs(nx * cell - (x1 - x0)) > 1e-6 * cell or abs(ny * cell - (y1 - y0)) > 1e-6 * cell:
            raise ValueError(f"extent {list(extent)} must be a positive whole number of cells of {cell} m")
        z0, z1 = (float(v) for v in z_range)
        n_levels = int(np.ceil((z1 - z0) / dz - 1e-9))
        step = cell / 2 if step is None else float(step)
        nz = max(2, int(np.ceil((z1 - z0) / step)) + 1)
        zs = np.linspace(z0, z1, nz)
        xs = x0 + (np.arange(nx) + 0.5) * cell
        ys = y0 + (np.arange(ny) + 0.5) * cell
        X, Y = (a.ravel() for a in np.meshgrid(xs, ys))
        bounds = []
        for s in range(0, nx * ny, batch_columns):
            cx, cy = X[s:s + batch_columns], Y[s:s + batch_columns]
            k = len(cx)
            pts = np.stack([np.repeat(cx, nz), np.repeat(cy, nz), np.tile(zs, k)], axis=1)
            f = evaluate(node, pts).reshape(k, nz).astype(np.float64)
            bounds.append(_runs_from_samples(f, zs, z0, dz, n_levels,
                                             min_gap=int(np.ceil(step / dz))))
        lv = [b for chunk in bounds for b in chunk]
        spec = ((material, None),) if column is None else tuple(column)
        mats, thick = _column_spec(spec, dz)
        return cls._from_runs((ny, nx), cell, (x0, y0, z0), dz, n_levels, lv, mats, thick)

    @classmethod
    def _from_runs(cls, shape, cell, origin, dz, n_levels, runs, mats, thick):
        """Stacks from per-column solid runs ``[(lo, hi), ...]`` (levels), banded by ``mats``."""
        off = [0]
        out_m, out_n = [], []
        for col in runs:
            layers = []
            z = 0
            for lo, hi in col:
                if lo > z:
                    layers.append((AIR, lo - z))
                # Bands from the top of the run downwards.
                bands, left = [], hi - lo
                for m, t in zip(mats, thick):
                    take = left if t is None else min(left, t)
                    if take > 0:
                        bands.append((m, take))
                    left -= take
                if left > 0:
                    bands.append((BEDROCK, left))
                layers.extend(reversed(bands))
                z = hi
            merged = []
            for m, n in layers:
                if merged and merged[-1][0] == m:
                    merged[-1] = (m, merged[-1][1] + n)
                else:
                    merged.append((m, n))
            out_m.extend(m for m, _ in merged)
            out_n.extend(n for _, n in merged)
            off.append(len(out_m))
        return cls(shape, cell, origin, dz, n_levels, np.array(off, dtype=np.uint32),
                   np.array(out_m, dtype=np.uint8), np.array(out_n, dtype=np.uint16))

    # ------------------------------------------------------------------- files
    def save(self, path) -> None:
        """Write the stacks to an ``.npz`` file atomically."""
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                write_npz(f, dict(
                    offsets=self.offsets, material=self.material, count=self.count,
                    grid=np.array([self.nx, self.ny, self.n_levels], dtype=np.int64),
                    geometry=np.array([self.cell, *self.origin, self.dz], dtype=np.float64),
                    material_names=np.array([MATERIAL_NAMES[i] for i in sorted(MATERIAL_NAMES)])), compress=True)

    @classmethod
    def load(cls, path) -> "MaterialStacks":
        """Read stacks written by :meth:`save` (``ValueError`` on a bad file).

        The arrays are checked before use (:data:`STACK_SPECS`; offsets rising from 0,
        known material ids): the compiled stack walkers index without bounds checks.
        """
        try:
            d = read_arrays(path, STACK_SPECS, "material stacks")
            nx, ny, n_levels = (int(v) for v in d["grid"])
            cell, x0, y0, z0, dz = (float(v) for v in d["geometry"])
            off = d["offsets"]
            if nx * ny + 1 != len(off) or off[0] != 0 or np.any(np.diff(off) < 0) or off[-1] != len(d["material"]):
                raise ValueError(f"offsets must rise from 0 to len(material) over nx ny + 1 = {nx * ny + 1} "
                                 f"entries (grid {nx}x{ny})")
            unknown = np.setdiff1d(d["material"], list(MATERIAL_NAMES))
            if unknown.size:
                raise ValueError(f"unknown material id {int(unknown[0])} (allowed: {sorted(MATERIAL_NAMES)})")
            return cls((ny, nx), cell, (x0, y0, z0), dz, n_levels, off, d["material"], d["count"])
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"cannot read material stacks from {Path(path).name}: {exc}") from None

    # ------------------------------------------------------------------ editing
    def rewrite(self, cols, lev0, block) -> "MaterialStacks":
        """Overwrite level windows of some columns.

        Parameters
        ----------
        cols : array_like of int
            Column indices ``c = j nx + i`` (unique).
        lev0 : int
            First level of the window (same for all columns).
        block : numpy.ndarray
            ``(len(cols), n)`` int16: per level of ``[lev0, lev0 + n)`` the new
            material id, or -1 to keep the current one.

        Returns
        -------
        MaterialStacks
            New stacks in canonical form.
        """
        cols = np.asarray(cols, dtype=np.int64)
        block = np.ascontiguousarray(block, dtype=np.int16)
        if len(cols) == 0:
            return self.copy()
        off, m, n = _kernels()._rewrite(self.offsets, self.material, self.count, cols, int(lev0), block,
                                        self.n_levels)
        return self.with_arrays(off, m, n)

    def dense_columns(self, cols, lev0, n):
        """Materials of levels ``[lev0, lev0 + n)`` of the given columns, ``(len(cols), n)`` uint8."""
        return _kernels()._decode_window(self.offsets, self.material, self.count,
                                         np.asarray(cols, dtype=np.int64), int(lev0), int(n))


def _column_spec(column, dz):
    mats, thick = [], []
    for k, entry in enumerate(column):
        name, t = entry
        mats.append(material_id(name))
        if t is None:
            if k != len(column) - 1:
                raise ValueError("only the last entry of a material column may omit its thickness")
            thick.append(None)
        else:
            if not (np.isfinite(t) and t > 0):
                raise ValueError(f"material column thickness must be > 0 (got {t})")
            thick.append(max(1, int(round(float(t) / dz))))
    if any(m == AIR for m in mats):
        raise ValueError("a material column cannot contain air")
    return mats, thick


def _csr_from_dense_counts(counts, mat_row):
    """CSR from a ``(ncol, K)`` matrix of layer counts (bottom-up material row ``mat_row``)."""
    # Fold adjacent equal materials of the row (e.g. a bedrock band over the bedrock base).
    keep_cols = [0]
    cols = [counts[:, 0].copy()]
    for k in range(1, len(mat_row)):
        if mat_row[k] == mat_row[keep_cols[-1]]:
            cols[-1] += counts[:, k]
        else:
            keep_cols.append(k)
            cols.append(counts[:, k].copy())
    mat_row = np.asarray(mat_row)[keep_cols]
    counts = np.stack(cols, axis=1)
    ncol, K = counts.shape
    if len(set(mat_row.tolist())) != K:
        raise ValueError("a material may appear only once in a material column "
                         "(besides the bedrock base)")
    keep = counts > 0
    lens = keep.sum(axis=1)
    off = np.concatenate([[0], np.cumsum(lens)]).astype(np.uint32)
    return off, np.broadcast_to(mat_row, (ncol, K))[keep].astype(np.uint8), counts[keep].astype(np.uint16)


def _runs_from_samples(f, zs, z0, dz, n_levels, min_gap=1):
    """Solid runs (in levels) of columns sampled along their axes (``f > 0`` inside).

    Air gaps thinner than ``min_gap`` levels (the sampling step) are closed: they are
    below the resolution of the sampling, and a slit left in a cliff would fill with
    the material column's top band and drain into a visible crack.
    """
    out = []
    inside = f > 0
    for row, ins in zip(f, inside):
        runs = []
        change = np.nonzero(ins[1:] != ins[:-1])[0]
        lo = 0 if ins[0] else None
        for k in change:
            a, b = row[k], row[k + 1]
            z = zs[k] + (zs[k + 1] - zs[k]) * a / (a - b)
            lev = int(np.clip(np.rint((z - z0) / dz), 0, n_levels))
            if ins[k + 1]:
                lo = lev
            else:
                if lev > lo:
                    runs.append((lo, lev))
                lo = None
        if lo is not None and n_levels > lo:
            runs.append((lo, n_levels))
        # Quantization can make runs touch; merge them, and close sub-step gaps.
        merged = []
        for r in runs:
            if merged and r[0] < merged[-1][1] + min_gap:
                merged[-1] = (merged[-1][0], max(merged[-1][1], r[1]))
            else:
                merged.append(r)
        out.append(merged)
    return out
