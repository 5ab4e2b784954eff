"""The parameters of a :class:`~.skeletal_set.SkeletalSet`, checked: its primitive arrays and its star noise.

What a set accepts (see its ``Parameters``): a non-empty ``(N, 3)`` array of first
skeleton ends, second ends of the same shape, finite values, radii ``> 0``, cores
``>= 0``, one energy per curve (``group``), energies ``>= 0`` for ``combine = "max"``,
and a star noise whose radius cannot vanish. Each check raises ``ValueError``
naming the parameter; the scene loader reports it as an error of the node's table.
"""

from __future__ import annotations

import numpy as np

from arches_render.field.noise import fbm_range


def primitive_arrays(a, b, radius, energy, core, group, combine):
    """Checked float64 arrays ``(a, b, R, e, c, grp)`` of the primitives, sorted by group (stable).

    ``b`` ``None`` makes points (``b = a``); ``radius``, ``energy`` and ``core`` may be one
    number each; ``group`` ``None`` gives every primitive a group of its own.
    """
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or len(a) == 0:
        raise ValueError(f"a must be a non-empty (N, 3) array (got shape {a.shape})")
    n = len(a)
    b = a.copy() if b is None else np.asarray(b, dtype=np.float64)
    if b.shape != a.shape:
        raise ValueError(f"b must have the shape of a {a.shape} (got {b.shape})")
    R = _per_prim(radius, n, "radius")
    e = _per_prim(energy, n, "energy")
    c = _per_prim(core, n, "core")
    for name, v in (("a", a), ("b", b), ("radius", R), ("energy", e), ("core", c)):
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name} contains NaN or infinite values")
    if not np.all(R > 0):
        raise ValueError("radius must be > 0 for every primitive")
    if not np.all(c >= 0):
        raise ValueError("core must be >= 0 for every primitive")
    if combine not in ("sum", "max"):
        raise ValueError(f"combine must be 'sum' or 'max' (got {combine!r})")
    if combine == "max" and np.any(e < 0):
        raise ValueError("combine = 'max' needs energies >= 0")
    grp = np.arange(n) if group is None else np.asarray(group)
    if grp.shape != (n,) or not np.issubdtype(grp.dtype, np.integer) or np.any(grp < 0):
        raise ValueError("group must be (N,) non-negative integers")
    # Contiguous groups: cell lists keep index order, so members stay adjacent.
    order = np.argsort(grp, kind="stable")
    a, b, R, e, c, grp = a[order], b[order], R[order], e[order], c[order], grp[order]
    if group is not None:
        first = np.r_[True, grp[1:] != grp[:-1]]
        ge = np.repeat(e[first], np.diff(np.r_[np.flatnonzero(first), n]))
        if not np.allclose(ge, e):
            raise ValueError("primitives of one group (curve) must share their energy")
    return a, b, R, e, c, grp


def noise_params(noise):
    """Validated star-noise parameters (or None)."""
    if noise is None:
        return None
    p = dict(amplitude=0.2, wavelength=5.0, octaves=2, lacunarity=2.0, gain=0.5, seed=0)
    unknown = set(noise) - set(p)
    if unknown:
        raise ValueError(f"unknown noise parameter(s): {', '.join(sorted(unknown))}")
    p.update(noise)
    if not p["wavelength"] > 0:
        raise ValueError("noise wavelength must be > 0")
    if not 1 <= int(p["octaves"]) <= 8:
        raise ValueError("noise octaves must be in [1, 8]")
    span = float(p["amplitude"]) * fbm_range(int(p["octaves"]), float(p["gain"]))
    if not 0 <= span < 0.95:
        raise ValueError(f"noise amplitude * fbm range must be in [0, 0.95) (got {span:.3g}): "
                         "the radius would vanish")
    p["span"] = span
    return p


def _per_prim(v, n, name):
    arr = np.asarray(v, dtype=np.float64)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} must be one number or an ({n},) array (got shape {arr.shape})")
    return arr.copy()
