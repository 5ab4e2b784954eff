"""scikit-image's face and interior tests of Lewiner's ambiguous cases 3, 4 and 6.

The ``exact`` mode of :func:`arches_render.mesh.lewiner.plain_runs` resolves those
cases as scikit-image's ``marching_cubes`` does, bit for bit: its ``test_face``,
``test_internal`` and the part of ``the_big_switch`` that picks the tiling (a port of
scikit-image 0.26's Cython ``Cell``, BSD-3; the tables are read from scikit-image at
run time by :func:`~arches_render.mesh.lewiner.lewiner_tables`).

References
----------
Lewiner, T. et al. (2003). Efficient implementation of marching cubes' cases with
topological guarantees. Journal of Graphics Tools 8(2).
scikit-image 0.26, ``skimage/measure/_marching_cubes_lewiner_cy.pyx`` (``Cell``).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["EPS", "BIT_TO_V", "ambiguous_tiling"]

#: scikit-image's ``FLT_EPSILON`` (``np.spacing(1.0)``, a double's epsilon despite the name).
EPS = float(np.spacing(1.0))
#: ``v`` number of the corner with bit index ``4 dz + 2 dy + dx`` (scikit-image's ``vv``).
BIT_TO_V = np.array([0, 1, 3, 2, 4, 5, 7, 6], dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def _test_face(vc, face):
    """scikit-image's ``test_face`` on the cube values ``vc`` (``v0 .. v7``, level
    subtracted): whether the face's saddle joins the corners of ``face``'s sign."""
    f = abs(face)
    if f == 1:
        A, B, C, D = vc[0], vc[4], vc[5], vc[1]
    elif f == 2:
        A, B, C, D = vc[1], vc[5], vc[6], vc[2]
    elif f == 3:
        A, B, C, D = vc[2], vc[6], vc[7], vc[3]
    elif f == 4:
        A, B, C, D = vc[3], vc[7], vc[4], vc[0]
    elif f == 5:
        A, B, C, D = vc[0], vc[3], vc[2], vc[1]
    else:
        A, B, C, D = vc[4], vc[7], vc[6], vc[5]
    ac_bd = A * C - B * D
    if -EPS < ac_bd < EPS:
        return face >= 0
    return np.float64(face) * A * ac_bd >= 0


@numba.njit(cache=True, nogil=True)
def ambiguous_tiling(vc, case, cfg, amb_test):
    """scikit-image's ``the_big_switch`` for cases 3, 4 and 6: the tiling's number in
    ``lewiner._AMBIGUOUS``, or -1 for 6.1.2 (it needs the cube's centre vertex: left to
    scikit-image; never chosen in 75,000 random case 6 cubes, so never tested here)."""
    if case == 3:
        return 1 if _test_face(vc, amb_test[0, cfg, 0]) else 0
    if case == 4:
        return 2 if _test_internal(vc, 4, -1, amb_test[1, cfg, 0]) else 3
    if _test_face(vc, amb_test[2, cfg, 0]):
        return 6
    return 4 if _test_internal(vc, 6, amb_test[2, cfg, 2], amb_test[2, cfg, 1]) else -1


@numba.njit(cache=True, nogil=True)
def _test_internal(vc, case, edge, s):
    """scikit-image's ``test_internal`` for cases 4 and 6 (``edge``: TEST6's reference
    edge), on the cube values ``vc`` (``v0 .. v7``, level subtracted)."""
    v0, v1, v2, v3, v4, v5, v6, v7 = vc[0], vc[1], vc[2], vc[3], vc[4], vc[5], vc[6], vc[7]
    At, Bt, Ct, Dt = 0.0, 0.0, 0.0, 0.0
    if case == 4:
        a = (v4 - v0) * (v6 - v2) - (v7 - v3) * (v5 - v1)
        b = v2 * (v4 - v0) + v0 * (v6 - v2) - v1 * (v7 - v3) - v3 * (v5 - v1)
        t = -b / (2 * a + EPS)
        if t < 0 or t > 1:
            return s > 0
        At = v0 + (v4 - v0) * t
        Bt = v3 + (v7 - v3) * t
        Ct = v2 + (v6 - v2) * t
        Dt = v1 + (v5 - v1) * t
    else:
        # (edge, its two ends, and the three edges parallel to it, as scikit-image lists them)
        if edge == 0:
            t = v0 / (v0 - v1 + EPS)
            Bt, Ct, Dt = v3 + (v2 - v3) * t, v7 + (v6 - v7) * t, v4 + (v5 - v4) * t
        elif edge == 1:
            t = v1 / (v1 - v2 + EPS)
            Bt, Ct, Dt = v0 + (v3 - v0) * t, v4 + (v7 - v4) * t, v5 + (v6 - v5) * t
        elif edge == 2:
            t = v2 / (v2 - v3 + EPS)
            Bt, Ct, Dt = v1 + (v0 - v1) * t, v5 + (v4 - v5) * t, v6 + (v7 - v6) * t
        elif edge == 3:
            t = v3 / (v3 - v0 + EPS)
            Bt, Ct, Dt = v2 + (v1 - v2) * t, v6 + (v5 - v6) * t, v7 + (v4 - v7) * t
        elif edge == 4:
            t = v4 / (v4 - v5 + EPS)
            Bt, Ct, Dt = v7 + (v6 - v7) * t, v3 + (v2 - v3) * t, v0 + (v1 - v0) * t
        elif edge == 5:
            t = v5 / (v5 - v6 + EPS)
            Bt, Ct, Dt = v4 + (v7 - v4) * t, v0 + (v3 - v0) * t, v1 + (v2 - v1) * t
        elif edge == 6:
            t = v6 / (v6 - v7 + EPS)
            Bt, Ct, Dt = v5 + (v4 - v5) * t, v1 + (v0 - v1) * t, v2 + (v3 - v2) * t
        elif edge == 7:
            t = v7 / (v7 - v4 + EPS)
            Bt, Ct, Dt = v6 + (v5 - v6) * t, v2 + (v1 - v2) * t, v3 + (v0 - v3) * t
        elif edge == 8:
            t = v0 / (v0 - v4 + EPS)
            Bt, Ct, Dt = v3 + (v7 - v3) * t, v2 + (v6 - v2) * t, v1 + (v5 - v1) * t
        elif edge == 9:
            t = v1 / (v1 - v5 + EPS)
            Bt, Ct, Dt = v0 + (v4 - v0) * t, v3 + (v7 - v3) * t, v2 + (v6 - v2) * t
        elif edge == 10:
            t = v2 / (v2 - v6 + EPS)
            Bt, Ct, Dt = v1 + (v5 - v1) * t, v0 + (v4 - v0) * t, v3 + (v7 - v3) * t
        else:
            t = v3 / (v3 - v7 + EPS)
            Bt, Ct, Dt = v2 + (v6 - v2) * t, v1 + (v5 - v1) * t, v0 + (v4 - v0) * t
    test = 0
    if At >= 0:
        test += 1
    if Bt >= 0:
        test += 2
    if Ct >= 0:
        test += 4
    if Dt >= 0:
        test += 8
    if test == 5:
        # (scikit-image's port falls off its if-chain here, returning 0)
        return s > 0 if At * Ct - Bt * Dt < EPS else False
    if test == 10:
        return s > 0 if At * Ct - Bt * Dt >= EPS else False
    if test == 7 or test == 11 or test == 13 or test >= 14:
        return s < 0
    return s > 0
