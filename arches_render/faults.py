"""Test-only fault injection: kill this process by a signal at a named point of its work.

This is a hook for the fault tests (``tests/test_robust_faults.py``), not a
feature: nothing sets it outside the tests, and unset it costs one dictionary
look-up per call. Killing a subprocess after a random delay mostly lands in its
start-up (imports, kernel compilation), so the moments that matter (an output
half written, a temporary complete but not renamed, a cache entry's lock held,
a turntable between frames) were rarely hit; a named point hits each of them
every time.

``ARCHES_TEST_KILL_AT=POINT[:N][@SIGNAL]`` makes the process send itself ``SIGNAL``
(default ``SIGKILL``: no handler, no ``finally``, no flush, what the OOM killer or a
power cut leaves; ``@SIGSEGV`` is a native crash as Mitsuba or a kernel dies of one,
issue 38) at

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
    (:mod:`arches_render.render.turntable`), before the next one;
``render.job[:K]``
    at the start of the ``K``-th render job of this process
    (:func:`arches_render.render.jobs.run_job`: a still, a tile, a frame; in a Dask
    worker's render process, :mod:`arches_render.render.isolated`);
``render.task[:K]``
    at the start of the ``K``-th render task of this Dask worker, in the worker
    itself (:func:`arches_render.render.isolated.run_isolated`): a worker lost.
"""

from __future__ import annotations

import os
import signal
from collections import Counter

__all__ = ["ENV", "POINTS", "point"]

#: The environment variable naming the kill point.
ENV = "ARCHES_TEST_KILL_AT"

#: Every point the code calls :func:`point` with.
POINTS = ("atomic.before_replace", "atomic.written", "cache.locked", "turntable.after_frame", "render.job",
          "render.task")

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
    spec, _, signame = spec.partition("@")
    want, _, arg = spec.partition(":")
    if want != name:
        return
    n = int(arg or 1)
    sig = getattr(signal, signame or "SIGKILL", None)
    if name == "atomic.written":
        os.truncate(path, min(n, os.path.getsize(path)))
        _die(sig)
    _reached[name] += 1
    if _reached[name] == n:
        _die(sig)


def _die(sig) -> None:
    # stdio is not flushed on purpose: a real kill does not flush it either.
    if sig is not None:
        if hasattr(signal, "SIGKILL") and sig != signal.SIGKILL:
            import resource
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # a test's crash leaves no core file
        os.kill(os.getpid(), sig)
    os._exit(137)  # pragma: no cover - Windows has no SIGKILL; a signal that did not kill
