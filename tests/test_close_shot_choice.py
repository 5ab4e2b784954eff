"""The close shots' choice and their sun (issue 34; generators/terrain/shots.py, "Choice",
and scene_writer.sun_for): the sun behind the first shot and out of every view, later
shots turned from it, height classes, and landforms in 1 % of the frame first."""

from __future__ import annotations

import math

import numpy as np


def test_one_sun_lights_the_close_shot_from_behind_and_never_looks_into_the_overview():
    from arches_render.generators.terrain.scene_writer import SUN_CLEAR, sun_for
    # One view: behind it, turned aside by 55 degrees (as before the overview had a say).
    assert sun_for({"azimuth": 30.0})["azimuth"] == -95.0  # 30 + 180 + 55, wrapped
    # An overview that does not face the first view's sun leaves it where it was.
    assert sun_for([{"azimuth": 30.0}, {"azimuth": 60.0}])["azimuth"] == -95.0
    # A close shot looking east and an overview looking west: the sun moves off the
    # overview's axis (SUN_CLEAR) and stays nearest behind-aside for the shot.
    assert SUN_CLEAR == 60.0
    sun = sun_for([{"azimuth": 0.0}, {"azimuth": 180.0}])["azimuth"]
    assert abs(abs(sun) - 120.0) < 1e-9, sun
    # Any pair: neither view looks into the sun.
    rng = np.random.default_rng(4)
    for a, b in rng.uniform(-180.0, 180.0, (200, 2)):
        sun = sun_for([{"azimuth": a}, {"azimuth": b}])["azimuth"]
        for view in (a, b):
            assert abs((sun - view + 180.0) % 360.0 - 180.0) >= SUN_CLEAR, (a, b, sun)


def _view(landform, position_deg, score, cover=0.3, volume=100.0):
    """A close-shot candidate 100 m from its landform at the origin, at ``position_deg``
    around it (so it looks towards ``position_deg + 180``)."""
    from arches_render.generators.terrain.shots import Shot
    a = math.radians(position_deg)
    return Shot(origin=np.array([100.0 * math.cos(a), 100.0 * math.sin(a), 10.0]), target=np.zeros(3), fov=50.0,
                cover=cover, volume_m3=volume, azimuth=a, landform=landform, score=score)


def test_later_close_shots_turn_away_from_the_sun_chosen_for_the_first():
    from arches_render.generators.terrain.shots import choose_shots, view_azimuth
    # Landform 0 (the largest): views from 0, 90 and 180 degrees around it, best first;
    # landform 1: its best view looks the same way as landform 0's first.
    views = [[_view(0, 0.0, 3.0), _view(0, 90.0, 2.0), _view(0, 180.0, 1.0)],
             [_view(1, 0.0, 3.0, volume=50.0), _view(1, 270.0, 2.0, volume=50.0)]]
    plain = choose_shots(views, 3)
    assert [(s["landform"], round(math.degrees(s["azimuth"]))) for s in plain] == [(0, 0), (1, 0), (0, 90)]
    # A sun towards 180 degrees: the second shot (landform 1 seen from 0 degrees, looking
    # towards 180) would stare into it.
    calls = []

    def sun(first):
        calls.append(first)
        return 180.0, 60.0

    shots = choose_shots(views, 3, sun)
    assert calls == [plain[0]]  # the sun is chosen for the first shot, which stays
    assert shots[0] is plain[0]
    for s in shots[1:]:
        assert abs((view_azimuth(s) - 180.0 + 180.0) % 360.0 - 180.0) >= 60.0, s
    # Landform 1's view from 270 degrees (looking towards 90) replaces its view into the
    # sun; the further view of landform 0 is the one from 90 degrees (looking towards 270).
    assert [(s["landform"], round(math.degrees(s["azimuth"]))) for s in shots] == [(0, 0), (1, 270), (0, 90)]
    # No view clear of the sun: the shots into it are kept rather than fewer shots.
    few = [[_view(0, 0.0, 3.0), _view(0, 90.0, 2.0)]]
    assert [id(s) for s in choose_shots(few, 2, lambda first: (0.0, 179.0))] == [id(s) for s in few[0]]
    # A sun that every later shot clears changes nothing.
    assert [id(s) for s in choose_shots(views, 3, lambda first: (0.0, 10.0))] == [id(s) for s in plain]


def test_later_close_shots_take_height_classes_not_yet_taken_when_they_score_enough():
    """Eye, drone, aerial (issue 34): after the first shot, a landform's best view of a
    height class no shot has yet replaces its best view when it scores at least
    CLASS_SCORE of it; otherwise the best view stays. Further views prefer new classes too."""
    from arches_render.generators.terrain.shots import CLASS_SCORE, choose_shots

    def view(landform, position, score, cls):
        return dict(_view(landform, position, score), height_class=cls)

    assert CLASS_SCORE == 0.5
    a = [view(0, 0.0, 3.0, "eye"), view(0, 90.0, 2.9, "eye"), view(0, 180.0, 1.6, "aerial")]
    b = [view(1, 0.0, 2.0, "eye"), view(1, 90.0, 1.2, "drone")]
    shots = choose_shots([a, b], 3)
    # Landform 1's drone view (1.2 >= 0.5 x 2.0) over its eye view; then landform 0's
    # aerial view (1.6 >= 0.5 x 3.0) over its second eye view.
    assert [(s["landform"], s["height_class"]) for s in shots] == [(0, "eye"), (1, "drone"), (0, "aerial")]
    # Too weak (below half the view it would replace): the best views, as before.
    b[1]["score"], a[2]["score"] = 0.9, 1.4
    shots = choose_shots([a, b], 3)
    assert [(s["landform"], s["height_class"], s["score"]) for s in shots] == [
        (0, "eye", 3.0), (1, "eye", 2.0), (0, "eye", 2.9)]


def test_close_shots_that_frame_their_landform_in_a_hundredth_of_the_frame_come_first():
    # Issue 34: 3-D landforms in 1 % of every close shot's pixels. An aerial view of
    # Maunga Whau's crater framed its lava-tube mouths in 0.4 % and was taken before
    # views that framed them in 1-8 %. Views under MIN_COVER only fill up a count the
    # others leave short (a caldera's walls give one view over it).
    from arches_render.generators.terrain.shots import MIN_COVER, choose_shots
    assert MIN_COVER == 0.01
    a = [_view(0, 0.0, 3.0, cover=0.009), _view(0, 90.0, 2.0, cover=0.2), _view(0, 180.0, 1.9, cover=0.01)]
    b = [_view(1, 0.0, 2.5, cover=0.004, volume=1e4)]
    assert [(s["landform"], round(math.degrees(s["azimuth"]))) for s in choose_shots([a, b], 2)] == [(0, 90), (0, 180)]
    shots = choose_shots([a, b], 3)
    assert [(s["landform"], round(math.degrees(s["azimuth"]))) for s in shots] == [(0, 90), (0, 180), (1, 0)]
