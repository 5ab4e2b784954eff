"""Unit tests of :mod:`arches_render.backend`: which libLLVM Dr.Jit may use.

Fast: nothing here renders. The one subprocess test points Dr.Jit at a real
LLVM 14/15 (when the machine has one) and checks that the CLI stops with a
one-line message instead of crashing inside LLVM.
"""

from __future__ import annotations

import glob
import os
import subprocess
import sys
from pathlib import Path

import pytest

from arches_render import backend
from arches_render.backend import BackendError, check_llvm, find_newest_libllvm, llvm_major_from_path

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("path, major", [
    ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15),
    ("libLLVM-15.so.1", 15),
    ("libLLVM-14.0.6.so.1", 14),
    ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", 19),
    ("libLLVM-19.so", 19),
    ("libLLVM.so", None),
    ("libc.so.6", None),
])
def test_llvm_major_from_path(path, major):
    assert llvm_major_from_path(path) == major


@pytest.mark.parametrize("loaded", [
    ["/usr/lib/x86_64-linux-gnu/libLLVM-14.so.1"],
    ["/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"],
    ["/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"],
])
def test_check_llvm_rejects_old_llvm(loaded):
    with pytest.raises(BackendError) as info:
        check_llvm(loaded)
    msg = str(info.value)
    assert "libllvm19" in msg
    assert ("Cannot select fminimum" in msg) == ("15" in loaded[-1])
    assert "\n" not in msg


def test_check_llvm_rejects_missing_llvm():
    with pytest.raises(BackendError, match="libllvm19"):
        check_llvm([])


@pytest.mark.parametrize("loaded", [
    ["/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"],
    ["/usr/lib/x86_64-linux-gnu/libLLVM-19.so"],
    ["/usr/lib/x86_64-linux-gnu/libLLVM-16.so.1"],
])
def test_check_llvm_accepts_recent_llvm(loaded):
    check_llvm(loaded)  # no exception


def _touch(folder: Path, *names: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        (folder / name).write_bytes(b"")


def test_find_newest_libllvm_picks_highest(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    _touch(a, "libLLVM-14.so.1", "libLLVM-15.so", "libLLVM-17.so.1", "libLLVM.so")
    _touch(b, "libLLVM.so.18.1", "libLLVM-16.so", "libfoo.so.20")
    assert find_newest_libllvm(dirs=[str(a), str(b)]) == str(b / "libLLVM.so.18.1")


def test_find_newest_libllvm_ignores_old_versions(tmp_path):
    _touch(tmp_path, "libLLVM-14.so.1", "libLLVM-15.so.1", "libLLVM-15.so", "libLLVM.so")
    assert find_newest_libllvm(dirs=[str(tmp_path)]) is None


def test_find_newest_libllvm_empty_and_missing_dirs(tmp_path):
    assert find_newest_libllvm(dirs=[str(tmp_path), str(tmp_path / "nope")]) is None


def _old_libllvm(major: int) -> str | None:
    paths = sorted(glob.glob(f"/usr/lib/*/libLLVM-{major}.so*"))
    return paths[0] if paths else None


@pytest.mark.parametrize("major", [14, 15])
def test_cli_refuses_old_libllvm(major):
    """With DRJIT_LIBLLVM_PATH at LLVM 14/15 the CLI exits 1 with one line, no traceback.

    Dr.Jit itself refuses LLVM 14 with a notice of its own on stderr
    (``jit_llvm_init(): the located LLVM version (14) is too old ...``); that
    line is not ours and is allowed. LLVM 15 is accepted by Dr.Jit and would
    crash later: only our line may appear.
    """
    lib = _old_libllvm(major)
    if lib is None:
        # Needs a real old libLLVM to load; Debian 12 machines (CI's) ship 14 and 15.
        pytest.skip(f"no libLLVM {major} on this machine")
    from arches_render.cli import EXIT_FAILURE

    env = dict(os.environ, DRJIT_LIBLLVM_PATH=lib)
    env.pop("ARCHES_VARIANT", None)
    proc = subprocess.run([sys.executable, "-m", "arches_render.cli", "info", "scenes/default.toml"],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == EXIT_FAILURE, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.strip().splitlines() if not line.startswith("jit_llvm_init():")]
    assert len(lines) == 1, proc.stderr[-2000:]
    assert lines[0].startswith("arches-render: error:")
    assert "libllvm19" in lines[0]
    assert ("Cannot select fminimum" if major == 15 else "too old") in lines[0]
    assert proc.stdout == ""


def test_backend_module_has_no_drjit_import_side_effect():
    """Importing the backend must not load Dr.Jit (it has to pick libLLVM first)."""
    code = "import sys; from arches_render import backend; print('drjit' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
    assert backend.MIN_LLVM_MAJOR == 16
