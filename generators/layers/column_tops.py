"""Free space above material stacks: window maxima of the columns' tops.

The convolution surface's value is ``-sigma`` (less its tie-break) wherever the kernel
cube around a point holds no matter (:mod:`.convolution_surface`). Its coarse grid
proves that in boxes of empty coarse cells, which end a cell or two above the ground:
a ray skimming a layered terrain a metre up stepped ``sigma / sqrt(3)`` at a time
(every_generator's bounce rays: 130-150 steps over 20-50 m of air).

Columns carry a top ``T_ij`` (the top of their highest interval of the skeleton's
materials; ``-inf`` for an empty column). For windows of ``w`` columns each way around
a point's column, ``M_w`` is the largest top in the window. A point ``q`` whose
horizontal distance from ``p`` is below ``R_w = w s - sigma`` (``s`` the column size)
has its cube's footprint inside ``p``'s window (``p`` lies at least ``w s`` inside the
window's edges), so where also ``q_z - sigma > M_w`` its cube is empty. Hence the free
length ``min(R_w, p_z - sigma - M_w)`` (ball) or, on the line of a unit direction
``u``, ``min(R_w / |u_xy|, (p_z - sigma - M_w) / |u_z|)`` both ways
(:func:`arches_render.field.heightfield.window_reach`: the maximum mipmaps' bound of the
heightfield, Tevs et al. 2008, for the stacks' tops). Lookups outside the grid clamp
to its edge columns, whose window holds every column of the grid a clamped point's
window would; the columns beyond the grid hold no matter.

References
----------
Peytavie, A., Galin, E., Grosjean, J., Merillou, S. (2009). Arches: a framework for
modeling complex terrains. Computer Graphics Forum 28(2), 457-467.
Tevs, A., Ihrke, I., Seidel, H.-P. (2008). Maximum mipmaps for fast, accurate, and
scalable dynamic height field rendering. I3D '08.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from arches_render.field.heightfield import window_reach
from arches_render.field.node import clip_index, opaque_float
from arches_render.field.packed_columns import gather_columns, pack_columns
from arches_render.field.window_filters import window_max

#: Half-widths of the windows in columns (each taken where it holds more than the cube).
WINDOWS = (2, 8, 32)

#: The top of an empty column: below any level (a float32 that stays finite in sums).
NO_TOP = -1e30


class ColumnTops:
    """Window maxima of the stacks' column tops and the free lengths above them.

    Parameters
    ----------
    offsets, top : numpy.ndarray
        The skeleton's merged intervals as CSR (``offsets`` of ``nx ny + 1``, tops
        bottom-up within a column), as :meth:`.MaterialStacks.intervals` gives them.
    stacks : MaterialStacks
        Their grid (origin, column size, ``nx``, ``ny``).
    sigma : float
        The kernel's half-side.
    """

    def __init__(self, offsets, top, stacks, sigma):
        nx, ny, s = stacks.nx, stacks.ny, stacks.cell
        count = np.diff(offsets)
        tops = np.full(nx * ny, NO_TOP)
        tops[count > 0] = top[offsets[1:][count > 0] - 1]
        tops = tops.reshape(ny, nx)
        self.windows = [w for w in WINDOWS if w * s > sigma and w < 2 * max(nx, ny)]
        self._maxima, self._width = pack_columns([window_max(tops, 2 * w + 1).astype(np.float32)
                                                  for w in self.windows]) if self.windows else (None, 0)
        self._radii = [opaque_float(w * s - sigma) for w in self.windows]
        x0, y0, _ = stacks.origin
        self._x0, self._y0, self._inv_s = opaque_float(x0), opaque_float(y0), opaque_float(1.0 / s)
        self._sigma = opaque_float(sigma)
        self.nx, self.ny = nx, ny
        self.nbytes = 0 if self._maxima is None else dr.width(self._maxima) * 4

    def free_length(self, p, line=None):
        """A length around ``p`` (ball, or both ways on a line: ``line`` from
        :func:`~arches_render.field.heightfield.line_factors`) in which every point's
        cube is empty (module docstring); 0 where no window proves one."""
        if not self.windows:
            return mi.Float(0.0)
        i = mi.UInt32(clip_index((p.x - self._x0) * self._inv_s, 0.0, self.nx - 1.0))
        j = mi.UInt32(clip_index((p.y - self._y0) * self._inv_s, 0.0, self.ny - 1.0))
        maxima = gather_columns(self._maxima, j * self.nx + i, self._width, len(self.windows))
        clear = [p.z - self._sigma - m for m in maxima]
        return window_reach(mi.Float(0.0), clear, self._radii, line)
