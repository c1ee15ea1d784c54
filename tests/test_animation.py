"""``ddtrack animate`` and ddtrack.animation: frame times, the footprint, the GIF it writes, its errors."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from conftest import SCENARIOS
from matplotlib.colors import to_rgb
from PIL import Image

from ddtrack.animation import animate, footprint, frame_indices, gains_moved, read_run
from ddtrack.cli import main
from ddtrack.errors import ConfigError
from ddtrack.plotting import ADAPTIVE, ROBOT

# On a line at 0.3 rad from its start, heading along it: the robot moves up and to the right (more right) for 4 s.
ON_THE_LINE = [
    "--set",
    "simulation.duration=4",
    "--set",
    "simulation.metric_window=[0, 4]",
    "--set",
    "trajectory.heading=0.3",
    "--set",
    "initial.pose=[0, 0, 0.3]",
]


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """A 4 s `ddtrack run` folder of the paper's line case (400 rows)."""
    out = tmp_path_factory.mktemp("anim") / "line"
    assert main(["run", str(SCENARIOS / "paper_line.toml"), *ON_THE_LINE, "--out", str(out)]) == 0
    return out


def frames(path) -> list[np.ndarray]:
    with Image.open(path) as gif:
        shown = []
        for k in range(gif.n_frames):
            gif.seek(k)
            shown.append(np.asarray(gif.convert("RGB"), dtype=float))
        return shown


def test_frame_times_follow_fps_and_speed():
    t = np.arange(4000) * 0.01  # a 40 s run sampled at T_c = 10 ms
    rows, speed = frame_indices(t, fps=20, speed=2.0)
    assert speed == 2.0 and rows[0] == 0 and rows[-1] == 3999
    assert len(rows) == 401  # a frame every 0.1 s of simulated time up to 39.9 s, plus the last row
    assert np.allclose(np.diff(t[rows])[:-1], 0.1)
    slow, _ = frame_indices(t[:50], fps=20, speed=0.1)  # 5 ms per frame: rows repeat, so the timing holds
    assert len(slow) == 99 and np.all(np.diff(slow) >= 0) and len(np.unique(slow)) == 50


def test_frame_count_is_bounded_by_playing_faster():
    t = np.arange(8000) * 0.01
    rows, speed = frame_indices(t, fps=20, speed=1.0, max_frames=600)
    assert len(rows) == 600 and rows[0] == 0 and rows[-1] == 7999
    assert speed == pytest.approx(t[-1] * 20 / 599)  # the whole run in 600 frames at 20 fps
    assert frame_indices(t[:1], fps=20, speed=1.0)[0].tolist() == [0]  # a one-row run is one frame


def test_footprint_geometry():
    L, R, theta = 0.25, 0.05, 0.6
    shape = footprint(1.0, 2.0, theta, half_axle=L, wheel_radius=R)
    heading, left = np.array([np.cos(theta), np.sin(theta)]), np.array([-np.sin(theta), np.cos(theta)])
    assert np.allclose(shape["right_wheel"].mean(axis=0), [1.0, 2.0] - L * left)  # wheels on the axle, at -+L
    assert np.allclose(shape["left_wheel"].mean(axis=0), [1.0, 2.0] + L * left)
    wheel = shape["left_wheel"]
    assert np.isclose(np.ptp(wheel @ heading), 2 * R)  # a wheel is its diameter long
    assert np.allclose(shape["arrow"][0], [1.0, 2.0]) and (shape["arrow"][1] - shape["arrow"][0]) @ heading > L
    body = shape["body"] - [1.0, 2.0]
    assert np.max(np.abs(body @ left)) < L  # the chassis lies between the wheels


def test_animate_writes_a_gif_of_the_run(short_run, cli):
    code, out, err = cli("animate", short_run, "--fps", "10", "--speed", "1")
    assert code == 0, err
    columns, _ = read_run(short_run)
    expected, _ = frame_indices(columns["t"], fps=10, speed=1.0)
    gif = short_run / "animation.gif"
    assert f"wrote {gif}: {len(expected)} frames at 10 fps" in out
    with Image.open(gif) as image:
        assert image.format == "GIF" and image.size[0] == 640  # no gains panel: backstepping's gains are fixed
        assert 300 <= image.size[1] <= 700 and image.size[1] % 2 == 0  # the map's aspect; even, as H.264 needs
        assert image.n_frames == len(expected) == 41  # 0.1 s of the run per frame, and its last row
        assert image.info["duration"] == 100  # ms per frame at 10 fps
    shown = frames(gif)
    assert np.mean(np.any(shown[0] != shown[-1], axis=-1)) > 0.001  # more than a clock changed
    assert [p.name for p in short_run.iterdir() if p.name.startswith(".")] == []  # no temporary file left


def test_the_drawn_robot_moves_as_the_run(short_run, tmp_path):
    columns, _ = read_run(short_run)
    gif = tmp_path / "plain.gif"
    info = animate(columns, gif, half_axle=0.25, wheel_radius=0.05, fps=1, speed=1.0, zoom=False)
    assert info.frames == 5 and info.speed == 1.0  # t = 0, 1, 2, 3 and 3.99 s
    fill = 0.55 * np.asarray(to_rgb(ROBOT)) * 255 + 0.45 * 255  # the body's face colour over the white map
    centres = []
    for image in frames(gif):
        body = np.argwhere(np.linalg.norm(image - fill, axis=-1) < 12)  # (row, column) of the body's pixels
        assert len(body) > 200, "the robot's body is not in the frame"
        centres.append(body.mean(axis=0))
    moved = np.diff(np.array(centres)[:, ::-1] * [1, -1], axis=0)  # (right, up) in pixels; image rows count down
    rows, _ = frame_indices(columns["t"], fps=1, speed=1.0)
    travelled = np.diff(np.column_stack([columns["x"][rows], columns["y"][rows]]), axis=0)  # [m]
    assert np.all(travelled[:, 0] > 0.3) and np.all(travelled[:, 1] > 0.1)  # accelerating from rest
    scale = np.sum(moved * travelled) / np.sum(travelled**2)  # pixels per metre of the equal-aspect map
    assert 100 < scale < 250
    assert np.allclose(moved, scale * travelled, atol=2.0)  # the drawn body follows the recorded pose to 2 px


def test_gains_panel_when_the_gains_moved(short_run, tmp_path):
    columns, _ = read_run(short_run)
    assert not gains_moved(columns)
    columns["kx"] = np.linspace(1.0, 3.0, len(columns["t"]))  # as an adaptive run would log them
    assert gains_moved(columns)
    info = animate(columns, tmp_path / "gains.gif", half_axle=0.25, wheel_radius=0.05, fps=2, speed=2.0)
    with Image.open(info.path) as image:
        assert image.size == (1080, 560) and image.n_frames == info.frames == 5  # 1 s of the run per frame
    last = frames(info.path)[-1]
    red = np.linalg.norm(last - np.asarray(to_rgb(ADAPTIVE)) * 255, axis=-1) < 12
    assert red[:, :600].sum() == 0 and red[:, 600:].sum() > 300  # the gain curves, on the right-hand panel


def test_a_folder_that_is_not_a_run_exits_2_and_writes_nothing(tmp_path, cli):
    (tmp_path / "scenario.toml").write_text((SCENARIOS / "paper_line.toml").read_text())
    code, _out, err = cli("animate", tmp_path)
    assert code == 2 and "timeseries.parquet missing" in err and "Traceback" not in err
    code, _, err = cli("animate", tmp_path / "nowhere")
    assert code == 2 and "is not a folder" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scenario.toml"]


def test_unknown_suffix_and_mp4_without_ffmpeg_exit_2(short_run, tmp_path, cli, monkeypatch):
    code, _, err = cli("animate", short_run, "--out", tmp_path / "run.avi")
    assert code == 2 and ".gif or .mp4" in err
    monkeypatch.setattr("shutil.which", lambda name: None)  # as on a machine without ffmpeg
    code, _, err = cli("animate", short_run, "--out", tmp_path / "run.mp4")
    assert code == 2 and "needs ffmpeg" in err
    assert list(tmp_path.iterdir()) == []


def test_a_failed_render_leaves_no_file(short_run, tmp_path, monkeypatch):
    columns, _ = read_run(short_run)

    def fail(self):
        raise RuntimeError("disk full")

    monkeypatch.setattr("ddtrack.animation._BlitPillowWriter.finish", fail)
    with pytest.raises(RuntimeError, match="disk full"):
        animate(columns, tmp_path / "run.gif", half_axle=0.25, wheel_radius=0.05, fps=2)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ConfigError, match="gif or .mp4"):
        animate(columns, tmp_path / "run.png", half_axle=0.25, wheel_radius=0.05)


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not on PATH")
def test_mp4_through_ffmpeg(short_run, tmp_path, cli):
    code, out, err = cli("animate", short_run, "--out", tmp_path / "run.mp4", "--fps", "2", "--speed", "1")
    assert code == 0, err
    assert "9 frames at 2 fps" in out  # 0.5 s of the run per frame, and its last row
    head = (tmp_path / "run.mp4").read_bytes()[:12]
    assert head[4:8] == b"ftyp"  # an MP4 container
    assert [p.name for p in tmp_path.iterdir()] == ["run.mp4"]


def test_importing_ddtrack_leaves_matplotlib_s_backend_alone(short_run, tmp_path):
    """A notebook or a GUI keeps its backend: importing the plotting and animation modules changes nothing, and an
    animation still renders (on an Agg canvas of its own) under a backend that cannot blit (here: svg)."""
    import subprocess
    import sys

    script = (
        "import matplotlib; matplotlib.use('svg')\n"
        "import ddtrack, ddtrack.plotting, ddtrack.animation\nddtrack.enable_float64()\n"
        "from ddtrack.animation import animate, read_run\n"
        "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()\n"
        f"columns, _ = read_run({str(short_run)!r})\n"
        f"info = animate(columns, {str(tmp_path / 'svg.gif')!r}, half_axle=0.25, wheel_radius=0.05, fps=1, speed=1.0)\n"
        "assert matplotlib.get_backend() == 'svg'\n"
        "print(info.frames)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert int(done.stdout.strip()) == 5 and len(frames(tmp_path / "svg.gif")) == 5
