"""Seed points ``p_k`` of the rock volumes and their anisotropic metrics.

Peytavie et al. 2009, section 3 ("Creation of seed points"): every cell
``C_ijk`` of a corner cube grid holds ``n_k`` seed points, ``1 <= n_k <= s``,
placed with a low-discrepancy sequence. Section 4: every seed carries an
ellipsoidal distance

    d_k(p) = f_k(p) / g_k,
    f_k(p) = alpha_k ((p - p_k).x)^2 + beta_k ((p - p_k).y)^2 + gamma_k ((p - p_k).z)^2,

with a uniformly random frame ``(x, y, z)``, ``g_k`` uniform in ``[1, g_max]``
(the paper uses ``g_max = 4``) and ``alpha_k, beta_k, gamma_k`` uniform in
user intervals. A larger coefficient makes the distance grow faster along its
axis, so the cell (and the rock) is *shorter* along that axis.

Randomness is counter based: a cell's seeds are a pure function of a 64-bit
key (scene seed, owner region and the cell's place in it, see
:mod:`.corner_cubes`), so the same cell gets the same seeds in every corner
cube that contains it. The low-discrepancy sequence is the 3-D Halton
sequence (bases 2, 3, 5) under a per-cell Cranley-Patterson rotation.

References
----------
Peytavie A., Galin E., Grosjean J., Merillou S. (2009). Procedural generation
of rock piles using aperiodic tiling. Computer Graphics Forum 28(7), 1801-1809.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SeedParams", "Seeds", "hash_keys", "hash_uniform", "halton", "cell_seeds"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _mix(z):
    """SplitMix64 finalizer on a uint64 array (wrapping arithmetic)."""
    z = z + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


def hash_keys(*keys) -> np.ndarray:
    """A 64-bit hash of integer keys, broadcast over arrays.

    Parameters
    ----------
    *keys : int or array_like of int
        Signed or unsigned integers; arrays broadcast together.

    Returns
    -------
    numpy.ndarray of uint64
    """
    with np.errstate(over="ignore"):
        h = np.uint64(0x2545F4914F6CDD1D)
        for k in keys:
            k = np.asarray(k)
            k = k.astype(np.int64).view(np.uint64) if k.dtype.kind == "i" else k.astype(np.uint64)
            h = _mix(h ^ k)
        return np.asarray(h, dtype=np.uint64)


def hash_uniform(h, stream: int) -> np.ndarray:
    """Uniform floats in ``[0, 1)`` from hashes ``h``, one independent stream per ``stream``."""
    with np.errstate(over="ignore"):
        z = _mix(np.asarray(h, dtype=np.uint64) ^ (np.uint64(stream + 1) * _GOLDEN))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def halton(index, base: int) -> np.ndarray:
    """Radical inverse of integer ``index`` (>= 1) in ``base``: the Halton sequence."""
    i = np.asarray(index, dtype=np.int64).copy()
    out = np.zeros(i.shape)
    f = 1.0 / base
    while np.any(i > 0):
        out += f * (i % base)
        i //= base
        f /= base
    return out


@dataclass(frozen=True)
class SeedParams:
    """Shape and density controls of the seed points (section 4).

    Parameters
    ----------
    seeds_per_cell : (int, int)
        ``n_k`` range ``[min, s]``; ``(1, 1)`` gives rocks of similar size,
        ``(1, 20)`` mixes rocks and gravel (figure 12).
    g_max : float
        ``g_k`` is uniform in ``[1, g_max]`` (the paper: 4).
    alpha, beta, gamma : (float, float)
        Intervals of the metric coefficients along the local frame axes.
    """

    seeds_per_cell: tuple = (1, 1)
    g_max: float = 4.0
    alpha: tuple = (1.0, 1.0)
    beta: tuple = (1.0, 1.0)
    gamma: tuple = (1.0, 1.0)

    def __post_init__(self):
        lo, hi = self.seeds_per_cell
        if not (1 <= lo <= hi <= 64):
            raise ValueError(f"seeds_per_cell must satisfy 1 <= min <= max <= 64 (got {lo}, {hi})")
        if not 1.0 <= self.g_max <= 16.0:
            raise ValueError(f"g_max must be in [1, 16] (got {self.g_max})")
        for name in ("alpha", "beta", "gamma"):
            a, b = getattr(self, name)
            if not 0.05 <= a <= b <= 20.0:
                raise ValueError(f"{name} must be an interval [lo, hi] with 0.05 <= lo <= hi <= 20 "
                                 f"(got [{a}, {b}])")


@dataclass
class Seeds:
    """Seed points of a set of cells, in cell units.

    Attributes
    ----------
    cell : (K, 3) int64
        Integer cell of each seed.
    offset : (K, 3) float64
        Position inside the cell, in ``[0, 1)^3``; ``p_k = cell + offset``.
    metric : (K, 6) float64
        ``M_k = (alpha x x^T + beta y y^T + gamma z z^T) / g_k`` as
        ``(xx, yy, zz, xy, xz, yz)``, so ``d_k(p) = (p - p_k)^T M_k (p - p_k)``.
    uid : (K,) uint64
        Context-free identity of the seed (tie-breaks and per-rock randomness).
    """

    cell: np.ndarray
    offset: np.ndarray
    metric: np.ndarray
    uid: np.ndarray

    def __len__(self):
        return len(self.uid)

    @property
    def position(self) -> np.ndarray:
        return self.cell + self.offset

    def take(self, idx) -> "Seeds":
        return Seeds(self.cell[idx], self.offset[idx], self.metric[idx], self.uid[idx])


def _random_frames(h) -> np.ndarray:
    """Uniformly distributed rotations (normalised Gaussian quaternions), shape (K, 3, 3)."""
    u = [hash_uniform(h, 10 + i) for i in range(4)]
    # Box-Muller: two pairs of uniforms give four independent normals.
    r1, r2 = np.sqrt(-2.0 * np.log1p(-u[0])), np.sqrt(-2.0 * np.log1p(-u[2]))
    q = np.stack([r1 * np.cos(2 * np.pi * u[1]), r1 * np.sin(2 * np.pi * u[1]),
                  r2 * np.cos(2 * np.pi * u[3]), r2 * np.sin(2 * np.pi * u[3])], axis=-1)
    q /= np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-300)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def cell_seeds(cells, keys, params: SeedParams) -> Seeds:
    """The seed points of cells, a pure function of each cell's key.

    Parameters
    ----------
    cells : (N, 3) array_like of int
        Cells (in the caller's cell coordinates) the seeds are placed in.
    keys : (N,) array_like of uint64
        Context-free key of each cell (see :func:`.corner_cubes.cell_keys`).
    params : SeedParams

    Returns
    -------
    Seeds
        Seeds ordered by cell, then by their index in the cell's sequence.

    References
    ----------
    Peytavie et al. 2009, sections 3 and 4.
    """
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    keys = np.asarray(keys, dtype=np.uint64).reshape(-1)
    lo, hi = params.seeds_per_cell
    count = lo + np.minimum((hash_uniform(keys, 0) * (hi - lo + 1)).astype(np.int64), hi - lo)
    which = np.repeat(np.arange(len(keys)), count)
    j = np.arange(len(which)) - np.repeat(np.cumsum(count) - count, count)
    kh = keys[which]
    shift = np.stack([hash_uniform(kh, 1 + a) for a in range(3)], axis=-1)
    seq = np.stack([halton(j + 1, b) for b in (2, 3, 5)], axis=-1)
    offset = np.mod(seq + shift, 1.0)
    uid = hash_keys(kh, j)
    g = 1.0 + (params.g_max - 1.0) * hash_uniform(uid, 4)
    coef = np.stack([a + (b - a) * hash_uniform(uid, 5 + i)
                     for i, (a, b) in enumerate((params.alpha, params.beta, params.gamma))], -1)
    R = _random_frames(uid)                       # columns are the local axes x, y, z
    M = np.einsum("kia,ka,kja->kij", R, coef, R) / g[:, None, None]
    metric = np.stack([M[:, 0, 0], M[:, 1, 1], M[:, 2, 2], M[:, 0, 1], M[:, 0, 2], M[:, 1, 2]], -1)
    return Seeds(cells[which], offset, metric, uid)


def anisotropic_distance(seeds: Seeds, k, points) -> np.ndarray:
    """``d_k(p)`` of seeds ``k`` at points ``p`` (cell units), broadcast (reference implementation)."""
    d = np.asarray(points, dtype=np.float64) - seeds.position[k]
    m = seeds.metric[k]
    return (m[..., 0] * d[..., 0] ** 2 + m[..., 1] * d[..., 1] ** 2 + m[..., 2] * d[..., 2] ** 2
            + 2 * (m[..., 3] * d[..., 0] * d[..., 1] + m[..., 4] * d[..., 0] * d[..., 2]
                   + m[..., 5] * d[..., 1] * d[..., 2]))
