"""Lookdev in Jupyter: a look that shows itself, a preview that refines in place, sliders.

In a notebook (``pip install -e '.[notebook]'``)::

    from arches_render import api
    look = api.load("scenes/default.toml", resolution=(320, 180), spp=16)
    look                                          # shows the last render (renders one if none)
    look.preview()                                # one image, refined pass by pass in place
    look.slider("lights.0.elevation", 0.0, 90.0)  # a slider and the image it re-renders

A :class:`~arches_render.api.Lookdev` is displayed through IPython's rich display
protocol (``_repr_png_``): the image of its last render under the scene's view
transform and exposure (``[render] view``, ``exposure``), as the PNG beside an EXR
would be. A slider moves one dotted key (:meth:`~arches_render.api.Lookdev.set`), so a
sun, a camera or a material value re-renders as a parameter edit, without compiling a
kernel (``look.compiled`` says so after each render). IPython and ipywidgets are
imported here only, when a notebook asks: nothing else of the package needs them.

References
----------
IPython rich display: https://ipython.readthedocs.io/en/stable/config/integrating.html
ipywidgets: https://ipywidgets.readthedocs.io/en/stable/
"""

from __future__ import annotations

from .imaging.colour import view_to_uint8
from .imaging.exposure import exposure_of
from .imaging.preview import png_bytes

__all__ = ["look_png", "preview", "slider"]


def look_png(look, rgb) -> bytes:
    """The PNG of a render of ``look`` under its scene's view and exposure.

    Parameters
    ----------
    look : arches_render.api.Lookdev
    rgb : numpy.ndarray
        ``(H, W, 3)`` linear Rec.709, a render of ``look``.

    Returns
    -------
    bytes
    """
    settings = look.desc.render
    return png_bytes(view_to_uint8(rgb, settings.view, exposure_of(settings, rgb)[0]))


def preview(look, spp=None):
    """Render ``look`` and show it in one notebook output that each pass refines.

    Parameters
    ----------
    look : arches_render.api.Lookdev
    spp : int, optional
        Samples per pixel (default: the look's).

    Returns
    -------
    numpy.ndarray
        The final render, ``(H, W, 3)`` linear.
    """
    from IPython.display import Image, display
    handle = None

    def show(done, rgb):
        nonlocal handle
        image = Image(data=look_png(look, rgb), format="png")
        if handle is None:
            handle = display(image, display_id=True)
        else:
            handle.update(image)

    return look.render(spp=spp, on_pass=show)


def slider(look, key: str, lo: float, hi: float, step: float | None = None):
    """A slider over one dotted key of ``look`` and the image it re-renders on release.

    Parameters
    ----------
    look : arches_render.api.Lookdev
    key : str
        A numeric key of :meth:`~arches_render.api.Lookdev.set` (``"lights.0.elevation"``).
    lo, hi : float
        The slider's range.
    step : float, optional
        Default: a hundredth of the range.

    Returns
    -------
    ipywidgets.VBox
        The ``FloatSlider`` (``children[0]``) above the ``Image`` (``children[1]``).
        Setting the slider's ``value`` from code re-renders as a drag does.
    """
    import ipywidgets as widgets
    value = float(look.get(key))
    control = widgets.FloatSlider(value=min(max(value, lo), hi), min=lo, max=hi,
                                  step=step or (hi - lo) / 100.0, description=key,
                                  continuous_update=False, style={"description_width": "initial"})
    image = widgets.Image(value=look._repr_png_(), format="png")

    def moved(change):
        look.set(key, change["new"])
        image.value = look_png(look, look.render())

    control.observe(moved, names="value")
    return widgets.VBox([control, image])
