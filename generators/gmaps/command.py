"""``arches-render evolve SCENARIO -o OUT``: topological terrain evolution on 3-G-maps.

Runs one of the seeded scenarios of :mod:`.scenarios`
(``arch``, ``drilling``, ``cavern``; Bezin et al., *Topological Operations for
Geomorphological Evolution*) and writes triangulated meshes, one per volume with
its material:

* ``OUT`` a folder: ``volume_<label>.ply`` per volume and ``manifest.json``
  (label, material preset, faces, watertight), written last;
* ``OUT`` ending in ``.glb`` or ``.gltf``: one glTF scene, a mesh and a PBR
  material per volume.

``--every K`` also writes the map every K steps (``OUT/step_0003/`` or
``OUT_step0003.glb``). Options: ``--seed`` (default 0), ``--steps`` (default: the
scenario's length), ``--no-check`` (skip the map validity check run after every
event), ``-q``. Progress (events, steps) goes to stderr.
"""

from __future__ import annotations

from pathlib import Path

from arches_render.commands import Progress, UsageError, bounded_int

from . import scenarios
from .export import write_gltf, write_ply_folder
from .scenarios import SCENARIOS


def register(subparsers):
    p = subparsers.add_parser(
        "evolve", help="run a 3-G-map terrain evolution scenario and write a mesh per volume",
        description="Evolve a terrain of material volumes stored in a 3-generalized map under vertex "
                    "displacements (Bezin et al.): arch, drilling or cavern. Writes a triangle mesh per "
                    "volume with its material (PLY folder + manifest.json, or one .glb/.gltf).")
    p.add_argument("scenario", choices=SCENARIOS, help="scenario to run")
    p.add_argument("-o", "--output", required=True,
                   help="output folder (PLY per volume + manifest.json) or a .glb/.gltf file")
    p.add_argument("--seed", type=bounded_int("--seed", 0, 2 ** 31 - 1), default=0, help="random seed (default 0)")
    p.add_argument("--steps", type=bounded_int("--steps", 1, 1000), default=None,
                   help="simulation steps (default: the scenario's length)")
    p.add_argument("--every", type=bounded_int("--every", 1, 1000), default=None,
                   help="also write the meshes every K steps")
    p.add_argument("--no-check", action="store_true", help="skip the validity check after each event")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _writer(out: Path):
    if out.suffix.lower() in (".glb", ".gltf"):
        return lambda g, mats, meta, path=out: write_gltf(g, path, mats)
    if out.suffix:
        raise UsageError(f"-o/--output must be a folder or end in .glb/.gltf (got {out})")
    return lambda g, mats, meta, path=out: write_ply_folder(g, path, mats, meta)


def run(args) -> int:
    out = Path(args.output)
    write = _writer(out)
    if out.suffix and not out.parent.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
    total = args.steps or scenarios.default_steps(args.scenario)
    bar = Progress(f"evolve {args.scenario}", "step", args.quiet)
    bar(0, total)

    def on_step(step, res):
        bar.bar.set_postfix(events=res.events, refresh=False)
        bar(step + 1, total)
        if args.every and (step + 1) % args.every == 0 and step + 1 < total:
            tag = f"step_{step + 1:04d}"
            path = out / tag if not out.suffix else out.with_name(f"{out.stem}_{tag}{out.suffix}")
            _writer(path)(res.gmap, res.materials, _meta(args, res))

    res = scenarios.run(args.scenario, seed=args.seed, steps=total, on_step=on_step, check=not args.no_check)
    bar.close()
    write(res.gmap, res.materials, _meta(args, res))
    counts = ", ".join(f"{k} {v}" for k, v in sorted(res.counts().items())) or "none"
    topo = ", ".join(f"volume {t['label']}: genus {t['genus']:g}" for t in res.gmap.volume_topology())
    print(f"wrote {out} ({args.scenario}, seed {args.seed}, {res.steps} steps, {res.events} events: "
          f"{counts}; {topo})")
    return 0


def _meta(args, res):
    return {"scenario": args.scenario, "seed": args.seed, "steps": res.steps, "events": res.events,
            "counts": res.counts(),
            "topology": [{k: t[k] for k in ("label", "euler", "genus")} for t in res.gmap.volume_topology()]}
