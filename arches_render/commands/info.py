"""``arches-render info SCENE``: render settings, cameras, lights, materials and the field's numbers."""

from __future__ import annotations

from collections import Counter

from ..scene import load_scene
from . import scene_argument


def register(subparsers) -> None:
    i = subparsers.add_parser("info", help="print the scene's field: node count, bounds, memory")
    scene_argument(i)
    i.set_defaults(func=run)


def run(args) -> int:
    desc = load_scene(args.scene)
    print(f"scene      {desc.name}  ({args.scene})")
    if desc.description:
        print(f"           {desc.description}")
    s = desc.render
    print(f"render     {s.width}x{s.height}, {s.spp} spp, seed {s.seed}, geometry {s.geometry}, "
          f"max_depth {s.max_depth}")
    for k, (name, c) in enumerate(desc.cameras.items()):
        print(f"{'cameras' if k == 0 else '':11s}{name}: origin [{', '.join(f'{v:.6g}' for v in c.origin)}], "
              f"target [{', '.join(f'{v:.6g}' for v in c.target)}], fov {c.fov:g}")
    print(f"lights     {', '.join(l['type'] for l in desc.lights)}")
    print(f"materials  {', '.join(desc.materials)}")
    print(f"meshes     {len(desc.meshes)}")
    if desc.atmosphere is not None:
        a = desc.atmosphere
        haze = f", haze {a.haze_density:g} /m over {a.haze_height:g} m" if a.haze_density > 0 else ""
        print(f"atmosphere turbidity {a.turbidity:g}, density x{a.density:g}{haze}")
    if desc.field is None:
        print("field      none")
        return 0
    f = desc.field
    lo, hi = f.bounds()
    kinds = Counter(n.kind for n in f.walk())
    print(f"field      {f.count()} nodes ({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))})")
    print(f"bounds     [{lo[0]:.2f}, {lo[1]:.2f}, {lo[2]:.2f}] .. [{hi[0]:.2f}, {hi[1]:.2f}, {hi[2]:.2f}] m")
    print(f"lipschitz  {f.lipschitz:.3f}")
    print(f"memory     {f.tree_nbytes() / 1024:.1f} KiB")
    print(f"material   {desc.field_material}")
    return 0
