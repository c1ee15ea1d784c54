"""Printed numbers keep their significant digits at every scale (a TurtleBot's effort is 0.0043, not 0.0)."""

from __future__ import annotations

import math

from ddtrack._format import percent, significant, with_interval


def test_significant_digits_at_every_scale():
    assert significant(0.0043) == "0.00430"  # fixed decimals printed this as 0.0
    assert significant(17.94) == "17.9"
    assert significant(12345.0) == "1.23e+04"
    assert significant(100.0) == "100" and significant(1.0) == "1.00" and significant(0.0) == "0"
    assert significant(None) == "–" and significant(math.nan) == "nan" and significant(-math.inf) == "-inf"
    for x in (3.21e-7, 0.0456, 4.56, 456.0, 4.56e6):  # three significant digits, read back to 1 part in 200
        assert abs(float(significant(x)) - x) <= 0.005 * x


def test_interval_and_percent():
    assert with_interval(0.0043, 0.0031, 0.0059) == "0.00430 [0.00310, 0.00590]"
    assert with_interval(0.04, None, None) == "0.0400"
    assert percent(0.092) == "9.20 %" and percent(None) == "–"
