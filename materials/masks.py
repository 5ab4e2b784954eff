"""Material terms from the terrain itself: strata colours, cavity/occlusion and wetness.

Three terms of a ``triplanar`` material read the landscape at the shading point
``p`` (world space) instead of a texture. Each is enabled by its properties
(and, for the first two, by a node attached with
:meth:`~arches_render.materials.triplanar.TriplanarBSDF.set_node`), and each also
serves as a layer mask (``set_layer_mask(i, None, lo, hi, kind)`` with ``kind``
``"cavity"`` or ``"wetness"``).

Strata (``strata_count`` colours ``strata{k}_color``, role ``"strata"``)
    The geology of terrain amplification is a resistance field ``rho(p)`` in
    ``[0, 1]`` (Paris et al. 2019, Sec. 4: hard rock 1, soft rock 0). Its *layer
    function* is the stratum index

        layer(p) = #{k >= 1 : rho(p) >= level_k},   level_1 < ... < level_{K-1},

    (``strata{k}_level``, default ``k / K``), and the painted layer
    (``strata_layer``) takes colour ``k`` of the palette for ``layer(p) = k``:
    softest first. The paper's Fig. 4 shows resistant rock pale and soft rock dark,
    the convention of the bundled palettes (:data:`PALETTES`). With
    ``strata_soft = s > 0`` each step is a smoothstep over ``level_k +- s/2``
    (in resistance units) instead of a hard step. Since the erosion node ``f - f_D
    (1 - rho)`` carves soft strata deeper, the colour bands line up with the
    terrain's ledges and notches on every cliff, folds and faults included.

Strata of fallen blocks (``strata_blocks``, roles ``"strata_blocks"`` and ``"strata_blocks_gate"``)
    A block that fell from a cliff carries the beds it broke from, not the bed at
    the height where it came to rest (at the foot, the cliff's lowest bed: every
    block under a banded wall came out in that one colour). Where the gate node's
    value ``m`` is past ``strata_blocks_lo`` towards ``strata_blocks_hi`` the colour
    blends, by ``smoothstep``, to the palette colour of the ``strata_blocks`` node
    (the geology lifted into the cliff band, see
    :mod:`arches_render.generators.terrain.talus`). The gate is the bare-rock mask's
    node, evaluated once for both (the material shares equal mask nodes); the second
    resistance is evaluated only in packets holding a lane on a block.

Cavity (``cavity_radius``, role ``"cavity"``: a field, by default the scene's root)
    Ambient occlusion from the field itself, after Evans (2006) and Quilez's
    distance-field occlusion: with ``f`` positive inside matter and about a signed
    distance (metres) outside, and ``n`` the normal,

        crease  = sum_k w_k clamp((f(p + d_k n) + d_k) / d_k, 0, 1) / sum_k w_k,
        ceiling = 1 - 0.4 min(t_hit / 8R, 1)   if rock is found above, else 0,
        o = 1 - (1 - crease)(1 - ceiling),

    ``d_k = R k / K`` (``K = cavity_samples``, ``w_k = 1/k``); ``t_hit`` is where a
    short sphere-tracing march of ``2K`` steps (``max(-f, d_1/2)`` each) straight up
    from ``p + d_1 n`` meets rock (``f > -d_1/10``) within ``8R`` (rock far overhead
    occludes less than rock just above). A point in a crease
    or a narrow cave sees its normal run into rock (``crease``); a cave floor, a
    cave wall and an overhang's underside have rock straight above them
    (``ceiling``; ``z`` the up axis). The albedo is multiplied by ``1 -
    cavity_strength * o`` and the wetness raised by ``cavity_damp * o``: cave
    interiors and overhang undersides come out darker and damper. ``3K`` field
    evaluations per shading call, in one recorded loop so that the tree's code is
    emitted once.

Wetness (``wet_level``, ``wet_height``)
    ``w = 1 - smoothstep(level, level + height, p_z)`` (1 below the water line,
    fading over ``height`` metres above it), plus the cavity's dampness, clamped to
    ``[0, 1]``. Wet rock is darker and more saturated (Lekner and Dorf 1988: light
    trapped by total internal reflection in the water film): ``a_wet = Y + (a d -
    Y d)(1 + 0.5 w)`` with ``d = 1 - w (1 - wet_darken)`` and ``Y`` the luminance, and
    smoother: ``sigma_wet = sigma (1 - w (1 - wet_gloss))``.

References
----------
Paris, A. et al. (2019). Terrain amplification with implicit 3D features. ACM TOG
38(5), Sec. 4 and Fig. 4 (resistance, strata).
Evans, A. (2006). Fast approximations for global illumination on dynamic scenes.
SIGGRAPH 2006 course notes (ambient occlusion from distance fields).
Lekner, J., Dorf, M. C. (1988). Why some things are darker when wet. Applied
Optics 27(7), 1278-1280.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..field.node import evaluate

__all__ = ["PALETTES", "MASK_KINDS", "NODE_ROLES", "look_keys", "node_value", "strata_index", "strata_levels",
           "terrain_look", "Look"]

#: Named strata palettes, softest stratum first (linear RGB albedo).
PALETTES = {
    "sandstone": ((0.17, 0.085, 0.05), (0.33, 0.16, 0.085), (0.50, 0.30, 0.17), (0.62, 0.50, 0.37)),
    "limestone": ((0.30, 0.28, 0.24), (0.46, 0.43, 0.37), (0.60, 0.57, 0.50), (0.72, 0.70, 0.64)),
    "basalt": ((0.05, 0.045, 0.04), (0.09, 0.08, 0.07), (0.14, 0.12, 0.10), (0.21, 0.19, 0.16)),
    "badlands": ((0.28, 0.13, 0.08), (0.52, 0.40, 0.30), (0.36, 0.22, 0.14), (0.66, 0.58, 0.47),
                 (0.44, 0.25, 0.15)),
}
#: Layer-mask kinds besides a node's value.
MASK_KINDS = ("node", "cavity", "wetness")
#: Roles of the nodes a material reads (``set_node``).
NODE_ROLES = ("strata", "cavity", "strata_blocks", "strata_blocks_gate")
MAX_STRATA = 8

_FLOATS = {"strata_soft": 0.0, "strata_blocks_lo": 0.0, "strata_blocks_hi": 1.0, "cavity_radius": 2.0,
           "cavity_strength": 0.6, "cavity_damp": 0.5,
           "wet_level": 0.0, "wet_height": 1.5, "wet_darken": 0.55, "wet_gloss": 0.5}
_INTS = {"strata_count": 0, "strata_layer": 0, "cavity_samples": 3}
_LUMA = (0.2126, 0.7152, 0.0722)


def look_keys(props_names) -> set:
    """The property names this module reads (for the plugin's unknown-key check)."""
    keys = set(_FLOATS) | set(_INTS) | {"cavity", "wetness", "strata_blocks"}
    keys |= {k for k in props_names if k.startswith("strata") and k.endswith(("_color", "_level"))}
    return keys


def strata_index(rho, levels) -> np.ndarray:
    """The layer function ``#{k >= 1 : rho >= level_k}`` on numpy values.

    Parameters
    ----------
    rho : array_like
        Resistances (clamped to ``[0, 1]`` first).
    levels : sequence of float
        ``level_1 < ... < level_{K-1}``.

    Returns
    -------
    numpy.ndarray
        Integer stratum index in ``0 .. K-1``.
    """
    r = np.clip(np.asarray(rho, np.float64), 0.0, 1.0)
    return np.searchsorted(np.asarray(levels, np.float64), r, side="right")


def strata_levels(node, box, count: int, samples: int = 20000, seed: int = 0) -> list[float]:
    """Resistance levels that split a geology into ``count`` strata where its histogram has valleys.

    Parameters
    ----------
    node : object
        A resistance node (``eval``; clamped to ``[0, 1]``).
    box : (lo, hi)
        The volume the rock occupies (numpy 3-vectors): the terrain's extent from
        its lowest to its highest point.
    count : int
        Number of strata (>= 2).
    samples : int
        Random points evaluated.
    seed : int

    Returns
    -------
    list of float
        ``count - 1`` increasing levels in (0, 1): the multi-level Otsu thresholds of
        the sampled resistances (Liao, Chen and Chung 2001), which fall in the gaps
        between hard and soft rock, so that each colour band is one kind of rock
        rather than a slice through one; evenly spaced quantiles where the
        resistances have too few distinct values.
    """
    lo, hi = (np.asarray(v, np.float64) for v in box)
    P = np.random.default_rng(seed).uniform(lo, hi, (int(samples), 3))
    rho = np.clip(evaluate(node, P).astype(np.float64), 0.0, 1.0)
    try:
        from skimage.filters import threshold_multiotsu  # on use: skimage.filters takes 0.4 s to import
        levels = [float(v) for v in threshold_multiotsu(rho, classes=count)]
    except ValueError:  # fewer distinct values than classes
        levels = []
    if len(levels) != count - 1 or any(b <= a for a, b in zip(levels, levels[1:])):
        levels = [float(v) for v in np.quantile(rho, np.arange(1, count) / count)]
    out = [min(max(v, 1e-3), 1.0 - 1e-3) for v in levels]
    for i in range(1, len(out)):
        out[i] = max(out[i], out[i - 1] + 1e-4)  # strictly increasing, still below 1
    return out


def terrain_look(node, box, palette: str = "sandstone", geology: str = "geology", sea_level=None,
                 cavity_radius: float = 2.0) -> dict:
    """The lookdev keys of an amplified terrain's material: strata from its geology, cavity, wetness.

    What ``arches-render amplify`` writes into ``[materials.landscape]`` (see
    :mod:`arches_render.scene.material_keys` for the keys), so that every
    amplified terrain colours its rock from its own geology by default.

    Parameters
    ----------
    node : object
        The built resistance node (to place the levels).
    box : (lo, hi)
        The rock's volume (:func:`strata_levels`).
    palette : str
        A name of :data:`PALETTES`.
    geology : str
        Name of the resistance node's ``[nodes]`` table in the scene.
    sea_level : float, optional
        Water line of the wet band.
    cavity_radius : float
        Reach of the occlusion (metres), about two DEM cells.

    Returns
    -------
    dict
        ``{"strata": {...}, "cavity": {...}[, "wetness": {...}]}``.
    """
    colours = PALETTES[palette]
    look = {"strata": {"node": geology, "palette": palette,
                       "levels": strata_levels(node, box, len(colours))},
            "cavity": {"radius": float(cavity_radius)}}
    if sea_level is not None:
        look["wetness"] = {"level": float(sea_level), "height": float(cavity_radius)}
    return look


def node_value(values, node, p):
    """``node.eval(p)`` once per shading call and node (``values``: the call's cache): the
    fallen blocks' bare-rock masks and strata gate share one node, a costly blocks field."""
    if id(node) not in values:
        values[id(node)] = mi.Float(node.eval(mi.Point3f(p)))
    return values[id(node)]


def _op(v, kind=None):
    x = (kind or mi.Float)(v)
    dr.make_opaque(x)
    return x


def _smoothstep(t):
    t = dr.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


class Look:
    """The strata, cavity and wetness terms of one material (see the module docstring).

    Built from the plugin's properties by :meth:`from_props`; nodes come later
    through :meth:`set_node`.
    """

    def __init__(self, props, layer_count):
        get = props.get
        self.f = {k: _op(float(get(k, d))) for k, d in _FLOATS.items()}
        count = int(get("strata_count", 0))
        if not (count == 0 or 2 <= count <= MAX_STRATA):
            raise ValueError(f"triplanar: strata_count {count} is outside 2..{MAX_STRATA} (0: none)")
        self.strata_layer = int(get("strata_layer", 0))
        if count and not 0 <= self.strata_layer < layer_count:
            raise ValueError(f"triplanar: strata_layer {self.strata_layer} is outside 0..{layer_count - 1}")
        self.colors, self.levels = [], []
        levels = [float(get(f"strata{k}_level", k / count)) for k in range(1, count)]
        if any(b <= a for a, b in zip(levels, levels[1:])):
            raise ValueError(f"triplanar: strata levels {levels} must increase")
        for k in range(count):
            c = get(f"strata{k}_color", None)
            if c is None:
                raise ValueError(f"triplanar: strata{k}_color is missing (strata_count = {count})")
            c = [float(v) for v in c]
            if len(c) != 3 or min(c) < 0.0 or max(c) > 1.0:
                raise ValueError(f"triplanar: strata{k}_color needs 3 values in [0, 1]")
            self.colors.append(_op(c, mi.Color3f))
        self.levels = [_op(v) for v in levels]
        self.samples = int(get("cavity_samples", 3))
        if not 1 <= self.samples <= 8:
            raise ValueError(f"triplanar: cavity_samples {self.samples} is outside 1..8")
        self.cavity = bool(get("cavity", False))
        self.wetness = bool(get("wetness", False))
        if self.f["strata_soft"] < 0.0 or self.f["cavity_radius"] <= 0.0 or self.f["wet_height"] <= 0.0:
            raise ValueError("triplanar: strata_soft must be >= 0, cavity_radius and wet_height > 0")
        self.blocks = bool(get("strata_blocks", False)) and self.strata
        if self.blocks and self.f["strata_blocks_lo"] == self.f["strata_blocks_hi"]:
            raise ValueError("triplanar: strata_blocks_lo must differ from strata_blocks_hi")
        self.nodes = dict.fromkeys(NODE_ROLES)

    @property
    def strata(self) -> bool:
        return bool(self.colors)

    def set_node(self, role, node):
        if role not in NODE_ROLES:
            raise ValueError(f"triplanar: node role '{role}' is not one of {', '.join(NODE_ROLES)}")
        self.nodes[role] = node

    # ------------------------------------------------------------- terms
    def strata_color(self, p, role="strata"):
        """Palette colour of the stratum at ``p`` (``mi.Color3f``) by the node of ``role``."""
        node = self.nodes[role]
        rho = dr.clip(mi.Float(node.eval(mi.Point3f(p))), 0.0, 1.0)
        out = mi.Color3f(self.colors[0])
        soft = self.f["strata_soft"]
        for k in range(1, len(self.colors)):
            lv = self.levels[k - 1]
            step = dr.select(soft > 0.0, _smoothstep((rho - lv) * dr.rcp(dr.maximum(soft, 1e-9)) + 0.5),
                             dr.select(rho >= lv, 1.0, 0.0))
            out = out + step * (self.colors[k] - self.colors[k - 1])
        return out

    def blocks_color(self, p, tint, m):
        """The colour ``tint`` (the bed at ``p``) blended towards the bed of the fallen blocks'
        node by ``smoothstep`` of the gate value ``m`` (see the module docstring)."""
        lo, hi = self.f["strata_blocks_lo"], self.f["strata_blocks_hi"]
        g = _smoothstep((m - lo) * dr.rcp(hi - lo))
        return dr.if_stmt((mi.Point3f(p), tint, g), g > 0.0,
                          lambda q, t, g: t + g * (self.strata_color(q, "strata_blocks") - t),
                          lambda q, t, g: t, label="triplanar_blocks")

    def occlusion(self, p, n, active=True):
        """Cavity/occlusion ``o`` in ``[0, 1]`` at ``p`` with normal ``n`` (0 without a field)."""
        node = self.nodes["cavity"]
        if node is None or not self.cavity:
            return mi.Float(0.0)
        R = self.f["cavity_radius"]
        K = self.samples
        step = R * (1.0 / K)
        reach = 8.0 * R
        up = mi.Vector3f(0.0, 0.0, 1.0)
        start = p + n * step

        def body(i, crease, wsum, t, hit):
            # Iterations 0..K-1: crease samples along the normal; K..3K-1: the march upwards.
            along = i < K
            k = mi.Float(i + 1)
            d = step * k
            q = dr.select(along, p + n * d, start + up * t)
            f = mi.Float(node.eval(mi.Point3f(q)))
            w = dr.rcp(k)
            crease = dr.select(along, crease + w * dr.clip((f + d) * dr.rcp(d), 0.0, 1.0), crease)
            wsum = dr.select(along, wsum + w, wsum)
            marching = ~along & ~hit & (t < reach)
            hit |= marching & (f > -0.1 * step)
            t = dr.select(marching & ~hit, t + dr.maximum(-f, 0.5 * step), t)
            return i + 1, crease, wsum, t, hit

        zero = dr.zeros(mi.Float, dr.width(p.x))
        # Inactive lanes leave at once: packets without an active lane skip the march.
        active = mi.Bool(active)
        _, crease, wsum, t, hit = dr.while_loop(
            (mi.UInt32(0), zero, zero, zero, dr.zeros(mi.Bool, dr.width(p.x))),
            lambda i, *_: (i < 3 * K) & active, body, label="triplanar_cavity")
        crease = crease * dr.rcp(dr.maximum(wsum, 1e-6))
        # Rock far overhead occludes less than rock just above (0.6 at the reach).
        ceiling = dr.select(hit, 1.0 - 0.4 * dr.clip(t * dr.rcp(reach), 0.0, 1.0), 0.0)
        return dr.select(mi.Bool(active), 1.0 - (1.0 - crease) * (1.0 - ceiling), 0.0)

    def wet(self, p, occ):
        """Wetness ``w`` in ``[0, 1]`` at ``p`` given the occlusion ``occ``."""
        w = mi.Float(0.0)
        if self.wetness:
            w = 1.0 - _smoothstep((p.z - self.f["wet_level"]) * dr.rcp(self.f["wet_height"]))
        if self.cavity:
            w = w + self.f["cavity_damp"] * occ
        return dr.clip(w, 0.0, 1.0)

    def albedo_factor(self, a, occ, wet):
        """The albedo ``a`` (``mi.Color3f``) darkened by occlusion and wetness."""
        if self.cavity:
            a = a * (1.0 - self.f["cavity_strength"] * occ)
        if self.wetness or self.cavity:
            d = 1.0 - wet * (1.0 - self.f["wet_darken"])
            a = a * d
            y = a.x * _LUMA[0] + a.y * _LUMA[1] + a.z * _LUMA[2]
            a = dr.clip(y + (a - y) * (1.0 + 0.5 * wet), 0.0, 1.0)
        return a

    def roughness_factor(self, wet):
        """Factor on the Oren-Nayar roughness of wet rock."""
        return 1.0 - wet * (1.0 - self.f["wet_gloss"])

    @property
    def active(self) -> bool:
        """Whether any term is on (otherwise the material skips this module)."""
        return self.strata or self.cavity or self.wetness

    def traverse(self, callback):
        """Expose the opaque values (``cavity_radius``, ``strata{k}_color``, ...)."""
        for k, v in self.f.items():
            callback.put(k, v, mi.ParamFlags.NonDifferentiable)
        for k, c in enumerate(self.colors):
            callback.put(f"strata{k}_color", c, mi.ParamFlags.NonDifferentiable)
        for k, lv in enumerate(self.levels):
            callback.put(f"strata{k + 1}_level", lv, mi.ParamFlags.NonDifferentiable)

    def opaque(self):
        """Opaque values, for ``parameters_changed``."""
        return [self.f, self.colors, self.levels]
