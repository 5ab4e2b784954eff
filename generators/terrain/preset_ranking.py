"""``auto`` ranks the presets by what they make: the 3-D landforms a camera could see (issue 34).

``--preset auto`` amplifies every preset the DEM's measures allow
(:func:`.fallback.preset_candidates`) and measures what each made, as the close
shots measure landforms (:mod:`.shots`): over the fullest landform-sized cells of
its primitives (:func:`.shots.landform_cells`), the *visible 3-D volume*
(:func:`.shots.landform_volume` with ``reach`` one landform size): air under matter
(caves, arches, overhangs, undercuts) within a landform size of open sky, matter
standing above the plain terrain (hoodoos), and a quarter of the ground only
lowered. A tunnel network deep in the rock counts only its first landform size
inside each cave mouth: the karst lattice of a 10 m canyon DEM holds 1.05e7 m^3 of
air under rock, of which 5.7e5 m^3 can be looked into.

Order
    Volumes of different landforms do not compare: strata undercut whole
    escarpments while the sea cuts notches, so on a synthetic coast at 50 m cells
    ``strata`` made 1.7e7 m^3 against the sea's 5.7e5 m^3, and on the Salish Sea
    DEM karst tunnels outweighed the coast. The preset the DEM's measures chose
    (:func:`.preset_choice.choose_preset`: sea cliffs on a coast) therefore stays
    first while it makes at least :data:`MIN_LANDFORMS` landforms' worth, ``F^3``
    with ``F`` its landform size (:func:`.preset_choice.landform_scales`): the river
    undercuts of the NM canyon make 7.4-37 (by seed), the sea of the synthetic coast 63,
    of the Salish and Devil's Slide coasts 90 and 54. A choice that makes less is no
    subject for the three close shots (the karst lattice of a 200 m Alpine DEM made
    nothing; the river on the Maunga Whau cone 1.35, undercuts of 6 m on its rim, where
    karst's lava-tube mouths made 1060: its crater held a lake to the brim and its shots
    framed grass), and then every preset goes by volume, largest first. The others
    follow by volume either way; ties keep the candidates' order.

The kept preset is then the first in this order whose landforms a close shot can
frame (:func:`.fallback.amplify_soft`); the scene's header lists what each made.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), sections 6.1-6.3 (the
processes), 7 (their landforms).
"""

from __future__ import annotations

import numpy as np

from .shots import landform_cells, landform_volume

__all__ = ["MIN_LANDFORMS", "visible_volume", "rank_order", "ranking_line"]

#: The chosen preset stays first while its visible volume is at least this many cubes of
#: its landform size (module docstring, "Order"): one a close shot.
MIN_LANDFORMS = 3.0


def visible_volume(result) -> tuple[float, float]:
    """Visible 3-D volume (m^3) of the landforms of an amplification (module docstring)
    and its landform size ``F`` (m).

    Parameters
    ----------
    result : Amplified
        From :func:`.amplify.amplify`.

    Returns
    -------
    (float, float)
        The volume (0 for a tree without primitives) and ``F``.
    """
    feature = result.feature
    if not result.stats.get("primitives"):
        return 0.0, feature
    plain, root = result.terrain, result.landforms or result.root  # (the landforms, not the fallen blocks)
    return float(sum(landform_volume(root, plain, box, reach=feature)[0]
                     for box in landform_cells(root, result.extent, feature))), feature


def rank_order(volumes, features) -> list[int]:
    """The order in which to try the presets (module docstring, "Order").

    Parameters
    ----------
    volumes, features : sequence of float
        Visible 3-D volumes (m^3) and landform sizes (m) of the candidates, in
        :func:`.fallback.preset_candidates` order (the DEM's choice first).

    Returns
    -------
    list of int
        Indices into ``volumes``.

    Examples
    --------
    >>> rank_order([3.0, 10.0, 5.0], [1.0, 1.0, 1.0])   # the choice makes 3 landforms: it stays first
    [0, 1, 2]
    >>> rank_order([0.5, 10.0, 5.0], [1.0, 1.0, 1.0])   # half a landform: by volume
    [1, 2, 0]
    """
    v = np.asarray(volumes, dtype=np.float64)
    by_volume = [int(i) for i in np.argsort(-v, kind="stable")]
    if len(v) and v[0] >= MIN_LANDFORMS * float(features[0]) ** 3:
        return [0] + [i for i in by_volume if i != 0]
    return by_volume


def ranking_line(names, volumes, features, primitives, order, why_none=None) -> str:
    """One header line: what each preset made, and the order it gives.

    Parameters
    ----------
    names : sequence of str
        Presets, in candidate order.
    volumes, features, primitives : sequence
        Their visible 3-D volumes (m^3), landform sizes (m) and primitive counts.
    order : sequence of int
        From :func:`rank_order`.
    why_none : sequence of str or None, optional
        Per preset, why it made no primitive (shown where it made none).

    Returns
    -------
    str
    """
    parts = []
    for i in order:
        if primitives[i]:
            made = (f"{volumes[i]:.3g} m3 of 3-D landforms seen from the air, {volumes[i] / features[i] ** 3:.3g} "
                    f"landforms of {features[i]:.3g} m ({primitives[i]} primitives)")
        else:
            made = "nothing" + (f" ({why_none[i]})" if why_none and why_none[i] else "")
        parts.append(f"{names[i]} {made}")
    if order[0] == 0:
        how = f"{names[0]}, the DEM's choice, first (it makes at least {MIN_LANDFORMS:g} landforms), then by volume"
    else:
        how = f"by volume ({names[0]}, the DEM's choice, makes under {MIN_LANDFORMS:g} landforms)"
    return f"auto ranked the presets by what they make: {'; '.join(parts)}. Order: {how}"
