"""Landscape evolution (generators/terrain/landscape_evolution.py): small grids, each test
checks a property of the model that a wrong routing, order or scheme would break."""

from __future__ import annotations

import numpy as np
import pytest

from arches_render.generators.terrain import landscape_evolution as le


def _noise(n, seed=0, amp=1.0):
    return amp * np.random.default_rng(seed).random((n, n))


def test_route_flow_topological_order_and_closed_edges():
    H = _noise(30, 1, 5.0)
    out = np.zeros(H.shape, bool)
    out[0, 12] = True  # one outlet: every other edge is closed
    inflow = np.zeros(H.shape)
    inflow[-1, 5] = 1e6
    f = le.route_flow(H, 10.0, out, inflow)
    pos = np.empty(H.size, int)
    pos[f["order"]] = np.arange(H.size)
    rec = f["receiver"]
    inner = rec >= 0
    assert len(f["order"]) == H.size and (rec < 0).sum() == 1
    assert np.all(pos[rec[inner]] < pos[inner]), "a receiver must come before its donors"
    # All water (cells and the inflow) leaves through the single outlet.
    assert f["area"][0, 12] == pytest.approx(H.size * 100.0 + 1e6)


def test_stream_power_reaches_the_slope_area_law():
    """At steady state the implicit step gives K A^m S = U exactly (Braun & Willett 2013)."""
    H = _noise(40, 2)
    out = le.edge_outlets(H.shape, "s")
    K, U, cell = 2e-5, 1e-3, 50.0
    for _ in range(400):
        new, _ = le.stream_power_step(H, cell, 2e4, U, K, out)
        change = np.abs(new - H).max()
        H = new
        if change < 1e-9:
            break
    assert change < 1e-9, "no steady state"
    f = le.route_flow(H, cell, out)
    rec, h, A = f["receiver"], H.ravel(), f["area"].ravel()
    ok = rec >= 0
    S = (h[ok] - h[rec[ok]]) / f["distance"][ok]
    assert H.max() > 50.0  # a real relief, not a flat tile
    np.testing.assert_allclose(K * A[ok] ** 0.5 * S / U, 1.0, rtol=1e-6)


def test_implicit_step_is_stable_for_any_dt():
    H = _noise(24, 3, 10.0)
    out = le.edge_outlets(H.shape, "nsew")
    new, _ = le.stream_power_step(H, 10.0, 1e9, 1e-3, 1e-4, out)
    assert np.all(np.isfinite(new))
    assert np.all(new <= H + 1e-3 * 1e9 + 1e-6) and np.all(new >= H[out].min() - 1e-9)


def test_thermal_erosion_conserves_mass_and_reaches_the_talus_angle():
    H = np.zeros((21, 21))
    H[8:13, 8:13] = 50.0  # a block with vertical walls
    cell, talus = 5.0, 35.0
    T = le.thermal_erosion(H, cell, talus, iterations=4000)
    assert T.sum() == pytest.approx(H.sum(), rel=1e-12)
    lim = np.tan(np.radians(talus)) * cell
    steps = np.concatenate([np.abs(np.diff(T, axis=0)).ravel(), np.abs(np.diff(T, axis=1)).ravel()])
    assert steps.max() <= 1.02 * lim  # no wall steeper than the talus (2 % of convergence slack)
    assert T.max() < 50.0 and T.max() > 5.0


def test_diffusion_damps_the_checkerboard_mode():
    """Sub-steps at half the CFL bound damp the grid-scale mode (at the bound it flips sign)."""
    j, i = np.mgrid[0:16, 0:16]
    H = np.where((i + j) % 2 == 0, 1.0, -1.0)
    D, cell = 0.25, 1.0
    out = le.diffuse(H, cell, D, 1.0)  # exactly dx^2 / (4 D): one step at the bound
    assert np.abs(out[4:-4, 4:-4]).max() < 0.5


def test_strata_layers_and_determinism():
    s = le.Strata.alternating(0.0, 100.0, 20.0, 0.3, jitter=0.0)
    z = np.array([1.0, 13.0, 15.0, 19.9, 21.0])
    np.testing.assert_array_equal(s.is_hard(z), [False, False, True, True, False])
    H0 = _noise(32, 4, 2.0)
    kw = dict(steps=6, dt=5e3, uplift=2e-3, K=2e-5, outlets=le.edge_outlets(H0.shape, "we"),
              strata=le.Strata.alternating(-50.0, 10.0, 15.0, seed=1), diffusivity=0.01)
    a = le.evolve(H0, 20.0, **kw)
    b = le.evolve(H0, 20.0, **kw)
    assert np.array_equal(a, b)
    assert a.max() > H0.max()  # uplift outpaced erosion on the interfluves
