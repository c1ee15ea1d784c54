"""The ``[controller]`` section of the open-loop replay of a plan of timed velocity commands (registered with the
others in ``registry``); its file is read inside the scenario's folder as a waypoints file is."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
from pydantic import Field, ModelWrapValidatorHandler, PrivateAttr, ValidationInfo, model_validator

from ..controllers.replay import Replay
from ..errors import ConfigError
from ..model import RobotParams
from ._base import FieldError
from .controller_configs import _ControllerSection
from .trajectory_configs import _contained
from .waypoint_rows import CsvColumns, read_csv_columns

PLAN_COLUMNS = CsvColumns("replay file", ("t", "v", "omega"), "(t [s], v [m/s], omega [rad/s])", ("t", "v", "omega"))


class ReplayConfig(_ControllerSection):
    """Open loop: replays a plan of timed (v, omega) commands whatever the pose (e.g. an excitation plan).

    ``file`` is a CSV under the header ``t,v,omega`` (any order), each command held from its time until the next
    row's, read relative to the scenario file and inside its folder tree as a waypoints file is; the resolved
    scenario holds the rows inline (``times``, ``commands``). The last row is held for as long as the step before
    it (a single row: one control period), and then the robot stops: a plan that has run out must not leave a robot
    driving. The commands go to a velocity-commanded plant as they are, with no clamp; a ``robot.preset`` refuses a
    plan beyond its top speed or yaw rate (:meth:`check_within`). The reference is not used, so tracking metrics say
    nothing about a controller.
    """

    kind: Literal["replay"]
    file: str | None = Field(
        None, description="CSV file with the header t,v,omega (any order) [s, m/s, rad/s], relative to the scenario."
    )
    times: list[float] | None = Field(
        None, description="Inline time of each command instead of a file, strictly increasing [s]."
    )
    commands: list[tuple[float, float]] | None = Field(
        None, description="Inline [v, omega] of each time [m/s, rad/s], each held until the next time."
    )
    _lines: tuple[int, ...] = PrivateAttr(default=())  # the file's line of each row (empty: the rows were inline)
    _source: str = PrivateAttr(default="")

    @model_validator(mode="wrap")
    @classmethod
    def _read_file(cls, data: Any, handler: ModelWrapValidatorHandler[ReplayConfig], info: ValidationInfo) -> Any:
        name = data.get("file") if isinstance(data, dict) else None
        lines: tuple[int, ...] = ()
        if isinstance(name, str) and data.get("times") is None and data.get("commands") is None:
            path = Path((info.context or {}).get("base_dir", "."))
            try:
                columns, lines = read_csv_columns(_contained(path, name, what="a replay file"), PLAN_COLUMNS)
            except ValueError as exc:  # names the file, its line and the fix (or the path and its fix)
                raise FieldError("file", str(exc)) from None
            if not lines:
                raise FieldError("file", f"replay file '{name}' has no rows; give at least one row under t,v,omega")
            late = [i for i in range(1, len(lines)) if not columns["t"][i] > columns["t"][i - 1]]
            if late:
                i = late[0]
                raise FieldError(
                    "file",
                    f"replay file '{name}' line {lines[i]}: t = {columns['t'][i]:g} s is not after "
                    f"{columns['t'][i - 1]:g} s; times must increase row by row",
                )
            rows = list(zip(columns["v"], columns["omega"], strict=True))
            data = {**data, "file": None, "times": columns["t"], "commands": rows}
        elif isinstance(data, dict) and isinstance(data.get("commands"), list):  # strict mode takes tuples, not lists
            data = {**data, "commands": [tuple(c) if isinstance(c, list) else c for c in data["commands"]]}
        model = handler(data)
        if lines:
            model._lines, model._source = lines, str(name)
        return model

    @model_validator(mode="after")
    def _valid_plan(self) -> ReplayConfig:
        if self.file is not None:
            raise FieldError("file", "give only one of 'file' and 'times' with 'commands'")
        if self.times is None or self.commands is None:
            missing = "times" if self.times is None else "commands"
            raise FieldError(missing, "is missing", "give 'file' (a CSV t,v,omega), or both 'times' and 'commands'")
        if not self.times:
            raise FieldError("times", "is empty", "give at least one time and its [v, omega] in commands")
        if len(self.commands) != len(self.times):
            raise FieldError(
                "commands", f"has {len(self.commands)} rows for {len(self.times)} times; give one [v, omega] per time"
            )
        late = [i for i in range(1, len(self.times)) if not self.times[i] > self.times[i - 1]]
        if late:
            i = late[0]
            raise FieldError(
                f"times[{i}]", f"{self.times[i]:g} s is not after {self.times[i - 1]:g} s; times must increase"
            )
        return self

    def row_name(self, row: int) -> tuple[str, str]:
        """(field, words) naming row ``row`` (0-based) in a message: the file's line, or the inline index."""
        if self._lines:
            return "controller.file", f"replay file '{self._source}' line {self._lines[row]}"
        return f"controller.commands[{row}]", f"the command at t = {self.times[row]:g} s"  # type: ignore[index]

    def check_within(self, top_speed: float | None, top_yaw_rate: float | None, robot: str) -> None:
        """Refuse (:class:`ConfigError`) a command above the top speed [m/s] or yaw rate [rad/s] of ``robot`` (what
        sets them, e.g. "a turtlebot3_burger (robot.preset)"; None: no limit): the simulated plant may follow it, the
        real robot could not, and its log would describe a robot that does not exist."""
        commands = np.abs(np.asarray(self.commands, float))
        for column, (what, unit, top) in enumerate((("speed", "m/s", top_speed), ("yaw rate", "rad/s", top_yaw_rate))):
            if top is not None and np.any(commands[:, column] > top):
                row = int(np.argmax(commands[:, column]))
                field, where = self.row_name(row)
                raise ConfigError(
                    field,
                    f"{where} commands a {what} of {float(commands[row, column]):.4g} {unit}, above the top {what} "
                    f"of {robot}, {top:.4g} {unit}: the real robot could not follow it",
                    "scale the plan to the robot (ddtrack excite --preset NAME), or raise plant.motor.supply_voltage "
                    "to the battery's",
                )

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Replay:
        """The replay; ``nominal`` and ``key`` are unused (nothing is modelled, nothing is drawn)."""
        assert self.times is not None and self.commands is not None, "the validator requires both"
        last_step = self.times[-1] - self.times[-2] if len(self.times) > 1 else control_period
        times = jnp.asarray(self.times, float)
        return Replay(times, jnp.asarray(self.commands, float).reshape(-1, 2), times[-1] + last_step)
