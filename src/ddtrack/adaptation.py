"""Say when the NN-adaptive controller's adaptation could not work, instead of reporting a silent ``ok``.

:func:`adaptation_warnings` reads a finished run (its time-series columns and the emulator's identification
NMSE) and returns the reasons, each ``{"code", "message"}``:

* ``identification_failed``: an output's prediction NMSE is above :data:`MAX_NMSE` while the gain law uses the
  network's Jacobian, so the gains follow a wrong sensitivity;
* ``adaptation_gated``: the error/saturation gate was open less than :data:`MIN_GATE_OPEN` of the time;
* ``adaptation_inactive``: no gain moved by more than :data:`MIN_GAIN_CHANGE` of its start value, so the run
  is backstepping with extra steps.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

NN_KIND = "nn_adaptive_backstepping"
MAX_NMSE = 0.2  #: a one-step predictor this poor has no usable Jacobian (a good identification gives ~1e-3)
MIN_GATE_OPEN = 0.1  #: fraction of the run
MIN_GAIN_CHANGE = 0.01  #: relative to the start value
_GAINS = ("kx", "ky", "ktheta")
_OUTPUTS = ("forward", "lateral", "yaw")


def _settings(controller: Any) -> tuple[str, str, bool]:
    """(kind, jacobian source, adapts at all) of a controller config or a bare kind name."""
    if isinstance(controller, str):
        return controller, "network", True
    rates = getattr(controller, "rates", (1.0,))
    return controller.kind, getattr(controller, "jacobian", "network"), any(r > 0 for r in rates)


def adaptation_warnings(
    controller: Any, columns: Mapping[str, Sequence[float]], nmse: Sequence[float] | None = None
) -> list[dict[str, str]]:
    """The reasons the NN-adaptive adaptation of one run could not work; [] for any other controller.

    Parameters
    ----------
    controller : NNAdaptiveConfig or str
        The run's ``[controller]`` config, or just its kind (then the network's Jacobian is assumed).
    columns : mapping of str to array
        The run's time series (``kx, ky, ktheta`` and ``gate`` are read when present).
    nmse : sequence of 3 floats, optional
        The emulator's identification NMSE (forward, lateral, yaw); None when it was not identified.
    """
    kind, jacobian, adapts = _settings(controller)
    if kind != NN_KIND:
        return []
    found = []
    if nmse is not None and jacobian == "network" and max(nmse) > MAX_NMSE:
        values = ", ".join(f"{name} {value:.3g}" for name, value in zip(_OUTPUTS, nmse, strict=True))
        found.append(
            {
                "code": "identification_failed",
                "message": (
                    f"the emulator's identification failed (NMSE {values}; above {MAX_NMSE:g} is unusable), so the "
                    "gains follow a wrong Jacobian; lengthen controller.identification_duration, keep "
                    'identification_speed well inside the clamps, or set controller.jacobian = "model"'
                ),
            }
        )
    if "gate" in columns and len(columns["gate"]) and np.mean(columns["gate"]) < MIN_GATE_OPEN:
        found.append(
            {
                "code": "adaptation_gated",
                "message": (
                    f"the gains could adapt only {100 * np.mean(columns['gate']):.3g} % of the time (the gate closes "
                    "when e_tr >= controller.gate_error or a clamp or torque limit acts); raise gate_error or ease "
                    "the limits"
                ),
            }
        )
    if adapts and all(g in columns for g in _GAINS) and len(columns["kx"]):
        change = max(float(np.max(np.abs(np.asarray(columns[g]) - columns[g][0]) / abs(columns[g][0]))) for g in _GAINS)
        if change <= MIN_GAIN_CHANGE:
            found.append(
                {
                    "code": "adaptation_inactive",
                    "message": (
                        f"no gain moved by more than {100 * change:.2g} % of its start value: this run is backstepping "
                        "with fixed gains; see the warnings above or raise controller.rates"
                    ),
                }
            )
    return found
