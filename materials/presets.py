"""Named triplanar material presets, stored as TOML data in ``materials/presets/``.

A preset file holds ``description``, ``sharpness``, ``space``, an optional
``[detail]`` table (the procedural detail layer: ``octaves``, ``wavelength``,
``gain``, ``albedo``, ``roughness``, ``bump``, ``seed``; see
:mod:`~arches_render.materials.detail`) and a list of ``[[layer]]`` tables (bottom
layer first) whose keys are the fields of
:class:`~arches_render.materials.triplanar.Layer`. Overrides address a layer
by its ``name``: ``{'snow.height_min': 40.0}`` or ``{'snow': {'height_min': 40.0}}``;
a scene's ``detail`` key overrides the detail (:mod:`arches_render.scene.material_keys`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from .. import tomlfile
from .detail import DETAIL_KEYS
from .triplanar import Layer, triplanar_dict

__all__ = ["PRESET_DIR", "list_presets", "preset_layers", "preset_dict"]

PRESET_DIR = Path(__file__).resolve().parent / "presets"
_OPTIONS = {"sharpness": 8.0, "space": "world"}
_LAYER_KEYS = tuple(f.name for f in dataclasses.fields(Layer))


def list_presets() -> list[str]:
    """Names of the bundled presets.

    Returns
    -------
    list of str
        Sorted file stems of ``materials/presets/*.toml``.
    """
    return sorted(p.stem for p in PRESET_DIR.glob("*.toml"))


def _read(name: str) -> dict:
    names = list_presets()
    if name not in names:
        raise ValueError(f"unknown material preset '{name}'; allowed: {', '.join(names)}")
    path = PRESET_DIR / f"{name}.toml"
    data = tomlfile.load(path)
    extra = sorted(set(data) - {"description", "layer", "detail", *_OPTIONS})
    if extra:
        raise ValueError(f"{path}: unknown key '{extra[0]}'; allowed: description, layer, detail, "
                         f"{', '.join(_OPTIONS)}")
    bad = sorted(set(data.get("detail", {})) - {k[len("detail_"):] for k in DETAIL_KEYS})
    if bad:
        raise ValueError(f"{path}: [detail] has unknown key '{bad[0]}'; allowed: "
                         f"{', '.join(k[len('detail_'):] for k in DETAIL_KEYS)}")
    if not data.get("layer"):
        raise ValueError(f"{path}: needs at least one [[layer]] table")
    for i, table in enumerate(data["layer"]):
        bad = sorted(set(table) - set(_LAYER_KEYS))
        if bad:
            raise ValueError(f"{path}: layer {i} has unknown key '{bad[0]}'; allowed: "
                             f"{', '.join(_LAYER_KEYS)}")
    return data


def _flatten(overrides: dict) -> dict:
    flat = {}
    for key, value in overrides.items():
        if isinstance(value, dict):
            for sub, v in value.items():
                flat[f"{key}.{sub}"] = v
        else:
            flat[key] = value
    return flat


def preset_layers(name: str, overrides: dict | None = None) -> tuple[list[Layer], dict]:
    """Layers and options of a preset, with optional overrides.

    Parameters
    ----------
    name : str
        A name from :func:`list_presets`.
    overrides : dict, optional
        ``'sharpness'``, ``'space'``, and ``'<layer name>.<Layer field>'``
        keys (or ``{'<layer name>': {field: value}}``).

    Returns
    -------
    layers : list of Layer
        Bottom layer first.
    options : dict
        ``{'sharpness': float, 'space': str}`` and the preset's ``detail_*``
        properties (keyword arguments of
        :func:`~arches_render.materials.triplanar.triplanar_dict`).

    Raises
    ------
    ValueError
        Unknown preset, unknown override key, or an invalid value (the message
        names the preset and key and lists the allowed values).
    """
    data = _read(name)
    options = {k: data.get(k, d) for k, d in _OPTIONS.items()}
    tables = [dict(t) for t in data["layer"]]
    names = [t.get("name", f"layer{i}") for i, t in enumerate(tables)]
    for key, value in _flatten(overrides or {}).items():
        if key in _OPTIONS:
            options[key] = value
            continue
        layer, _, field = key.partition(".")
        if layer not in names:
            raise ValueError(f"preset '{name}': unknown override '{key}'; allowed: "
                             f"{', '.join(_OPTIONS)} or '<layer>.<field>' with layer in "
                             f"{', '.join(names)}")
        if field not in _LAYER_KEYS:
            raise ValueError(f"preset '{name}': unknown override '{key}'; allowed fields: "
                             f"{', '.join(_LAYER_KEYS)}")
        tables[names.index(layer)][field] = value
    try:
        options["sharpness"] = float(options["sharpness"])
        layers = [Layer(**t) for t in tables]
    except (TypeError, ValueError) as e:
        raise ValueError(f"preset '{name}': {e}") from None
    if options["space"] not in ("world", "object"):
        raise ValueError(f"preset '{name}': space '{options['space']}' is not one of world, object")
    for key, value in data.get("detail", {}).items():
        options[f"detail_{key}"] = value
    return layers, options


def preset_dict(name: str, overrides: dict | None = None) -> dict:
    """Plugin dictionary of a preset for :func:`mitsuba.load_dict`.

    Parameters
    ----------
    name : str
        A name from :func:`list_presets`.
    overrides : dict, optional
        As in :func:`preset_layers`.

    Returns
    -------
    dict
        ``{'type': 'triplanar', ...}``.

    Raises
    ------
    ValueError
        As in :func:`preset_layers`.
    """
    layers, options = preset_layers(name, overrides)
    return triplanar_dict(layers, **options)
