"""Camera paths: a keyframed flight through the scene's named cameras.

A ``[camera_path]`` table lists keys ``(time_i, camera_i)`` with strictly
increasing times (seconds) and names of ``[cameras.NAME]`` (or ``"camera"``).
Each of the camera's parameters ``q`` (origin, target, up and field of view) is
interpolated by a cubic Hermite spline through the keys with Catmull–Rom
tangents for non-uniform times (the "finite difference" cardinal spline of
Catmull and Rom 1974, as in Kochanek and Bartels 1984 with zero tension, bias and
continuity):

    m_i = (q_{i+1} - q_{i-1}) / (t_{i+1} - t_{i-1})      (interior keys)
    m_0 = (q_1 - q_0) / (t_1 - t_0),   m_n = (q_n - q_{n-1}) / (t_n - t_{n-1})

so the path passes through every key at its time and is C¹ in time (position and
velocity continuous), the first derivative being the tangent shared by the two
segments that meet at a key. The tangents are divided by *time* differences, not
parameter differences, so a camera moves at the speed the keys' spacing implies
(a key held for longer slows the move down). Times are used directly as the
spline's knots rather than centripetal chord lengths: the user's times are the
contract (the frame at time ``t_i`` is camera ``i``), and centripetal knots would
move the keys in time. The Hermite evaluation is SciPy's
:class:`scipy.interpolate.CubicHermiteSpline` (maintained, exact at the knots).

The ``up`` vector is renormalised after interpolation; the field of view is
interpolated in degrees. Frames sample the path at ``t_0 + k / fps`` for
``k = 0 .. round((t_n - t_0) fps)``, or at ``frames`` evenly spaced times over
``[t_0, t_n]`` (both ends included) when a frame count is given.
"""

from __future__ import annotations

import numpy as np

__all__ = ["catmull_rom_tangents", "path_spline", "path_times", "path_cameras"]


def catmull_rom_tangents(times, values):
    """Catmull–Rom tangents of ``values`` (``n x d``) at strictly increasing ``times`` (``n``).

    Parameters
    ----------
    times : array_like, shape (n,)
        Key times, strictly increasing, ``n >= 2``.
    values : array_like, shape (n, d)
        Key values.

    Returns
    -------
    numpy.ndarray, shape (n, d)
        ``dq/dt`` at each key (see the module docstring; one-sided at the ends).
    """
    t = np.asarray(times, np.float64)
    q = np.asarray(values, np.float64)
    if t.ndim != 1 or len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("times must be strictly increasing, at least two")
    m = np.empty_like(q)
    m[1:-1] = (q[2:] - q[:-2]) / (t[2:] - t[:-2])[:, None]
    m[0] = (q[1] - q[0]) / (t[1] - t[0])
    m[-1] = (q[-1] - q[-2]) / (t[-1] - t[-2])
    return m


def path_spline(keys):
    """The C¹ spline through camera keys.

    Parameters
    ----------
    keys : sequence of (float, Camera)
        ``(time, camera)`` pairs, times strictly increasing; a camera has ``origin``,
        ``target``, ``up`` (3 floats each) and ``fov`` (degrees).

    Returns
    -------
    scipy.interpolate.CubicHermiteSpline
        Maps time to a 10-vector ``origin(3), target(3), up(3), fov``.
    """
    t = np.array([float(time) for time, _ in keys])
    q = np.array([[*c.origin, *c.target, *c.up, c.fov] for _, c in keys], np.float64)
    # On use: scipy.interpolate took 0.18 s of every CLI call (the turntable command imports
    # this module).
    from scipy.interpolate import CubicHermiteSpline
    return CubicHermiteSpline(t, q, catmull_rom_tangents(t, q))


def path_times(t0: float, t1: float, fps: float, frames: int | None = None) -> np.ndarray:
    """Frame times over ``[t0, t1]``: every ``1/fps`` seconds, or ``frames`` evenly spaced."""
    if frames is None:
        frames = int(round((t1 - t0) * fps)) + 1
        return np.minimum(t0 + np.arange(frames) / float(fps), t1)
    if frames == 1:
        return np.array([float(t0)])
    return np.linspace(t0, t1, int(frames))


def path_cameras(keys, fps: float = 24.0, frames: int | None = None) -> list:
    """Cameras of every frame of a path.

    Parameters
    ----------
    keys : sequence of (float, Camera)
        See :func:`path_spline`.
    fps : float
        Frames per second (used when ``frames`` is None).
    frames : int, optional
        Frame count over the whole path.

    Returns
    -------
    list of tuple
        ``(origin, target, up, fov)`` per frame (tuples of floats), the form of
        :class:`arches_render.render.jobs.RenderJob`'s ``camera``.
    """
    spline = path_spline(keys)
    out = []
    for time in path_times(keys[0][0], keys[-1][0], fps, frames):
        q = spline(time)
        up = q[6:9] / max(np.linalg.norm(q[6:9]), 1e-12)
        out.append((tuple(map(float, q[0:3])), tuple(map(float, q[3:6])), tuple(map(float, up)),
                    float(q[9])))
    return out
