"""``auto`` ranks the presets by what they make (issue 34; generators/terrain/preset_ranking.py):
the order rule, and the visible 3-D volume it ranks by (buried tunnels do not count, cave
mouths do)."""

from __future__ import annotations

import numpy as np

from arches_render import field as F
from arches_render.backend import variant
from arches_render.generators.terrain.preset_ranking import MIN_LANDFORMS, rank_order, ranking_line
from arches_render.generators.terrain.shots import landform_volume


def test_the_dems_choice_stays_first_while_it_makes_a_landform_a_shot_else_all_go_by_volume():
    assert MIN_LANDFORMS == 3.0  # one landform for each of the three close shots
    # The choice makes 3 landforms of 1 m: first; the others by volume, nothing last.
    assert rank_order([3.0, 10.0, 50.0, 0.0], [1.0] * 4) == [0, 2, 1, 3]
    # 23.9 m^3 is under three landforms of 2 m (24 m^3): by volume; ties keep the candidates' order.
    assert rank_order([23.9, 30.0, 30.0, 0.0], [2.0, 1.0, 1.0, 1.0]) == [1, 2, 0, 3]
    assert rank_order([24.0, 30.0], [2.0, 1.0]) == [0, 1]  # exactly three landforms are enough
    assert rank_order([0.0, 0.0], [1.0, 1.0]) == [0, 1]
    # One landform and a third (the river on the Maunga Whau cone) is not a subject.
    assert rank_order([1.35 * 5.84 ** 3, 1.06e6], [5.84, 10.0]) == [1, 0]


def test_the_ranking_line_says_what_each_made_in_the_order_tried():
    line = ranking_line(["karst", "strata", "river"], [0.0, 2e6, 3e4], [10.0, 100.0, 20.0], [0, 30, 12],
                        rank_order([0.0, 2e6, 3e4], [10.0, 100.0, 20.0]), ["no tunnel", None, None])
    assert line.index("strata 2e+06 m3") < line.index("river 3e+04 m3") < line.index("karst nothing (no tunnel)")
    assert "2 landforms of 100 m (30 primitives)" in line and "3.75 landforms of 20 m (12 primitives)" in line
    assert line.endswith("Order: by volume (karst, the DEM's choice, makes under 3 landforms)")


def test_buried_tunnels_are_not_seen_from_the_air_but_cave_mouths_are():
    variant()
    ground = F.Box((0.0, 0.0, -30.0), (50.0, 50.0, 30.0))  # rock from below the box (z = -60) to z = 0
    # A tunnel of radius 5 with 7 m of rock above it, inside the block...
    buried = F.Difference(ground, F.Capsule((-30.0, 0.0, -12.0), (30.0, 0.0, -12.0), 5.0))
    # ...and the same tunnel running out of the block's side (a cave mouth in a cliff at x = 50).
    mouth = F.Difference(ground, F.Capsule((-30.0, 0.0, -12.0), (80.0, 0.0, -12.0), 5.0))
    box = (np.array([-60.0, -20.0, -45.0]), np.array([60.0, 20.0, 10.0]))
    reach = 6.0
    whole_buried, voxel = landform_volume(buried, ground, box, cells=96)
    seen_buried, _ = landform_volume(buried, ground, box, cells=96, reach=reach)
    whole_mouth, _ = landform_volume(mouth, ground, box, cells=96)
    seen_mouth, _ = landform_volume(mouth, ground, box, cells=96, reach=reach)
    tube = np.pi * 5.0 ** 2
    # Without reach the buried tunnel is a 60 m tube and more (its round ends), voxelized.
    assert 0.8 * tube * 60.0 < whole_buried < 1.2 * tube * 70.0, (whole_buried, voxel)
    assert seen_buried == 0.0
    # With reach: the first 6 m inside the mouth (plus a voxel of discretisation), not the 80 m behind.
    assert 0.5 * tube * reach < seen_mouth < tube * (reach + 2 * voxel) < whole_mouth, (seen_mouth, whole_mouth)
