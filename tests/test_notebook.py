"""Lookdev in Jupyter (issue 35 part 2): a notebook, run by a real kernel as Jupyter runs it
(nbclient), loads a scene, displays the look, moves a slider, displays it again and shows a
progressive preview. The outputs are checked as a notebook would hold them: PNG images,
different where the sun moved, the slider's render compiling nothing, and one preview output
that each pass replaced rather than one image a pass."""

from __future__ import annotations

import base64
import io

import numpy as np

from production_helpers import FLAT, write_scene

CELLS = [
    "from arches_render import api\nlook = api.load(SCENE, resolution=(48, 27), spp=2)",
    "look",
    "box = look.slider('lights.0.elevation', 5.0, 85.0)\nbox.children[0].value = 12.0\n"
    "print(look.compiled, look.get('lights.0.elevation'))",
    "look",
    # Count the in-place updates the preview sends (one a pass after the first).
    "import IPython.display as d\nupdates = []\nupdate = d.DisplayHandle.update\n"
    "d.DisplayHandle.update = lambda self, obj, **kw: (updates.append(1), update(self, obj, **kw))[1]\n"
    "final = look.preview(spp=32)\nprint(final.shape, len(updates))",
]


def _png(output) -> np.ndarray:
    from PIL import Image
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(output["data"]["image/png"]))))


def _images(cell) -> list:
    return [_png(o) for o in cell.outputs if "image/png" in o.get("data", {})]


def _stdout(cell) -> str:
    return "".join(o.get("text", "") for o in cell.outputs if o.get("name") == "stdout")


def test_a_notebook_displays_the_look_and_a_slider_re_renders_it(tmp_path):
    import nbformat
    from nbclient import NotebookClient
    scene = write_scene(tmp_path, FLAT, "flat")
    cells = [nbformat.v4.new_code_cell(c.replace("SCENE", repr(str(scene)))) for c in CELLS]
    nb = nbformat.v4.new_notebook(cells=cells)
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    first, after = _images(nb.cells[1]), _images(nb.cells[3])
    assert len(first) == 1 and len(after) == 1
    assert first[0].shape[:2] == (27, 48) and after[0].shape == first[0].shape
    # The sun went from 50 to 12 degrees: the same view, darker.
    assert not np.array_equal(first[0], after[0])
    assert after[0][..., :3].mean() < first[0][..., :3].mean()
    # A slider's render is a parameter edit: no kernel compiled, the key set.
    assert _stdout(nb.cells[2]).split() == ["0", "12.0"]
    # Two passes (32 spp), one output, refined in place.
    preview = _images(nb.cells[4])
    assert len(preview) == 1 and preview[0].shape == first[0].shape
    assert _stdout(nb.cells[4]).strip() == "(27, 48, 3) 1"
