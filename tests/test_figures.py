"""The run figures say what they show: titles name the controller, states.png shows v and omega with their
references, the metric window and the torque limit have legend entries, the torque axis fits the torques, the legend
sits above the data, and a kinematic run gets no torque figure."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SCENARIOS

from ddtrack.plotting import plot_errors, plot_path, plot_states, plot_torques, plt


def columns(n: int = 200, torque: float = 1.0) -> dict[str, np.ndarray]:
    t = np.linspace(0.0, 2.0, n)
    c = {"t": t, "x": t, "y": 0.1 * t, "theta": 0.1 + 0 * t, "v": 1 + 0 * t, "omega": 0 * t}
    c |= {f"{k}_ref": v + 0.01 for k, v in list(c.items()) if k != "t"}
    c |= {
        "e_x": 0.01 + 0 * t,
        "e_y": 0.01 + 0 * t,
        "e_theta": 0 * t,
        "e_tr": 0.014 + 0 * t,
        "tau_r": torque * np.sin(t),
        "tau_l": -torque * np.sin(t),
    }
    return c


def labels(ax) -> list[str]:
    legend = ax.get_legend()
    return [] if legend is None else [text.get_text() for text in legend.get_texts()]


def test_states_show_v_and_omega_with_references():
    fig = plot_states(columns(), title="case: nn_adaptive_backstepping on line")
    assert [ax.get_ylabel() for ax in fig.axes] == ["x [m]", "y [m]", "theta [rad]", "v [m/s]", "omega [rad/s]"]
    assert all(len(ax.lines) == 2 for ax in fig.axes)  # the state and its reference, on every panel
    assert fig.get_suptitle() == "case: nn_adaptive_backstepping on line"
    plt.close(fig)


def test_the_metric_window_has_a_legend_entry():
    fig = plot_errors(columns(), window=(0.5, 2.0))
    assert "metric window [0.5, 2] s" in labels(fig.axes[0])
    plt.close(fig)


@pytest.mark.parametrize("limit, drawn", [(1.2, True), (10.0, False), (1e308, False)])
def test_the_torque_axis_fits_the_torques(limit, drawn):
    fig = plot_torques(columns(torque=1.0), max_torque=limit)
    ax = fig.axes[0]
    _low, high = ax.get_ylim()
    assert high < 2.0 * max(1.0, limit if drawn else 1.0)  # the torques, not a far limit, set the scale
    entry = [text for text in labels(ax) if text.startswith("limit")]
    assert len(entry) == 1 and ("off scale" in entry[0]) == (not drawn)
    plt.close(fig)


def test_the_path_legend_sits_above_the_axes_not_on_the_start():
    fig = plot_path(columns(), title="t")
    legend = fig.axes[0].get_legend()
    fig.canvas.draw()
    box, axes_box = legend.get_window_extent(), fig.axes[0].get_window_extent()
    assert box.y0 >= axes_box.y1 - 1  # in a row above the plotting area: it cannot hide the start marker
    assert "start" in labels(fig.axes[0])
    plt.close(fig)


def test_run_figures_are_titled_and_a_kinematic_run_has_no_torques(tmp_path, cli):
    from PIL import Image  # noqa: F401  (the PNGs are real images)

    out = tmp_path / "run"
    code, _, _ = cli(
        "run",
        SCENARIOS / "circle.toml",
        "--controller",
        "kinematic_backstepping",
        "--set",
        "simulation.duration=2",
        "--set",
        "simulation.metric_window=[0, 2]",
        "--out",
        out,
    )
    assert code == 0
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["errors.png", "path.png", "states.png"]


def test_help_shows_every_command_summary_whole():
    from click.testing import CliRunner

    from ddtrack.cli import cli

    text = CliRunner().invoke(cli, ["--help"], terminal_width=80).output
    listed = " ".join(text.split("Commands:")[1].split())
    for name, command in cli.commands.items():
        summary = command.get_short_help_str(limit=10_000)
        assert not summary.endswith("...") and summary.endswith(".") and f"{name} {summary}" in listed, summary
