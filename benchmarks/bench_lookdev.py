"""Lookdev benchmarks: the gallery's cost, and what the look costs over a plain material.

``lookdev_gallery_s``   seconds of the slowest gallery render (``examples/make_gallery.py``'s
                        list: 1280x720 at each scene's spp, denoised, ACES view), each in
                        a fresh process with an empty kernel cache (JIT included).
                        Baseline: the goal, 600 s. Extra fields: every scene's seconds
                        and spp, the load.
``lookdev_cost_ratio``  seconds of ``scenes/gallery/every_generator.toml`` (320x180,
                        16 spp, warm kernels) with its look (atmosphere, strata colours
                        from the geology, cavity, wetness, histogram tiling, detail)
                        over the same scene with plain triplanar materials (repeat
                        tiling, no detail, strata, cavity or wetness) and no
                        atmosphere, same run (the rock piles' preset material, which has
                        no scene-level switch, is the same in both). Baseline: the goal, 1.3.
``lookdev_default_mesh_ratio``  seconds of ``scenes/default.toml`` in mesh mode (its
                        marching-cubes mesh, 320x180, 16 spp, warm kernels, mesh built
                        outside the timing) with its triplanar look over the same with
                        a plain diffuse material, same run: what the look costs where it
                        is shaded once per vertex by ``implicit_path`` (issue 33 part 2).
                        Baseline: the goal of ``lookdev_cost_ratio``, 1.3. Extra fields:
                        both times, both integrators, the load.
``preview_first_image_s``  seconds from a saved edit of ``scenes/default.toml`` (its sun) to
                        the first image of ``arches-render preview`` (160x90, warm
                        kernels, the file watcher included). Baseline: the goal, 1 s.
                        Extra fields: the seconds to the full 640x360, 16 spp, the
                        kernels the edits compiled, the load.
``lookdev_parts_default``  what each part of ``scenes/default.toml``'s look costs
                        (issue 33 part 1): the scene rendered (320x180, 16 spp, warm
                        kernels, field and mesh) with its look, with one part off at a
                        time (histogram tiling -> repeat, detail, strata colours, cavity,
                        atmosphere) and with a plain diffuse material, every variant in
                        one run. Value: the field render with its look over the plain
                        one. Baseline: the goal of ``lookdev_cost_ratio``, 1.3. Extra
                        fields: ``{geometry}_{variant}`` seconds and
                        ``{geometry}_{variant}_x`` (over the look), the load.
"""

from __future__ import annotations

import copy
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from arches_render import tomlfile
from arches_render.render.renderer import build_scene
from arches_render.scene import SceneError, load_scene, parse_scene
from arches_render.timing import REPO, median_renders

sys.path.insert(0, str(REPO / "examples"))
import make_gallery  # noqa: E402  (the gallery's list of renders lives with the script that makes it)

COMBINED = REPO / "scenes" / "gallery" / "every_generator.toml"
DEFAULT = REPO / "scenes" / "default.toml"
#: The plain material of ``lookdev_default_mesh_ratio``: a sandstone-like grey-brown.
PLAIN_DIFFUSE = {"type": "diffuse", "color": [0.35, 0.3, 0.25]}
LOOK_KEYS = ("strata", "cavity", "wetness", "masks")


def bench_lookdev_gallery_s(repeat):
    seconds, spps = {}, {}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        for path, spp, resolution in make_gallery.gallery_renders():
            home = Path(tmp) / f"home_{path.stem}"  # Dr.Jit caches kernels under $HOME/.drjit
            home.mkdir()
            args = [sys.executable, "-m", "arches_render.cli", "render", str(path), "-o",
                    str(Path(tmp) / f"{path.stem}.exr"), "-q", "--denoise", "--view", "aces"]
            args += ["--spp", str(spp)] if spp else []
            args += ["--resolution", resolution] if resolution else []
            t = time.perf_counter()
            subprocess.run(args, cwd=REPO, env=dict(os.environ, HOME=str(home)), check=True,
                           stdout=subprocess.DEVNULL)
            seconds[path.stem] = round(time.perf_counter() - t, 1)
            spps[path.stem] = spp or load_scene(path).render.spp
    return dict(value=max(seconds.values()), unit="s", baseline=600.0, baseline_is="goal",
                slowest=max(seconds, key=seconds.get), seconds=seconds, spp=spps,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2), cold_kernel_cache=True)


def plain_document(doc: dict) -> dict:
    """``doc`` with plain triplanar materials and no atmosphere (the baseline of the cost ratio)."""
    doc = dict(doc)
    doc.pop("atmosphere", None)
    materials = {}
    for name, mat in doc.get("materials", {}).items():
        if mat.get("type", "triplanar") == "triplanar":
            mat = {k: v for k, v in mat.items() if k not in LOOK_KEYS}
            mat.update(tiling="repeat", detail=False)
        materials[name] = mat
    doc["materials"] = materials
    return doc


def diffuse_document(doc: dict) -> dict:
    """``doc`` with every triplanar material replaced by :data:`PLAIN_DIFFUSE` (the
    atmosphere kept: the ratio measures the material alone)."""
    materials = {name: dict(PLAIN_DIFFUSE) if mat.get("type", "triplanar") == "triplanar" else mat
                 for name, mat in doc.get("materials", {}).items()}
    return dict(doc, materials=materials)


def parse_plain(doc: dict, path):
    """:func:`parse_scene` of a plain document at ``path`` (its data paths resolve
    from there; no file is written), dropping the nodes only the look used (a
    geology read by the strata colours), which the loader refuses as unused."""
    doc = dict(doc, nodes=dict(doc.get("nodes", {})))
    while True:
        try:
            return parse_scene(doc, path)
        except SceneError as err:
            name = err.key.split(".", 1)[1] if err.key.startswith("nodes.") else None
            if name not in doc["nodes"] or "used by neither" not in err.message:
                raise
            del doc["nodes"][name]


def bench_lookdev_cost_ratio(repeat):
    w, h, spp = 320, 180, 16
    load0 = os.getloadavg()[0]
    plain = parse_plain(plain_document(tomlfile.load(COMBINED)), COMBINED)
    scenes = [build_scene(desc, "field", w, h) for desc in (load_scene(COMBINED), plain)]
    look, base = median_renders(scenes, spp, repeat)
    return dict(value=look / base, unit="x", baseline=1.3, baseline_is="goal", look_s=look, plain_s=base,
                scene=str(COMBINED.relative_to(REPO)), resolution=f"{w}x{h}", spp=spp,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def bench_lookdev_default_mesh_ratio(repeat):
    w, h, spp = 320, 180, 16
    load0 = os.getloadavg()[0]
    plain = parse_plain(diffuse_document(tomlfile.load(DEFAULT)), DEFAULT)
    scenes = [build_scene(desc, "mesh", w, h) for desc in (load_scene(DEFAULT), plain)]
    look, base = median_renders(scenes, spp, repeat)
    return dict(value=look / base, unit="x", baseline=1.3, baseline_is="goal", look_s=look, plain_s=base,
                integrators=[str(s.integrator()).split("[")[0] for s in scenes],
                scene=str(DEFAULT.relative_to(REPO)), resolution=f"{w}x{h}", spp=spp,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def _without(doc: dict, material: str, **keys) -> dict:
    """``doc`` with keys of one material set (``None``: removed)."""
    doc = copy.deepcopy(doc)
    mat = doc["materials"][material]
    for key, value in keys.items():
        if value is None:
            mat.pop(key, None)
        else:
            mat[key] = value
    return doc


def look_variants(doc: dict, material: str) -> dict:
    """``{variant: document}``: the look, each part off in turn, and a plain diffuse material."""
    return {"look": doc,
            "repeat_tiling": _without(doc, material, tiling="repeat"),
            "no_detail": _without(doc, material, detail=False),
            "no_strata": _without(doc, material, strata=None),
            "no_cavity": _without(doc, material, cavity=None),
            "no_atmosphere": {k: v for k, v in doc.items() if k != "atmosphere"},
            "plain": diffuse_document(doc)}


def bench_lookdev_parts_default(repeat):
    w, h, spp = 320, 180, 16
    load0 = os.getloadavg()[0]
    doc = tomlfile.load(DEFAULT)
    variants = look_variants(doc, doc["field"]["material"])
    out = {}
    for geometry in ("field", "mesh"):
        scenes = [build_scene(parse_plain(d, DEFAULT), geometry, w, h) for d in variants.values()]
        times = dict(zip(variants, median_renders(scenes, spp, repeat)))
        for name, t in times.items():
            out[f"{geometry}_{name}"] = round(t, 3)
            out[f"{geometry}_{name}_x"] = round(t / times["look"], 3)
    return dict(value=out["field_look"] / out["field_plain"], unit="x", baseline=1.3, baseline_is="goal", **out,
                scene=str(DEFAULT.relative_to(REPO)), resolution=f"{w}x{h}", spp=spp,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


def bench_preview_first_image_s(repeat):
    """Seconds from a saved edit of the default scene (its sun's elevation) to the
    preview's first image (160x90), on warm kernels: the file watcher, the reload, the
    parameter edit and the small render (issue 35 part 1; goal 1 s). Extra: the seconds
    to the full resolution (the scene's 640x360 and 16 spp, denoised), the kernels the
    edits compiled, the load."""
    import shutil
    import threading

    from arches_render.preview.server import watch_scene
    from arches_render.preview.session import PreviewSession
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        shutil.copytree(REPO / "scenes" / "data", folder / "data")
        path = folder / "default.toml"
        text = (REPO / "scenes" / "default.toml").read_text()
        path.write_text(text)
        session = PreviewSession(path).start()
        stop = threading.Event()
        watch_scene(session, stop)
        last = session.wait_for(lambda s: s.stage == "done", 600)  # compiles (or loads) the kernels
        firsts, fulls, compiled = [], [], 0
        for k in range(max(3, repeat)):
            t0 = time.perf_counter()
            path.write_text(text.replace("elevation = 33.0", f"elevation = {30.0 - 3.0 * k:.1f}"))
            first = session.wait_for(lambda s, n=last.picture: s.picture > n and s.stage == "first", 120)
            firsts.append(time.perf_counter() - t0)
            last = session.wait_for(lambda s, n=first.picture: s.picture > n and s.stage == "done", 600)
            fulls.append(time.perf_counter() - t0)
            compiled += first.compiled + last.compiled
        stop.set()
        session.stop()
    return dict(value=statistics.median(firsts), unit="s", baseline=1.0, baseline_is="goal",
                first_size=list(first.size), full_s=statistics.median(fulls), full_size=list(last.size),
                edits=len(firsts), firsts_s=[round(x, 3) for x in firsts], compiled_by_edits=compiled,
                load=round(0.5 * (load0 + os.getloadavg()[0]), 2))


BENCHMARKS = {
    "preview_first_image_s": (bench_preview_first_image_s, 3),
    "lookdev_gallery_s": (bench_lookdev_gallery_s, 1),
    "lookdev_cost_ratio": (bench_lookdev_cost_ratio, 3),
    "lookdev_default_mesh_ratio": (bench_lookdev_default_mesh_ratio, 3),
    "lookdev_parts_default": (bench_lookdev_parts_default, 3),
}
