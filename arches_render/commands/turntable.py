"""``arches-render turntable``: a seamless orbit (or a camera path) of EXR frames, optionally on Dask, with an MP4.

::

    arches-render turntable SCENE -o DIR [--frames N] [--spp N] [--resolution WxH] [--seed S]
                            [--camera NAME | --path] [--mp4] [--view VIEW] [--denoise] [--no-aovs]
                            [--workers N | --scheduler ADDRESS] [-q]

Frames go to ``DIR/NAME.####.exr`` from 1001 (see :mod:`arches_render.render.turntable`);
frames already complete are skipped. ``--path`` flies the scene's
``[camera_path]`` (:mod:`arches_render.render.camera_path`) instead of orbiting:
its ``fps`` sets the frame count unless ``--frames`` is given. Without ``--workers``/``--scheduler`` the
frames render in this process; ``--workers N`` starts a Dask LocalCluster of N
worker processes, ``--scheduler`` uses a running cluster.
"""

from __future__ import annotations

import time
from pathlib import Path

from ..imaging.colour import VIEWS, view_to_uint8
from ..imaging.exposure import exposure_of
from ..imaging.exr import read_exr
from ..imaging.video import write_mp4
from ..render.camera_path import path_cameras
from ..render.distributed import dask_client
from ..render.turntable import plan_turntable, render_turntable
from ..scene import load_scene
from . import (Progress, UsageError, bounded_int, check_render_memory, resolution, scene_argument,
               writable_output)


def register(subparsers) -> None:
    t = subparsers.add_parser("turntable", help="render a seamless orbit of EXR frames (and an MP4)")
    scene_argument(t)
    t.add_argument("-o", "--output", required=True, help="output folder of the frames")
    t.add_argument("--frames", type=bounded_int("--frames", 1, 100000), default=None,
                   help="frames per revolution (default 48), or over the whole --path")
    t.add_argument("--spp", type=bounded_int("--spp", 1, 1 << 20), help="samples per pixel")
    t.add_argument("--resolution", type=resolution, help="WxH, e.g. 640x360")
    t.add_argument("--seed", type=bounded_int("--seed", 0, 2 ** 31 - 1), help="sampler seed")
    t.add_argument("--camera", metavar="NAME", help="orbit from the scene's camera NAME "
                                                    "([cameras.NAME]; default: the first camera)")
    t.add_argument("--path", action="store_true", help="fly the scene's [camera_path] instead of orbiting")
    t.add_argument("--passes", type=bounded_int("--passes", 1, 4096), help="sample passes per frame")
    t.add_argument("--mp4", action="store_true", help="also write DIR/NAME.mp4 (H.264 preview)")
    t.add_argument("--fps", type=bounded_int("--fps", 1, 240), default=24, help="MP4 frame rate")
    t.add_argument("--view", default=None, help="view transform of the MP4 (srgb, aces, aces-p3, untonemapped)")
    t.add_argument("--denoise", action="store_true", help="add an OIDN-denoised layer to every frame")
    t.add_argument("--no-aovs", dest="aovs", action="store_false", help="beauty only (no AOV layers)")
    g = t.add_mutually_exclusive_group()
    g.add_argument("--workers", type=bounded_int("--workers", 1, 1024),
                   help="render on a Dask LocalCluster of N worker processes")
    g.add_argument("--scheduler", metavar="ADDRESS", help="render on a running Dask cluster (tcp://host:8786)")
    t.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    t.set_defaults(func=run)


def run(args) -> int:
    desc = load_scene(args.scene)
    view = args.view or desc.render.view
    if view not in VIEWS:
        raise UsageError(f"--view must be one of {', '.join(VIEWS)} (got {view!r})")
    cameras = None
    if args.path:
        if args.camera:
            raise UsageError("--camera and --path exclude each other (the path names its cameras)")
        if desc.camera_path is None:
            raise UsageError(f"{args.scene}: --path needs a [camera_path] table in the scene")
        keys = [(time, desc.cameras[name]) for time, name in desc.camera_path.keys]
        cameras = path_cameras(keys, desc.camera_path.fps, args.frames)
    desc.select_camera(args.camera)
    frames = len(cameras) if cameras is not None else (args.frames or 48)
    out = Path(args.output)
    if out.suffix.lower() in (".exr", ".mp4", ".png"):
        raise UsageError(f"-o/--output is a folder for the frames (got {out})")
    s = desc.render
    width, height = args.resolution or (s.width, s.height)
    spp = args.spp or s.spp
    denoise = args.denoise or s.denoise
    check_render_memory(desc, width, height, args.aovs or denoise, "field")
    writable_output(out, folder=True)  # last check: it creates the folder
    plan = plan_turntable(desc, args.scene, out, frames, spp, width, height, args.seed,
                          args.passes or s.passes, aovs=args.aovs, denoise=denoise, cameras=cameras)
    skipped = frames - len(plan.todo)
    t0 = time.perf_counter()
    bar = Progress(f"turntable {desc.name}", "frame", args.quiet)
    if args.workers or args.scheduler:
        with dask_client(args.scheduler, args.workers) as client:
            render_turntable(plan, denoise, client, progress=bar)
    else:
        samples = Progress("  samples", "spp", args.quiet)
        render_turntable(plan, denoise, progress=bar, sample_progress=samples)
        samples.close()
    bar.close()
    elapsed = time.perf_counter() - t0
    msg = (f"wrote {len(plan.todo)} frames to {out} ({width}x{height}, {spp} spp, {elapsed:.1f} s)"
           + (f"; {skipped} complete frames skipped" if skipped else ""))
    if args.mp4:
        mp4 = out / f"{desc.name}.mp4"
        # One exposure for the whole clip (metered on its first frame): no flicker.
        exposure, _ = exposure_of(s, read_exr(plan.paths[0]).rgb)
        write_mp4(mp4, (view_to_uint8(read_exr(p).rgb, view, exposure) for p in plan.paths), fps=args.fps)
        msg += f"; {mp4}"
    print(msg)
    return 0
