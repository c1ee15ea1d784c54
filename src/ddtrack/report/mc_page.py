"""The page of a ``ddtrack mc`` folder: statistics per controller, paired improvements, distributions."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from ..metrics import improvement
from ..plotting import plt
from ._page import (
    GAIN_NAMES,
    KINDS,
    MAX_RUN_ROWS,
    Card,
    Cell,
    Figure,
    Section,
    Table,
    _field,
    _mpl,
    _read_json,
    _read_table,
    _read_toml,
    ci_cell,
    fmt,
    fmt_ci,
    plot_distributions,
    svg,
)
from .reproduce_page import fmt_window
from .run_page import (
    _scenario_section,
    _written,
)

# --- mc folder -----------------------------------------------------------------------------------------------

MC_STATISTICS = (
    ("e_tr_mean", "mean e_tr [m]"),
    ("e_tr_rms", "RMS e_tr [m]"),
    ("e_tr_max", "max e_tr [m]"),
    ("settling_time", "settling [s]"),
    ("effort", "effort [N² m² s]"),
    ("saturation_fraction", "saturated [%]"),
)
MC_COLUMNS = (
    "controller",
    "seed",
    "status",
    "e_tr_mean",
    "e_tr_max",
    "settling_time",
    "window_start",
    "window_end",
    "final_kx",
    "final_ky",
    "final_ktheta",
)


def _mc_page(folder: Path) -> dict:
    path = folder / "summary.json"
    summary = _read_json(path)
    controllers = _field(summary, "controllers", path=path)
    baseline = str(_field(summary, "improvement_over", path=path))
    gains = _field(summary, "improvement", path=path)
    runs = _read_table(folder / "runs.parquet", MC_COLUMNS).to_pylist()
    by_controller: dict[str, list[dict]] = {str(name): [] for name in controllers}
    for row in runs:
        by_controller.setdefault(str(row["controller"]), []).append(row)
    rows: tuple[tuple[str | Cell, ...], ...] = tuple(
        (
            str(name),
            fmt(len(by_controller[str(name)])),
            fmt(stats["failures"]),
            *(ci_cell(stats[key], scale=100.0 if key == "saturation_fraction" else 1.0) for key, _ in MC_STATISTICS),
        )
        for name, stats in controllers.items()
    )
    tables = [
        Table(
            "mc-table",
            ("controller", "runs", "failures", *(label for _, label in MC_STATISTICS)),
            rows,
            caption="Mean [95 % CI] over runs; failed runs are left out of the means.",
        )
    ]
    if gains:
        tables.append(
            Table(
                "improvement-table",
                ("controller", "over", "improvement [%]", "paired runs"),
                tuple(
                    (str(name), baseline, ci_cell(stat, 3), fmt(stat["paired_runs"])) for name, stat in gains.items()
                ),
                left=2,
                caption="Paired by seed: 100 (E_baseline − E) / E_baseline over the seeds where both runs succeeded.",
            )
        )
    figures = [
        Figure(
            "fig-etr",
            "Mean e_tr of each run, per controller (box: quartiles; points: runs).",
            svg(
                plot_distributions(
                    {n: [r["e_tr_mean"] for r in rs] for n, rs in by_controller.items()},
                    ylabel="mean e_tr per run [m]",
                    title="tracking error",
                ),
                "etr",
                "distribution of the mean tracking error",
            ),
            wide=len(by_controller) > 4,
        )
    ]
    paired = _paired_improvements(by_controller, baseline)
    if any(paired.values()):
        figures.append(
            Figure(
                "fig-improvement",
                f"Improvement of each run over {baseline} on the same seed.",
                svg(
                    plot_distributions(
                        paired,
                        ylabel="improvement [%]",
                        reference=0.0,
                        title=f"paired improvement over {_mpl(baseline)}",
                    ),
                    "improvement",
                    "distribution of the paired improvement",
                ),
                wide=len(by_controller) > 5,
            )
        )
    gain_figure = _final_gains_figure(by_controller)
    if gain_figure is not None:
        figures.append(
            Figure(
                "fig-final-gains",
                "Final gains of each run, for the controllers that have gains.",
                svg(gain_figure, "final-gains", "final gains"),
            )
        )
    sections = [
        Section("summary", "Per controller", tables=tuple(tables)),
        Section("distributions", "Distributions", figures=tuple(figures)),
    ]
    shown = (
        "controller",
        "seed",
        "status",
        "e_tr_mean",
        "e_tr_max",
        "settling_time",
        "final_kx",
        "final_ky",
        "final_ktheta",
    )
    note = (
        f"The first {MAX_RUN_ROWS} of {len(runs)} runs; every run is in runs.csv."
        if len(runs) > MAX_RUN_ROWS
        else "Every run (also in runs.csv and runs.parquet)."
    )
    sections.append(
        Section(
            "runs",
            "Runs",
            (note,),
            tables=(
                Table(
                    "runs-table",
                    shown,
                    tuple(tuple(fmt(r[c]) for c in shown) for r in runs[:MAX_RUN_ROWS]),
                    left=3,
                    nowrap=3,
                    collapsed=True,
                ),
            ),
        )
    )
    if (folder / "scenario.toml").is_file():
        text, scenario = _read_toml(folder / "scenario.toml")
        sections.append(_scenario_section(text, scenario, "scenario.toml"))
    else:
        windows = sorted({(r["window_start"], r["window_end"]) for r in runs if r["window_start"] is not None})
        sections.append(
            Section(
                "scenario",
                "Scenario",
                (
                    "An mc folder does not store its scenario (see the command that wrote it); metric window "
                    + ", ".join(fmt_window(w) for w in windows)
                    + ".",
                ),
            )
        )
    n = max((len(v) for v in by_controller.values()), default=0)
    failures = sum(int(stats["failures"]) for stats in controllers.values())
    cards = [
        Card("runs per controller", fmt(n)),
        Card("controllers", str(len(controllers))),
        Card("baseline", baseline),
    ]
    for name, stat in gains.items():
        cards.append(
            Card(
                f"{name} vs {baseline}",
                f"{fmt_ci(stat, 3)} %",
                "good" if stat["mean"] is not None and stat["mean"] > 0 else "bad",
            )
        )
    cards.append(Card("failed runs", str(failures), "good" if failures == 0 else "bad"))
    return {
        "title": "Monte Carlo",
        "subtitle": f"{n} seeds per controller on common random numbers: " + ", ".join(str(c) for c in controllers),
        "cards": tuple(cards),
        "sections": sections,
        "written": _written(folder, KINDS["mc"]),
    }


def _paired_improvements(by_controller: Mapping[str, list[dict]], baseline: str) -> dict[str, list[float]]:
    """Per controller, 100 (E_baseline - E) / E_baseline for each seed where both have a result."""
    if baseline not in by_controller:
        return {}
    base = {
        r["seed"]: r["e_tr_mean"] for r in by_controller[baseline] if r["e_tr_mean"] is not None and r["e_tr_mean"] > 0
    }
    return {
        name: [
            improvement(base[r["seed"]], r["e_tr_mean"])
            for r in runs
            if r["e_tr_mean"] is not None and r["seed"] in base
        ]
        for name, runs in by_controller.items()
        if name != baseline
    }


def _final_gains_figure(by_controller: Mapping[str, list[dict]]) -> plt.Figure | None:
    keys = ("final_kx", "final_ky", "final_ktheta")
    having = {name: runs for name, runs in by_controller.items() if any(r[k] is not None for r in runs for k in keys)}
    if not having:
        return None
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(max(4.5, 0.9 * len(having) + 2.0), 6.4), layout="constrained")
    for ax, key, label in zip(axes, keys, GAIN_NAMES, strict=True):
        plot_distributions(
            {name: [r[key] for r in runs] for name, runs in having.items()}, ax=ax, ylabel=f"final {label}"
        )
    for ax in axes[:-1]:
        ax.tick_params(labelbottom=False)  # the names once, under the last panel
    return fig
