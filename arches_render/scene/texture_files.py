"""Image files that scenes name (layer textures, environment maps): read and checked at load time.

Mitsuba reads these images when the scene is built, and a file it cannot decode
ends the render there in a ``RuntimeError`` traceback. :func:`check_texture` reads
the image at load time through the same reader (``mitsuba.Bitmap``), so what it
accepts is exactly what the renderer will accept, and decides for every case:

=====================================  ===========================================
the file                               outcome
=====================================  ===========================================
missing, unreadable, truncated,        refused: one line naming the file, the key
not an image, CMYK JPEG, ...           and Mitsuba's reason
more than the memory available         refused with the estimate
multi-channel (not Y, YA, RGB, RGBA)   refused (a colour or greyscale image is needed)
16-bit integer samples                 converted: read at full precision as float
greyscale where colour is expected     converted: used as a grey texture (the layer's
                                       ``tint`` gives the colour)
an alpha channel                       converted: alpha ignored
=====================================  ===========================================

Every conversion is reported in one line on stderr (once per file and process),
so the user knows what the renderer made of their file.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import mitsuba as mi

from ..resources import ResourceError, check_memory

__all__ = ["check_texture", "note"]

_CHECKED: dict = {}
_NOTED: set = set()


def note(message: str) -> None:
    """Print ``arches-render: note: MESSAGE`` on stderr, once per message and process."""
    if message not in _NOTED:
        _NOTED.add(message)
        print(f"arches-render: note: {message}", file=sys.stderr, flush=True)


def check_texture(path, t, key: str, colour: bool = True) -> list[str]:
    """Check the image ``path`` named by key ``key`` of table ``t``; return the conversions made.

    Parameters
    ----------
    path : str or Path
        The image (already resolved by :func:`arches_render.scene.paths.scene_file`).
    t : arches_render.scene.validate.Table
        For the error messages (scene file and key path).
    key : str
    colour : bool
        Whether a colour image is expected (a colour layer or an environment map).

    Returns
    -------
    list of str
        The conversions (also printed, see :func:`note`); empty when none.

    Raises
    ------
    SceneError
        The file cannot be decoded, has an unsupported channel layout, or needs
        more memory than is available.
    """
    path = Path(path)
    st = os.stat(path)
    cache_key = (str(path), st.st_mtime_ns, st.st_size, bool(colour))
    if cache_key in _CHECKED:
        return _CHECKED[cache_key]
    name = path.name
    if st.st_size == 0:
        raise t.error(key, f"{name}: the image file is empty")
    try:
        bmp = mi.Bitmap(str(path))
    except Exception as exc:  # Mitsuba's readers raise RuntimeError with the reason
        reason = " ".join(str(exc).split())
        reason = reason.split("]")[-1].strip() or reason
        raise t.error(key, f"{name}: cannot read the image ({reason}); it must be a PNG, JPEG, "
                           f"OpenEXR, RGBE or PFM image with Y, YA, RGB or RGBA channels") from None
    fmt = bmp.pixel_format()
    P = mi.Bitmap.PixelFormat
    if fmt not in (P.Y, P.YA, P.RGB, P.RGBA):
        raise t.error(key, f"{name}: has pixel format {str(fmt).split('.')[-1]}; "
                           f"it must be greyscale (Y, YA) or colour (RGB, RGBA)")
    w, h, ch = bmp.width(), bmp.height(), bmp.channel_count()
    try:
        # The decoded bitmap, its float32 conversion and the texture on the device.
        check_memory(w * h * ch * (bmp.bytes_per_pixel() // ch + 8), f"the {w}x{h} image {name}")
    except ResourceError as exc:
        raise t.error(key, str(exc)) from None
    notes = []
    if bmp.component_format() == mi.Struct.Type.UInt16:
        notes.append("16-bit samples, converted to float at full precision")
    if colour and fmt in (P.Y, P.YA):
        notes.append("greyscale where colour is expected, converted: used as a grey texture "
                     "whose colour is the layer's tint")
    if fmt in (P.YA, P.RGBA):
        notes.append("alpha channel ignored")
    for n in notes:
        note(f"{path}: {n}")
    _CHECKED[cache_key] = notes
    return notes


def layer_textures(t, preset: str, overrides: dict, base_dir) -> dict:
    """The overrides of a triplanar material with every texture the scene names resolved and checked.

    A preset's own textures are bundled data (``materials/textures/``). A texture the
    scene sets (``overrides = { "rock.texture" = ... }``) is a bundled file name, or a
    path relative to the scene file that :func:`arches_render.scene.paths.scene_file`
    keeps inside the allowed folders; it is replaced by its real path and checked
    with :func:`check_texture` (colour when the layer decodes sRGB).

    Parameters
    ----------
    t : arches_render.scene.validate.Table
        The material's table (errors name ``overrides.LAYER.texture``).
    preset : str
    overrides : dict
    base_dir : str or Path
        The scene's folder.

    Returns
    -------
    dict
        ``overrides`` with ``'LAYER.texture'`` keys set to real paths.
    """
    from ..materials import presets
    from ..materials.triplanar import TEXTURE_DIR
    from .paths import scene_file
    from .validate import Table

    layers, _ = presets.preset_layers(preset, overrides)
    defaults = {layer.name: layer.texture for layer in presets.preset_layers(preset)[0]}
    out = dict(overrides)
    for layer in layers:
        name = layer.texture
        if not name or name == defaults.get(layer.name):
            continue
        if not isinstance(name, str):
            raise t.error(f"overrides.{layer.name}.texture", f"must be a string (got {name!r})")
        if "/" not in name and "\\" not in name and (TEXTURE_DIR / name).is_file():
            continue
        sub = Table({"texture": name}, t.file, t.key(f"overrides.{layer.name}"))
        path = scene_file(sub, "texture", base_dir=base_dir, what="texture")
        check_texture(path, sub, "texture", colour=bool(layer.srgb))
        out[f"{layer.name}.texture"] = str(path)
    return out
