"""Metrics over finished runs (model.md §4.4; paper eq. 35). Plain NumPy."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

WINDOW_TOLERANCE = 1e-9  # [s] sample times are k * T_c in floating point
#: the final fraction of the metric window a run must spend beyond its bound, without coming back, to have lost the
#: path: long enough that a transient (a corner, a latency-driven swing) is not counted
LOST_PATH_HOLD = 0.2


def tracking_error(e_x: np.ndarray, e_y: np.ndarray) -> np.ndarray:
    """e_tr = sqrt(e_x^2 + e_y^2) = |(x_r - x, y_r - y)| [m] (paper eq. 35).

    Parameters
    ----------
    e_x, e_y : ndarray
        Along-track and lateral posture errors [m] (model.md §2.2), of one shape.

    Returns
    -------
    ndarray
        The tracking error [m], of that shape.
    """
    return np.hypot(e_x, e_y)


def window_mask(t: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """Samples with start <= t <= end."""
    start, end = window
    return (t >= start - WINDOW_TOLERANCE) & (t <= end + WINDOW_TOLERANCE)


def window_statistics(t: np.ndarray, e_tr: np.ndarray, window: tuple[float, float]) -> dict[str, float | None]:
    """Mean, RMS, max and last value of e_tr over the samples in ``window`` [s]; None when it holds none."""
    values = np.asarray(e_tr)[window_mask(np.asarray(t), window)]
    if values.size == 0:
        return {"e_tr_mean": None, "e_tr_rms": None, "e_tr_max": None, "e_tr_final": None}
    return {
        "e_tr_mean": float(np.mean(values)),
        "e_tr_rms": float(np.sqrt(np.mean(values**2))),
        "e_tr_max": float(np.max(values)),
        "e_tr_final": float(values[-1]),
    }


def lost_path_time(t: np.ndarray, e_tr: np.ndarray, window: tuple[float, float], bound: float) -> float | None:
    """When the run lost the path: the start of the final stretch of ``window`` [s] over which e_tr stays beyond
    ``bound`` [m] to the window's end, when that stretch lasts at least :data:`LOST_PATH_HOLD` of the window; None
    for a run that tracks (it ends within the bound, or came back long enough before the end)."""
    mask = window_mask(np.asarray(t), window)
    times, values = np.asarray(t)[mask], np.asarray(e_tr)[mask]
    if values.size == 0 or not values[-1] > bound:
        return None
    within = np.flatnonzero(~(values > bound))
    start = float(times[within[-1] + 1]) if within.size else float(times[0])
    return start if times[-1] - start >= LOST_PATH_HOLD * (window[1] - window[0]) - WINDOW_TOLERANCE else None


def rate_ci(count: int, total: int, confidence: float = 0.95) -> dict:
    """A proportion ``count / total`` with its Wilson score interval (sound at 0 and at ``total``, unlike the
    normal one): ``mean``, ``ci_low``, ``ci_high`` as fractions, and ``n`` = ``total`` (all None without runs)."""
    from scipy.special import ndtri  # the normal quantile, as scipy.stats.norm.ppf, without its second's import

    if total == 0:
        return {"mean": None, "ci_low": None, "ci_high": None, "n": 0}
    z = float(ndtri(0.5 + confidence / 2))
    p = count / total
    centre = (p + z**2 / (2 * total)) / (1 + z**2 / total)
    half = z * math.sqrt(p * (1 - p) / total + z**2 / (4 * total**2)) / (1 + z**2 / total)
    low = 0.0 if count == 0 else max(0.0, centre - half)  # exactly the bound at the ends, not a rounding's 3e-15
    high = 1.0 if count == total else min(1.0, centre + half)
    return {"mean": p, "ci_low": low, "ci_high": high, "n": total}


def settling_time(t: np.ndarray, e_tr: np.ndarray, threshold: float) -> float | None:
    """First sample time after which e_tr stays below ``threshold`` [m] to the end; None if never."""
    above = np.flatnonzero(np.asarray(e_tr) >= threshold)
    if above.size == 0:
        return float(t[0])
    last = int(above[-1])
    return None if last + 1 >= len(t) else float(t[last + 1])


def effort(tau_r: np.ndarray, tau_l: np.ndarray, control_period: float) -> float | None:
    """Integral of tau_R^2 + tau_L^2 over the run [N^2 m^2 s] (exact under the zero-order hold)."""
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is reported as None, not a warning
        total = float(np.sum(np.asarray(tau_r) ** 2 + np.asarray(tau_l) ** 2) * control_period)
    return total if math.isfinite(total) else None


def saturation_fraction(saturated: np.ndarray) -> float:
    """Fraction of control periods in which a velocity clamp or the torque limit was active."""
    return float(np.mean(np.asarray(saturated) > 0.5))


def improvement(baseline: float, candidate: float) -> float:
    """Percent reduction of the error from ``baseline`` to ``candidate``: 100 (E_BS - E_NN) / E_BS (the paper's
    Table 1).

    Parameters
    ----------
    baseline : float
        The baseline's error E_BS, e.g. backstepping's mean e_tr [m]; must be > 0.
    candidate : float
        The candidate's error E_NN, in the same unit.

    Returns
    -------
    float
        The improvement [%]: positive when the candidate's error is lower, 100 when it is 0.

    Raises
    ------
    ValueError
        If ``baseline`` is not > 0.
    """
    if not baseline > 0.0:
        raise ValueError(f"the baseline error must be > 0 to compare against it, got {baseline}")
    return 100.0 * (baseline - candidate) / baseline


# The range each statistic can take; its confidence interval stays inside it (see :func:`mean_ci`).
METRIC_DOMAINS = {
    "e_tr_mean": "nonnegative",
    "e_tr_rms": "nonnegative",
    "e_tr_max": "nonnegative",
    "e_tr_final": "nonnegative",
    "settling_time": "nonnegative",
    "effort": "nonnegative",
    "saturation_fraction": "fraction",
    "improvement": "at_most_100",
}
DOMAINS = ("real", "nonnegative", "fraction", "at_most_100")


def _interval(mean: float, se: float, quantile: float, domain: str) -> tuple[float, float]:
    """mean -/+ quantile * se on a scale where the domain is the whole real line (delta method), mapped back.

    nonnegative: log(m); fraction: logit(m); at_most_100: log(100 - m). On the domain's edge (all values equal to
    it, e.g. no saturation in any run) the interval is that point."""
    if domain == "real":
        return mean - quantile * se, mean + quantile * se
    if domain == "nonnegative":
        if mean <= 0.0:
            return 0.0, 0.0
        half = quantile * se / mean  # d log(m) / dm = 1 / m
        return mean * math.exp(-half), mean * math.exp(half)
    if domain == "fraction":
        if mean <= 0.0 or mean >= 1.0:
            return mean, mean
        centre, half = math.log(mean / (1.0 - mean)), quantile * se / (mean * (1.0 - mean))
        return 1.0 / (1.0 + math.exp(-(centre - half))), 1.0 / (1.0 + math.exp(-(centre + half)))
    if domain == "at_most_100":
        low, high = _interval(100.0 - mean, se, quantile, "nonnegative")
        return 100.0 - high, 100.0 - low
    raise ValueError(f"unknown domain '{domain}'; one of {', '.join(DOMAINS)}")


def _check_domain(values: np.ndarray, domain: str) -> None:
    bounds = (
        {
            "real": (-np.inf, np.inf),
            "nonnegative": (0.0, np.inf),
            "fraction": (0.0, 1.0),
            "at_most_100": (-np.inf, 100.0),
        }[domain]
        if domain in DOMAINS
        else None
    )
    if bounds is None:
        raise ValueError(f"unknown domain '{domain}'; one of {', '.join(DOMAINS)}")
    if values.size and (values.min() < bounds[0] or values.max() > bounds[1]):
        raise ValueError(f"values outside the domain '{domain}' {list(bounds)}: {values.min()} .. {values.max()}")


def pooled_improvement(
    baselines: Sequence[float | None], candidates: Sequence[float | None], confidence: float = 0.95
) -> dict:
    """Paired improvement of the pooled mean error, 100 (1 - sum(candidates) / sum(baselines)), with a delta-method
    confidence interval of the ratio over the pairs (on log(ratio), so it never passes 100 %); same keys as
    :func:`mean_ci`.

    Unlike the mean of per-pair improvements, it stays finite when some baseline errors are near zero (an exact
    model): each pair weighs by its baseline error. Pairs with a None on either side are counted as ``missing``.
    """
    from scipy.special import stdtrit  # Student's t quantile, as scipy.stats.t.ppf (1 s of import less)

    pairs = [(b, c) for b, c in zip(baselines, candidates, strict=True) if b is not None and c is not None]
    summary: dict[str, float | int | None] = {
        "mean": None,
        "ci_low": None,
        "ci_high": None,
        "n": len(pairs),
        "missing": len(baselines) - len(pairs),
    }
    if not pairs or not sum(b for b, _ in pairs) > 0.0:
        return summary
    base, cand = np.asarray(pairs, dtype=float).T
    ratio = cand.sum() / base.sum()
    summary["mean"] = 100.0 * (1.0 - ratio)
    if len(pairs) >= 2:  # var(ratio) ~ var(c_i - ratio b_i) / (n mean(b)^2), the ratio estimator's delta method
        se = np.std(cand - ratio * base, ddof=1) / (np.sqrt(len(pairs)) * base.mean())
        quantile = float(stdtrit(len(pairs) - 1, 0.5 + confidence / 2))
        low, high = _interval(float(ratio), float(se), quantile, "nonnegative" if ratio >= 0 else "real")
        summary |= {"ci_low": 100.0 * (1.0 - high), "ci_high": 100.0 * (1.0 - low)}
    return summary


def mean_ci(values: Sequence[float | None], confidence: float = 0.95, domain: str = "real") -> dict:
    """Mean and a two-sided confidence interval of the mean over independent values (seeds), inside ``domain``.

    ``domain`` is the range the values can take (:data:`METRIC_DOMAINS` maps each statistic to its own):
    ``"real"`` gives the Student-t interval mean -/+ t s / sqrt(n). The others build that interval on a scale
    where the domain is the whole line and map it back (delta method): log(m) for ``"nonnegative"`` values (errors,
    effort, settling time), logit(m) for a ``"fraction"`` (saturation), log(100 - m) for ``"at_most_100"``
    (improvements in %). So the interval never leaves the domain, is asymmetric where the values are skewed,
    and is the single point m when all values sit on the domain's edge (no saturation in any run: [0, 0]).

    None entries (a failed run, a settling time never reached) are left out and counted as ``missing``;
    the mean is None when nothing is left, the interval None with fewer than two values.
    """
    from scipy.special import stdtrit  # Student's t quantile, as scipy.stats.t.ppf (1 s of import less)

    present = np.asarray([v for v in values if v is not None], dtype=float)
    _check_domain(present, domain)
    summary: dict[str, float | int | None] = {
        "mean": None,
        "ci_low": None,
        "ci_high": None,
        "n": int(present.size),
        "missing": len(values) - int(present.size),
    }
    mean = float(np.mean(present)) if present.size else None
    summary["mean"] = mean
    if mean is not None and present.size >= 2:
        se = float(np.std(present, ddof=1) / np.sqrt(present.size))
        quantile = float(stdtrit(present.size - 1, 0.5 + confidence / 2))
        low, high = _interval(mean, se, quantile, domain)
        summary |= {"ci_low": low, "ci_high": high}
    return summary


def summarize(
    columns: Mapping[str, np.ndarray],
    *,
    status: str,
    window: tuple[float, float],
    control_period: float,
    settling_threshold: float,
    failure_time: float | None = None,
    warnings: Sequence[dict] = (),
    floor_friction: float = 0.8,
    lost_path_error: float | None = None,
) -> dict:
    """The ``metrics.json`` dictionary of a run (docs/guide.md).

    Error statistics are over ``window``; settling time, effort and saturation fraction over the
    whole run. A failed run has every statistic None (JSON null) beside its status and failure time.

    Parameters
    ----------
    columns : mapping of str to ndarray
        The run's time series (:func:`ddtrack.timeseries`): ``t`` [s], ``e_tr`` [m], ``tau_r``, ``tau_l`` [N m],
        and ``saturated``, ``kx``, ``ky``, ``ktheta`` where the controller logs them.
    status : str
        ``"ok"``, ``"diverged"`` or ``"non_finite"`` (:attr:`SimResult.status_name`).
    window : (float, float)
        Start and end of the error statistics [s] (``simulation.metric_window``).
    control_period : float
        T_c [s], the time each torque sample is held (for the effort integral).
    settling_threshold : float
        e_tr [m] below which the run counts as settled.
    failure_time : float, optional
        When a failed run failed [s].
    floor_friction : float, optional
        The floor's friction coefficient, against which ``time_above_floor_mu`` counts (``plant.floor_friction``).
    lost_path_error : float, optional
        e_tr [m] beyond which a run that stays there to the end has lost the path (:func:`lost_path_time`); None:
        not judged.
    warnings : sequence of dict, optional
        Why the result may not mean what it seems, each ``{"code", "message"}`` (:func:`ddtrack.runner.run_warnings`).

    Returns
    -------
    dict
        ``status, window, e_tr_mean, e_tr_rms, e_tr_max, e_tr_final`` [m], ``settling_time`` [s] (None if
        never), ``effort`` [N^2 m^2 s] (None without torques), ``saturation_fraction`` [0..1]; ``final_gains``
        (Kx, Ky, Ktheta) where the controller has gains; ``failure_time`` [s] for a failed run; ``warnings``
        (always present, [] when there are none); where the run has ``mu_required`` (a torque-driven plant):
        ``mu_required_max`` (the friction coefficient the run needed), ``time_above_floor_mu`` [s] and
        ``wheel_speed_max`` [rad/s], over the whole run; on a plant that models grip (``mu_used`` in the columns,
        :func:`ddtrack.plausibility.grip_used`), ``mu_used_max`` (the most its own contact forces used),
        ``time_sliding`` [s] and ``wheel_speed_max`` instead; where the controller sees odometry (``odom_ex`` in the
        columns): :func:`odometry_error`'s, over the whole run; with ``lost_path_error``, ``lost_path`` (bool),
        ``lost_path_time`` [s] (None while it tracks) and the bound ``lost_path_error`` [m] of a run that ran to its
        end.
    """
    metrics: dict = {"status": status, "window": [float(window[0]), float(window[1])]}
    keys = ("e_tr_mean", "e_tr_rms", "e_tr_max", "e_tr_final", "settling_time", "effort", "saturation_fraction")
    if status != "ok":
        metrics |= dict.fromkeys(keys)
        metrics["failure_time"] = failure_time
    else:
        t, e_tr = columns["t"], columns["e_tr"]
        metrics |= window_statistics(t, e_tr, window)
        metrics["settling_time"] = settling_time(t, e_tr, settling_threshold)
        if lost_path_error is not None:
            lost = lost_path_time(t, e_tr, window, lost_path_error)
            metrics |= {"lost_path": lost is not None, "lost_path_time": lost, "lost_path_error": lost_path_error}
        metrics["effort"] = effort(columns["tau_r"], columns["tau_l"], control_period)
        metrics["saturation_fraction"] = saturation_fraction(columns["saturated"]) if "saturated" in columns else 0.0
        if "mu_required" in columns and len(columns["mu_required"]):
            mu = np.asarray(columns["mu_required"])
            metrics["mu_required_max"] = float(np.max(mu))
            metrics["time_above_floor_mu"] = float(np.count_nonzero(mu > floor_friction) * control_period)
        if "mu_used" in columns and len(columns["mu_used"]):  # a plant that models grip: its own contact forces
            metrics["mu_used_max"] = float(np.max(columns["mu_used"]))
            metrics["time_sliding"] = float(np.count_nonzero(columns["sliding"]) * control_period)
        if ("mu_required" in columns or "mu_used" in columns) and len(columns["wheel_speed_r"]):
            metrics["wheel_speed_max"] = float(np.max(np.abs([columns["wheel_speed_r"], columns["wheel_speed_l"]])))
        if "odom_ex" in columns and len(columns["odom_ex"]):
            metrics |= odometry_error(columns["odom_ex"], columns["odom_ey"], columns["odom_etheta"])
    if all(k in columns for k in ("kx", "ky", "ktheta")) and len(columns["t"]):
        gains = [float(columns[k][-1]) for k in ("kx", "ky", "ktheta")]
        metrics["final_gains"] = gains if all(map(math.isfinite, gains)) else None
    metrics["warnings"] = [dict(w) for w in warnings]
    return metrics


def odometry_error(e_x: np.ndarray, e_y: np.ndarray, e_theta: np.ndarray) -> dict[str, float]:
    """How far the odometry estimate strayed from the true pose (estimated minus true, per period): the position
    error |(e_x, e_y)| at the end and at its largest, ``odom_error_final``, ``odom_error_max`` [m], and the largest
    heading error ``odom_heading_error_max`` [rad]."""
    position = np.hypot(e_x, e_y)
    return {
        "odom_error_final": float(position[-1]),
        "odom_error_max": float(np.max(position)),
        "odom_heading_error_max": float(np.max(np.abs(e_theta))),
    }


def warning_counts(runs: list[dict]) -> dict[str, int]:
    """How many runs carry each warning code (a run counts once per code)."""
    counts: dict[str, int] = {}
    for r in runs:
        for code in sorted({w["code"] for w in r.get("warnings") or ()}):  # records from before warnings: none
            counts[code] = counts.get(code, 0) + 1
    return counts


def lost_path_warnings(metrics: dict) -> list[dict]:
    """A run that ended off its path (``lost_path``): its error statistics describe a robot no longer tracking."""
    if not metrics.get("lost_path"):
        return []
    from ._format import significant

    message = (
        f"the robot is off its path: e_tr stayed beyond {significant(metrics['lost_path_error'])} m "
        f"(simulation.lost_path_error) from t = {metrics['lost_path_time']:g} s to the end of the metric window "
        "(it lost the path, or never reached it); its error statistics measure how far off it was, not how well it "
        "tracks, and benchmarks count it apart"
    )
    return [{"code": "lost_path", "message": message}]
