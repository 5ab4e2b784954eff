"""Golden-image tests: make a calibrated reference once, check cheap renders against it.

A golden ``NAME`` is two files in the golden folder:

* ``NAME.exr``: the reference, rendered with ``ref_spp`` samples per pixel
  (seed 0), half float, ZIP-compressed; its header records name, spp, seed,
  resolution, versions and date;
* ``NAME.json``: what a check needs besides the pixels: the test spp, the
  calibration seeds, the thresholds (with the noise measured to set them),
  reference spp and seed, resolution, versions, date, and a digest of the
  reference pixels so that an EXR replaced without re-calibration is noticed.

:func:`update_golden` renders the reference and calibrates the thresholds from
renders at the test spp with the calibration seeds (see
:func:`arches_render.imaging.compare.calibrate`). :func:`check_golden` renders
once at the test spp with a seed that took part in neither and compares. The
renderer is a callable ``render(seed, spp) -> (H, W, 3) array`` supplied by the
caller, so the workflow serves every scene test and knows nothing of Mitsuba.

The reference is calibrated against as stored (rounded to half floats), so
calibration and checks see the same numbers.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from .. import __version__
from ..atomic import atomic_write
from .compare import CalibrationWarning, CompareResult, Thresholds, calibrate, compare
from .exr import HALF_MAX, ExrError, read_exr, write_exr
from .report import check_name, clear_report, write_failure_report

__all__ = ["Golden", "GoldenMissingError", "GoldenError", "RenderFn", "update_golden", "check_golden",
           "load_golden", "golden_paths", "DEFAULT_CHECK_SEED", "REF_SEED", "UPDATE_HINT"]

RenderFn = Callable[[int, int], np.ndarray]
"""``render(seed, spp) -> (H, W, 3)`` linear RGB array (numpy, or anything :func:`numpy.asarray` takes)."""

REF_SEED = 0
"""Seed of the reference render."""

DEFAULT_CHECK_SEED = 17
"""Seed of check renders: unlike the calibration seeds, so a check sees fresh noise."""

UPDATE_HINT = "run `pytest --update-goldens` (or `pytest --update-goldens -k <test>`) to (re)create it"

_FORMAT = 1


class GoldenError(AssertionError):
    """A golden is unusable: inconsistent files, or made for another resolution or spp."""


class GoldenMissingError(FileNotFoundError):
    """The golden files do not exist yet."""


@dataclass
class Golden:
    """A golden reference with its comparison settings, as stored.

    Attributes
    ----------
    name : str
        Golden name (file stem).
    ref : numpy.ndarray
        Reference image, float32 ``(H, W, 3)``, half-float values.
    thresholds : Thresholds
        Calibrated limits.
    test_spp, ref_spp, ref_seed : int
        Samples per pixel of check renders and of the reference; the
        reference's seed.
    calib_seeds : tuple of int
        Seeds of the calibration renders.
    header : dict of str to str
        Metadata stored in the EXR.
    meta : dict
        Everything else in the JSON file (date, versions, caller metadata).
    exr_path, json_path : pathlib.Path
        The two files.
    """

    name: str
    ref: np.ndarray = field(repr=False)
    thresholds: Thresholds
    test_spp: int
    ref_spp: int
    ref_seed: int
    calib_seeds: tuple[int, ...]
    header: dict[str, str] = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    exr_path: Path | None = None
    json_path: Path | None = None

    @property
    def resolution(self) -> tuple[int, int]:
        """``(width, height)`` of the reference."""
        return self.ref.shape[1], self.ref.shape[0]


def golden_paths(name: str, golden_dir: str | os.PathLike) -> tuple[Path, Path]:
    """The ``(NAME.exr, NAME.json)`` paths of golden ``name`` in ``golden_dir``."""
    base = Path(golden_dir) / check_name(name)
    return base.with_name(base.name + ".exr"), base.with_name(base.name + ".json")


def _digest(rgb: np.ndarray) -> str:
    # Hash of the half-float pixels: survives re-compression of the EXR, not a
    # change of its content.
    return hashlib.sha256(np.ascontiguousarray(rgb, dtype=np.float16).tobytes()).hexdigest()


def _as_half(rgb: np.ndarray) -> np.ndarray:
    # The same rounding write_exr applies, so calibration sees the stored values.
    return np.clip(rgb, -HALF_MAX, HALF_MAX).astype(np.float16).astype(np.float32)


def _call_render(render: RenderFn, seed: int, spp: int, what: str) -> np.ndarray:
    img = np.asarray(render(int(seed), int(spp)), dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"render(seed={seed}, spp={spp}) for the {what} returned shape {img.shape}; "
                         f"expected (H, W, 3)")
    return img


def _versions() -> dict[str, str]:
    # Only modules the renderer already imported: importing Mitsuba here would
    # load libLLVM before arches_render.backend could choose it.
    out = {"arches_render": __version__, "python": sys.version.split()[0], "numpy": np.__version__}
    for mod in ("mitsuba", "drjit"):
        m = sys.modules.get(mod)
        if m is not None and getattr(m, "__version__", None):
            out[mod] = str(m.__version__)
    return out


def update_golden(name: str, render: RenderFn, *, ref_spp: int, test_spp: int,
                  calib_seeds: Sequence[int] = (1, 2, 3, 4), golden_dir: str | os.PathLike,
                  meta: Mapping[str, object] | None = None, **calibrate_kwargs) -> Golden:
    """Render and store the reference of golden ``name`` and calibrate its thresholds.

    Parameters
    ----------
    name : str
        Golden name; the files are ``golden_dir/NAME.exr`` and ``NAME.json``.
    render : callable
        ``render(seed, spp) -> (H, W, 3)`` linear RGB; must be deterministic for
        a given seed (use a ``box`` reconstruction filter).
    ref_spp : int
        Samples per pixel of the reference (seed 0); at least 16x ``test_spp``
        so that the reference's own noise is small against the test's.
    test_spp : int
        Samples per pixel of calibration and check renders.
    calib_seeds : sequence of int, optional
        Seeds of the calibration renders (default 1, 2, 3, 4); not 0 nor
        :data:`DEFAULT_CHECK_SEED`.
    golden_dir : str or os.PathLike
        Folder of the goldens (created if missing).
    meta : mapping, optional
        Caller metadata (scene file, camera, ...) stored in both files.
    **calibrate_kwargs
        Passed to :func:`arches_render.imaging.compare.calibrate` (margins).

    Returns
    -------
    Golden
        The stored golden.

    Warns
    -----
    CalibrationWarning
        When ``ref_spp < 16 * test_spp``, or as :func:`calibrate` warns.

    Notes
    -----
    Nothing is written until all renders and the calibration succeeded; the
    EXR and then the JSON are each written atomically. The JSON holds a
    digest of the reference pixels, so a crash between the two writes is
    reported by :func:`check_golden` rather than silently mixing versions.
    """
    exr_path, json_path = golden_paths(name, golden_dir)
    seeds = tuple(int(s) for s in calib_seeds)
    if ref_spp < 1 or test_spp < 1:
        raise ValueError(f"spp must be positive, got ref_spp={ref_spp}, test_spp={test_spp}")
    if not seeds or len(set(seeds)) != len(seeds) or REF_SEED in seeds or DEFAULT_CHECK_SEED in seeds:
        raise ValueError(f"calib_seeds {seeds} must be distinct and differ from the reference seed {REF_SEED} "
                         f"and the check seed {DEFAULT_CHECK_SEED}")
    if ref_spp < 16 * test_spp:
        warnings.warn(f"golden {name!r}: ref_spp={ref_spp} < 16 x test_spp={test_spp}; the reference's own "
                      f"noise will loosen the thresholds", CalibrationWarning, stacklevel=2)

    ref = _call_render(render, REF_SEED, ref_spp, "reference")
    if not np.all(np.isfinite(ref)):
        raise ValueError(f"golden {name!r}: the reference render has NaN or infinite pixels")
    ref = _as_half(ref)
    renders = []
    for s in seeds:
        img = _call_render(render, s, test_spp, f"calibration (seed {s})")
        if img.shape != ref.shape:
            raise ValueError(f"golden {name!r}: calibration render (seed {s}) is {img.shape}, "
                             f"the reference {ref.shape}")
        renders.append(img)
    thresholds = calibrate(ref, renders, **calibrate_kwargs)

    h, w = ref.shape[:2]
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    versions = _versions()
    meta = {str(k): v for k, v in (meta or {}).items()}
    header = {"name": name, "spp": ref_spp, "seed": REF_SEED, "resolution": f"{w}x{h}", "date": now,
              **{f"version.{k}": v for k, v in versions.items()},
              **{f"meta.{k}": v if isinstance(v, str) else json.dumps(v) for k, v in meta.items()}}
    record = {
        "format": _FORMAT, "name": name, "date": now, "resolution": [w, h],
        "reference": {"file": exr_path.name, "spp": ref_spp, "seed": REF_SEED, "pixels_sha256": _digest(ref)},
        "test_spp": test_spp, "calib_seeds": list(seeds), "thresholds": thresholds.to_dict(),
        "versions": versions, "meta": meta,
    }
    exr_path.parent.mkdir(parents=True, exist_ok=True)
    write_exr(exr_path, ref, header=header)
    with atomic_write(json_path, "w", encoding="utf-8") as f:
        json.dump(record, f, indent=2, default=str)
        f.write("\n")
    return Golden(name=name, ref=ref, thresholds=thresholds, test_spp=test_spp, ref_spp=ref_spp,
                  ref_seed=REF_SEED, calib_seeds=seeds, header={k: str(v) for k, v in header.items()},
                  meta=record, exr_path=exr_path, json_path=json_path)


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
        When the files are unreadable or do not belong together.
    """
    exr_path, json_path = golden_paths(name, golden_dir)
    missing = [p for p in (exr_path, json_path) if not p.is_file()]
    if missing:
        raise GoldenMissingError(f"golden {name!r} is missing ({', '.join(map(str, missing))}): {UPDATE_HINT}")
    try:
        record = json.loads(json_path.read_text(encoding="utf-8"))
        thresholds = Thresholds.from_dict(record["thresholds"])
        ref_info = record["reference"]
        test_spp, calib = int(record["test_spp"]), tuple(int(s) for s in record["calib_seeds"])
    except (ValueError, KeyError, TypeError) as e:
        raise GoldenError(f"golden {name!r}: cannot read {json_path} ({e!r}); {UPDATE_HINT}") from e
    try:
        img = read_exr(exr_path)
    except ExrError as e:
        raise GoldenError(f"golden {name!r}: {e}; {UPDATE_HINT}") from e
    if _digest(img.rgb) != ref_info.get("pixels_sha256"):
        raise GoldenError(f"golden {name!r}: {exr_path.name} does not match the reference recorded in "
                          f"{json_path.name} (replaced without re-calibration?); {UPDATE_HINT}")
    return Golden(name=name, ref=img.rgb, thresholds=thresholds, test_spp=test_spp,
                  ref_spp=int(ref_info["spp"]), ref_seed=int(ref_info.get("seed", REF_SEED)), calib_seeds=calib,
                  header=img.header, meta=record, exr_path=exr_path, json_path=json_path)


def check_golden(name: str, render: RenderFn, *, golden_dir: str | os.PathLike,
                 report_dir: str | os.PathLike, seed: int | None = None, ref_spp: int | None = None,
                 test_spp: int | None = None) -> CompareResult:
    """Render at the golden's test spp and compare with its reference.

    Parameters
    ----------
    name : str
        Golden name.
    render : callable
        ``render(seed, spp) -> (H, W, 3)`` linear RGB, as for :func:`update_golden`.
    golden_dir : str or os.PathLike
        Folder of the goldens.
    report_dir : str or os.PathLike
        Root of failure reports; a failure writes ``report_dir/NAME/``, a pass
        removes a stale report of that name.
    seed : int, optional
        Seed of the check render (default :data:`DEFAULT_CHECK_SEED`); must
        differ from the reference and calibration seeds, whose noise the
        thresholds were fitted to.
    ref_spp, test_spp : int, optional
        What the calling test asks for; when given and different from what the
        golden was made with, the golden is stale and the check fails.

    Returns
    -------
    CompareResult
        The passing result.

    Raises
    ------
    GoldenMissingError
        When the golden does not exist (message: run ``pytest --update-goldens``).
    GoldenError
        (an :class:`AssertionError`) when the golden is stale or inconsistent.
    AssertionError
        When the comparison fails; the message names the failed checks and the
        report folder.
    """
    g = load_golden(name, golden_dir)
    seed = DEFAULT_CHECK_SEED if seed is None else int(seed)
    if seed == g.ref_seed or seed in g.calib_seeds:
        raise ValueError(f"check seed {seed} was used to make golden {name!r} (reference {g.ref_seed}, "
                         f"calibration {g.calib_seeds}); pick another")
    stale = [f"{k} {want} (golden has {have})" for k, want, have in
             (("ref_spp", ref_spp, g.ref_spp), ("test_spp", test_spp, g.test_spp))
             if want is not None and int(want) != have]
    if stale:
        raise GoldenError(f"golden {name!r} is stale: the test asks for {', '.join(stale)}; {UPDATE_HINT}")

    test = _call_render(render, seed, g.test_spp, "check")
    if test.shape != g.ref.shape:
        raise GoldenError(f"golden {name!r}: the render is {test.shape[1]}x{test.shape[0]} pixels, the golden "
                          f"{g.ref.shape[1]}x{g.ref.shape[0]}; if that is intended, {UPDATE_HINT}")
    result = compare(g.ref, test, g.thresholds)
    if result.passed:
        clear_report(report_dir, name)
        return result
    page = write_failure_report(report_dir, name, g.ref, test, result)
    reasons = "\n".join(f"  - {f}" for f in result.failures)
    raise AssertionError(f"golden {name!r} failed (seed {seed}, {g.test_spp} spp):\n{reasons}\n"
                         f"report: {page.parent} (open {page.name}); if the change is intended, {UPDATE_HINT}")
