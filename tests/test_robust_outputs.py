"""Outputs that cannot be written (issue 17, "Faults"): a missing folder, a read-only folder, a full disk.

Each gives one clear line and leaves nothing behind: no partial file, no temporary
file, no folder made. A missing or read-only folder is known before any work and
exits with status 2 (the argument is wrong); a disk that fills up while writing
exits with status 1. The full disk is a tiny tmpfs mounted for the test where the
machine allows it (root with CAP_SYS_ADMIN), else ``os.fsync`` failing with ENOSPC
as a full disk reports on delayed allocation.
"""

from __future__ import annotations

import contextlib
import errno
import os
import subprocess

import numpy as np
import pytest

from helpers import variant
from robust_helpers import BASE_SCENE, assert_one_line_error, cli, listing, write


@pytest.fixture(autouse=True)
def _variant():
    variant()


@contextlib.contextmanager
def _mounted(folder, options):
    """A tmpfs mounted on ``folder`` with ``options``, or ``None`` where mounting is not permitted."""
    folder.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        yield None
        return
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True)
    if r.returncode != 0:
        yield None
        return
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


@contextlib.contextmanager
def _read_only(folder):
    """``folder`` made read-only: chmod for users, a read-only mount for root (which ignores modes)."""
    if os.geteuid() != 0:
        folder.mkdir(parents=True, exist_ok=True)
        folder.chmod(0o555)
        try:
            yield folder
        finally:
            folder.chmod(0o755)
        return
    with _mounted(folder, "ro,size=64k") as mnt:
        if mnt is None:
            pytest.skip("running as root without the right to mount a read-only folder")
        yield mnt


def _commands(tmp_path, out_dir):
    """(argv, output) of every command that writes, aimed at ``out_dir``."""
    scene = write(tmp_path, BASE_SCENE)
    np.save(tmp_path / "dem.npy", np.add.outer(np.arange(12.0), np.arange(12.0)).astype(np.float32))
    return [
        (["render", scene, "-o", out_dir / "x.exr", "-q"], out_dir / "x.exr"),
        (["turntable", scene, "-o", out_dir / "frames", "--frames", "2", "-q"], out_dir / "frames"),
        (["mesh", scene, "-o", out_dir / "x.ply", "-q"], out_dir / "x.ply"),
        (["amplify", tmp_path / "dem.npy", "-o", out_dir / "x.toml", "-q"], out_dir / "x.toml"),
    ]


def test_missing_output_folder_is_a_clear_error_and_nothing_is_made(tmp_path, capsys):
    missing = tmp_path / "no" / "such"
    for argv, out in _commands(tmp_path, missing):
        rc, err = cli(capsys, *argv)
        assert_one_line_error(rc, err, "-o/--output", str(out), "does not exist")
        assert not (tmp_path / "no").exists()


def test_generator_commands_refuse_a_missing_folder_too(tmp_path, capsys):
    scene = write(tmp_path, BASE_SCENE)
    for cmd in ("rocks", "blocks", "layers"):
        rc, err = cli(capsys, cmd, scene, "-o", tmp_path / "no" / "x.npz")
        assert_one_line_error(rc, err, "-o/--output", "does not exist")
    assert not (tmp_path / "no").exists()


def test_read_only_output_folder_is_refused_before_any_work(tmp_path, capsys):
    with _read_only(tmp_path / "ro") as ro:
        before = listing(ro)
        for argv, out in _commands(tmp_path, ro):
            rc, err = cli(capsys, *argv)
            assert_one_line_error(rc, err, "-o/--output", str(out), "is not writable")
        assert listing(ro) == before


def _fill(folder, leave=8 << 10):
    """Fill the file system of ``folder`` until about ``leave`` bytes are free."""
    with open(folder / "filler", "wb") as f:
        while True:
            free = os.statvfs(folder).f_bavail * os.statvfs(folder).f_frsize
            if free <= leave:
                break
            try:
                f.write(b"\0" * min(free - leave, 1 << 20))
                f.flush()
            except OSError:
                break


@pytest.mark.parametrize("disk", ["tmpfs", "enospc"])
def test_full_disk_while_writing_is_a_clear_error_and_leaves_nothing(tmp_path, capsys, monkeypatch, disk):
    scene = write(tmp_path, BASE_SCENE)
    with contextlib.ExitStack() as stack:
        if disk == "tmpfs":
            where = stack.enter_context(_mounted(tmp_path / "full", "size=256k"))
            if where is None:
                pytest.skip("no right to mount a tiny tmpfs here (the enospc case covers the code path)")
            _fill(where)
        else:  # the disk reports ENOSPC when the data is flushed (delayed allocation)
            where = tmp_path / "full"
            where.mkdir()

            def full(fd):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            monkeypatch.setattr(os, "fsync", full)
        before = listing(where)
        rc, err = cli(capsys, "render", scene, "-o", where / "x.exr", "--resolution", "64x48", "-q")
        monkeypatch.undo()
        assert rc == 1, err
        assert "Traceback" not in err
        lines = [ln for ln in err.splitlines() if ln.startswith("arches-render: error:")]
        assert len(lines) == 1 and "cannot write" in lines[0] and "x.exr" in lines[0], err
        assert "No space left on device" in lines[0] or "no space left" in lines[0], lines[0]
        assert listing(where) == before  # no partial EXR, no temporary file


def test_stale_temporary_files_of_dead_processes_are_swept(tmp_path):
    from arches_render import atomic
    dead = _dead_pid()
    stale = tmp_path / f".x.tmp-{atomic._HOST}-{dead}-abcd.exr"
    stale_dir = tmp_path / f".scene.tmp-{atomic._HOST}-{dead}-efgh.d"
    live = tmp_path / f".x.tmp-{atomic._HOST}-{os.getppid()}-ijkl.exr"
    other_host = tmp_path / f".x.tmp-elsewhere-{dead}-mnop.exr"
    for p in (stale, live, other_host):
        p.write_bytes(b"half")
    stale_dir.mkdir()
    (stale_dir / "heights.npy").write_bytes(b"half")
    with atomic.atomic_write(tmp_path / "x.txt", "w") as f:
        f.write("complete")
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == sorted([live.name, other_host.name, "x.txt"])
    assert (tmp_path / "x.txt").read_text() == "complete"


def _dead_pid() -> int:
    p = subprocess.Popen(["true"])
    p.wait()
    return p.pid
