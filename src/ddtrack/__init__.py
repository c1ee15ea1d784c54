"""ddtrack: trajectory-tracking controllers for differential-drive mobile robots, simulated in JAX.

Quick start::

    import ddtrack
    ddtrack.enable_float64()                  # once, first: ddtrack computes in float64
    scenario = ddtrack.load_scenario("scenarios/paper_line.toml")
    result = ddtrack.run(scenario, seed=0)
    columns = ddtrack.timeseries(result)     # NumPy columns: t, x, y, ..., e_tr, tau_r, tau_l

``import ddtrack`` is light: the names below are imported on first use (PEP 562), so the command line's
``--help`` does not pay for JAX. Importing ddtrack changes no process-wide setting but one: Gymnasium knows
``ddtrack/DiffDriveTracking-v0`` as soon as it is imported, before or after ddtrack (registering on import is
how Gymnasium finds third-party environments). Switching JAX to float64 is your call: :func:`enable_float64`.
"""

import sys as _sys
from importlib import import_module as _import_module
from types import ModuleType
from typing import TYPE_CHECKING, Any

from ._after_import import after_import as _after_import


def _register_env(gymnasium: ModuleType) -> None:
    if f"{__name__}.envs" in _sys.modules:  # Gymnasium loads inside ddtrack.envs' import, which registers at its end
        return
    from .envs import register_envs  # one place registers ddtrack/DiffDriveTracking-v0

    register_envs()


_after_import("gymnasium", _register_env)

if TYPE_CHECKING:  # type checkers and IDEs see the public names; at run time they load on first use
    from ._pytree import pytree_dataclass as pytree_dataclass
    from ._pytree import static_field as static_field
    from .errors import ConfigError as ConfigError
    from .errors import DdtrackError as DdtrackError
    from .errors import RunError as RunError
    from .metrics import improvement as improvement
    from .metrics import summarize as summarize
    from .metrics import tracking_error as tracking_error
    from .precision import enable_float64 as enable_float64
    from .runner import prepare as prepare
    from .runner import run as run
    from .runner import run_batch as run_batch
    from .scenario import Scenario as Scenario
    from .scenario import load_scenario as load_scenario
    from .scenario import register_controller as register_controller
    from .scenario import register_plant as register_plant
    from .scenario import register_trajectory as register_trajectory
    from .scenario import validate_scenario as validate_scenario
    from .sim import ClosedLoop as ClosedLoop
    from .sim import Draws as Draws
    from .sim import SimResult as SimResult
    from .sim import simulate as simulate
    from .sim import timeseries as timeseries
    from .studies.batches import monte_carlo as monte_carlo

__version__ = "0.1.0"

_SOURCES = {
    "ConfigError": "errors",
    "DdtrackError": "errors",
    "RunError": "errors",
    "improvement": "metrics",
    "summarize": "metrics",
    "tracking_error": "metrics",
    "monte_carlo": "studies.batches",
    "prepare": "runner",
    "run": "runner",
    "run_batch": "runner",
    "Scenario": "scenario",
    "register_controller": "scenario",
    "register_plant": "scenario",
    "register_trajectory": "scenario",
    "load_scenario": "scenario",
    "validate_scenario": "scenario",
    "ClosedLoop": "sim",
    "Draws": "sim",
    "SimResult": "sim",
    "simulate": "sim",
    "timeseries": "sim",
    "enable_float64": "precision",
    "pytree_dataclass": "_pytree",
    "static_field": "_pytree",
}

__all__ = sorted(_SOURCES)  # noqa: PLE0605 (the lazy-import table above is the one list of public names)


def __getattr__(name: str) -> Any:
    if name not in _SOURCES:
        raise AttributeError(f"module 'ddtrack' has no attribute '{name}'")
    value = getattr(_import_module(f".{_SOURCES[name]}", __name__), name)
    globals()[name] = value  # the next access is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SOURCES))
