"""Issue 38: fields that lie flat next to their surface, and points that are not numbers.

The ``every_generator`` scene crashed (SIGSEGV) in mesh mode with AOVs. Its ``blocks``
node is clamped at ``-margin`` in the air, so next to a steep host the field is flat
where marching cubes puts some vertices: their field normal was zero, Mitsuba's
interpolated shading normal NaN on the faces whose three vertices had one, and the
``albedo`` AOV shaded those hits (the cavity term marches the field from ``p`` along
the normal): NaN points reached the blocks' and brick grids' cell lookups, whose
``UInt32(clip(NaN))`` index read gigabytes past their arrays. These tests pin both
halves: the mesh's normals, and lookups that stay inside their arrays for any point.
"""

from __future__ import annotations

import math

import numpy as np

from helpers import REPO, variant

variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from arches_render.field.node import cell_index, clip_index  # noqa: E402
from arches_render.mesh.polygonize import field_normals, polygonize, shading_normals  # noqa: E402
from arches_render.scene import load_scene  # noqa: E402

EVERY = REPO / "scenes" / "gallery" / "every_generator.toml"

# A box wall under columnar blocks whose clamp (margin 5 cm) is thin against the 0.5 m
# voxel: the field is flat at -0.05 m where marching cubes puts the vertices of the
# wall's bottom and top faces (measured: about 190 of 2,900 vertices).
FLAT_BLOCKS = """
[camera]
origin = [8.0, -5.0, -6.0]
target = [-2.0, 0.0, 0.0]
[[lights]]
type = "constant"
[materials.rock]
type = "triplanar"
preset = "basalt"
cavity = true
[field]
root = "cliff"
material = "rock"
[nodes.cliff]
type = "blocks"
host = { type = "box", center = [-4.0, 0.0, 4.0], size = [8.0, 14.0, 8.0] }
margin = 0.05
structure = "columnar"
tile_size = 10.0
spacing = 1.1
region = [-2.5, -7.0, 0.0, 2.5, 7.0, 8.5]
min_slope = 60.0
seed = 4
"""


def _odd_points():
    """NaN, infinities, huge and ordinary coordinates, mixed per axis."""
    odd = [math.nan, math.inf, -math.inf, 3e30, -3e30, 0.0, 5.0, -5.0]
    pts = np.array([(x, y, z) for x in odd for y in odd for z in odd], np.float32)
    return mi.Point3f(*(mi.Float(pts[:, i]) for i in range(3)))


def test_cell_index_is_inside_the_grid_for_any_float():
    x = mi.Float([math.nan, math.inf, -math.inf, 3e30, -3e30, -0.5, 0.0, 2.7, 6.99, 7.0, 9.0])
    assert cell_index(x, 7).numpy().tolist() == [0, 6, 0, 6, 0, 0, 0, 2, 6, 6, 6]
    assert cell_index(x, 7, mi.Int32).numpy().tolist() == [0, 6, 0, 6, 0, 0, 0, 2, 6, 6, 6]
    assert clip_index(x, -2.0, 9.5).numpy().tolist() == [-2.0, 9.5, -2.0, 9.5, -2.0, -0.5, 0.0,
                                                          np.float32(2.7), np.float32(6.99), 7.0, 9.0]


def test_every_node_of_the_combined_scene_reads_inside_its_arrays_at_any_point(capfd):
    """Dr.Jit's debug mode checks every gather's index: before the fix the blocks' world cells
    and the brick grid's top level read out of bounds at NaN points (and the render died)."""
    desc = load_scene(EVERY)
    nodes = list(desc.field.walk())
    kinds = {n.kind for n in nodes}
    assert {"blocks_field", "skeletal_set", "layers", "implicit_heightfield"} <= kinds, kinds
    p = _odd_points()
    dr.set_flag(dr.JitFlag.Debug, True)
    try:
        for node in nodes:
            f = node.eval(p)
            g, ds = node.eval_bounds(p, (0.0,))
            dr.eval(f, g, ds)
            dr.sync_thread()
    finally:
        dr.set_flag(dr.JitFlag.Debug, False)
    err = capfd.readouterr().err
    assert "out-of-bounds" not in err, err[:2000]


def test_marching_cubes_normals_are_unit_where_the_field_is_flat(tmp_path):
    scene = tmp_path / "flat.toml"
    scene.write_text(FLAT_BLOCKS)
    desc = load_scene(scene)
    mesh = polygonize(desc.field, 0.5)
    v, f, n = mesh.vertices.astype(np.float64), mesh.faces.astype(np.int64), mesh.normals.astype(np.float64)
    raw = field_normals(desc.field, v, 0.25 * 0.5)
    flat = np.linalg.norm(raw, axis=1) < 0.5
    assert flat.sum() >= 50, flat.sum()  # the case this test is about
    assert np.isfinite(n).all()
    # 1e-5: unit normals stored in float32 (norm error ~1e-7); a NaN or zero normal fails by far.
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    # Elsewhere the field's own normals are kept (where they face the way their faces do).
    geo = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    ring = sum(np.stack([np.bincount(f[:, k], weights=geo[:, c], minlength=len(v)) for c in range(3)], 1)
               for k in range(3))
    kept = ~flat & (np.einsum("ij,ij->i", raw, ring) > 0)
    assert kept.sum() > 0.9 * (~flat).sum()
    np.testing.assert_array_equal(n[kept], raw[kept])
    # A flat vertex's normal faces the way its faces do (the mesh is wound outwards, by
    # the field's normals); marching cubes leaves a few faces of zero area, which face no way.
    geo = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    proper = np.linalg.norm(geo, axis=1) > 0
    for k in range(3):
        on = proper & flat[f[:, k]]
        assert on.sum() > 50 and (np.einsum("ij,ij->i", geo[on], n[f[on, k]]) > 0).all()


def test_shading_normals_replace_flat_and_backward_field_normals_by_their_faces():
    """A vertex normal that is zero, NaN, or faces away from the vertex's faces (a feature
    below the voxel: the gradient sees it, the coarse faces do not; such a normal renders
    black, below its shading frame's horizon) becomes its faces' area-weighted normal;
    usable normals stay bit for bit."""
    # Two triangles of a unit square in z = 0, wound up (+z), and a third tilted one.
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 1]], np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 2]], np.int64)
    geo = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    tilt = np.array([0.6, 0.0, 0.8], np.float32)
    normals = np.array([[0, 0, -1],            # backward: faces +z
                        [0, 0, 0],             # flat
                        [np.nan, 0, 0],        # not a number
                        tilt,                  # usable, kept
                        [0.0, 0.6, 0.8]], np.float32)  # usable (faces its one face's way), kept
    out = shading_normals(normals, f, geo)
    assert out.dtype == np.float32 and np.isfinite(out).all()
    # 1e-6: unit vectors normalised in double and stored in float32 (a few ulps of 6e-8
    # each); a zero, NaN or unnormalised normal fails by far.
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-6)
    np.testing.assert_array_equal(out[0], [0, 0, 1])
    for k in (1, 2):  # the normals of faces (0, 1, 2) and (1, 4, 2), area-weighted
        ring = geo[(f == k).any(axis=1)].sum(axis=0)
        # (1e-6: the float32 rounding of the stored normal, as above)
        np.testing.assert_allclose(out[k], ring / np.linalg.norm(ring), atol=1e-6)
    np.testing.assert_array_equal(out[3:], normals[3:])
    # All usable: returned as they are.
    good = np.tile(np.float32([0, 0, 1]), (5, 1))
    good[4] = geo[2] / np.linalg.norm(geo[2])
    assert shading_normals(good, f, geo) is good
