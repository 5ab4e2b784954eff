"""Make synthetic DEMs shaped by a landscape-evolution model, into ``scenes/data/``.

Each DEM starts from fBm on a plain or a ramp and goes through uplift, implicit
stream-power incision, thermal erosion with rock-dependent talus angles and creep
(:mod:`generators.terrain.landscape_evolution`), at real scales (metres, years):

``eroded_coast``    384^2 at 20 m (7.7 km): an uplifted coastal range drained by
                    rivers into a sea whose floor reaches -100 m at the south edge;
                    waves cut the shore (cliffs) and the floor stays below 0 m.
``eroded_canyon``   512^2 at 10 m (5.1 km): a plateau of hard and soft strata, uplifted
                    300 m while a river entering from the west (2,000 km^2 of upstream
                    catchment) keeps its course to the east: a meandering canyon with
                    stepped walls and side canyons.
``eroded_mesas``    384^2 at 15 m (5.8 km): a caprock plateau dissected from all four
                    edges until mesas and buttes stand above a soft-rock plain.

Files: ``scenes/data/NAME.npy`` (float32 metres, row ``j`` at ``y = y0 + j cell``),
described in ``scenes/data/DEMS.md``. With ``--preview DIR`` a hillshade PNG per DEM
goes to ``DIR`` (not shipped).

Run from the repository root (about a minute per DEM on two cores)::

    python examples/make_eroded_dems.py [--preview out/eroded] [NAME ...]

Everything is seeded: the same command writes the same bytes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

import arches_render  # noqa: E402,F401  (points Dr.Jit at a good libLLVM first)
from arches_render.generators.terrain import landscape_evolution as le  # noqa: E402
from arches_render.field.heightmaps import fbm_heightmap  # noqa: E402


def _fbm(n, cell, wavelength, seed, octaves=7):
    """fBm in ``[-1, 1]`` on an ``n x n`` grid of ``cell`` metres."""
    L = (n - 1) * cell
    return 2.0 * fbm_heightmap((0, 0, L, L), (n, n), 1.0, wavelength, octaves, seed=seed) - 1.0


def _bar(name):
    t0 = time.perf_counter()

    def progress(done, total):
        if done == total or done % max(1, total // 20) == 0:
            w = 30 * done // total
            print(f"\r{name:15s} [{'#' * w}{'.' * (30 - w)}] {done}/{total} {time.perf_counter() - t0:5.1f} s",
                  end="" if done < total else "\n", flush=True)
    return progress


def coast():
    n, cell = 384, 20.0
    y = np.arange(n)[:, None] * cell / ((n - 1) * cell)  # 0 at the south edge, 1 north
    noise = _fbm(n, cell, 2500.0, seed=11)
    # A ramp from -100 m offshore to +60 m inland, its shoreline made irregular by the
    # noise (headlands and bays); uplift only where the initial surface is land-ish,
    # so the sea floor keeps its shape and the range rises behind the coast.
    h0 = -90.0 + 170.0 * y + 60.0 * noise
    uplift = 6e-4 * np.clip((h0 + 10.0) / 60.0, 0.0, 1.0)
    out = le.edge_outlets((n, n), "s")
    params = dict(steps=150, dt=4000.0, uplift=uplift, K=2e-5, outlets=out, talus_deg=33.0,
                  strata=le.Strata.alternating(-300.0, 200.0, 60.0, 0.35, seed=13, hard_k_factor=0.2,
                                               hard_talus_deg=60.0),
                  diffusivity=0.01, sea_level=0.0, wave_rate=5e-4)
    return n, cell, h0, params, 0.0


def _meander(n, cell, j_in, j_out, amplitude, wavelength, seed):
    """Row of a meandering river course at each column (a sine-generated path plus fBm)."""
    x = np.arange(n) * cell
    wobble = _fbm(n, cell, 0.7 * wavelength, seed=seed, octaves=3)[n // 2]
    base = j_in + (j_out - j_in) * x / x[-1]
    return base + (amplitude * np.sin(2 * np.pi * x / wavelength) + 0.6 * amplitude * wobble) / cell


def canyon():
    n, cell = 512, 10.0
    x = np.arange(n)[None, :] / (n - 1.0)
    noise = _fbm(n, cell, 1500.0, seed=21)
    h0 = 4.0 * noise + 2.0 * (1.0 - x)  # a plain tilted gently to the east
    # The river meandered on the plain before the uplift: a shallow channel that it keeps
    # while cutting down (entrenched meanders, as on the San Juan and Colorado rivers).
    j_in, j_out = n // 2 - 60, n // 2 + 40
    course = _meander(n, cell, j_in, j_out, 700.0, 2600.0, seed=22)
    rows = np.arange(n)[:, None]
    h0 -= 3.0 * np.exp(-0.5 * ((rows - course[None, :]) * cell / 25.0) ** 2)
    out = np.zeros((n, n), dtype=bool)
    out[int(round(course[-1])), -1] = True  # the river leaves through one cell of the east edge
    inflow = np.zeros((n, n))
    inflow[int(round(course[0])), 0] = 2.0e9  # and enters from the west with a large catchment
    params = dict(steps=200, dt=5000.0, uplift=3e-4, K=3e-5, outlets=out, inflow=inflow, talus_deg=35.0,
                  strata=le.Strata.alternating(-400.0, 20.0, 60.0, 0.35, seed=23, hard_k_factor=0.08, hard_talus_deg=72.0),
                  diffusivity=0.005)
    return n, cell, h0, params, 1500.0


def mesas():
    n, cell = 384, 15.0
    L = (n - 1) * cell
    noise = _fbm(n, cell, 1800.0, seed=31)
    # A dome of uplift with a ragged outline (a monocline-bounded upwarp, like the
    # Monument Upwarp): the plain around it stays at base level, so no escarpment follows
    # the tile's edges; the dome's flanks retreat into mesas and buttes.
    y, x = np.mgrid[0:n, 0:n] * cell
    r = np.hypot(x - 0.5 * L, y - 0.5 * L) / (0.5 * L)
    t = np.clip((1.0 - r ** 2) + 0.45 * _fbm(n, cell, 2500.0, seed=34, octaves=4), 0.0, 0.35) / 0.35
    uplift = 3e-4 * t * t * (3.0 - 2.0 * t)
    h0 = 3.0 * noise
    out = le.edge_outlets((n, n), "nsew")
    params = dict(steps=240, dt=5000.0, uplift=uplift, K=4e-5, outlets=out, talus_deg=30.0,
                  strata=le.Strata.alternating(-400.0, 20.0, 110.0, 0.3, seed=33, hard_k_factor=0.04,
                                               hard_talus_deg=75.0),
                  diffusivity=0.005)
    return n, cell, h0, params, 1200.0


DEMS = {"eroded_coast": coast, "eroded_canyon": canyon, "eroded_mesas": mesas}


def hillshade_png(H, cell, path, sea_level=None, width=960):
    """Write a hillshade (sun from the north-west, 40 deg) tinted by elevation, north up."""
    from PIL import Image
    gy, gx = np.gradient(H, cell)
    # Rows run south to north: the image is flipped so that north is up.
    nrm = np.stack([-gx, -gy, np.ones_like(H)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    az, alt = np.radians(315.0), np.radians(40.0)
    sun = np.array([np.sin(az) * np.cos(alt), np.cos(az) * np.cos(alt), np.sin(alt)])
    s = np.clip(nrm @ sun, 0.0, 1.0)
    z = (H - H.min()) / max(float(np.ptp(H)), 1e-9)
    rgb = np.stack([0.42 + 0.5 * z, 0.40 + 0.38 * z, 0.30 + 0.3 * z], -1) * (0.2 + 0.8 * s[..., None])
    if sea_level is not None:
        w = H < sea_level
        depth = np.clip((sea_level - H) / 100.0, 0, 1)[..., None]
        rgb = np.where(w[..., None], (np.array([0.15, 0.35, 0.55]) * (1 - 0.5 * depth)) * (0.6 + 0.4 * s[..., None]),
                       rgb)
    img = Image.fromarray((np.clip(rgb[::-1], 0, 1) * 255).astype(np.uint8))
    img.resize((width, int(round(width * H.shape[0] / H.shape[1]))), Image.LANCZOS).save(path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("names", nargs="*", metavar="NAME", help=f"any of {', '.join(DEMS)} (default: all)")
    ap.add_argument("--out", type=Path, default=REPO / "scenes" / "data")
    ap.add_argument("--preview", type=Path, default=None, help="folder for hillshade PNGs")
    args = ap.parse_args(argv)
    unknown = sorted(set(args.names) - set(DEMS))
    if unknown:
        ap.error(f"unknown DEM {', '.join(unknown)}; allowed: {', '.join(DEMS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.names or list(DEMS):
        n, cell, h0, params, base = DEMS[name]()
        # The model runs relative to base level; ``base`` puts it at a plausible altitude.
        H = le.evolve(h0, cell, progress=_bar(name), **params) + base
        np.save(args.out / f"{name}.npy", H.astype(np.float32))
        print(f"{name}: {n}x{n} at {cell:g} m, heights {H.min():.1f} .. {H.max():.1f} m")
        if args.preview:
            args.preview.mkdir(parents=True, exist_ok=True)
            hillshade_png(H, cell, args.preview / f"{name}.png", 0.0 if "sea_level" in params else None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
