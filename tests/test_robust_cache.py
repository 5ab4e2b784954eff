"""The generators' cache (:mod:`arches_render.cache`) under damage and concurrency (issue 17, "Faults").

A truncated, garbage, other-version, bit-flipped or renamed entry is detected by its
seal (checksum and format version), reported in one line and rebuilt to the same
bits; two processes building the same tile at once both succeed with identical
results and leave one entry.
"""

from __future__ import annotations

import io
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from arches_render import cache
from helpers import REPO
from robust_helpers import run_cli, write


def _payload_cache(folder):
    """A load_or_build over a small npz payload, counting builds."""
    builds = []

    def build():
        builds.append(1)
        return np.arange(1000, dtype=np.float64) * 0.5

    def save(value, path):
        with open(path, "wb") as f:
            np.savez(f, v=value)

    def load(f):
        with np.load(f, allow_pickle=False) as z:
            return z["v"]

    def get():
        return cache.load_or_build(folder / "thing-0123.npz", load, build, save)
    return get, builds


def _damage(path, how):
    data = path.read_bytes()
    if how == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif how == "garbage":
        path.write_bytes(b"\x00garbage" * 300)
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "bit-flip":
        b = bytearray(data)
        b[len(b) // 2] ^= 0x01
        path.write_bytes(bytes(b))
    elif how == "other-version":  # an entry as an older arches-render wrote it: the payload, no seal
        path.write_bytes(data[: -64])
    elif how == "other-seal":
        path.write_bytes(data[:-64] + b"ARCACHE0" + data[-56:])
    elif how == "renamed":  # a valid entry of another key copied over this one
        other = path.with_name("thing-9999.npz")
        buf = io.BytesIO()
        np.savez(buf, v=np.zeros(3))
        other.write_bytes(buf.getvalue())
        cache._seal_file(other, other.name)
        path.write_bytes(other.read_bytes())
        other.unlink()


@pytest.mark.parametrize("how, said", [
    ("truncated", "truncated"), ("garbage", "no seal"), ("empty", "truncated"), ("bit-flip", "checksum"),
    ("other-version", "no seal of this version"), ("other-seal", "no seal of this version"),
    ("renamed", "checksum"),
])
def test_damaged_entries_are_detected_reported_and_rebuilt(tmp_path, capsys, how, said):
    get, builds = _payload_cache(tmp_path)
    value, source = get()
    assert source == "built" and len(builds) == 1
    entry = tmp_path / "thing-0123.npz"
    good = entry.read_bytes()
    assert get()[1] == "disk" and len(builds) == 1
    _damage(entry, how)
    capsys.readouterr()
    again, source = get()
    err = capsys.readouterr().err
    assert source == "built" and len(builds) == 2
    assert np.array_equal(again, value)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("arches-render: cache:") and "thing-0123.npz" in lines[0], err
    assert said in lines[0] and "rebuilding" in lines[0], lines[0]
    assert entry.read_bytes() == good  # the same bits as the first build
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["thing-0123.npz"]


def test_a_sealed_entry_stays_readable_by_plain_numpy(tmp_path):
    """The seal trails the zip archive, so tools (and older versions) still read the payload."""
    get, _ = _payload_cache(tmp_path)
    value, _ = get()
    with np.load(tmp_path / "thing-0123.npz", allow_pickle=False) as z:
        assert np.array_equal(z["v"], value)


def test_read_only_cache_folder_only_costs_time(tmp_path, monkeypatch):
    from arches_render import atomic
    get, builds = _payload_cache(tmp_path / "ro")

    def refuse(path):
        raise atomic.OutputError(path, "Read-only file system")
    monkeypatch.setattr(atomic, "_create", refuse)
    monkeypatch.setattr(cache, "atomic_path", atomic.atomic_path)
    assert get()[1] == "built" and get()[1] == "built" and len(builds) == 2


def test_truncated_rock_tile_entry_is_rebuilt_not_a_traceback(tmp_path):
    """The bug of the issue: a truncated rock-tile entry ended the render in zipfile.BadZipFile."""
    scene = write(tmp_path, ROCKS)
    env = _env(tmp_path)
    first = run_cli("rocks", scene, "-o", tmp_path / "a.npz", "-q", env=env)
    assert first.returncode == 0 and "built" in first.stdout, first.stderr
    (entry,) = (tmp_path / "cache" / "rocks").glob("rocks-*.npz")
    good = entry.read_bytes()
    entry.write_bytes(good[: len(good) // 3])
    r = run_cli("render", scene, "-o", tmp_path / "r.exr", "--resolution", "12x8", "--spp", "1", "--no-aovs",
                "-q", env=env)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and "BadZipFile" not in r.stderr
    notes = [ln for ln in r.stderr.splitlines() if ln.startswith("arches-render: cache:")]
    assert len(notes) == 1 and entry.name in notes[0] and "truncated" in notes[0], r.stderr
    assert entry.read_bytes() == good


ROCKS = """
[render]
resolution = [12, 8]
[camera]
origin = [0.0, -9.0, 3.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
[[lights]]
type = "constant"
radiance = 1.0
[[rock_piles]]
support = { shape = "box", center = [0, 0, 0], size = [2, 2, 1] }
rock_size = 0.3
tiling = "periodic"
poisson_radius = 0.15
seed = 8
erosion = { steps = 3 }
preset = "basalt"
"""


def _env(tmp_path):
    import os
    return dict(os.environ, ARCHES_RENDER_CACHE=str(tmp_path / "cache"))


def test_two_processes_building_the_same_tile_both_succeed_with_one_entry(tmp_path):
    scene = write(tmp_path, ROCKS)
    env = _env(tmp_path)
    cmd = [sys.executable, "-m", "arches_render.cli", "rocks", str(scene), "-q", "-o"]
    procs = [subprocess.Popen(cmd + [str(tmp_path / f"out{i}.npz")], cwd=REPO, env=env, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE) for i in range(2)]
    results = [p.communicate(timeout=600) + (p.returncode,) for p in procs]
    for out, err, rc in results:
        assert rc == 0, err
        assert "Traceback" not in err
    # The lock: one process built, the other waited and read the entry.
    sources = sorted("built" if " built in " in out else "cache" for out, _, _ in results)
    assert sources == ["built", "cache"], [r[0] for r in results]
    assert (tmp_path / "out0.npz").read_bytes() == (tmp_path / "out1.npz").read_bytes()
    entries = [p.name for p in (tmp_path / "cache" / "rocks").iterdir() if not p.name.startswith(".")]
    assert len(entries) == 1, entries
    leftovers = [p.name for p in (tmp_path / "cache" / "rocks").iterdir() if ".tmp-" in p.name]
    assert not leftovers


def test_lock_is_released_when_its_holder_is_killed(tmp_path):
    """A builder killed while holding the lock does not block the next one (the kernel drops flocks)."""
    code = textwrap.dedent(f"""
        import os, sys, time
        from pathlib import Path
        from arches_render import cache
        with cache._locked(Path({str(tmp_path)!r}) / "x.npz"):
            print("locked", flush=True)
            time.sleep(600)
    """)
    p = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "locked"
    p.kill()
    p.wait(timeout=60)
    get_value = cache.load_or_build(tmp_path / "x.npz", lambda f: f.read(), lambda: b"v",
                                    lambda v, path: open(path, "wb").write(v))
    assert get_value == (b"v", "built")
