"""The layers of a ``triplanar`` material (:mod:`.triplanar`): their Python description
(:class:`Layer`), their checks, and the flattened plugin dictionary Mitsuba loads.

Each layer ``i`` becomes the plugin properties ``layer{i}_<field>``; the plugin reads them
back (:class:`~.triplanar.TriplanarBSDF`) with the same names, defaults and checks.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields

from .detail import DETAIL_KEYS
from .textures import TILINGS

__all__ = ["MAX_LAYERS", "Layer", "triplanar_dict", "LAYER_FLOATS", "LAYER_OTHER", "GLOBAL_PROPS", "SPACES",
           "layer_count", "check_layer_values", "finite", "colour"]

MAX_LAYERS = 8
# Stand-in for an unbounded rule: finite so that ``bound - x`` never meets
# ``inf - inf`` in the coverage ramps, yet far beyond any terrain.
UNBOUNDED = 1e30

# Per-layer property suffixes and their defaults (the rule defaults always hold).
LAYER_FLOATS = {
    "roughness": 0.0, "scale": 1.0,
    "height_min": -math.inf, "height_max": math.inf, "height_soft": 0.0,
    "slope_min": -math.inf, "slope_max": math.inf, "slope_soft": 0.0,
    "coverage": 1.0,
}
LAYER_OTHER = {"texture": "", "tint": (1.0, 1.0, 1.0), "srgb": True, "normalize": True,
               "name": "", "tiling": "histogram"}
GLOBAL_PROPS = {"layer_count", "sharpness", "space", "pixel_spread", *DETAIL_KEYS}
LAYER_KEY = re.compile(r"layer(\d+)_")
SPACES = ("world", "object")


@dataclass
class Layer:
    """One paint layer of a :class:`~.triplanar.TriplanarBSDF` (Python side of the flattened properties).

    Parameters
    ----------
    texture : str
        PNG file name inside ``materials/textures/`` or an absolute path;
        ``''`` for a constant layer.
    tint : tuple of 3 floats
        Linear RGB multiplying the texture. With ``normalize`` it is the
        layer's mean albedo.
    roughness : float
        Oren–Nayar ``sigma`` in radians, in ``[0, 1]``; 0 is Lambert.
    scale : float
        Metres per texture repeat (> 0).
    height_min, height_max, height_soft : float
        Full coverage for ``height_min <= p.z <= height_max``, fading to 0
        over ``height_soft`` metres outside (smoothstep).
    slope_min, slope_max, slope_soft : float
        The same in degrees of the angle between ``n`` and ``+Z``.
    coverage : float
        Overall coverage multiplier in ``[0, 1]``.

        The base layer (index 0) is always fully covered: its rules are ignored.
    srgb : bool
        Decode the texture from sRGB (colour); ``False`` for linear data.
    normalize : bool
        Divide the texture by its mean luminance, so ``tint`` sets the mean.
    name : str
        Label for presets, overrides and AOVs.
    tiling : str
        ``'histogram'`` (random tiles, histogram-preserving blend; the default),
        ``'bands'`` (tiles offset along u only, for banded textures) or ``'repeat'``
        (the plain repeat, which shows its period).
    """

    texture: str = ""
    tint: tuple = (1.0, 1.0, 1.0)
    roughness: float = 0.0
    scale: float = 1.0
    height_min: float = -math.inf
    height_max: float = math.inf
    height_soft: float = 0.0
    slope_min: float = -math.inf
    slope_max: float = math.inf
    slope_soft: float = 0.0
    coverage: float = 1.0
    srgb: bool = True
    normalize: bool = True
    name: str = ""
    tiling: str = "histogram"

    def __post_init__(self):
        self.tint = tuple(float(c) for c in self.tint)
        if len(self.tint) != 3:
            raise ValueError(f"Layer '{self.name}': tint needs 3 values, got {len(self.tint)}")
        for key in LAYER_FLOATS:
            setattr(self, key, float(getattr(self, key)))
        check_layer_values(self.name or "?", self.roughness, self.scale, self.coverage,
                            self.height_soft, self.slope_soft)
        if self.tiling not in TILINGS:
            raise ValueError(f"Layer '{self.name}': tiling '{self.tiling}' is not one of {', '.join(TILINGS)}")


def check_layer_values(label, roughness, scale, coverage, height_soft, slope_soft):
    """Raise ``ValueError`` naming layer ``label`` when a value is out of its range."""
    if not 0.0 <= roughness <= 1.0:
        raise ValueError(f"layer {label}: roughness {roughness} is outside [0, 1]")
    if not scale > 0.0:
        raise ValueError(f"layer {label}: scale {scale} must be > 0 (metres per repeat)")
    if not 0.0 <= coverage <= 1.0:
        raise ValueError(f"layer {label}: coverage {coverage} is outside [0, 1]")
    if height_soft < 0.0 or slope_soft < 0.0:
        raise ValueError(f"layer {label}: height_soft/slope_soft must be >= 0")


def triplanar_dict(layers, sharpness: float = 8.0, space: str = "world", **extra) -> dict:
    """Flattened plugin dictionary of a triplanar material for :func:`mitsuba.load_dict`.

    Parameters
    ----------
    layers : sequence of Layer
        Bottom (base) layer first; at most :data:`MAX_LAYERS`.
    sharpness : float
        Exponent of the projection blend (8 in the Arches paper).
    space : str
        ``'world'`` or ``'object'`` (positions from the ``vertex_objp`` mesh attribute).
    **extra
        Further plugin properties: ``detail_*``, ``strata_*``, ``cavity*``,
        ``wet*``, ``pixel_spread`` (see the module docstring).

    Returns
    -------
    dict
        ``{'type': 'triplanar', 'layer_count': n, 'layer0_tint': [...], ...}``.

    Raises
    ------
    ValueError
        On an empty or too long layer list or an unknown space.
    """
    layers = list(layers)
    if not 1 <= len(layers) <= MAX_LAYERS:
        raise ValueError(f"triplanar: {len(layers)} layers given, allowed 1..{MAX_LAYERS}")
    if space not in SPACES:
        raise ValueError(f"triplanar: unknown space '{space}', allowed: {', '.join(SPACES)}")
    d = {"type": "triplanar", "layer_count": len(layers), "sharpness": float(sharpness),
         "space": space, **extra}
    for i, layer in enumerate(layers):
        for f in fields(Layer):
            value = getattr(layer, f.name)
            d[f"layer{i}_{f.name}"] = list(value) if f.name == "tint" else value
    return d


def finite(x: float) -> float:
    """``x`` clamped to ``[-UNBOUNDED, UNBOUNDED]`` (an unbounded rule made finite)."""
    return float(min(max(x, -UNBOUNDED), UNBOUNDED))


def colour(value, key):
    """Three floats from ``value`` (a scalar is grey); ``key`` names it in the error."""
    try:
        c = [float(v) for v in value]
    except TypeError:
        c = [float(value)] * 3
    if len(c) != 3:
        raise ValueError(f"triplanar: {key} needs 3 values, got {len(c)}")
    return c


def layer_count(props, look_keys) -> int:
    """The layer count of the plugin properties ``props`` (``layer_count``, else the highest
    layer index named), after checking that every property name is known.

    Parameters
    ----------
    props : mi.Properties
    look_keys : callable
        ``look_keys(names)``: the names of the look's terms (strata, cavity, wetness).

    Returns
    -------
    int

    Raises
    ------
    ValueError
        On a count outside ``1..MAX_LAYERS`` or an unknown property.
    """
    names = set(props.keys())
    indices = [int(m.group(1)) for m in map(LAYER_KEY.match, names) if m]
    count = int(props.get("layer_count", 1 + max(indices, default=0)))
    if not 1 <= count <= MAX_LAYERS:
        raise ValueError(f"triplanar: layer_count {count} is outside 1..{MAX_LAYERS}")
    allowed = set(GLOBAL_PROPS) | look_keys(names) | {
        f"layer{i}_{k}" for i in range(count) for k in (*LAYER_FLOATS, *LAYER_OTHER)}
    unknown = sorted(names - allowed)
    if unknown:
        raise ValueError(f"triplanar: unknown properties {unknown}; per layer i < {count}: "
                         f"layer{{i}}_{{{', '.join((*LAYER_FLOATS, *LAYER_OTHER))}}}, "
                         f"global: {', '.join(sorted(GLOBAL_PROPS))}, strata*, cavity*, wet*")
    return count
