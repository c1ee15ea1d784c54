"""Numbers as text: significant digits, so a TurtleBot's effort of 0.0043 does not print as 0.0."""

from __future__ import annotations

import math

MISSING = "–"


def significant(x: float | int | None, digits: int = 3) -> str:
    """``x`` to ``digits`` significant digits: 0.0043 -> '0.00430', 17.94 -> '17.9', 12345 -> '1.23e+04'.

    None -> '–'; NaN, inf and 0 as 'nan', 'inf', '-inf', '0'.
    """
    if x is None:
        return MISSING
    x = float(x)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == 0.0:
        return "0"
    text = f"{x:#.{digits}g}"  # '#' keeps trailing zeros (0.00430), which say how precise the number is
    mantissa, e, exponent = text.partition("e")
    return mantissa.rstrip(".") + e + exponent


def with_interval(mean: float | None, low: float | None, high: float | None, digits: int = 3) -> str:
    """'mean [low, high]', or the mean alone when there is no interval (one value)."""
    text = significant(mean, digits)
    if mean is None or low is None or high is None:
        return text
    return f"{text} [{significant(low, digits)}, {significant(high, digits)}]"


def interval_text(summary: dict | None, scale: float = 1.0, digits: int = 3) -> str:
    """'mean [low, high]' of a :func:`ddtrack.metrics.mean_ci` summary, each times ``scale`` (100 for a fraction in
    %); '' where there is no summary or no mean (a leaderboard's empty cell)."""
    if not summary or summary.get("mean") is None:
        return ""
    low, high = (None if summary.get(k) is None else scale * summary[k] for k in ("ci_low", "ci_high"))
    return with_interval(scale * summary["mean"], low, high, digits)


def percent(fraction: float | None, digits: int = 3) -> str:
    """A fraction in [0, 1] as a percentage '9.20 %' (the one convention for saturation in printed output)."""
    return MISSING if fraction is None else f"{significant(100.0 * fraction, digits)} %"
