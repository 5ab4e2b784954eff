#!/bin/bash
# The cuda_ad_rgb check on a lent GPU machine (the workplace's `device` tool), in two steps:
#
#   bash benchmarks/device_check.sh pack   # here: packs what the device lacks into .whl/
#   device run, carry [".whl"]:  bash benchmarks/device_check.sh run [LANDSCAPE_SECONDS]
#
# Why it is built this way (first run, 2026-12-04):
# - Only the working tree and carried folders travel, 64 MiB in all, and the device has no
#   network. Its python3 (3.12) has numpy, scipy, scikit-image, numba, tifffile, imageio,
#   pillow, tqdm, pytest and xdist, not Mitsuba or Dr.Jit. The Mitsuba wheel alone is 63 MB,
#   so `pack` keeps its rgb variants and the plugins our scenes use, adds Dr.Jit, OpenEXR,
#   OpenColorIO, trimesh, platformdirs, colour-science and flip-evaluator, and xz-compresses
#   them (35 MB beside a 24 MB tree). OIDN (88 MB) and embreex (15 MB) do not fit: the
#   default scene renders undenoised there, and amplifying a DEM (its shots cast rays with
#   embreex) fails, so the real-DEM cases of the landscape benchmark and of
#   tests/test_tracer_budget.py cannot run there.
# - Nothing is installed there: the repository root goes first on PYTHONPATH and two links
#   stand in for pyproject's package-dir mapping (arches_render.generators, .materials).
# - Everything is logged to $OUT/log as it goes: a step that runs out of time still reports
#   what it printed. A whole run took ~4 min of the 15 a session is lent.
set -u
cd "$(dirname "$0")/.."
PLATFORMS="--platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64"

pack() {
    local tmp
    tmp=$(mktemp -d)
    grep -qx "/.whl/" .git/info/exclude 2>/dev/null || grep -qx "/.whl/" .gitignore || echo "/.whl/" >>.git/info/exclude
    mkdir -p .whl "$tmp/wheels" "$tmp/site"
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp $PLATFORMS \
        -d "$tmp/wheels" mitsuba==3.9.1 drjit==1.5.0 OpenEXR opencolorio trimesh platformdirs colour-science \
        flip-evaluator || exit 1
    for w in "$tmp"/wheels/*.whl; do unzip -q -o "$w" -d "$tmp/site"; done
    # The variants we do not render with, spectral data, and plugins no scene uses.
    (cd "$tmp/site/mitsuba" && rm -f cuda_ad_mono* cuda_ad_spectral* llvm_ad_mono* llvm_ad_spectral* \
        scalar_spectral* data/srgb.coeff plugins/ellipsoids* plugins/bsplinecurve.so plugins/linearcurve.so \
        plugins/volpath*.so plugins/ptracer.so plugins/timed_sunsky.so)
    tar -cJf .whl/site.tar.xz -C "$tmp/site" .
    rm -rf "$tmp"
    du -sh .whl/site.tar.xz
}

run() {
    local landscape_s=${1:-170}
    exec > >(tee -a "$OUT/log") 2>&1
    export PYTHONUNBUFFERED=1 ARCHES_VARIANT=cuda_ad_rgb
    step() { echo; echo "=== $(date +%T) $*"; }
    step setup
    rm -rf /tmp/site && mkdir -p /tmp/site /tmp/out && tar -xJf .whl/site.tar.xz -C /tmp/site || exit 1
    export PYTHONPATH=$PWD:/tmp/site
    ln -sfn ../materials arches_render/materials
    ln -sfn ../generators arches_render/generators
    sed -i 's/^denoise = true/denoise = false/' scenes/default.toml  # (no OIDN there)
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
    python3 -c "from arches_render import backend; import mitsuba, drjit; print(backend.set_variant(), mitsuba.__version__, drjit.__version__)" || exit 1
    step "CLI render of the default scene, cold kernel cache, field and mesh"
    for g in field mesh; do
        /usr/bin/time -f "$g: wall %e s, max rss %M kB" env HOME=/tmp/home_$g \
            python3 -m arches_render.cli render scenes/default.toml --geometry $g -q -o /tmp/out/default_$g.exr
        cp /tmp/out/default_$g.png "$OUT/"
    done
    step "benchmarks of the default scene"
    timeout 150 python3 benchmarks/run.py --json render_field_vs_mesh render_field_vs_sdfgrid render_default_s \
        | tee "$OUT/bench_default.json"
    step "tracer and golden tests (each result as it comes)"
    timeout 150 python3 -m pytest -p no:cacheprovider -p no:benchmark -n 16 -v --tb=line tests/test_tracer_holes.py \
        tests/test_tracer_budget.py tests/test_heightfield_caster.py tests/test_golden_scenes.py 2>&1 \
        | grep -E "PASSED|FAILED|ERROR|^E " | tail -80
    step "wavefront against megakernel (160x90, 8 spp): on a GPU the wavefront may pay everywhere"
    timeout 150 python3 benchmarks/run.py --json render_wavefront_vs_megakernel | tee "$OUT/bench_wavefront.json"
    step "landscape benchmark, gallery scenes (160x90, 8 spp)"
    ARCHES_BENCH_LANDSCAPE_SCENES=$(ls scenes/gallery/*.toml | xargs -n1 basename | sed 's/\.toml$//' | paste -sd,) \
        ARCHES_BENCH_LANDSCAPE=160x90,8 timeout "$landscape_s" python3 benchmarks/run.py --json \
        render_landscape_field_vs_mesh | tee "$OUT/bench_landscape.json"
    step done
}

case "${1:-}" in
    pack) pack ;;
    run) shift; run "$@" ;;
    *) echo "usage: bash benchmarks/device_check.sh pack | run [LANDSCAPE_SECONDS]" >&2; exit 2 ;;
esac
