"""Test-only fault injection: SIGKILL this process at a named point of its output path.

This is a hook for the fault tests (``tests/test_robust_faults.py``), not a
feature: nothing sets it outside the tests, and unset it costs one dictionary
look-up per call. Killing a subprocess after a random delay mostly lands in its
start-up (imports, kernel compilation), so the moments that matter (an output
half written, a temporary complete but not renamed, a cache entry's lock held,
a turntable between frames) were rarely hit; a named point hits each of them
every time.

``ARCHES_TEST_KILL_AT=POINT[:N]`` makes the process send itself ``SIGKILL`` (no
handler, no ``finally``, no flush: what the OOM killer or a power cut leaves) at

``atomic.before_replace[:K]``
    the ``K``-th (default first) atomic publish of this process
    (:mod:`arches_render.atomic`), its temporary file complete, just before the
    :func:`os.replace` onto the destination;
``atomic.written:N``
    the first atomic publish of this process, its temporary file cut to its first
    ``N`` bytes: the file a kill leaves after ``N`` bytes were written;
``cache.locked[:K]``
    the ``K``-th cache build of this process (:mod:`arches_render.cache`), holding
    the entry's build lock, before building;
``turntable.after_frame[:K]``
    after the ``K``-th frame this process wrote
    (:mod:`arches_render.render.turntable`), before the next one.
"""

from __future__ import annotations

import os
import signal
from collections import Counter

__all__ = ["ENV", "POINTS", "point"]

#: The environment variable naming the kill point.
ENV = "ARCHES_TEST_KILL_AT"

#: Every point the code calls :func:`point` with.
POINTS = ("atomic.before_replace", "atomic.written", "cache.locked", "turntable.after_frame")

_reached: Counter = Counter()


def point(name: str, path=None) -> None:
    """Die here when ``$ARCHES_TEST_KILL_AT`` names this point (see the module docstring).

    Parameters
    ----------
    name : str
        One of :data:`POINTS`.
    path : str or os.PathLike, optional
        The temporary file of an ``atomic.*`` point (``atomic.written`` cuts it).
    """
    spec = os.environ.get(ENV)
    if not spec:
        return
    want, _, arg = spec.partition(":")
    if want != name:
        return
    n = int(arg or 1)
    if name == "atomic.written":
        os.truncate(path, min(n, os.path.getsize(path)))
        _die()
    _reached[name] += 1
    if _reached[name] == n:
        _die()


def _die() -> None:
    # stdio is not flushed on purpose: a real kill does not flush it either.
    if hasattr(signal, "SIGKILL"):
        os.kill(os.getpid(), signal.SIGKILL)
    os._exit(137)  # pragma: no cover - Windows has no SIGKILL
