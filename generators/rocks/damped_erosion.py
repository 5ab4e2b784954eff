"""Damped spheroidal erosion of the voxel rock volumes (Peytavie et al. 2009, section 5).

Damping. Every contact point ``c_ij`` of a rock has a compactly supported
damping function of ``r = |p - c_ij|``::

    omega_ij(r) = 0              r < a
                  (r - a)/(b - a)  a <= r < b
                  1              otherwise

and the rock's damping field is ``omega(p) = min_ij omega_ij(p)`` over its
contact points, so no erosion happens within ``a`` of a contact. The periodic
tile of Arches (section 5) uses a Gaussian resistance instead,
``rho_ij(p) = exp(-|p - c_ij|^2 / r^2)`` with the Poisson radius ``r``; its
damping is ``1 - max_ij rho_ij``.

Erosion. Every voxel starts with ``rho = 1``. Each iteration, a voxel at the
surface of its rock (sharing a face with an empty voxel or a voxel of another
rock) loses ``rho <- rho - epsilon(p) omega(p)``, and is empty at ``rho = 0``.
The amount follows spheroidal weathering (Beardall et al. 2007): a voxel
weathers in proportion to its exposure, the mean emptiness ``1 - rho`` of its
26 neighbours (voxels of other rocks count as empty), times a rate, so
corners (more exposed) erode faster than faces and rocks round off.
Iterations are synchronous (all voxels read the previous state).

References
----------
Peytavie A., Galin E., Grosjean J., Merillou S. (2009). Procedural generation
of rock piles using aperiodic tiling. Computer Graphics Forum 28(7).
Beardall M., Farley M., Ouderkirk D., et al. (2007). Goblins by spheroidal
weathering. Eurographics Workshop on Natural Phenomena, 7-14.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["damping_piecewise", "damping_field", "erode"]

LINEAR, GAUSSIAN = 0, 1


def damping_piecewise(r, a: float, b: float):
    """``omega_ij(r)`` of the paper: 0 inside ``a``, linear to 1 at ``b``."""
    r = np.asarray(r, dtype=np.float64)
    return np.clip((r - a) / (b - a), 0.0, 1.0)


@numba.njit(parallel=True, cache=True, nogil=True)
def _damping_kernel(labels, g0, V, start, cpts, a, b, far2, kind, period, own, out):
    for i in numba.prange(labels.shape[0]):
        for j in range(labels.shape[1]):
            for k in range(labels.shape[2]):
                l = labels[i, j, k]
                w = 1.0
                if l >= 0 and l + 1 < start.shape[0] and own[l]:
                    x = (g0[0] + i + 0.5) / V
                    y = (g0[1] + j + 0.5) / V
                    z = (g0[2] + k + 0.5) / V
                    for c in range(start[l], start[l + 1]):
                        dx = x - cpts[c, 0]
                        dy = y - cpts[c, 1]
                        dz = z - cpts[c, 2]
                        if period:
                            dx -= np.floor(dx + 0.5)
                            dy -= np.floor(dy + 0.5)
                            dz -= np.floor(dz + 0.5)
                        r2 = dx * dx + dy * dy + dz * dz
                        if r2 > far2:       # surely r >= b: omega_ij = 1, which lowers nothing
                            continue
                        if kind == 0:
                            r = np.sqrt(r2)
                            v = 0.0 if r < a else (1.0 if r >= b else (r - a) / (b - a))
                        else:
                            v = 1.0 - np.exp(-r2 / (a * a))
                        if v < w:
                            w = v
                out[i, j, k] = w


def damping_field(labels, g0, V: int, n_labels: int, pairs, points, a: float, b: float = 0.0,
                  kind: int = LINEAR, periodic: bool = False, own=None) -> np.ndarray:
    """The damping field ``omega`` of every voxel from its own rock's contact points.

    Parameters
    ----------
    labels : (nx, ny, nz) int32
        Rock label of every voxel (``-1``: none).
    g0 : (3,) int
        Global index of voxel ``[0, 0, 0]``; positions are ``(g0 + i + 0.5) / V``.
    V : int
        Voxels per unit of the contact points' coordinates.
    n_labels : int
        Number of labels.
    pairs : (P, 2) int
        Rocks of each contact point.
    points : (P, 3) float
        Contact points.
    a, b : float
        Contact and blend radii (``LINEAR``); ``a`` is the Gaussian radius for ``GAUSSIAN``.
    kind : int
        ``LINEAR`` (aperiodic tiles) or ``GAUSSIAN`` (Arches periodic tile).
    periodic : bool
        Minimum-image distances in the unit tile.
    own : (n_labels,) bool, optional
        Rocks whose voxels need the field (others get 1: they are not eroded).

    Returns
    -------
    (nx, ny, nz) float64 in [0, 1]
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    owner = np.concatenate([pairs[:, 0], pairs[:, 1]])
    pts = np.concatenate([points, points])
    order = np.argsort(owner, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=n_labels))]).astype(np.int64)
    own = np.ones(n_labels, dtype=np.bool_) if own is None else np.asarray(own, dtype=np.bool_)
    out = np.empty(labels.shape, dtype=np.float64)
    # Past b (1 + 1e-9) the correctly rounded sqrt is >= b whatever the rounding of r2 or
    # of this bound, so those contacts are skipped before the square root (LINEAR only).
    far2 = (b * (1.0 + 1e-9)) ** 2 if kind == LINEAR else np.inf
    _damping_kernel(labels, np.asarray(g0, np.int64), float(V), start, np.ascontiguousarray(pts[order]),
                    float(a), float(b), float(far2), int(kind), bool(periodic), own, out)
    return out


#: Flat-index offsets are built for the 27 voxels of a 3 x 3 x 3 block in this order
#: (di, dj, dk in -1..1, dk fastest), the order the exposure is summed in.
_CENTRE = 13


@numba.njit(cache=True, nogil=True)
def _eroding_voxels(labels, own, omega):
    """Initial ``rho`` (1 on the own rocks, 0 elsewhere) and the voxels that erosion can change.

    Those are the own voxels with ``omega > 0``: at ``omega = 0`` (a contact)
    ``rho - rate * e * 0 = rho``. Returns ``rho`` and the voxels in C order as
    ``(i, j, k)``, flat indices and their ``omega``.
    """
    lf = labels.ravel()
    of = omega.ravel()
    rho = np.zeros(labels.shape)
    rf = rho.ravel()
    n = 0
    for p in range(lf.shape[0]):
        if lf[p] >= 0 and own[lf[p]]:
            rf[p] = 1.0
            if of[p] > 0.0:
                n += 1
    cells = np.empty((n, 3), dtype=np.int64)
    flat = np.empty(n, dtype=np.int64)
    w = np.empty(n)
    _, ny, nz = labels.shape
    q = 0
    for p in range(lf.shape[0]):
        if rf[p] > 0.0 and of[p] > 0.0:
            cells[q, 0], cells[q, 1], cells[q, 2] = p // (ny * nz), (p // nz) % ny, p % nz
            flat[q] = p
            w[q] = of[p]
            q += 1
    return rho, cells, flat, w


@numba.njit(parallel=True, cache=True, nogil=True)
def _neighbourhoods(labels, cells, delta, periodic):
    """Static neighbourhood of every eroding voxel: which of its 27 neighbours share its label.

    Labels never change during erosion, so the label comparisons of every step
    are done once here (``delta``: flat offsets of the 27-block). Returns
    ``same`` (bit ``t`` set: neighbour ``t`` lies in the grid, after wrapping
    if ``periodic``, and has the voxel's label) and ``row``: ``-1`` for voxels
    whose neighbours are ``flat + delta[t]``, else the row of ``nbr`` that
    lists their (wrapped) flat neighbour indices; only voxels on the grid's
    border need a row.
    """
    nx, ny, nz = labels.shape
    n = cells.shape[0]
    same = np.zeros(n, dtype=np.int64)
    row = np.full(n, -1, dtype=np.int64)
    rows = 0
    for q in range(n):
        i, j, k = cells[q, 0], cells[q, 1], cells[q, 2]
        if not (0 < i < nx - 1 and 0 < j < ny - 1 and 0 < k < nz - 1):
            row[q] = rows
            rows += 1
    nbr = np.full((rows, 27), -1, dtype=np.int64)
    flat = labels.ravel()
    for q in numba.prange(n):
        i, j, k = cells[q, 0], cells[q, 1], cells[q, 2]
        l = labels[i, j, k]
        m = 0
        if row[q] < 0:
            p = (i * ny + j) * nz + k
            for t in range(27):
                m |= np.int64(flat[p + delta[t]] == l) << t
            same[q] = m
            continue
        t = 0
        for di in range(-1, 2):
            for dj in range(-1, 2):
                for dk in range(-1, 2):
                    a, b, c = i + di, j + dj, k + dk
                    if periodic:
                        a, b, c = a % nx, b % ny, c % nz
                    if 0 <= a < nx and 0 <= b < ny and 0 <= c < nz:
                        if labels[a, b, c] == l:
                            m |= 1 << t
                        if row[q] >= 0:
                            nbr[row[q], t] = (a * ny + b) * nz + c
                    t += 1
        same[q] = m
    return same, row, nbr


@numba.njit(parallel=True, cache=True, nogil=True)
def _erode_kernel(flat, same, row, nbr, delta, faces, omega, rate, steps, rho):
    """``steps`` synchronous erosion iterations of the voxels ``flat`` of the flat grid ``rho``.

    A voxel is at the surface when one of its 6 face neighbours is outside the
    grid, of another rock, or empty; then it loses ``rate * exposure * omega``
    with the exposure summed over its 27-block in the fixed order of ``delta``
    (the voxel's own term added then taken off), so the result is the same bits
    whatever the grid's shape or the voxel's place in it.
    """
    n = flat.shape[0]
    nxt = np.empty(n, dtype=rho.dtype)
    all_faces = 0
    for t in faces:
        all_faces |= 1 << t
    for _ in range(steps):
        for q in numba.prange(n):
            p = flat[q]
            r0 = rho[p]
            nxt[q] = r0
            if r0 <= 0.0:
                continue
            m = same[q]
            r = row[q]
            surface = (m & all_faces) != all_faces
            if not surface:
                for t in faces:
                    if rho[p + delta[t] if r < 0 else nbr[r, t]] <= 0.0:
                        surface = True
                        break
            if not surface:
                continue
            expo = 0.0
            if r < 0:
                # Branch free: an unshared neighbour reads rho * 0 = 0 (rho is finite).
                for t in range(27):
                    expo += 1.0 - rho[p + delta[t]] * float((m >> t) & 1)
            else:
                for t in range(27):
                    s = 0.0
                    if (m >> t) & 1:
                        s = rho[nbr[r, t]]
                    expo += 1.0 - s
            # The loop counted the voxel itself (1 - rho); the exposure is over its 26 neighbours.
            expo -= 1.0 - r0
            nxt[q] = max(0.0, r0 - rate * (expo / 26.0) * omega[q])
        # A serial copy: numba would fuse two parallel loops over the same range, letting
        # this write race with the reads above (a nondeterministic result).
        for q in range(n):
            rho[flat[q]] = nxt[q]


def erode(labels, own, omega, steps: int, rate: float, periodic: bool = False) -> np.ndarray:
    """Damped spheroidal erosion of the rocks marked in ``own``.

    Parameters
    ----------
    labels : (nx, ny, nz) int32
        Rock label per voxel.
    own : (n_labels,) bool
        Rocks to erode (others stay as they are and count as foreign).
    omega : (nx, ny, nz) float
        Damping field in ``[0, 1]`` (:func:`damping_field`).
    steps : int
        Number of erosion iterations (user controlled, section 5).
    rate : float
        ``epsilon`` of a fully exposed voxel per iteration.
    periodic : bool
        The grid wraps around.

    Returns
    -------
    (nx, ny, nz) float32
        Erosion state ``rho`` in ``[0, 1]`` (0: empty); 0 outside the own rocks.
    """
    labels = np.ascontiguousarray(labels)
    rho, cells, flat, w = _eroding_voxels(labels, np.asarray(own, dtype=np.bool_),
                                          np.ascontiguousarray(omega, dtype=np.float64))
    nx, ny, nz = labels.shape
    d = np.array([-1, 0, 1], dtype=np.int64)
    delta = ((d[:, None, None] * ny + d[None, :, None]) * nz + d[None, None, :]).ravel()
    faces = np.array([_CENTRE - 9, _CENTRE - 3, _CENTRE - 1, _CENTRE + 1, _CENTRE + 3, _CENTRE + 9],
                     dtype=np.int64)
    same, row, nbr = _neighbourhoods(labels, cells, delta, bool(periodic))
    _erode_kernel(flat, same, row, nbr, delta, faces, w, float(rate), int(steps), rho.reshape(-1))
    return rho.astype(np.float32)
