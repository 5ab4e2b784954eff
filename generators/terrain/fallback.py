"""Presets that fail soft and rank by what they make (issues 22, 34).

A preset can find nothing on a DEM it was chosen for: a low sandy coast has a sea
but no cliff for waves to undercut; the karst lattice of a 200 m DEM of high
mountains is so wide that its tunnels stay deep in the rock, out of any camera's
sight. Such a run used to end in a traceback or in a scene with the overview
camera alone. With ``--preset auto``, :func:`amplify_soft` amplifies every preset
:func:`preset_candidates` allows, orders them by the 3-D landforms each made
(:mod:`.preset_ranking`, said in one header line) and keeps the first that makes a
landform a close shot can frame (:func:`.shots.close_shots`, the same measure the
scene writer uses for its cameras); each one passed over is said in one line
(``nothing to carve: ...``) that the command prints and writes in the scene's header.

What counts as nothing
    No primitive (the preset's own reason, from ``stats["nothing"]``, or the
    default of :data:`NOTHING`), or primitives without a close shot: no landform
    with 3-D volume (overhangs, caves, arches, standing matter) seen with sky
    from a camera in air over the tile.
Candidates
    ``--preset auto``: the preset :func:`.preset_choice.choose_preset` picks, then
    the others that the DEM's measures allow, cliff landforms first (a DEM with
    escarpments gets undercut beds before anything else): ``sea`` (a sea at the
    border), ``strata`` (slopes over 30 deg on 3 % of the land, or walls: 1 % in
    escarpments 40 m tall, :func:`.preset_choice.has_walls`), ``hoodoos`` (slopes
    over 30 deg on 3 % of the land), ``river`` (always: water shapes most land),
    ``karst`` (a closed depression).
    The ranking keeps the choice first unless it made under one landform's worth;
    ties keep this order. A preset named with ``--preset`` runs alone: the user chose it, so it is
    not replaced, but the line says that ``auto`` would try the others.
When all fail
    The first attempt in the ranked order is kept (its geology still colours the
    rock), with a last line saying the scene is the terrain and what it made.

Each attempt writes its data into a folder of its own, so the files of the kept
one are never overwritten by another; the same seed gives the same attempts.

References
----------
Paris, A., Galin, E., Peytavie, A., Guérin, E., Gain, J. (2019). Terrain
amplification with implicit 3D features. ACM TOG 38(5), sections 6.1-6.3.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from .amplify import amplify
from .preset_choice import choose_preset, has_walls
from .preset_ranking import rank_order, ranking_line, visible_volume
from .scene_writer import scene_document

__all__ = ["NOTHING", "preset_candidates", "Attempt", "amplify_soft"]

#: Why a preset made no primitive, when it does not say it itself.
NOTHING = {
    "sea": "no coastal cliff in the sea band eroded",
    "river": "no valley wall deep and steep enough for the river to undercut",
    "karst": "no tunnel percolated from the sinks",
    "hoodoos": "no site where a hoodoo grows",
    "strata": "no escarpment steeper than 40 deg",
}

_STEEP = 0.03  # share of the land over 30 deg: escarpments exist (the strata rule's threshold)


def preset_candidates(heights, cell_size, sea_level=0.0):
    """The presets to try on a DEM, best first, each with why.

    Parameters
    ----------
    heights : numpy.ndarray
        ``(ny, nx)`` finite elevations (m).
    cell_size : float
        Metres between samples.
    sea_level : float
        Sea level (m).

    Returns
    -------
    list of (str, str)
        ``(preset, reason)``: the choice of :func:`.preset_choice.choose_preset`
        first, then the others the measures allow (module docstring).
    """
    first, reason, st = choose_preset(heights, cell_size, sea_level)
    pct = lambda v: f"{100 * v:.0f} %"  # noqa: E731
    steep = st["steep_fraction"] >= _STEEP
    cliffs = f"slopes over 30 deg on {pct(st['steep_fraction'])} of the land"
    allowed = [
        ("sea", st["sea_fraction"] >= 0.01 and st["sea_border_fraction"] >= 0.01,
         f"sea on {pct(st['sea_fraction'])} of the tile"),
        ("strata", steep or has_walls(st), f"escarpments: {cliffs}, {st['cliff_height_m']:.0f} m high"),
        ("hoodoos", steep, f"badland slopes: {cliffs}"),
        ("river", True, f"water shapes most land (valleys {st['channel_incision_m']:.0f} m deep)"),
        ("karst", st["depressions"] >= 1, f"{st['depressions']} closed depressions"),
    ]
    # River before hoodoos where valleys drain the tile: undercut walls before pinnacles.
    if st["main_catchment_fraction"] >= 0.25:
        allowed[2], allowed[3] = allowed[3], allowed[2]
    return [(first, reason)] + [(name, why) for name, ok, why in allowed if ok and name != first]


@dataclass
class Attempt:
    """The kept amplification: result, scene document, header lines and its data folder."""

    result: object
    doc: dict
    lines: list
    folder: Path
    notes: list = field(default_factory=list)

    @property
    def close_shots(self) -> int:
        """Named cameras besides ``overview``."""
        return sum(1 for name in self.doc["cameras"] if name != "overview")


def amplify_soft(heights, cell_size, preset, seed, work_dir, prefix, name, sea_level=0.0, precision=None,
                 progress=None, shots_progress=None, say=None, options=None, context=None, lake_levels=None):
    """Amplify with the best preset that makes a landform (see the module docstring).

    Parameters
    ----------
    heights, cell_size : numpy.ndarray, float
        The DEM and its cell (m), as in :func:`preset_candidates`.
    preset : str
        ``"auto"`` or a preset name (which then runs alone).
    seed : int
        Seed of every attempt.
    work_dir : Path
        Folder of the first attempt's data files; later attempts use sub-folders
        ``_try2``, ``_try3``... with the same relative names.
    prefix : str
        Relative path prefix of the data files.
    name : str
        Scene name.
    sea_level : float or None
        As in :func:`.amplify.amplify`.
    precision : float, optional
        Smallest detail (m).
    progress, shots_progress : callable, optional
        Progress of the amplification steps and of the close shots.
    say : callable, optional
        ``say(line)`` for the ranking line and each ``nothing to carve`` line, as it happens.
    options : dict, optional
        :func:`.amplify.amplify`'s options, for every attempt.
    context : (numpy.ndarray, tuple), optional
        ``(heights, extent)`` of the DEM the heights are a refined crop of
        (:mod:`.refined_crop`), given to every attempt's result (its overview and far field).
    lake_levels : numpy.ndarray, optional
        The levels of the lakes of the DEM the heights are a refined crop of
        (:func:`.amplify.amplify`).

    Returns
    -------
    Attempt
        ``notes`` holds the ranking and ``nothing to carve`` lines (also for the header).
    """
    level = 0.0 if sea_level is None else float(sea_level)
    H = np.asarray(heights, dtype=np.float32).astype(np.float64)
    candidates = preset_candidates(H, cell_size, level) if preset == "auto" else [(preset, "chosen by the user")]
    notes = []

    def tell(line):
        notes.append(line)
        if say:
            say(line)

    runs = []
    for k, (choice, reason) in enumerate(candidates):
        folder = Path(work_dir) / (f"_try{k + 1}" if k else "")
        run = _Run(partial(_amplify_one, H, cell_size, choice, reason, seed, folder, prefix, sea_level, precision,
                           progress, options, context, lake_levels), folder, choice, reason)
        runs.append(run)
        if "note" in run.get().stats:  # a flat DEM: no preset acts on it
            break
        if len(candidates) > 1:
            run.measure()
            if k:  # only the DEM's choice, most often kept, stays in memory
                run.result = None
    if len(runs) > 1:
        # --preset auto: every applicable preset ran; try them in the order of what they made.
        order = rank_order([r.volume for r in runs], [r.feature for r in runs])
        tell(ranking_line([r.preset for r in runs], [r.volume for r in runs], [r.feature for r in runs],
                          [r.primitives for r in runs], order, [r.nothing for r in runs]))
        runs = [runs[i] for i in order]
    return _keep_first_with_shots(runs, name, preset, shots_progress, notes, tell)


def _amplify_one(H, cell_size, choice, reason, seed, folder, prefix, sea_level, precision, progress, options,
                 context, lake_levels):
    result = amplify(H, cell_size, choice, seed, folder, prefix, sea_level=sea_level, precision=precision,
                     progress=progress, options=options, lake_levels=lake_levels)
    result.reason, result.context = reason, context
    return result


@dataclass
class _Run:
    """One preset's amplification for :func:`amplify_soft`: built, measured, and dropped
    from memory unless it is the DEM's choice; :meth:`get` builds it again (the same seed
    and folder give the same tree and files) when the ranking or a fallback tries it.
    Holding every preset's tree took the 5 km benchmark's peak from 719 to 1144 MB."""

    build: object
    folder: Path
    preset: str
    reason: str
    result: object = None
    volume: float = 0.0
    feature: float = 0.0
    primitives: int = 0
    nothing: str = ""

    def get(self):
        if self.result is None:
            self.result = self.build()
        return self.result

    def measure(self):
        """Visible 3-D volume, landform size and what the preset made (:mod:`.preset_ranking`)."""
        r = self.get()
        self.volume, self.feature = visible_volume(r)
        self.primitives = r.stats["primitives"]
        self.nothing = r.stats.get("nothing", NOTHING[self.preset])


def _keep_first_with_shots(runs, name, preset, shots_progress, notes, tell):
    """The first of ``runs`` (:class:`_Run`, in the order to try) whose landforms a close
    shot frames, else the first; a ``nothing to carve`` line for each one passed."""
    first = None
    for k, run in enumerate(runs):
        result, folder = run.get(), run.folder
        choice, st = result.preset, result.stats
        made = st["primitives"] > 0
        doc, lines = scene_document(result, name, folder, progress=shots_progress) if made or first is None \
            else (None, None)
        attempt = Attempt(result, doc, lines, folder, notes)
        if first is None:
            first = attempt
        if made and attempt.close_shots:
            return attempt
        if "note" in st:
            why = st["note"]
        elif not made:
            why = f"the {choice} preset made 0 primitives ({st.get('nothing', NOTHING[choice])})"
        else:
            why = (f"the {choice} preset made {st['primitives']} primitives but no landform a close shot "
                   f"can frame (all within the rock or under the DEM's detail)")
        rest = runs[k + 1:]
        if rest:
            then = f"trying {rest[0].preset} ({rest[0].reason})"
        elif first.result.stats["primitives"]:
            then = f"the scene keeps what the {first.result.preset} preset made"
        else:
            then = "the scene is the terrain alone"
        if not rest and preset != "auto":
            then += " (--preset auto tries the other presets)"
        tell(f"nothing to carve: {why}; {then}")
    return first
