"""The page of a run folder (``ddtrack run``)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..plotting import ROBOT, plot_errors, plot_gains, plot_path, plot_states, plot_torques, plt
from ..sim import remedy
from ..studies.recorded import driven_by
from ._page import (
    GAIN_NAMES,
    KINDS,
    METRICS,
    Card,
    Figure,
    Section,
    Table,
    _field,
    _positive_log,
    _read_json,
    _read_table,
    _read_toml,
    _short_list,
    decimate,
    fmt,
    svg,
)

# --- run folder ----------------------------------------------------------------------------------------------

SERIES = (
    "t",
    "x",
    "y",
    "theta",
    "v",
    "omega",
    "x_ref",
    "y_ref",
    "theta_ref",
    "v_ref",
    "omega_ref",
    "e_x",
    "e_y",
    "e_theta",
    "e_tr",
    "tau_r",
    "tau_l",
)


def _scenario_section(text: str, data: Mapping[str, Any], path: str) -> Section:
    """The resolved scenario: a small table per TOML section (top-level keys first), and the file itself."""
    top = tuple((str(key), _toml_value(value)) for key, value in data.items() if not isinstance(value, Mapping))
    tables = [Table("scenario-top", ("key", "value"), top, left=2)] if top else []
    for i, (section, values) in enumerate((k, v) for k, v in data.items() if isinstance(v, Mapping)):
        rows = tuple((str(key), _toml_value(value)) for key, value in values.items()) or (("(none)", ""),)
        tables.append(Table(f"scenario-{i}", (f"[{section}]", "value"), rows, left=2))
    return Section(
        "scenario",
        "Scenario",
        (f"As stored in {path}, fully resolved (defaults included).",),
        tables=tuple(tables),
        code=text,
        code_title=f"{path} as written",
        layout="grid",
    )


def _toml_value(value: Any) -> str:
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list) and value and isinstance(value[0], list):
        return _short_list(value, limit=4)
    return fmt(value, digits=10)


def _written(folder: Path, names: Sequence[str]) -> str:
    times = [(folder / name).stat().st_mtime for name in names if (folder / name).is_file()]
    return _utc(max(times)) if times else "unknown"


def _driver_text(driver: Mapping[str, Any]) -> str:
    """``driven_by`` in words: whatever published the topic drove the plant of ``ddtrack robot``, and how it ended."""
    text = f"whatever published {driver.get('topic', '/cmd_vel')} ({driver.get('command')}, {driver.get('mode')} mode)"
    if "ended" in driver:
        text += f"; the run ended {driver['ended']} after {fmt(driver.get('periods'))} periods"
    return text


def _utc(timestamp: float) -> str:
    return dt.datetime.fromtimestamp(timestamp, dt.UTC).strftime("%Y-%m-%d %H:%M UTC")


def _run_page(folder: Path) -> dict:
    text, scenario = _read_toml(folder / "scenario.toml")
    metrics_path, toml_path = folder / "metrics.json", folder / "scenario.toml"
    metrics = _read_json(metrics_path)
    table = _read_table(folder / "timeseries.parquet", SERIES)
    columns = {
        name: table.column(name).to_numpy(zero_copy_only=False).astype(np.float64) for name in table.column_names
    }
    name = str(_field(scenario, "name", path=toml_path))
    controller = _field(scenario, "controller", path=toml_path)
    kind = str(_field(controller, "kind", path=toml_path))
    trajectory = str(_field(scenario, "trajectory", "kind", path=toml_path))
    seed, duration = (_field(scenario, "simulation", key, path=toml_path) for key in ("seed", "duration"))
    status = str(_field(metrics, "status", path=metrics_path))
    window = tuple(_field(metrics, "window", path=metrics_path))

    rows = [("status", status, ""), ("metric window", f"[{fmt(window[0])}, {fmt(window[1])}]", "s")]
    for key, label, unit, scale in METRICS:
        if key in metrics:  # failure_time only where the run failed
            rows.append((label, fmt(metrics[key], scale=scale), unit))
    known = {"status", "window", "final_gains", "driven_by", *(m[0] for m in METRICS)}
    rows += [(key, fmt(value), "") for key, value in metrics.items() if key not in known]
    if isinstance(driver := metrics.get("driven_by"), Mapping):  # a live robot's run: what drove it, in words
        rows.append(("driven by", _driver_text(driver), ""))
    kind, _ = driven_by(metrics, kind)
    notes = []
    if status != "ok":
        when = f" at t = {fmt(metrics['failure_time'])} s" if "failure_time" in metrics else ""
        advice = remedy(status, columns, metrics.get("warnings", []))  # what ddtrack run printed
        notes.append(f"The run stopped{when}: {status}.{f' To try: {advice}.' if advice else ''}")
    sections = [
        Section(
            "metrics",
            "Metrics",
            (
                *notes,
                "Tracking error e_tr (paper eq. 35) over the metric window; "
                "settling time, effort and saturation over the whole run.",
            ),
            tables=(Table("metrics-table", ("metric", "value", "unit"), tuple(rows)),),
        )
    ]

    figures = [
        Figure(
            "fig-path",
            "Path in the plane: the robot against the reference (dashed).",
            svg(plot_path(decimate(columns, ("x", "y", "x_ref", "y_ref"))), "path", "path in the plane"),
        ),
        Figure(
            "fig-states",
            "x, y, θ, v and ω against time, with the reference (dashed).",
            svg(
                plot_states(
                    decimate(
                        columns, ("x", "y", "theta", "v", "omega", "x_ref", "y_ref", "theta_ref", "v_ref", "omega_ref")
                    )
                ),
                "states",
                "states against time",
            ),
        ),
        Figure(
            "fig-errors",
            "Posture errors and e_tr; the metric window is shaded.",
            svg(
                plot_errors(decimate(columns, ("e_x", "e_y", "e_theta", "e_tr")), window=window),
                "errors",
                "posture errors",
            ),
        ),
    ]
    if np.any(np.isfinite(columns["tau_r"])):  # a velocity-input (kinematic) plant has no torques
        figures.append(
            Figure(
                "fig-torques",
                "Wheel torques; dotted: the actuator limit.",
                svg(
                    plot_torques(decimate(columns, ("tau_r", "tau_l")), max_torque=_max_torque(scenario)),
                    "torques",
                    "wheel torques",
                ),
            )
        )
    sections.append(Section("figures", "Figures", figures=tuple(figures)))

    if "final_gains" in metrics and metrics["final_gains"] is not None:  # only controllers with gains have them
        sections.append(_gains_section(controller, metrics["final_gains"], columns))
    if (folder / "identification.json").is_file():
        sections.append(
            _identification_section(_read_json(folder / "identification.json"), folder / "identification.json")
        )
    sections.append(_scenario_section(text, scenario, "scenario.toml"))

    settle = metrics["settling_time"] if "settling_time" in metrics else None
    cards = (
        Card("status", status, "good" if status == "ok" else "bad"),
        Card("controller", kind),
        Card("trajectory", trajectory),
        Card("mean e_tr", "–" if metrics["e_tr_mean"] is None else f"{fmt(metrics['e_tr_mean'])} m"),
        Card("settling time", f"{fmt(settle)} s" if settle is not None else "never" if status == "ok" else "–"),
    )
    return {
        "title": name,
        "subtitle": f"{kind} on {trajectory}, seed {fmt(seed)}, {fmt(duration)} s",
        "cards": cards,
        "sections": sections,
        "written": _written(folder, KINDS["run"]),
    }


def _gains_section(controller: Mapping[str, Any], final: Sequence[float], columns: Mapping[str, np.ndarray]) -> Section:
    """Initial (scenario) and final (metrics) gains, and the gains figure when they moved."""
    initial = controller["gains"] if "gains" in controller else [None] * len(final)
    rows = []
    for label, start, end in zip(GAIN_NAMES, initial, final, strict=True):
        change = 100.0 * (end - start) / start if isinstance(start, int | float) and start else None
        rows.append((label, fmt(start), fmt(end), fmt(change, 3)))
    moved = all(k in columns for k in ("kx", "ky", "ktheta")) and any(
        np.nanmax(columns[k]) > np.nanmin(columns[k]) for k in ("kx", "ky", "ktheta")
    )
    figures = (
        (
            Figure(
                "fig-gains",
                "The gains against time (the paper's Figs. 13 and 17).",
                svg(plot_gains(decimate(columns, ("kx", "ky", "ktheta"))), "gains", "gains against time"),
            ),
        )
        if moved
        else ()
    )
    return Section(
        "gains",
        "Gains",
        (
            "Initial gains from the scenario, final gains at the end of the run."
            + ("" if moved else " They did not move."),
        ),
        tables=(Table("gains-table", ("gain", "initial", "final", "change [%]"), tuple(rows)),),
        figures=figures,
        layout="side" if figures else "",
    )


def _max_torque(scenario: Mapping[str, Any]) -> float | None:
    """The plant's torque limit: a key left out of [plant] takes the [robot] value (docs/guide.md)."""
    for section in ("plant", "robot"):
        if section in scenario and "max_torque" in scenario[section]:
            return float(scenario[section]["max_torque"])
    return None


def _identification_section(found: Mapping[str, Any], path: Path) -> Section:
    losses = np.asarray(_field(found, "epoch_loss", path=path), dtype=float)
    rows = [
        ("samples", fmt(_field(found, "samples", path=path))),
        ("epochs", fmt(_field(found, "epochs", path=path))),
        ("final loss", fmt(float(losses[-1]) if losses.size else None)),
    ]
    rows += [(f"prediction NMSE, {key}", fmt(value)) for key, value in _field(found, "nmse", path=path).items()]
    fig, ax = plt.subplots(figsize=(6.0, 3.0), layout="constrained")
    ax.plot(np.arange(1, losses.size + 1), losses, color=ROBOT, lw=1.4)
    ax.set(xlabel="epoch", ylabel="mean loss")
    _positive_log(ax, losses)
    ax.grid(alpha=0.3)
    return Section(
        "identification",
        "Emulator identification",
        ("The neural emulator's pre-training before the run: loss per epoch and the prediction NMSE.",),
        tables=(Table("identification-table", ("quantity", "value"), tuple(rows)),),
        figures=(
            Figure("fig-identification", "Training loss per epoch.", svg(fig, "identification", "identification loss")),
        ),
        layout="side",
    )
