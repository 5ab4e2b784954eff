"""Write the meshes of the gmaps scenes: ``scenes/data/gmaps_{arch,drilling,cavern}/``.

Each scenario of :mod:`arches_render.generators.gmaps.scenarios` runs with seed 0
and its default length; its volumes are written as PLY files (one per volume,
material in ``manifest.json``). The drilling and cavern terrains are also cut in
half by the plane y = 0, keeping y > 0, with the cut capped (the cross-sectional
views of the paper's Fig. 10b and 11), so that the shaft and the cavern can be
seen from the camera. Reproducible: ``python examples/make_gmaps_scenes.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CUT = {"arch": None, "drilling": 0.0, "cavern": 0.0}


def write(name: str, seed: int = 0) -> Path:
    from arches_render.atomic import atomic_path, atomic_write
    from arches_render.generators.gmaps import scenarios
    from arches_render.generators.gmaps.export import volume_meshes

    res = scenarios.run(name, seed=seed)
    folder = REPO / "scenes" / "data" / f"gmaps_{name}"
    folder.mkdir(parents=True, exist_ok=True)
    entries, lo, hi = [], np.full(3, np.inf), np.full(3, -np.inf)
    for label, part, mat, mesh in volume_meshes(res.gmap, res.materials):
        if CUT[name] is not None:
            mesh = mesh.slice_plane([0.0, CUT[name], 0.0], [0.0, 1.0, 0.0], cap=True)
        # One vertex per triangle corner: Mitsuba then shades every planar face
        # flat (shared vertices would average normals across the box edges).
        mesh = mesh.copy()
        mesh.unmerge_vertices()
        file = f"volume_{label}" + (f"_{part}" if part else "") + ".ply"
        with atomic_path(folder / file) as tmp:
            mesh.export(tmp, file_type="ply")
        lo, hi = np.minimum(lo, mesh.bounds[0]), np.maximum(hi, mesh.bounds[1])
        entries.append({"file": file, "label": int(label), "material": mat, "faces": int(len(mesh.faces))})
    doc = {"scenario": name, "seed": seed, "steps": res.steps, "events": res.events, "counts": res.counts(),
           "cut_y": CUT[name], "bounds": [lo.tolist(), hi.tolist()], "centre": ((lo + hi) / 2).tolist(),
           "volumes": entries}
    with atomic_write(folder / "manifest.json", "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=1)
    print(f"wrote {folder}: {len(entries)} volumes, centre {np.round((lo + hi) / 2, 3).tolist()}, "
          f"events {res.counts()}")
    return folder


if __name__ == "__main__":
    for n in ("arch", "drilling", "cavern"):
        write(n)
