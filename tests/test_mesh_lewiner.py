"""The compiled Lewiner marching cubes (arches_render.mesh.lewiner) in its ``exact`` mode:
scikit-image's ``marching_cubes`` bit for bit (vertices, faces, normals), at any level
and step, or a declined volume, never a different mesh."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from skimage.measure import marching_cubes

from arches_render.mesh import lewiner

# Cases with face or interior tests that the kernel leaves to scikit-image (3, 4, 6 are resolved).
_DECLINED = (7, 10, 12, 13)


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint8)


def _same_as_scikit_image(vol, level, step):
    """True when the kernel took the volume (and then gave scikit-image's arrays bit
    for bit), False when it declined it."""
    sub = np.ascontiguousarray(vol[::step, ::step, ::step])
    ok, g, keys, share, f, n = lewiner.plain_volume(sub, level, step)
    if not ok:
        return False
    try:
        v, ff, nn, _ = marching_cubes(vol, level, step_size=step, allow_degenerate=False)
    except RuntimeError:  # "No surface found"
        assert len(f) == 0 and len(g) == 0
        return True
    assert g.dtype == v.dtype == np.float32 and n.dtype == nn.dtype == np.float32
    np.testing.assert_array_equal(_bits(g), _bits(v))
    np.testing.assert_array_equal(f, ff)
    np.testing.assert_array_equal(_bits(n), _bits(nn))
    assert np.all(keys == -1) and not share.any()
    return True


def test_every_cube_configuration_is_scikit_images_or_declined():
    """One cube per configuration (random corner values, some at the level): taken
    configurations match scikit-image bit for bit (cases 3, 4 and 6 through their face
    and interior tests), and only cases 7, 10, 12 and 13 are declined."""
    T = lewiner.lewiner_tables()
    rng = np.random.default_rng(1)
    taken, declined = 0, 0
    resolved = {3: 0, 4: 0, 6: 0}
    for idx in range(1, 255):
        for trial in range(12):
            level = (0.0, 0.5, -0.25, 0.5)[trial % 4]
            mags = rng.uniform(0.05, 1.0, 8)
            vol = np.empty((2, 2, 2), np.float32)
            for c, (di, dj, dk) in enumerate(T["corner"]):
                vol[di, dj, dk] = level + (mags[c] if (idx >> c) & 1 else -mags[c])
            if trial % 4 == 3:
                vol[0, 0, 0] = level  # a corner on the surface
            case = T["cases"][sum(1 << c for c, (di, dj, dk) in enumerate(T["corner"])
                                  if np.float64(vol[di, dj, dk]) - level > 0), 0]
            if _same_as_scikit_image(vol, level, 1):
                taken += 1
                if case in resolved:
                    resolved[case] += 1
                assert case not in _DECLINED
            else:
                declined += 1
                assert case in _DECLINED
    assert taken > 1500 and declined > 500 and min(resolved.values()) > 50  # measured 2472, 576, >= 96


def _blobs(seed, shape=(23, 26, 21)):
    """Sums of a few random Gaussian bumps, zero border: rock-like volumes whose
    level sets have saddles (case 3 cubes) where two bumps meet."""
    rng = np.random.default_rng(seed)
    x = np.stack(np.meshgrid(*(np.arange(n, dtype=np.float64) for n in shape), indexing="ij"), -1)
    vol = np.zeros(shape)
    for _ in range(4):
        c = rng.uniform(5, np.array(shape) - 5)
        r = rng.uniform(2.0, 4.5)
        vol += rng.uniform(0.5, 1.0) * np.exp(-0.5 * ((x - c) ** 2).sum(-1) / r ** 2)
    vol += 0.25 * ndimage.gaussian_filter(rng.uniform(-1, 1, shape), 1.0)  # a rough surface
    vol[[0, -1]] = vol[:, [0, -1]] = vol[:, :, [0, -1]] = 0.0
    return vol.astype(np.float32)


def _cases(vol, level):
    """Lewiner's case of every cube of ``vol`` at ``level``."""
    T = lewiner.lewiner_tables()
    b = np.float64(vol) - level > 0
    idx = np.zeros(np.subtract(vol.shape, 1), np.int64)
    for c, (di, dj, dk) in enumerate(T["corner"]):
        idx |= b[di:di + idx.shape[0], dj:dj + idx.shape[1], dk:dk + idx.shape[2]].astype(np.int64) << c
    return T["cases"][idx, 0]


@pytest.mark.parametrize("step", [1, 2, 3])
def test_volumes_match_scikit_image_bit_for_bit(step):
    """Whole volumes at three levels and each step: vertex order, faces, winding and
    normals (scikit-image's accumulated corner gradients) equal bit for bit, cubes of
    cases 3, 4 and 6 included; declined volumes are those with another ambiguous case."""
    taken = with_ambiguous = 0
    for seed in range(8):
        vol = _blobs(seed)
        for level in (0.3, 0.5, 0.62):
            cases = _cases(vol[::step, ::step, ::step], level)
            ok = _same_as_scikit_image(vol, level, step)
            assert ok == (not np.isin(cases, _DECLINED).any())
            taken += ok
            with_ambiguous += ok and np.isin(cases, (3, 4, 6)).any()
    assert taken >= 18 and with_ambiguous >= 1  # measured: 24 of 24, 4 to 7 with such cubes


def test_level_outside_the_values_gives_no_surface():
    vol = _blobs(3)
    ok, g, _, _, f, n = lewiner.plain_volume(vol, 2.0, 1)
    assert ok and len(g) == len(f) == len(n) == 0


def test_degenerate_faces_are_declined():
    """A corner barely inside, away from the origin: its edges' vertices round to it in
    float32 and the faces degenerate, which scikit-image's ``allow_degenerate=False``
    removes (merging vertices). The kernel declines such a volume instead of emitting
    a different mesh."""
    vol = np.full((2, 2, 3), -1.0, np.float32)
    vol[1, 1, 1] = 1e-30
    _, f_all, _, _ = marching_cubes(vol, 0.0, allow_degenerate=True)
    _, f_kept, _, _ = marching_cubes(vol, 0.0, allow_degenerate=False)
    assert len(f_kept) < len(f_all)
    ok, g, _, _, f, n = lewiner.plain_volume(vol, 0.0, 1)
    assert not ok and len(g) == len(f) == 0
    vol[1, 1, 1] = 0.5  # well inside: taken, as scikit-image
    assert _same_as_scikit_image(vol, 0.0, 1)
