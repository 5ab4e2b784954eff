"""Shared helpers of the robustness tests (bad input, faults, fuzzing): plain functions, no fixtures."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from helpers import REPO

#: A scene with a sphere on a box: loads in milliseconds, renders a few pixels in seconds.
BASE_SCENE = textwrap.dedent("""
    [scene]
    name = "tiny"
    [render]
    resolution = [16, 12]
    spp = 2
    [camera]
    origin = [0.0, -6.0, 2.0]
    target = [0.0, 0.0, 0.5]
    [[lights]]
    type = "constant"
    radiance = 1.0
    [field]
    root = "ball"
    [nodes.ball]
    type = "sphere"
    center = [0.0, 0.0, 0.5]
    radius = 1.0
""")


def write(folder: Path, text: str, name: str = "scene.toml") -> Path:
    """Write ``text`` (dedented) to ``folder/name``; return the path."""
    path = Path(folder) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text))
    return path


def cli(capsys, *args) -> tuple[int, str]:
    """Run ``arches-render ARGS`` in this process; return the exit status and stderr."""
    rc, _, err = cli_out(capsys, *args)
    return rc, err


def cli_out(capsys, *args) -> tuple[int, str, str]:
    """Run ``arches-render ARGS`` in this process; return the exit status, stdout and stderr."""
    from arches_render.cli import main
    capsys.readouterr()
    rc = main([str(a) for a in args])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def assert_one_line_error(rc: int, err: str, *words: str) -> str:
    """Exit 2, no traceback, and the last stderr line is the error naming every one of ``words``."""
    assert rc == 2, err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("arches-render: error:")]
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def run_cli(*args, env=None, cwd=None, timeout=600) -> subprocess.CompletedProcess:
    """``python -m arches_render.cli ARGS`` in a fresh process."""
    env = dict(os.environ if env is None else env, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "arches_render.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd or REPO, env=env, timeout=timeout)


def listing(folder: Path) -> list[str]:
    """Every file below ``folder`` (hidden ones too), relative, sorted."""
    folder = Path(folder)
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file() or p.is_dir())
