"""Shared pytest options and fixtures of arches-render.

Golden-image tests
------------------
A scene test calls the ``golden`` fixture with a renderer::

    def test_arch(golden):
        golden("arch", render, ref_spp=128, test_spp=32)

where ``render(seed, spp)`` returns the render's
:class:`~arches_render.imaging.welch.PixelMoments` (mean, variance, coverage,
depth: :func:`arches_render.render.renderer.render_moments`). Normally this
renders once at the stored test spp and tests it against ``golden/arch.exr``
(see :mod:`arches_render.imaging.golden`); a failure writes
``test-reports/arch/index.html``. ``pytest --update-goldens`` renders the
reference first, writes ``golden/arch.exr`` and ``golden/arch.json``, and then
runs the check once.

This file imports no Mitsuba: collection stays fast, and Mitsuba must be
imported through :func:`arches_render.backend.set_variant` (it picks the
libLLVM Dr.Jit loads), which tests do when they need it.
"""

from __future__ import annotations

import gc
import os
import sys
from pathlib import Path

import pytest

from arches_render.imaging import golden as _golden

REPO = Path(__file__).resolve().parent.parent


def pytest_addoption(parser):
    parser.addoption("--update-goldens", action="store_true", default=False,
                     help="re-render golden references and re-calibrate their thresholds instead of "
                          "only checking against them (writes golden/NAME.exr and golden/NAME.json)")


@pytest.fixture(scope="module", autouse=True)
def _no_scenes_from_earlier_files():
    """Each test file starts with no scene of an earlier file alive in this process.

    Dr.Jit's kernels depend on the registry ids of the objects they dispatch over (BSDFs,
    shapes, emitters), and a new object takes the lowest free id: a scene built while an
    earlier file's scenes were still cached (the job cache keeps four) or awaiting the
    garbage collector traced other kernels than the same scene built in a fresh process,
    and missed the warm kernel cache (an LLVM compile of seconds: test_exposure's render
    traced 097a2.. alone, b6b45.. after test_render_jobs). Which files run before which,
    in which pytest-xdist worker, changes from run to run; with the caches cleared and the
    cycles collected here, a file's kernels are its own.
    """
    jobs = sys.modules.get("arches_render.render.jobs")
    if jobs is not None:
        jobs.clear_cache()
    if "mitsuba" in sys.modules:
        gc.collect()
    yield


@pytest.fixture(scope="session")
def update_goldens(request) -> bool:
    """``True`` when pytest runs with ``--update-goldens``."""
    return bool(request.config.getoption("--update-goldens"))


@pytest.fixture(scope="session")
def golden_dir() -> Path:
    """The repository's ``golden/`` folder."""
    return REPO / "golden"


@pytest.fixture(scope="session")
def report_dir() -> Path:
    """Root of failure reports: ``$ARCHES_REPORT_DIR`` or the repository's ``test-reports/``."""
    return Path(os.environ.get("ARCHES_REPORT_DIR") or REPO / "test-reports")


@pytest.fixture
def golden(update_goldens, golden_dir, report_dir):
    """Check a render against golden ``name`` (or re-create it under ``--update-goldens``).

    Returns a callable ``golden(name, render, ref_spp, test_spp, **kwargs)``:
    ``render(seed, spp) -> PixelMoments``; extra keyword arguments go to
    :func:`~arches_render.imaging.golden.update_golden` (``meta``) or, for
    ``seed``, to :func:`~arches_render.imaging.golden.check_golden`. It returns
    the :class:`~arches_render.imaging.welch.WelchResult` of the check.
    """
    def run(name, render, ref_spp, test_spp, *, seed=None, **update_kwargs):
        if update_goldens:
            _golden.update_golden(name, render, ref_spp=ref_spp, test_spp=test_spp, golden_dir=golden_dir,
                                  **update_kwargs)
        try:
            return _golden.check_golden(name, render, golden_dir=golden_dir, report_dir=report_dir, seed=seed,
                                        ref_spp=ref_spp, test_spp=test_spp)
        except _golden.GoldenMissingError as e:
            # A missing golden is a to-do, not a crash: one line, no traceback.
            pytest.fail(str(e), pytrace=False)
    return run


@pytest.fixture(scope="session")
def dask_cluster():
    """One Dask ``LocalCluster`` client (two worker processes) for every test that only
    submits work to a cluster: starting one costs seconds (worker processes, each
    importing Mitsuba on its first task). Tests that kill workers start their own."""
    from arches_render.render.distributed import dask_client
    with dask_client(workers=2) as client:
        yield client
