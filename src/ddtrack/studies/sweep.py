"""``ddtrack sweep``: parameter sweeps on Dask distributed, with run keys and a resumable result store.

A sweep file names a scenario, the controllers, the seeds and either a ``[grid]`` (cartesian product of
override values) or a ``[random]`` draw of override values (docs/sweeps.md). One *configuration* is a
controller plus its override values; one *run* is a configuration and a seed. A run's key is the sha256 of
the fully resolved scenario (``to_toml_dict``, canonical JSON) and the seed, so a key names exactly what
was simulated, whatever file or override spelling produced it.

The driver owns the store: workers only compute and return records; the driver writes each one as
``records/<key>.json`` (temporary name, then rename) as tasks finish, so a killed sweep leaves only whole
records, and the next start submits only the keys that have none (records with status ``error`` are
retried). ``results.parquet`` and ``results.csv`` (sorted by key) are written at the end.
"""

from __future__ import annotations

import hashlib
import io
import itertools
import json
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv
import pyarrow.parquet as pq
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..errors import ConfigError, did_you_mean
from ..metrics import warning_counts
from ..outdir import atomic_write
from ..scenario import FieldError, Scenario, load_scenario, read_toml, to_toml_dict
from ..trajectories.switched import TrajectoryFrame, trajectory_frame
from .cells import batch_program, cache_on_every_worker, programs_held
from .tasks import ERROR, error_record, error_records, plan_tasks, planned_keys, run_cells

RECORDS = "records"


# --- the sweep file ---------------------------------------------------------------------------------


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, strict=True)


class SeedRange(_Model):
    """Seeds ``start .. start + count - 1``."""

    start: int = Field(default=0, ge=0)
    count: int = Field(ge=1, le=1_000_000)


class Uniform(_Model):
    """A value drawn uniformly from ``[low, high)``."""

    low: float
    high: float

    @model_validator(mode="after")
    def _ordered(self) -> Uniform:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


class RandomSection(_Model):
    """``n`` configurations per controller, each ``section.key`` drawn from its range with ``seed``."""

    model_config = ConfigDict(extra="allow", allow_inf_nan=False, frozen=True, strict=True)
    __pydantic_extra__: dict[str, Uniform]

    n: int = Field(ge=1, le=1_000_000)
    seed: int = Field(default=0, ge=0)


class SweepFile(_Model):
    """A sweep file (docs/sweeps.md)."""

    scenario: str
    controllers: list[str] | None = Field(default=None, min_length=1)
    seeds: int | SeedRange = Field(union_mode="left_to_right")
    chunk: int = Field(default=16, ge=1, le=100_000)
    set: dict[str, Any] = Field(default_factory=dict)
    grid: dict[str, list[Any]] | None = None
    random: RandomSection | None = None

    @model_validator(mode="after")
    def _one_design(self) -> SweepFile:
        if (self.grid is None) == (self.random is None):
            raise FieldError("grid", "give exactly one of [grid] and [random]")
        if self.grid is not None:
            if not self.grid:
                raise FieldError("grid", 'is empty; give at least one "section.key" = [values]')
            for name, values in self.grid.items():
                if not values:
                    raise FieldError(f"grid.{name}", "has no values")
        if self.random is not None and not self.random.__pydantic_extra__:
            raise FieldError("random", 'draws nothing; add "section.key" = {low = ..., high = ...}')
        if self.controllers is not None and len(set(self.controllers)) != len(self.controllers):
            raise FieldError("controllers", "lists a controller twice")
        if isinstance(self.seeds, int) and not 1 <= self.seeds <= 1_000_000:
            raise FieldError("seeds", f"must be between 1 and 1000000 (got {self.seeds})")
        return self

    @property
    def seed_list(self) -> list[int]:
        if isinstance(self.seeds, int):
            return list(range(self.seeds))
        return list(range(self.seeds.start, self.seeds.start + self.seeds.count))


_MODELS: dict[str, type[BaseModel]] = {"": SweepFile, "seeds": SeedRange, "random": RandomSection}


def _sweep_error(exc: ValidationError) -> ConfigError:
    """pydantic's first error as a one-line ConfigError naming the sweep file's field."""
    errors = exc.errors()
    # an unknown key first; else the most specific error (seeds = {count = "x"} fails both the int and the
    # SeedRange member of the union: name seeds.count, not seeds)
    error = next((e for e in errors if e["type"] == "extra_forbidden"), max(errors, key=lambda e: len(e["loc"])))
    loc = [str(part) for part in error["loc"] if part not in ("int", "SeedRange")]
    cause = error.get("ctx", {}).get("error")
    if isinstance(cause, FieldError):
        return ConfigError(cause.field, str(cause))
    field = ".".join(loc)
    message = error["msg"].removeprefix("Value error, ")
    if error["type"] == "extra_forbidden":
        model = _MODELS.get(".".join(loc[:-1]), Uniform)
        return ConfigError(field, "unknown key", did_you_mean(loc[-1], model.model_fields))
    if error["type"] == "missing":
        return ConfigError(field, "is required", "see docs/sweeps.md for the sweep file format")
    got = error.get("input")
    shown = "" if isinstance(got, dict) else f" (got {got!r:.60})"
    return ConfigError(field, message + shown)


def _flatten(table: Any, prefix: str = "", *, leaf: Callable[[dict], bool] = lambda d: False) -> Any:
    """``{"robot": {"mass": [..]}}`` (unquoted dotted keys) -> ``{"robot.mass": [..]}``."""
    if not isinstance(table, dict):
        return table
    flat: dict[str, Any] = {}
    for key, value in table.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and not leaf(value):
            flat.update(_flatten(value, f"{name}.", leaf=leaf))
        else:
            flat[name] = value
    return flat


def read_sweep(path: str | Path) -> SweepFile:
    """Read and validate a sweep file; every problem is a :class:`ConfigError` naming the field."""
    path = Path(path)
    data = read_toml(path, "sweep", "docs/sweeps.md")
    for name in ("grid", "set"):
        if isinstance(data.get(name), dict):
            data[name] = _flatten(data[name])
    if isinstance(data.get("random"), dict):
        data["random"] = _flatten(data["random"], leaf=lambda d: bool({"low", "high"} & set(d)))
    try:
        return SweepFile.model_validate(data)
    except ValidationError as exc:
        raise _sweep_error(exc) from None


# --- the plan ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Configuration:
    """One controller with its override values, and the scenario they resolve to."""

    controller: str
    overrides: dict[str, Any]  #: the sweep's ``[set]`` values, then this configuration's grid or random values
    scenario: Scenario
    labels: dict[str, Any] | None = None  #: descriptive columns (``label.<name>``), e.g. a benchmark suite's cell

    def describe(self) -> dict[str, Any]:
        described = {"controller": self.controller, "overrides": self.overrides}
        return described | {"labels": self.labels} if self.labels else described


@dataclass(frozen=True)
class Plan:
    """A sweep resolved before anything runs: every configuration and every run's key."""

    configurations: list[Configuration]
    runs: dict[str, tuple[int, int]]  #: key -> (configuration index, seed), in plan order
    chunk: int  #: the most runs a task batches, across the cells that share a program (tasks.plan_tasks)

    def identity(self) -> str:
        """A short fingerprint of the plan's runs: an output folder resumes only the sweep that wrote it."""
        return hashlib.sha256("\n".join(sorted(self.runs)).encode()).hexdigest()[:16]

    def trajectory_frame(self) -> TrajectoryFrame | None:
        """The study's trajectory kinds: its cells on different kinds then share a program (None: one kind)."""
        return trajectory_frame([c.scenario.trajectory.build() for c in self.configurations])


def toml_value(value: Any) -> str:
    """A value as inline TOML, the form ``--set`` overrides are read in."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return (
            repr(value) if math.isfinite(value) else ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf"))
        )
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise ConfigError("", f"cannot use {value!r} as an override value")


def canonical(value: Any) -> str:
    """``value`` as compact JSON with sorted keys: equal values give equal text (and run keys)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


def run_key(scenario: Scenario, seed: int) -> str:
    """sha256 of the fully resolved scenario and the seed."""
    return hashlib.sha256(canonical({"scenario": to_toml_dict(scenario), "seed": seed}).encode()).hexdigest()


def _designs(sweep: SweepFile) -> Iterator[dict[str, Any]]:
    if sweep.grid is not None:
        names = list(sweep.grid)
        for values in itertools.product(*(sweep.grid[n] for n in names)):
            yield dict(zip(names, values, strict=True))
    else:
        assert sweep.random is not None  # SweepFile requires exactly one of grid and random
        ranges = dict(sorted((sweep.random.__pydantic_extra__ or {}).items()))  # file order must not change the draws
        rng = np.random.Generator(np.random.PCG64(sweep.random.seed))
        draws = rng.uniform(size=(sweep.random.n, len(ranges)))
        for row in draws:
            yield {name: float(r.low + u * (r.high - r.low)) for u, (name, r) in zip(row, ranges.items(), strict=True)}


def plan_sweep(sweep: SweepFile, base_dir: Path) -> Plan:
    """Resolve every configuration (bad overrides fail here, before anything runs) and key every run."""
    path = base_dir / sweep.scenario
    if not path.is_file():
        raise ConfigError("scenario", f"'{path}' is not a file", "give the scenario's path relative to the sweep file")
    controllers = sweep.controllers or [load_scenario(path).controller.kind]
    configurations: list[Configuration] = []
    runs: dict[str, tuple[int, int]] = {}
    seeds = sweep.seed_list
    designs = list(_designs(sweep))
    for controller in controllers:
        for design in designs:
            overrides = {**sweep.set, **design}
            text = [f"{name}={toml_value(value)}" for name, value in overrides.items()]
            scenario = load_scenario(path, overrides=text, controller=controller)
            configurations.append(Configuration(controller, overrides, scenario))
            for seed in seeds:
                runs.setdefault(run_key(scenario, seed), (len(configurations) - 1, seed))  # equal scenarios run once
    return Plan(configurations, runs, chunk=sweep.chunk)


# --- the tasks -----------------------------------------------------------------------------------


# --- the store -----------------------------------------------------------------------------------


def write_record(out: Path, record: dict) -> None:
    """Write ``record`` to ``out/records/<key>.json``, atomically (a killed sweep leaves no partial record)."""
    text = json.dumps(record, indent=1, sort_keys=True, allow_nan=False) + "\n"
    atomic_write(out / RECORDS / f"{record['key']}.json", lambda f: f.write(text.encode()))


def read_records(out: Path) -> dict[str, dict]:
    """The whole records in ``out/records`` by key; removes temporaries left by a killed sweep."""
    folder = out / RECORDS
    found: dict[str, dict] = {}
    if not folder.is_dir():
        return found
    for path in folder.iterdir():
        if path.name.startswith(".") and path.name.endswith(".tmp"):
            path.unlink(missing_ok=True)  # a write that never reached its rename
            continue
        if path.suffix != ".json":
            continue
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError):
            continue  # unreadable: treated as missing and written again
        if isinstance(record, dict) and record.get("key") == path.stem:
            found[path.stem] = record
    return found


def _column(values: list) -> pa.Array:
    """Scalars as a typed column; lists and tables (and mixed types) as JSON text, which CSV can hold."""
    if any(isinstance(v, list | dict) for v in values):
        return pa.array([None if v is None else canonical(v) for v in values], pa.string())
    try:
        return pa.array(values)
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        return pa.array([None if v is None else canonical(v) for v in values], pa.string())


def table(records: Sequence[dict]) -> pa.Table:
    """One row per run, sorted by key: key, controller, seed, status, error, one column per override
    (``set.<section.key>``), then the metrics (as ``ddtrack mc``'s table)."""
    records = sorted(records, key=lambda r: r["key"])
    rows = []
    for r in records:
        row = {
            "key": r["key"],
            "controller": r["configuration"]["controller"],
            "seed": r["seed"],
            "status": r["status"],
            "error": r["error"],
        }
        row |= {f"label.{k}": v for k, v in r["configuration"].get("labels", {}).items()}
        row |= {f"set.{k}": v for k, v in r["configuration"]["overrides"].items()}
        metrics = dict(r["metrics"] or {})
        window = metrics.pop("window", None) or [None, None]
        gains = metrics.pop("final_gains", None) or [None, None, None]
        metrics.pop("status", None)
        warnings = metrics.pop("warnings", None) or []
        row |= metrics | {
            "window_start": window[0],
            "window_end": window[1],
            "final_kx": gains[0],
            "final_ky": gains[1],
            "final_ktheta": gains[2],
            "warning_codes": ",".join(w["code"] for w in warnings),
            "warnings": " | ".join(w["message"] for w in warnings),
        }
        rows.append(row)
    names: dict[str, None] = {}
    for row in rows:
        names.update(dict.fromkeys(row))
    if not rows:
        names = dict.fromkeys(("key", "controller", "seed", "status", "error"))
    return pa.table({name: _column([row.get(name) for row in rows]) for name in names})


def write_results(out: Path, records: Sequence[dict]) -> pa.Table:
    """``results.parquet`` and ``results.csv`` (all records, sorted by key), each written atomically."""
    result = table(records)
    atomic_write(out / "results.parquet", lambda f: pq.write_table(result, f))
    buffer = io.BytesIO()
    pa.csv.write_csv(result, buffer)
    atomic_write(out / "results.csv", lambda f: f.write(buffer.getvalue()))
    return result


# --- the driver ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Outcome:
    """What :func:`run_sweep` did: run counts by origin and status."""

    total: int  #: runs in the plan
    reused: int  #: found in the store at start
    ran: int  #: records written by this sweep
    errors: int  #: runs with status "error" in the final results
    not_ok: int  #: runs that diverged or went non-finite
    warnings: dict  #: warning code -> runs that carry it (``metrics.json``'s ``warnings``)


def run_sweep(
    plan: Plan,
    out: Path,
    client: Any,
    *,
    on_record: Callable[[int, int], None] = lambda done, total: None,
    on_programs: Callable[[int, int], None] = lambda needed, held: None,
) -> Outcome:
    """Submit the runs that have no record to ``client``'s cluster, the runs of cells that share a simulation
    program batched together (:func:`plan_tasks`), write records as tasks finish, then the results tables.
    ``on_programs(needed, held)`` hears, before anything runs, how many simulation programs the runs need and how many
    the persistent compilation cache holds; ``on_record(done, total)`` follows progress."""
    from distributed import as_completed

    cache_on_every_worker(client)
    existing = {key: r for key, r in read_records(out).items() if key in plan.runs and r["status"] != ERROR}
    missing: dict[int, list[tuple[str, int]]] = {}
    for key, (index, seed) in plan.runs.items():
        if key not in existing:
            missing.setdefault(index, []).append((key, seed))
    frame = plan.trajectory_frame()  # one program per structure, whatever trajectories the cells follow
    indices = sorted(missing)
    keys = planned_keys(client, plan.configurations, indices, frame)
    tasks = plan_tasks(plan.configurations, plan.chunk, missing, keys)
    programs = {batch_program(key, size) for _, size, key in tasks}  # one each: a structure's tasks are one size
    on_programs(len(programs), programs_held(programs))
    futures = {}
    for task, size, _ in tasks:
        future = client.submit(run_cells, task, size, frame, pure=False)
        futures[future] = task
    done = len(existing)
    on_record(done, len(plan.runs))
    for future in as_completed(list(futures)):
        task = futures.pop(future)
        if future.status == "finished":
            records = future.result()
        else:  # the task could not run at all (e.g. it killed its workers too often): record why
            try:
                exc = future.exception()
            except Exception as cancelled:
                exc = cancelled
            records = [record for _, described, part in task for record in error_records(exc, described, part)]
        for record in records:
            write_record(out, record)
        done += len(records)
        on_record(done, len(plan.runs))
        future.release()
    final = {key: r for key, r in read_records(out).items() if key in plan.runs}
    write_results(out, list(final.values()))
    return Outcome(
        total=len(plan.runs),
        reused=len(existing),
        ran=len(plan.runs) - len(existing),
        errors=sum(r["status"] == ERROR for r in final.values()),
        not_ok=sum(r["status"] not in ("ok", ERROR) for r in final.values()),
        warnings=warning_counts([r["metrics"] or {"warnings": []} for r in final.values()]),
    )


__all__ = ["Configuration", "Outcome", "Plan", "SweepFile", "plan_sweep", "read_records", "read_sweep", "run_cells"]
__all__ += ["error_record", "run_key", "run_sweep", "table", "write_results"]
