"""Scene-file node types of terrain amplification (Paris et al. 2019).

Merged into the core node types by :func:`arches_render.scene.nodes.node_types`.
Lengths are metres; ``[ ]`` marks an optional key and its default. Arrays of
primitives come from ``file = "x.npz"`` (relative to the scene file, arrays as in
:data:`.skeletal_files.NPZ_KEYS`, written by :func:`.skeletal_files.save_npz` or
``numpy.savez``; no pickles) or inline keys of the same names.

=======================  ==================================================================
type                     keys
=======================  ==================================================================
implicit_heightfield     the keys of ``heightfield`` (extent, [base], source = "fbm" |
                         "file", ...) plus [R = 4 cells, <= side/4] (falloff), [T = R/2]
                         (threshold, in [R/3, 2R]), [bumps] (table: file (.npz with
                         center (N,2), radius, height) or inline center, radius,
                         height), [amplification] (table: amplitude, wavelength,
                         [octaves = 4], [lacunarity = 2], [gain = 0.5], [seed = 0],
                         [border = 0], [taper = 0]: fBm faded out within border +
                         taper metres of the tile's edge)
skeletal_set             file (.npz) or inline a (N x 3), [b = a], radius, [energy = 1],
                         [core = 0], [group]; [combine = "sum" | "max"],
                         [threshold = 0], [cell_size], [noise] (table: [amplitude =
                         0.2], [wavelength = 5], [octaves = 2], [lacunarity = 2],
                         [gain = 0.5], [seed = 0]: anisotropic star noise)
sum                      children (>= 1): the paper's blend f_A + f_B
local_warp               child, control (node: warp weight clamp(f_D, 0, 1)), [amplitude = 1],
                         [wavelength = 1], [octaves = 3], [lacunarity], [gain], [seed]
erosion                  child, field (erosion field f_D: a skeletal_set), resistance
                         (a resistance_* node): f - f_D (1 - rho)
resistance_turbulence    wavelength, [amplitude = 0.5], [offset = 0.5], [octaves = 4],
                         [lacunarity = 2], [gain = 0.5], [seed = 0], [strata = true]
resistance_plane         point, normal, R > 0, [weight = 1]
resistance_strata        spacing, R (<= spacing/2), [weight = 1], [normal = +Z], [phase = 0]
resistance_skeleton      a, [b = a], R > 0, [weight = 1]
resistance_constant      value
resistance_blend         children (resistance nodes): sum
resistance_fold          child, amplitude, [wavelength = 1], [octaves = 3], [lacunarity],
                         [gain], [seed]
resistance_fault         child, point, normal, slip (3 numbers), [width = 1] (> 0)
=======================  ==================================================================
"""

from __future__ import annotations

import numpy as np

from arches_render.scene import nodes as core
from arches_render.scene.array_files import Spec, read_arrays
from arches_render.scene.paths import scene_file
from arches_render.scene.validate import Table

from . import geology as G
from .erosion_node import Erosion
from .implicit_heightfield import ImplicitHeightfield
from .operators import LocalWarp, Sum
from .skeletal_files import NPZ_KEYS, load_npz
from .skeletal_set import SkeletalSet

#: The arrays of a ``bumps`` file (centres, radii, heights of the heightfield's bumps).
BUMP_SPECS = {"center": Spec(("n", 2)), "radius": Spec(("n",), scalar=True, lo=0.0, lo_open=True),
              "height": Spec(("n",), scalar=True)}


def _arrays(t: Table, ctx, names, required, allowed_file_keys=None):
    """Arrays from ``file`` (.npz) or inline keys; errors name the key."""
    if t.has("file"):
        path = scene_file(t, "file", (".npz",), ctx.base_dir, what="primitive file")
        try:
            data = load_npz(path) if allowed_file_keys is None else read_arrays(path, BUMP_SPECS, "bumps")
        except ValueError as exc:
            raise t.error("file", f"cannot read primitive arrays from {path.name}: {exc}") from None
        return data
    data = {}
    for name in names:
        if name in required or t.has(name):
            raw = t.raw(name)
            try:
                arr = np.asarray(raw, dtype=np.float64)
            except (TypeError, ValueError):
                raise t.error(name, f"must be a number or an array of numbers (got {raw!r})") from None
            data[name] = arr
    return data


def _noise_table(t: Table, name):
    sub = t.table(name, None)
    if sub is None:
        return None
    out = dict(amplitude=sub.number("amplitude", 0.2, lo=0.0),
               wavelength=sub.number("wavelength", 5.0, lo=0, lo_open=True),
               octaves=sub.integer("octaves", 2, lo=1, hi=8),
               lacunarity=sub.number("lacunarity", 2.0, lo=1.0, hi=4.0),
               gain=sub.number("gain", 0.5, lo=0.0, hi=1.0),
               seed=sub.integer("seed", 0, lo=0, hi=2 ** 32 - 1))
    sub.finish()
    return out


def _skeletal_set(t: Table, ctx):
    data = _arrays(t, ctx, NPZ_KEYS, ("a", "radius"))
    if "group" in data:
        g = data["group"]
        if not np.all(np.isfinite(g)) or not np.all(g == np.round(g)):
            raise t.error("group", "must hold integers")
        data["group"] = g.astype(np.int64)
    try:
        return SkeletalSet(data["a"], data.get("b"), data["radius"], data.get("energy", 1.0),
                           data.get("core", 0.0), data.get("group"), noise=_noise_table(t, "noise"),
                           combine=t.string("combine", "sum", choices={"sum", "max"}),
                           threshold=t.number("threshold", 0.0),
                           cell_size=t.number("cell_size", None, lo=0, lo_open=True))
    except ValueError as exc:
        raise t.error("file" if t.has("file") else "a", str(exc)) from None


def _implicit_heightfield(t: Table, ctx):
    hf = core.heightfield_node(t, ctx)  # the core keys: extent, source, file or fbm, base
    R = t.number("R", None, lo=0, lo_open=True)
    T = t.number("T", None, lo=0, lo_open=True)
    bumps = None
    sub = t.table("bumps", None)
    if sub is not None:
        bumps = _arrays(sub, ctx, ("center", "radius", "height"), ("center", "radius", "height"),
                        allowed_file_keys=True)
        sub.finish()
    amp = None
    sub = t.table("amplification", None)
    if sub is not None:
        amp = core.fbm_args(sub)
        amp.update(border=sub.number("border", 0.0, lo=0.0), taper=sub.number("taper", 0.0, lo=0.0))
        sub.finish()
    try:
        return ImplicitHeightfield(hf.heights_np, hf.extent, R=R, T=T, base=t.data.get("base"),
                                   bumps=bumps, amplification=amp)
    except ValueError as exc:
        msg = str(exc)
        key = ("T" if msg.startswith("threshold T") else "R" if msg.startswith("R ") or msg.startswith("R =")
               else "base" if msg.startswith("base") else "bumps" if "bump" in msg or "radius" in msg
               else "amplification" if "amplification" in msg else "extent")
        raise t.error(key, msg) from None


def children(t, ctx):
    return core.children(t, ctx, 1)


NODE_TYPES = {
    "implicit_heightfield": _implicit_heightfield,
    "skeletal_set": _skeletal_set,
    "sum": lambda t, c: Sum(*children(t, c)),
    "local_warp": lambda t, c: LocalWarp(core.child(t, c), c.build(t.raw("control"), t, "control"),
                                         **core.fbm_args(t, octaves=3)),
    "erosion": lambda t, c: Erosion(core.child(t, c), c.build(t.raw("field"), t, "field"),
                                    c.build(t.raw("resistance"), t, "resistance")),
    "resistance_turbulence": lambda t, c: G.Turbulence(
        t.number("wavelength", lo=0, lo_open=True), t.number("amplitude", 0.5), t.number("offset", 0.5),
        t.integer("octaves", 4, lo=1, hi=12), t.number("lacunarity", 2.0, lo=1.0, hi=4.0),
        t.number("gain", 0.5, lo=0.0, hi=1.0), t.integer("seed", 0, lo=0, hi=2 ** 32 - 1),
        t.boolean("strata", True)),
    "resistance_plane": lambda t, c: G.StrataPlane(t.vector("point"), t.vector("normal", nonzero=True),
                                                   t.number("R", lo=0, lo_open=True), t.number("weight", 1.0)),
    "resistance_strata": lambda t, c: G.Strata(t.number("spacing", lo=0, lo_open=True),
                                               t.number("R", lo=0, lo_open=True), t.number("weight", 1.0),
                                               t.vector("normal", default=[0.0, 0.0, 1.0], nonzero=True),
                                               t.number("phase", 0.0)),
    "resistance_skeleton": lambda t, c: G.LocalSkeleton(t.vector("a"), t.vector("b", default=None),
                                                        t.number("R", lo=0, lo_open=True),
                                                        t.number("weight", 1.0)),
    "resistance_constant": lambda t, c: G.Constant(t.number("value")),
    "resistance_blend": lambda t, c: G.Blend(*children(t, c)),
    "resistance_fold": lambda t, c: G.Fold(core.child(t, c), t.number("amplitude"),
                                           **{k: v for k, v in core.fbm_args(t, octaves=3).items()
                                              if k != "amplitude"}),
    "resistance_fault": lambda t, c: G.Fault(core.child(t, c), t.vector("point"),
                                             t.vector("normal", nonzero=True), t.vector("slip"),
                                             t.number("width", 1.0, lo=0, lo_open=True)),
}
