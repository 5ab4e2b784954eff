"""Shading normals that face the ray: no black crescents where a smooth mesh turns away.

A mesh with vertex normals is shaded with the interpolated normal ``N``, not its
faces' normal ``N_g``. Where a surface curves away from the viewer (the far side of
a hill, just below its silhouette) the ray can see a face (``N_g . w_i > 0``) whose
interpolated normal already points away (``N . w_i <= 0``): the BSDF, which asks
for ``cos theta_i > 0`` in the shading frame, returns nothing, and a black line
follows the silhouette. On the far field of a DEM these were dark crescents along
every far ridge (Maunga Whau's shots; issue 34), first taken for mirrored craters.

The fix bends ``N`` towards the ray just enough: where ``c = N . w_i < eps``
(:data:`MIN_COSINE`) on a face the ray sees from its front,

    N' = normalize(N + (eps - c) w_i),   N' . w_i = eps / sqrt(1 + eps^2 - c^2) > 0

(``|N + k w_i|^2 = 1 + 2 k c + k^2``, with ``k = eps - c``). ``N'`` equals ``N`` at
``c = eps`` (continuous) and stays in the plane of ``N`` and ``w_i``; lanes with
``c >= eps``, back faces, misses and field hits (their normal is the field's
gradient, the geometric one) keep their frame.

References
----------
Schüßler, V., Heitz, E., Hanika, J., Dachsbacher, C. (2017). Microfacet-based normal
mapping for robust Monte Carlo path tracing. ACM TOG 36(6) (the shading-normal
problem; its black regions, Fig. 2).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: The least cosine between a mesh hit's shading normal and the direction back along
#: the ray (a degree from grazing).
MIN_COSINE = 0.02


def facing_shading_frame(si, d):
    """``si`` with its shading frame bent to face the rays (module docstring).

    Parameters
    ----------
    si : mi.SurfaceInteraction3f
        Mesh hits of the rays (invalid lanes are left as they are).
    d : mi.Vector3f
        The rays' directions.

    Returns
    -------
    mi.SurfaceInteraction3f
        ``si`` with ``sh_frame`` and ``wi`` updated where bent.
    """
    wi = -d
    n = si.sh_frame.n
    c = dr.dot(n, wi)
    bend = si.is_valid() & (c < MIN_COSINE) & (dr.dot(si.n, wi) > 0.0)
    frame = mi.Frame3f(dr.normalize(n + (MIN_COSINE - c) * wi))
    si.sh_frame = dr.select(bend, frame, si.sh_frame)
    si.wi = dr.select(bend, frame.to_local(wi), si.wi)
    return si
