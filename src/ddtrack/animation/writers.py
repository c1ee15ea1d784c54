"""Frames into a file: a GIF by blitting into one palette, an MP4 through ffmpeg, written atomically."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.animation import FFMpegWriter, PillowWriter
from PIL import Image

from ..errors import ConfigError, RunError
from .scene import (
    MAX_FRAMES,
    SUFFIXES,
    AnimationInfo,
    Columns,
    _Scene,
    _scene,
    animation_figure,
    footprint,
    frame_indices,
    gains_moved,
    read_run,
)


class _Blitter:
    """Renders frames by blitting: the still parts (axes, ticks, the reference path, the gain curves) are drawn
    once; each frame restores them and draws only the moving artists (10 to 20 times faster than a full draw)."""

    def __init__(self, scene: _Scene) -> None:
        self.scene = scene
        canvas = scene.canvas
        canvas.draw()  # constrained layout, once
        scene.fig.set_layout_engine("none")  # frozen, so the background stays valid
        for artist in scene.moving:
            artist.set_animated(True)
        canvas.draw()
        self.background = canvas.copy_from_bbox(scene.fig.bbox)

    def frame(self, row: int) -> Image.Image:
        self.scene.draw(row)
        canvas = self.scene.canvas
        canvas.restore_region(self.background)
        for artist in self.scene.moving:
            self.scene.fig.draw_artist(artist)
        width, height = canvas.get_width_height(physical=True)
        return Image.frombuffer("RGBA", (width, height), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")


class _BlitPillowWriter(PillowWriter):
    """:class:`PillowWriter` fed by the blitter instead of a full ``savefig`` per frame, keeping each frame as
    8-bit indices into one palette: a quarter of the memory of RGB frames, and no colour flicker."""

    def __init__(self, *, fps: float, palette: Image.Image) -> None:
        super().__init__(fps=fps)  # type: ignore[arg-type]  # stubs say int; a float frame rate works (ms = 1000 / fps)
        self._palette = palette
        self.image: Image.Image | None = None
        self._frames: list[Image.Image] = []

    def grab_frame(self, **savefig_kwargs: Any) -> None:
        assert self.image is not None, "render() sets the frame's image before grabbing it"
        self._frames.append(self.image.quantize(palette=self._palette, dither=Image.Dither.NONE))

    def finish(self) -> None:
        frames, self._frames = self._frames, []
        frames.reverse()

        def handed_over() -> Iterator[
            Image.Image
        ]:  # Pillow copies each frame it encodes: drop ours as it goes, so only one set is held
            while frames:
                yield frames.pop()

        first = frames.pop()
        first.save(
            self.outfile,
            format="GIF",
            save_all=True,
            append_images=handed_over(),
            duration=round(1000 / self.fps),
            loop=0,
        )


def animate(
    columns: Columns,
    out: str | Path,
    *,
    half_axle: float,
    wheel_radius: float,
    fps: float = 20.0,
    speed: float = 2.0,
    max_frames: int = MAX_FRAMES,
    title: str = "",
    zoom: bool = True,
    dpi: float = 100,
) -> AnimationInfo:
    """Write an animation of a run to ``out`` (``.gif`` with Pillow, ``.mp4`` with ffmpeg), atomically.

    Parameters
    ----------
    columns : mapping of str to ndarray
        The run's time-series columns (see :func:`animation_figure`).
    out : str or Path
        The file to write; its suffix picks the format. It is rendered under a temporary name in the same
        folder and renamed into place, so a failure leaves no partial file.
    half_axle, wheel_radius : float
        The robot's L and R [m].
    fps : float
        Frames per second of the file [1/s].
    speed : float
        Simulated seconds per second of playback (1 = real time).
    max_frames : int
        Bound on the frame count; a longer run plays faster (see the returned speed).
    title : str
        Figure title.
    zoom : bool
        Add a magnified view following the robot when the path is much larger than the robot.
    dpi : float
        Resolution: a frame is 640 pixels wide at 100 dpi, its height following the map's aspect; 1080 x 560
        with the gains panel.

    Returns
    -------
    AnimationInfo
        The path, frame count, fps and the playback speed.

    Raises
    ------
    ConfigError
        For a suffix other than ``.gif`` and ``.mp4``, or ``.mp4`` without ffmpeg on PATH.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise ConfigError("--out", f"'{out.name}': an animation is written as .gif or .mp4", "e.g. --out run.gif")
    if suffix == ".mp4" and not (shutil.which("ffmpeg") and FFMpegWriter.isAvailable()):
        raise ConfigError(
            "--out",
            f"writing '{out.name}' needs ffmpeg on PATH, and it is not there",
            "install ffmpeg (e.g. apt install ffmpeg), or write a .gif (Pillow, no ffmpeg needed)",
        )
    rows, played = frame_indices(np.asarray(columns["t"], float), fps=fps, speed=speed, max_frames=max_frames)
    scene = _scene(columns, half_axle=half_axle, wheel_radius=wheel_radius, title=title, zoom=zoom, dpi=dpi)
    if suffix == ".gif":
        blitter = _Blitter(scene)
        # the last frame holds every colour the others use (the whole path, the gains)
        palette = blitter.frame(int(rows[-1])).quantize(colors=256, method=Image.Quantize.MEDIANCUT)
        gif = _BlitPillowWriter(fps=fps, palette=palette)

        def render(path: Path) -> None:
            with gif.saving(scene.fig, str(path), dpi):
                for row in rows:
                    gif.image = blitter.frame(int(row))
                    gif.grab_frame()
    else:
        writer = FFMpegWriter(fps=fps, codec="h264", extra_args=["-pix_fmt", "yuv420p"])  # type: ignore[arg-type]  # as above

        def render(path: Path) -> None:
            scene.fig.canvas.draw()
            scene.fig.set_layout_engine("none")  # the same layout in every frame
            with writer.saving(scene.fig, str(path), dpi):
                for row in rows:
                    scene.draw(int(row))
                    writer.grab_frame()

    _write_atomically(out, render)  # the figure is not pyplot's: nothing to close
    return AnimationInfo(path=out, frames=int(rows.size), fps=float(fps), speed=float(played))


def _write_atomically(path: Path, render: Callable[[Path], None]) -> None:
    """``render(tmp)`` to a temporary sibling of ``path``, then rename it into place (as rundir.atomic_write,
    which is above this module's layer; a writer such as ffmpeg needs a file name, not a file object)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        render(tmp)
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # mkstemp's 0600 would hide the file from the user's group
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):  # a full disk: one line naming the file, no partial file (as atomic_write)
            raise RunError(f"cannot write '{path}' ({exc.strerror or exc}); nothing partial was left") from exc
        raise


__all__ = ["AnimationInfo", "animate", "animation_figure", "footprint", "frame_indices", "gains_moved", "read_run"]
