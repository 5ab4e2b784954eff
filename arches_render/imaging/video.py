"""H.264 MP4 previews of image sequences (turntables), through the ffmpeg of imageio-ffmpeg.

Frames are display-referred 8-bit RGB (a view transform of
:mod:`arches_render.imaging.colour`). H.264 with 4:2:0 chroma subsampling
(``yuv420p``, the pixel format every player decodes) needs even width and height:
odd sizes are padded by one row/column repeating the edge pixels, never scaled,
so the preview shows the frame's pixels. The video is written to a temporary file
and renamed (atomic).

References
----------
ITU-T H.264 (2019), Advanced video coding for generic audiovisual services.
imageio-ffmpeg, https://github.com/imageio/imageio-ffmpeg (bundled ffmpeg binary).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from ..atomic import atomic_path

__all__ = ["pad_even", "write_mp4"]


def pad_even(frame: np.ndarray) -> np.ndarray:
    """Pad an ``(H, W, 3)`` frame to even ``H`` and ``W`` by repeating its last row/column."""
    h, w = frame.shape[:2]
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def write_mp4(path, frames: Iterable[np.ndarray], fps: float = 24.0, crf: int = 18) -> Path:
    """Encode uint8 RGB frames as an H.264 MP4, atomically.

    Parameters
    ----------
    path : str or Path
        Destination ``.mp4``.
    frames : iterable of numpy.ndarray
        uint8 ``(H, W, 3)`` frames of one size.
    fps : float
        Frame rate.
    crf : int
        x264 constant rate factor (lower is better; 18 is visually lossless).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ValueError
        For no frames, frames of different sizes or a non-uint8 frame.
    """
    import imageio_ffmpeg  # on use: only --mp4 needs it

    frames = iter(frames)
    first = next(frames, None)
    if first is None:
        raise ValueError("write_mp4: no frames")
    path = Path(path)
    with atomic_path(path) as tmp:
        size = None
        writer = None
        try:
            for f in (first, *frames):
                f = np.asarray(f)
                if f.dtype != np.uint8 or f.ndim != 3 or f.shape[2] != 3:
                    raise ValueError(f"write_mp4: frames must be uint8 (H, W, 3), got {f.dtype} {f.shape}")
                f = pad_even(f)
                if writer is None:
                    size = f.shape[:2]
                    writer = imageio_ffmpeg.write_frames(
                        str(tmp), (size[1], size[0]), fps=fps, codec="libx264", pix_fmt_in="rgb24",
                        pix_fmt_out="yuv420p", quality=None, macro_block_size=1,
                        output_params=["-crf", str(int(crf)), "-movflags", "+faststart"],
                        ffmpeg_log_level="error")
                    writer.send(None)  # start the generator
                elif f.shape[:2] != size:
                    raise ValueError(f"write_mp4: frame of size {f.shape[:2]} after {size}")
                writer.send(np.ascontiguousarray(f))
        finally:
            if writer is not None:
                writer.close()
    return path
