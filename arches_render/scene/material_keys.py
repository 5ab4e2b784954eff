"""The lookdev keys of a ``[materials.NAME]`` triplanar table: detail, strata, cavity, wetness, masks.

=============  =========================================================================
key            value
=============  =========================================================================
``detail``     table ``{octaves = 6 (1..10), wavelength = 4 m, gain = 0.6, albedo = 0.3,
               roughness = 0.3, bump = 0.15, seed = 0}`` (each optional; a preset's
               ``[detail]`` gives the defaults), or ``false`` to turn a preset's off
               (:mod:`arches_render.materials.detail`)
``strata``     table ``{node, [layer = the base layer], [palette = "sandstone"],
               [levels], [soft = 0]}``: ``node`` a resistance node (``[nodes.NAME]``
               or inline, e.g. the ``geology`` of an amplified terrain); ``palette`` a
               name of :data:`arches_render.materials.masks.PALETTES` or 2..8 colours
               (softest rock first); ``levels`` the resistances where colour ``k``
               begins (increasing, in (0, 1); default ``k / K``); ``soft`` the width of
               each step in resistance units (0: a hard step); ``blocks = {node, gate,
               lo, hi}``: where ``smoothstep(lo, hi, gate)`` the colour is that of
               resistance ``node`` instead (fallen blocks carry their cliff's beds,
               :mod:`arches_render.materials.masks`)
``cavity``     ``true`` or table ``{[node = the field's root], radius = 2 m, strength =
               0.6, damp = 0.5, samples = 3 (1..8)}``: occlusion from the field
``wetness``    table ``{level, [height = 1.5 m], [darken = 0.55], [gloss = 0.5]}``:
               wet rock near the water line ``level`` (metres)
``masks``      array of ``{layer, [kind = "node"], node, [lo = 0], [hi = 1]}``: layer
               ``layer``'s coverage times ``smoothstep(lo, hi, m)``, ``m`` the value of
               ``node`` (kind ``node``), the occlusion (``cavity``: needs ``cavity``) or
               the wetness (``wetness``: needs ``wetness`` or ``cavity``)
=============  =========================================================================

The math of each term is in :mod:`arches_render.materials.masks` and
:mod:`arches_render.materials.detail`.
"""

from __future__ import annotations

from ..materials.detail import DETAIL_KEYS, MAX_OCTAVES
from ..materials.masks import MASK_KINDS, MAX_STRATA, PALETTES
from .validate import Table

__all__ = ["FIELD_ROOT", "parse_look", "parse_masks"]

#: Stands for "the scene's field root" in a material's node roles (resolved when the BSDFs are built).
FIELD_ROOT = "<field root>"


def _switch(t: Table, name: str):
    """A key that is a table, ``true`` (a table of defaults) or ``false``: a Table, ``False`` or ``None``."""
    raw = t.raw(name, None)
    if raw is None or raw is False:
        return raw
    if raw is True:
        raw = {}
    if not isinstance(raw, dict):
        raise t.error(name, f"must be a table, true or false (got {raw!r})")
    return Table(raw, t.file, t.key(name))


def _detail(t: Table, props: dict) -> None:
    d = _switch(t, "detail")
    if d is None:
        return
    if d is False:
        props["detail_octaves"] = 0
        return
    base = {k: props.get(k, v) for k, v in DETAIL_KEYS.items()}
    props["detail_octaves"] = d.integer("octaves", base["detail_octaves"] or 6, lo=1, hi=MAX_OCTAVES)
    props["detail_wavelength"] = d.number("wavelength", base["detail_wavelength"], lo=0, lo_open=True)
    props["detail_gain"] = d.number("gain", base["detail_gain"], lo=0.0, hi=1.0)
    props["detail_albedo"] = d.number("albedo", base["detail_albedo"], lo=0.0, hi=1.0)
    props["detail_roughness"] = d.number("roughness", base["detail_roughness"], lo=0.0, hi=1.0)
    props["detail_bump"] = d.number("bump", base["detail_bump"], lo=0.0, hi=4.0)
    props["detail_seed"] = d.integer("seed", base["detail_seed"], lo=0, hi=2 ** 31 - 1)
    d.finish()


def _palette(s: Table):
    raw = s.raw("palette", "sandstone")
    if isinstance(raw, str):
        if raw not in PALETTES:
            raise s.error("palette", f"must be one of {', '.join(sorted(PALETTES))} or a list of colours "
                                     f"(got {raw!r})")
        return [list(c) for c in PALETTES[raw]]
    ok = (isinstance(raw, list) and 2 <= len(raw) <= MAX_STRATA
          and all(isinstance(c, list) and len(c) == 3
                  and all(isinstance(x, (int, float)) and not isinstance(x, bool) and 0 <= x <= 1 for x in c)
                  for c in raw))
    if not ok:
        raise s.error("palette", f"must be a palette name or 2..{MAX_STRATA} colours [r, g, b] in [0, 1] "
                                 f"(got {raw!r})")
    return [[float(x) for x in c] for c in raw]


def _strata(t: Table, builder, layer_names, props, nodes) -> None:
    s = t.table("strata", None)
    if s is None:
        return
    nodes["strata"] = builder.build(s.raw("node"), s, "node")
    layer = s.string("layer", layer_names[0], choices=set(layer_names))
    colours = _palette(s)
    count = len(colours)
    default = [k / count for k in range(1, count)]
    levels = s.raw("levels", default)
    if (not isinstance(levels, list) or len(levels) != count - 1
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and 0 < x < 1 for x in levels)
            or any(b <= a for a, b in zip(levels, levels[1:]))):
        raise s.error("levels", f"must be {count - 1} increasing resistances in (0, 1), one per colour after "
                                f"the first (got {levels!r})")
    props.update(strata_count=count, strata_layer=layer_names.index(layer),
                 strata_soft=s.number("soft", 0.0, lo=0.0, hi=1.0))
    for k, c in enumerate(colours):
        props[f"strata{k}_color"] = c
    for k, lv in enumerate(levels, start=1):
        props[f"strata{k}_level"] = float(lv)
    b = s.table("blocks", None)
    if b is not None:
        nodes["strata_blocks"] = builder.build(b.raw("node"), b, "node")
        nodes["strata_blocks_gate"] = builder.build(b.raw("gate"), b, "gate")
        lo, hi = b.number("lo"), b.number("hi")
        if lo == hi:
            raise b.error("hi", f"must differ from lo ({lo})")
        props.update(strata_blocks=True, strata_blocks_lo=lo, strata_blocks_hi=hi)
        b.finish()
    s.finish()


def _cavity(t: Table, builder, props, nodes) -> None:
    c = _switch(t, "cavity")
    if not c:
        return
    nodes["cavity"] = builder.build(c.raw("node"), c, "node") if c.has("node") else FIELD_ROOT
    props.update(cavity=True, cavity_radius=c.number("radius", 2.0, lo=0, lo_open=True),
                 cavity_strength=c.number("strength", 0.6, lo=0.0, hi=1.0),
                 cavity_damp=c.number("damp", 0.5, lo=0.0, hi=1.0),
                 cavity_samples=c.integer("samples", 3, lo=1, hi=8))
    c.finish()


def _wetness(t: Table, props) -> None:
    w = t.table("wetness", None)
    if w is None:
        return
    props.update(wetness=True, wet_level=w.number("level"),
                 wet_height=w.number("height", 1.5, lo=0, lo_open=True),
                 wet_darken=w.number("darken", 0.55, lo=0.0, hi=1.0),
                 wet_gloss=w.number("gloss", 0.5, lo=0.0, hi=1.0))
    w.finish()


def parse_look(t: Table, builder, layer_names, props: dict) -> dict:
    """Read ``detail``, ``strata``, ``cavity`` and ``wetness`` of a triplanar material table.

    Parameters
    ----------
    t : Table
        The ``[materials.NAME]`` table.
    builder : NodeBuilder
        Builds the nodes the keys name.
    layer_names : list of str
        The material's layers, base first.
    props : dict
        The plugin dictionary (from the preset); updated in place.

    Returns
    -------
    dict
        ``{role: node}`` for the roles ``strata`` and ``cavity`` present
        (:data:`FIELD_ROOT` for the scene's field).

    Raises
    ------
    SceneError
        On invalid values (naming file, key and range).
    """
    nodes = {}
    _detail(t, props)
    _strata(t, builder, layer_names, props, nodes)
    _cavity(t, builder, props, nodes)
    _wetness(t, props)
    return nodes


def parse_masks(t: Table, builder, layer_names, props: dict) -> list:
    """The ``masks`` array: ``[(layer index, node or None, lo, hi, kind)]`` (see the module docstring)."""
    masks = []
    for m in t.tables("masks"):
        layer = m.string("layer", choices=set(layer_names[1:]))
        kind = m.string("kind", "node", choices=set(MASK_KINDS))
        if kind == "node":
            node = builder.build(m.raw("node"), m, "node")
        else:
            node = None
            needs = {"cavity": ("cavity",), "wetness": ("wetness", "cavity")}[kind]
            if not any(props.get(k) for k in needs):
                raise m.error("kind", f"a '{kind}' mask needs the material's {' or '.join(needs)} key")
        lo, hi = m.number("lo", 0.0), m.number("hi", 1.0)
        if lo == hi:
            raise m.error("hi", f"must differ from lo ({lo})")
        m.finish()
        masks.append((layer_names.index(layer), node, lo, hi, kind))
    return masks
