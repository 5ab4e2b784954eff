"""Bedrock sculpting with a point primitive (Peytavie et al. 2009, section 4.1, figures 9-10).

A target vertex ``v`` is projected onto the surface ``f = 0`` of the convolution
field ``f`` (:func:`~.convolution_surface.paper_field`, in ``[-1, 1]``); ``n`` is the
outward normal there. A point primitive of radius ``R`` with the potential

    g(r) = (1 - (r / R)^2)^2  for r < R,  0 otherwise,

is centred at ``c = v - delta n`` (adding: slightly inside) or ``c = v + delta n``
(carving: slightly outside), ``0 <= delta <= R`` with ``delta = R / 2`` by default
("works well for smoothly sculpting the surface"). The modified field is
``f' = f + g(|p - c|)`` (add) or ``f' = f - g`` (carve), and the stacks whose axis
crosses the ball are re-layered along their axis by the sign of ``f'``: air
becomes ``material`` where ``f' >= 0`` (add), any solid becomes air where ``f' < 0``
(carve). Finally the granular layers are stabilized (step 5).

Outward normal: ``f > 0`` inside, so ``n = -grad f / |grad f|`` (the paper's
``grad f / |grad f|`` with its own orientation).
"""

from __future__ import annotations

import numpy as np

from .convolution_surface import paper_field
from .editing import Region, axis_mask, falloff
from .material_stacks import AIR, SOLID, MaterialStacks, material_id


def project_to_surface(stacks: MaterialStacks, v, sigma=None, iterations=8):
    """Project ``v`` onto ``f = 0``; returns ``(point, outward unit normal)``.

    Far from matter the field is flat, so ``v`` first moves along its stack axis to
    the nearest crossing (bisection), then Newton steps refine it. Raises
    ``ValueError`` when the axis meets no surface, so a tool aimed at empty sky fails
    loudly.
    """
    sigma = 0.5 * stacks.cell if sigma is None else sigma
    p = np.asarray(v, dtype=np.float64).reshape(3).copy()
    h = 0.25 * sigma
    E = np.eye(3) * h

    def grad(q):
        pts = np.concatenate([q + E, q - E])
        vals = paper_field(stacks, pts, sigma)
        return (vals[:3] - vals[3:]) / (2 * h)

    # The field is flat farther than sigma from matter: first find the surface along
    # the stack's axis through v (down from air, up from inside), as section 4.1 does.
    z0, z1 = stacks.z_range
    f0 = float(paper_field(stacks, p[None], sigma)[0])
    if abs(f0) >= 1.0 - 1e-9:
        zs = np.arange(p[2], z0 - sigma, -0.5 * sigma) if f0 < 0 else np.arange(p[2], z1 + sigma, 0.5 * sigma)
        pts = np.repeat(p[None], len(zs), axis=0)
        pts[:, 2] = zs
        f = paper_field(stacks, pts, sigma)
        cross = np.nonzero(np.sign(f) != np.sign(f0))[0]
        if len(cross) == 0:
            raise ValueError(f"no surface near {list(map(float, v))}: nothing above or below it "
                             "(aim the tool at the terrain)")
        a, b = zs[cross[0] - 1], zs[cross[0]]
        for _ in range(40):
            mid = 0.5 * (a + b)
            q = p.copy()
            q[2] = mid
            if np.sign(paper_field(stacks, q[None], sigma)[0]) == np.sign(f0):
                a = mid
            else:
                b = mid
        p[2] = 0.5 * (a + b)
    for _ in range(iterations):
        f = float(paper_field(stacks, p[None], sigma)[0])
        g = grad(p)
        g2 = float(g @ g)
        if g2 < 1e-12:
            raise ValueError(f"no surface near {list(map(float, v))}: the field is flat there "
                             "(aim the tool at the terrain)")
        step = f / g2 * g
        # Newton steps of at most a kernel size: the field is only C0.
        n = np.linalg.norm(step)
        if n > sigma:
            step *= sigma / n
        p = p - step
        if abs(f) < 1e-4:
            break
    g = grad(p)
    return p, -g / max(np.linalg.norm(g), 1e-12)


def sculpt(stacks: MaterialStacks, at, radius, mode="add", delta=None, material="bedrock",
           sigma=None):
    """Add or carve material around a surface point (section 4.1).

    Parameters
    ----------
    stacks : MaterialStacks
    at : sequence of 3 floats
        The target vertex ``v`` (projected onto the surface first).
    radius : float
        ``R`` of the point primitive, in metres (> 0).
    mode : {'add', 'remove'}
    delta : float, optional
        Offset ``delta`` of the centre along the normal, in ``[0, R]``; default ``R / 2``.
    material : str
        Material added (``mode='add'``).
    sigma : float, optional
        Kernel half-side of the field (default half the cell size).

    Returns
    -------
    MaterialStacks
        The edited stacks (not yet stabilized; see :func:`~.operations.apply_operations`).
    """
    if mode not in ("add", "remove"):
        raise ValueError(f"sculpt mode must be 'add' or 'remove' (got {mode!r})")
    R = float(radius)
    if not R > 0:
        raise ValueError(f"sculpt radius must be > 0 (got {radius})")
    delta = R / 2 if delta is None else float(delta)
    if not 0.0 <= delta <= R:
        raise ValueError(f"sculpt delta must be in [0, R] = [0, {R:g}] (got {delta:g})")
    mat = material_id(material)
    if mat == AIR:
        raise ValueError("sculpt material cannot be air (use mode = 'remove')")
    v, n = project_to_surface(stacks, at, sigma)
    c = v - delta * n if mode == "add" else v + delta * n
    region = Region(stacks, c - R, c + R)
    if region.empty:
        return stacks.copy()

    def inside_fn(P):
        g = falloff(np.linalg.norm(P - c, axis=-1), R)
        near = g > 0
        f = np.full(len(P), -1.0)
        f[near] = paper_field(stacks, P[near], sigma)
        # add: f + g >= 0 (new matter); remove: f - g < 0 (carved) -- both only within R.
        return near & ((f + g >= 0) if mode == "add" else (f - g < 0))

    inside = axis_mask(stacks, region, inside_fn)
    current = stacks.dense_columns(region.cols, region.lev0, region.n)
    block = np.full(inside.shape, -1, dtype=np.int16)
    if mode == "add":
        block[inside & (current == AIR)] = mat
    else:
        block[inside & np.isin(current, SOLID)] = AIR
    return stacks.rewrite(region.cols, region.lev0, block)
