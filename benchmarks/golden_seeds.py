"""False failures of the golden tests: check every shipped golden with many seeds.

    python benchmarks/golden_seeds.py [--seeds N] [--first SEED] [NAME ...]

Renders each golden's check (its test spp, resolution and seed ``SEED .. SEED + N - 1``;
none is the reference's seed 0), runs the two-sample tests and the power check
exactly as ``tests/test_golden_scenes.py`` does, and prints one line per golden:
passes, failures (with the first failure's text), the worst window ``|z|`` and
image-mean ``|z|`` seen against their limits. On an unchanged tree every check
should pass: with family-wise alpha = 1e-4 per test, a failure in 20 x 20 checks
would already be unusual. The last line is the total false-failure rate.

Slow (every golden's check ``N`` times: ~30 minutes for 20 seeds on 2 cores), so
it is not one of ``run.py``'s benchmarks.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="checks per golden (default 20)")
    ap.add_argument("--first", type=int, default=1001, help="first check seed (default 1001)")
    ap.add_argument("names", nargs="*", help="goldens to check (default: every shipped scene)")
    args = ap.parse_args(argv)

    sys.path.insert(0, str(REPO / "tests"))
    from helpers import SCENES, golden_checks, variant  # noqa: E402  (as the golden tests)
    shipped, (width, height), spp_of = golden_checks()
    variant()
    from arches_render.imaging.golden import load_golden
    from arches_render.imaging.welch import power_check, welch_compare
    from arches_render.render.renderer import build_scene, render_moments
    from arches_render.scene import load_scene

    total = failed = 0
    for name in args.names or shipped:
        g = load_golden(name, REPO / "golden")
        scene = build_scene(load_scene(SCENES / f"{name}.toml"), "field", width, height, moments=True)
        spp = spp_of(name)
        fails, worst_window, worst_mean, t0 = [], 0.0, 0.0, time.perf_counter()
        for seed in range(args.first, args.first + args.seeds):
            test = render_moments(scene, spp, seed=seed)
            res = welch_compare(g.ref, test)
            weak = power_check(g.ref, test) if res.passed else []
            if not res.passed or weak:
                fails.append(f"seed {seed}: {(res.failures or weak)[0]}")
            worst_window = max(worst_window, res.window_z)
            worst_mean = max(worst_mean, max(abs(z) for z in res.mean_z))
        total += args.seeds
        failed += len(fails)
        lim = res.limits
        print(f"{name:26s} {spp:4d} spp  {args.seeds - len(fails):3d}/{args.seeds} pass  worst window |z| "
              f"{worst_window:.2f} (limit {lim['window_z']:.2f})  worst mean |z| {worst_mean:.2f} (limit "
              f"{lim['mean_z']:.2f})  {time.perf_counter() - t0:6.1f} s" + (f"  first: {fails[0]}" if fails else ""),
              flush=True)
    print(f"false failures: {failed} of {total} checks ({failed / max(total, 1):.2%})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
