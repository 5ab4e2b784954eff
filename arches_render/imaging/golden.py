"""Golden-image tests: a reference with its variance, made once; a two-sample test per check.

A golden ``NAME`` is two files in the golden folder:

* ``NAME.exr``: the reference, rendered with ``ref_spp`` samples per pixel
  (seed 0): its mean (RGB), the per-sample variance of R, G, B and
  luminance (layer ``variance``), the fraction of samples that hit a
  surface (``coverage.hit``), the mean depth (``depth.Z``, float32) and its
  per-sample variance (``depth_variance.Z``); ZIP-compressed; the header records
  name, spp, seed, resolution, versions and date;
* ``NAME.json``: what a check needs besides the pixels: the test spp, the
  reference's spp and seed, resolution, versions, date, and a digest of the
  stored pixels so that an EXR replaced without the JSON is noticed.

:func:`update_golden` renders the reference; :func:`check_golden` renders once
at the test spp with another seed, compares with
:func:`arches_render.imaging.welch.welch_compare` (Welch's statistic per pixel,
per window and for the image mean; coverage and depth per pixel), and proves
with :func:`arches_render.imaging.welch.power_check`, on that same render, that
a 1 % global change, a 25 % change of the weakest 8 x 8 window at least a quarter as
bright as the image and a 25 % change of the weakest 16 x 16 window at least 1/32 as
bright, each up and down, would have failed. Shadows are proven by the 16 x 16
windows (:data:`arches_render.imaging.welch.WIDE_WINDOW`): an 8 x 8 window of
shadowed rock under sky light would need up to 550 spp, a 16 x 16 one 7-47 on the
shipped goldens. What is not proven: a change confined to a dark 8 x 8 square
(its 16 x 16 windows see it at half the z of a whole window's change), and regions darker
than 1/32 of the mean (none in the shipped goldens). Because the
reference's own noise is in the test, it needs only a few times the test's
samples (:data:`REF_SPP_FACTOR`), not a converged image.

The renderer is a callable ``render(seed, spp) -> PixelMoments`` supplied by
the caller (:func:`arches_render.render.renderer.render_moments` for scenes), so
the workflow knows nothing of Mitsuba.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from .. import __version__
from ..atomic import atomic_write
from .exr import ExrError, read_exr, write_exr
from .report import check_name, clear_report, write_failure_report
from .welch import ALPHA, PixelMoments, WelchResult, power_check, welch_compare

__all__ = ["Golden", "GoldenMissingError", "GoldenError", "GoldenWeakError", "RenderFn", "update_golden",
           "check_golden", "load_golden", "golden_paths", "DEFAULT_CHECK_SEED", "REF_SEED", "REF_SPP_FACTOR",
           "MIN_TEST_SPP",
           "UPDATE_HINT"]

RenderFn = Callable[[int, int], PixelMoments]
"""``render(seed, spp) -> PixelMoments``: beauty, second moments, coverage and depth of a render."""

REF_SEED = 0
"""Seed of the reference render."""

DEFAULT_CHECK_SEED = 17
"""Seed of check renders (anything but :data:`REF_SEED`)."""

MIN_TEST_SPP = 16
"""Fewest test samples per pixel: below this the per-pixel variance estimates have too
few degrees of freedom for the normal limit of Welch's statistic (at 2 spp a
correct render failed the per-pixel and depth tests)."""

REF_SPP_FACTOR = 4
"""The reference has at least this many times the test's samples: its noise then adds
``1 / REF_SPP_FACTOR`` to the variance of the test statistic (a 12 % wider noise)."""

UPDATE_HINT = "run `pytest --update-goldens` (or `pytest --update-goldens -k <test>`) to (re)create it"

_FORMAT = 2


class GoldenError(AssertionError):
    """A golden is unusable: inconsistent files, or made for another resolution or spp."""


class GoldenWeakError(GoldenError):
    """The test render has too few samples to prove that a golden catches what it must."""


class GoldenMissingError(FileNotFoundError):
    """The golden files do not exist yet."""


@dataclass
class Golden:
    """A golden reference as stored.

    Attributes
    ----------
    name : str
        Golden name (file stem).
    ref : PixelMoments
        The reference's statistics, as stored.
    test_spp, ref_spp, ref_seed : int
        Samples per pixel of check renders and of the reference; the reference's seed.
    header : dict of str to str
        Metadata stored in the EXR.
    meta : dict
        Everything in the JSON file (date, versions, caller metadata).
    exr_path, json_path : pathlib.Path
        The two files.
    """

    name: str
    ref: PixelMoments = field(repr=False)
    test_spp: int
    ref_spp: int
    ref_seed: int
    header: dict[str, str] = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    exr_path: Path | None = None
    json_path: Path | None = None

    @property
    def resolution(self) -> tuple[int, int]:
        """``(width, height)`` of the reference."""
        h, w = self.ref.shape
        return w, h


def golden_paths(name: str, golden_dir: str | os.PathLike) -> tuple[Path, Path]:
    """The ``(NAME.exr, NAME.json)`` paths of golden ``name`` in ``golden_dir``."""
    base = Path(golden_dir) / check_name(name)
    return base.with_name(base.name + ".exr"), base.with_name(base.name + ".json")


def _stored_arrays(m: PixelMoments) -> dict[str, np.ndarray]:
    # What the EXR holds, in the precision it holds it: float32 throughout but for
    # the coverage fraction (a fraction k / n needs no more than 11 bits). Half floats
    # would not do for the rest: the tests resolve a mean to FLOOR_REL = 1e-4 where
    # a pixel is noise-free, and a pixel that sees the sun has a sample variance
    # far beyond half's 65504.
    half = np.asarray(m.coverage, np.float32).astype(np.float16).astype(np.float32)
    return {"mean": np.asarray(m.mean, np.float32), "variance": np.asarray(m.sample_variance(), np.float32),
            "coverage": half, "depth": np.asarray(m.depth, np.float32),
            "depth_variance": np.asarray(m.depth_sample_variance(), np.float32)}


def _from_stored(n: int, a: Mapping[str, np.ndarray]) -> PixelMoments:
    return PixelMoments.from_sample_variance(n, a["mean"], a["variance"], a["coverage"], a["depth"],
                                             a["depth_variance"])


def _digest(arrays: Mapping[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for key in sorted(arrays):
        h.update(key.encode())
        h.update(np.ascontiguousarray(arrays[key], dtype=np.float32).tobytes())
    return h.hexdigest()


def _call_render(render: RenderFn, seed: int, spp: int, what: str) -> PixelMoments:
    out = render(int(seed), int(spp))
    if not isinstance(out, PixelMoments):
        raise TypeError(f"render(seed={seed}, spp={spp}) for the {what} returned {type(out).__name__}; "
                        f"expected PixelMoments (arches_render.render.renderer.render_moments)")
    if out.n != int(spp):
        raise ValueError(f"render(seed={seed}, spp={spp}) for the {what} says it took {out.n} samples")
    return out


def _versions() -> dict[str, str]:
    # Only modules the renderer already imported: importing Mitsuba here would
    # load libLLVM before arches_render.backend could choose it.
    out = {"arches_render": __version__, "python": sys.version.split()[0], "numpy": np.__version__}
    for mod in ("mitsuba", "drjit"):
        m = sys.modules.get(mod)
        if m is not None and getattr(m, "__version__", None):
            out[mod] = str(m.__version__)
    return out


def update_golden(name: str, render: RenderFn, *, ref_spp: int, test_spp: int, golden_dir: str | os.PathLike,
                  meta: Mapping[str, object] | None = None) -> Golden:
    """Render and store the reference of golden ``name``.

    Parameters
    ----------
    name : str
        Golden name; the files are ``golden_dir/NAME.exr`` and ``NAME.json``.
    render : callable
        ``render(seed, spp) -> PixelMoments``; deterministic for a given seed
        (use a ``box`` reconstruction filter).
    ref_spp : int
        Samples per pixel of the reference (seed 0); at least
        :data:`REF_SPP_FACTOR` times ``test_spp``.
    test_spp : int
        Samples per pixel of check renders, at least :data:`MIN_TEST_SPP`.
    golden_dir : str or os.PathLike
        Folder of the goldens (created if missing).
    meta : mapping, optional
        Caller metadata (scene file, camera, ...) stored in both files.

    Returns
    -------
    Golden
        The stored golden.

    Notes
    -----
    Nothing is written until the render succeeded; the EXR and then the JSON
    are each written atomically. The JSON holds a digest of the stored pixels,
    so a crash between the two writes is reported by :func:`check_golden`
    rather than silently mixing versions.
    """
    exr_path, json_path = golden_paths(name, golden_dir)
    if test_spp < MIN_TEST_SPP or ref_spp < REF_SPP_FACTOR * test_spp:
        raise ValueError(f"golden {name!r}: need test_spp >= {MIN_TEST_SPP} and ref_spp >= {REF_SPP_FACTOR} x test_spp, got "
                         f"ref_spp={ref_spp}, test_spp={test_spp}")
    ref = _call_render(render, REF_SEED, ref_spp, "reference")
    if not (np.all(np.isfinite(ref.mean)) and np.all(np.isfinite(ref.m2))):
        raise ValueError(f"golden {name!r}: the reference render has NaN or infinite pixels")
    arrays = _stored_arrays(ref)

    h, w = ref.shape
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    versions = _versions()
    meta = {str(k): v for k, v in (meta or {}).items()}
    header = {"name": name, "spp": ref_spp, "seed": REF_SEED, "resolution": f"{w}x{h}", "date": now,
              **{f"version.{k}": v for k, v in versions.items()},
              **{f"meta.{k}": v if isinstance(v, str) else json.dumps(v) for k, v in meta.items()}}
    record = {
        "format": _FORMAT, "name": name, "date": now, "resolution": [w, h],
        "reference": {"file": exr_path.name, "spp": ref_spp, "seed": REF_SEED, "pixels_sha256": _digest(arrays)},
        "test_spp": test_spp, "alpha": ALPHA, "versions": versions, "meta": meta,
    }
    exr_path.parent.mkdir(parents=True, exist_ok=True)
    layers = {"variance": (arrays["variance"], ("R", "G", "B", "Y")), "coverage": (arrays["coverage"], ("hit",)),
              "depth": (arrays["depth"], ("Z",)), "depth_variance": (arrays["depth_variance"], ("Z",))}
    write_exr(exr_path, arrays["mean"], header=header, layers=layers,
              full_precision=("rgb", "variance", "depth", "depth_variance"))
    with atomic_write(json_path, "w", encoding="utf-8") as f:
        json.dump(record, f, indent=2, default=str)
        f.write("\n")
    return Golden(name=name, ref=_from_stored(ref_spp, arrays), test_spp=test_spp, ref_spp=ref_spp,
                  ref_seed=REF_SEED, header={k: str(v) for k, v in header.items()}, meta=record,
                  exr_path=exr_path, json_path=json_path)


def load_golden(name: str, golden_dir: str | os.PathLike) -> Golden:
    """Read golden ``name`` from ``golden_dir``.

    Parameters
    ----------
    name : str
        Golden name.
    golden_dir : str or os.PathLike
        Folder of the goldens.

    Returns
    -------
    Golden

    Raises
    ------
    GoldenMissingError
        When either file is missing (the message says how to create them).
    GoldenError
        When the files are unreadable, of an older format, or do not belong together.
    """
    exr_path, json_path = golden_paths(name, golden_dir)
    missing = [p for p in (exr_path, json_path) if not p.is_file()]
    if missing:
        raise GoldenMissingError(f"golden {name!r} is missing ({', '.join(map(str, missing))}): {UPDATE_HINT}")
    try:
        record = json.loads(json_path.read_text(encoding="utf-8"))
        if record.get("format") != _FORMAT:
            raise ValueError(f"format {record.get('format')!r}, this harness reads format {_FORMAT}")
        ref_info = record["reference"]
        test_spp, ref_spp = int(record["test_spp"]), int(ref_info["spp"])
    except (ValueError, KeyError, TypeError) as e:
        raise GoldenError(f"golden {name!r}: cannot use {json_path} ({e}); {UPDATE_HINT}") from e
    try:
        img = read_exr(exr_path)
        arrays = {"mean": img.rgb, "variance": img.layers["variance"], "coverage": img.layers["coverage"],
                  "depth": img.layers["depth"], "depth_variance": img.layers["depth_variance"]}
    except ExrError as e:
        raise GoldenError(f"golden {name!r}: {e}; {UPDATE_HINT}") from e
    except KeyError as e:
        raise GoldenError(f"golden {name!r}: {exr_path.name} has no layer {e}; {UPDATE_HINT}") from e
    if _digest(arrays) != ref_info.get("pixels_sha256"):
        raise GoldenError(f"golden {name!r}: {exr_path.name} does not match the reference recorded in "
                          f"{json_path.name} (replaced without its JSON?); {UPDATE_HINT}")
    return Golden(name=name, ref=_from_stored(ref_spp, arrays), test_spp=test_spp, ref_spp=ref_spp,
                  ref_seed=int(ref_info.get("seed", REF_SEED)), header=img.header, meta=record,
                  exr_path=exr_path, json_path=json_path)


def check_golden(name: str, render: RenderFn, *, golden_dir: str | os.PathLike,
                 report_dir: str | os.PathLike, seed: int | None = None, ref_spp: int | None = None,
                 test_spp: int | None = None) -> WelchResult:
    """Render at the golden's test spp, compare with its reference, and prove the comparison's power.

    Parameters
    ----------
    name : str
        Golden name.
    render : callable
        ``render(seed, spp) -> PixelMoments``, as for :func:`update_golden`.
    golden_dir : str or os.PathLike
        Folder of the goldens.
    report_dir : str or os.PathLike
        Root of failure reports; a failure writes ``report_dir/NAME/``, a pass
        removes a stale report of that name.
    seed : int, optional
        Seed of the check render (default :data:`DEFAULT_CHECK_SEED`); must
        differ from the reference's, whose noise would otherwise be shared.
    ref_spp, test_spp : int, optional
        What the calling test asks for; when given and different from what the
        golden was made with, the golden is stale and the check fails.

    Returns
    -------
    WelchResult
        The passing result.

    Raises
    ------
    GoldenMissingError
        When the golden does not exist (message: run ``pytest --update-goldens``).
    GoldenError
        (an :class:`AssertionError`) when the golden is stale or inconsistent.
    GoldenWeakError
        When the test render could not have caught a 1 % global or a 25 % local
        change, up or down (its message names the spp that would).
    AssertionError
        When the comparison fails; the message names the failed tests and the
        report folder.
    """
    g = load_golden(name, golden_dir)
    seed = DEFAULT_CHECK_SEED if seed is None else int(seed)
    if seed == g.ref_seed:
        raise ValueError(f"check seed {seed} made the reference of golden {name!r}; pick another")
    stale = [f"{k} {want} (golden has {have})" for k, want, have in
             (("ref_spp", ref_spp, g.ref_spp), ("test_spp", test_spp, g.test_spp))
             if want is not None and int(want) != have]
    if stale:
        raise GoldenError(f"golden {name!r} is stale: the test asks for {', '.join(stale)}; {UPDATE_HINT}")

    test = _call_render(render, seed, g.test_spp, "check")
    if test.shape != g.ref.shape:
        raise GoldenError(f"golden {name!r}: the render is {test.shape[1]}x{test.shape[0]} pixels, the golden "
                          f"{g.ref.shape[1]}x{g.ref.shape[0]}; if that is intended, {UPDATE_HINT}")
    result = welch_compare(g.ref, test)
    if result.passed:
        weak = power_check(g.ref, test)
        if weak:
            raise GoldenWeakError(f"golden {name!r} cannot prove what it must at {g.test_spp} spp:\n"
                                  + "\n".join(f"  - {w}" for w in weak)
                                  + f"\nraise its test spp (and {UPDATE_HINT})")
        clear_report(report_dir, name)
        return result
    page = write_failure_report(report_dir, name, g.ref, test, result)
    reasons = "\n".join(f"  - {f}" for f in result.failures)
    raise AssertionError(f"golden {name!r} failed (seed {seed}, {g.test_spp} spp):\n{reasons}\n"
                         f"report: {page.parent} (open {page.name}); if the change is intended, {UPDATE_HINT}")
