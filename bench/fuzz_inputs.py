"""Fuzz the input files: mutate the shipped scenarios, ``--set`` overrides and sweep files, and check that every
case either runs or is refused cleanly (docs/reliability.md).

    python bench/fuzz_inputs.py [--cases N] [--runs R] [--seed S] [--workdir DIR]

Each mutation kind is a plain function ``kind(rng, base) -> Mutant`` taking a :class:`random.Random`, so
tests/test_fuzz.py drives the same functions from Hypothesis. A case is judged by :func:`judge`:

* ``ran``: ``ddtrack validate`` accepted it (exit code 0) and, for the sampled runs, ``ddtrack run`` ended
  with exit code 0 or 1 (a run that diverged), or refused it cleanly;
* ``refused``: exit code 2, stderr of one or two non-empty lines whose first names the field (the dotted path,
  or the file for an unreadable or non-TOML file), no "Traceback", nothing on stdout, and the ``--out``
  folder not created;
* ``bad``: anything else (an exception escaping ``ddtrack.cli.main``, another exit code, a message that does
  not name the field, a folder written). Must be 0.

Every refused scenario case is tried twice: ``validate`` and ``run --out DIR`` (same message, DIR absent).
Sweep cases run ``ddtrack sweep FILE --out DIR`` with the cluster replaced by a stub that raises, so a sweep
file that reaches the cluster counts as accepted, and one refused after the cluster started would show up
as ``bad``. Prints one table row per mutation kind; exit code 1 if any case is ``bad``.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import math
import random
import re
import shutil
import string
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
SHORT = ("simulation.duration=0.5", "simulation.metric_window=[0,0.5]")  # a run of 50 control periods


@dataclass
class Mutant:
    """One fuzzed input: the files to write, the overrides to pass, and the fields a refusal may name."""

    kind: str
    files: dict[str, bytes]  #: name -> content, written into a fresh folder; "input" is the file given to ddtrack
    overrides: tuple[str, ...] = ()
    fields: tuple[str, ...] = ()  #: a refusal's first line must contain one of these
    values_only: bool = True  #: only values changed (the shortened run still applies)
    note: str = ""
    folders: tuple[str, ...] = ()  #: empty folders to create beside the files


@dataclass
class Base:
    """A valid input to mutate: parsed TOML, its own file name and the files it needs beside it."""

    name: str
    data: dict[str, Any]
    extra: dict[str, bytes] = field(default_factory=dict)


def scenario_bases() -> list[Base]:
    """Every shipped scenario (waypoints.toml with its waypoints.csv)."""
    import tomllib

    bases = []
    for path in sorted(SCENARIOS.glob("*.toml")):
        data = tomllib.loads(path.read_text())
        extra = {"waypoints.csv": (SCENARIOS / "waypoints.csv").read_bytes()} if path.stem == "waypoints" else {}
        bases.append(Base(path.stem, data, extra))
    return bases


def sweep_bases() -> list[Base]:
    """Two small valid sweep files (a grid and a random design) over a copy of scenarios/paper_line.toml."""
    scenario = {"scenario.toml": (SCENARIOS / "paper_line.toml").read_bytes()}
    common = {
        "scenario": "scenario.toml",
        "controllers": ["backstepping"],
        "seeds": 2,
        "chunk": 2,
        "set": {"simulation.duration": 1.0, "simulation.metric_window": [0.0, 1.0]},
    }
    grid = common | {"grid": {"robot.mass": [9.0, 10.0], "controller.kc": [[5.0, 5.0], [10.0, 10.0]]}}
    rand = common | {
        "seeds": {"start": 3, "count": 2},
        "random": {"n": 2, "seed": 0, "plant.mass": {"low": 8.0, "high": 14.0}},
    }
    return [Base("sweep_grid", grid, scenario), Base("sweep_random", rand, scenario)]


# --- helpers ---------------------------------------------------------------------------------------


def leaves(data: Any, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Paths of every non-table value (TOML arrays count as one value)."""
    if not isinstance(data, dict):
        return [prefix]
    found = []
    for key, value in data.items():
        found += leaves(value, (*prefix, key))
    return found


def get(data: dict, path: tuple[str, ...]) -> Any:
    for key in path:
        data = data[key]
    return data


def put(data: dict, path: tuple[str, ...], value: Any) -> None:
    for key in path[:-1]:
        data = data.setdefault(key, {})
    data[path[-1]] = value


def dotted(path: tuple[str, ...]) -> str:
    return ".".join(path)


def numeric_leaves(data: dict) -> list[tuple[str, ...]]:
    def numeric(v: Any) -> bool:
        return (isinstance(v, int | float) and not isinstance(v, bool)) or (
            isinstance(v, list) and bool(v) and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        )

    return [p for p in leaves(data) if numeric(get(data, p))]


def with_element(rng: random.Random, data: dict, path: tuple[str, ...], value: Any) -> str:
    """Put ``value`` at ``path``, or in one element of the array there; return the field name to expect."""
    old = get(data, path)
    if isinstance(old, list):
        i = rng.randrange(len(old))
        old[i] = value
        return dotted(path)
    put(data, path, value)
    return dotted(path)


def accepted_fields(path: tuple[str, ...]) -> tuple[str, ...]:
    """A refusal about ``path`` names it; in a sweep file's [set], [grid] or [random] the scenario key alone
    (``robot.mass``) also counts, as that is what the scenario's validation names."""
    names = [dotted(path)]
    if path and path[0] in ("set", "grid", "random") and len(path) > 1:
        names.append(dotted(path[1:]))
        names.append(path[1])
    if len(path) >= 3 and path[0] == "randomize":  # a draw's spread: the draw is named (randomize.mass)
        names.append(dotted(path[:2]))
    if path[:1] == ("trajectory",) and path[-1] == "corner_radius":  # checked against the legs of the path
        names.append("trajectory.points")
    if any(n.startswith("simulation.") for n in names):  # cross-checks: duration = whole periods, window inside
        names += ["simulation.duration", "simulation.metric_window"]
    return tuple(names)


def toml_bytes(data: dict) -> bytes:
    return tomli_w.dumps(data).encode()


def mutant(
    kind: str,
    base: Base,
    data: dict,
    fields: tuple[str, ...] | list[str],
    *,
    values_only: bool = True,
    note: str = "",
    overrides: tuple[str, ...] = (),
    extra: dict[str, bytes] | None = None,
    folders: tuple[str, ...] = (),
) -> Mutant:
    files = dict(base.extra) | (extra or {})
    files["input"] = toml_bytes(data)
    return Mutant(kind, files, overrides, tuple(fields), values_only, note, folders)


# --- the mutation kinds (each: rng, base -> Mutant) ------------------------------------------------

WRONG = ["text", "", True, False, [1, 2, 3], [], {"a": 1}, [[1.0]], ["a", "b"], 7, 0.5]


def wrong_type(rng: random.Random, base: Base) -> Mutant:
    """A value replaced by one of another type (string, bool, array, table, number)."""
    data = copy.deepcopy(base.data)
    path = rng.choice(leaves(data))
    old = get(data, path)
    choices = [w for w in WRONG if type(w) is not type(old) and not (isinstance(old, float) and type(w) is int)]
    value = rng.choice(choices)
    put(data, path, value)
    return mutant("wrong_type", base, data, accepted_fields(path), note=f"{dotted(path)} = {value!r}")


def random_word(rng: random.Random) -> str:
    return rng.choice(string.ascii_lowercase) + "".join(
        rng.choices(string.ascii_lowercase + "_" + string.digits, k=rng.randint(1, 12))
    )


def unknown_key(rng: random.Random, base: Base) -> Mutant:
    """A key that no section has, at the top level or in a section."""
    data = copy.deepcopy(base.data)
    tables = [()] + [p for p in _tables(data) if p[:1] not in (("set",), ("grid",))]
    where = rng.choice(tables)
    key = "zz_" + random_word(rng)
    put(data, (*where, key), rng.choice([1.0, "x", [1, 2], True]))
    return mutant(
        "unknown_key", base, data, accepted_fields((*where, key)), values_only=False, note=dotted((*where, key))
    )


def _tables(data: dict, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    found = []
    for key, value in data.items():
        if isinstance(value, dict):
            found.append((*prefix, key))
            found += _tables(value, (*prefix, key))
    return found


def typo(rng: random.Random, word: str) -> str:
    i = rng.randrange(len(word))
    how = rng.choice(["drop", "double", "swap", "replace", "case"] if len(word) > 1 else ["double", "replace"])
    if how == "drop":
        return word[:i] + word[i + 1 :]
    if how == "double":
        return word[:i] + word[i] + word[i:]
    if how == "swap":
        i = min(i, len(word) - 2)
        return word[:i] + word[i + 1] + word[i] + word[i + 2 :]
    if how == "case":
        return word[:i] + word[i].swapcase() + word[i + 1 :]
    return word[:i] + rng.choice(string.ascii_lowercase.replace(word[i], "")) + word[i + 1 :]


def misspelt_key(rng: random.Random, base: Base) -> Mutant:
    """An existing key (or section name) misspelt: a letter dropped, doubled, swapped, replaced or recased."""
    data = copy.deepcopy(base.data)
    candidates = [
        p for p in leaves(data) + _tables(data) if p[:1] not in (("set",), ("grid",), ("random",)) or len(p) == 1
    ]
    path = rng.choice(candidates)
    parent = get(data, path[:-1]) if len(path) > 1 else data
    new = typo(rng, path[-1])
    if new in parent or new == path[-1]:
        new = path[-1] + "x"
    parent[new] = parent.pop(path[-1])
    fields = accepted_fields((*path[:-1], new)) + (f"{dotted(path)}: is required",)  # a required key, misspelt
    if path == ("trajectory",) or (len(path) == 1 and path[0] in ("name", "scenario", "seeds")):  # a required key
        fields += accepted_fields(path)
    if path[-1] == "kind":  # the kind is missing now
        fields += (dotted((*path[:-1], "kind")),)
    if path == ("grid",) or path == ("random",):  # the design is missing now
        fields += ("grid",)
    return mutant("misspelt_key", base, data, fields, values_only=False, note=f"{dotted(path)} -> {new}")


def missing_section(rng: random.Random, base: Base) -> Mutant:
    """A whole section (or top-level key) left out."""
    data = copy.deepcopy(base.data)
    key = rng.choice(list(data))
    del data[key]
    return mutant(
        "missing_section",
        base,
        data,
        (key, "grid") if key in ("grid", "random") else (key,),
        values_only=False,
        note=key,
    )


def nan_inf(rng: random.Random, base: Base) -> Mutant:
    """A number (or an array element) replaced by nan, inf or -inf."""
    data = copy.deepcopy(base.data)
    path = rng.choice(numeric_leaves(data))
    value = rng.choice([math.nan, math.inf, -math.inf])
    with_element(rng, data, path, value)
    return mutant("nan_inf", base, data, accepted_fields(path), note=f"{dotted(path)} = {value}")


POSITIVE = [
    ("robot", "mass"),
    ("robot", "inertia"),
    ("robot", "wheel_radius"),
    ("robot", "half_axle"),
    ("robot", "max_torque"),
    ("plant", "mass"),
    ("plant", "inertia"),
    ("plant", "wheel_radius"),
    ("simulation", "duration"),
    ("simulation", "control_period"),
    ("simulation", "substeps"),
    ("trajectory", "speed"),
    ("controller", "max_velocity"),
]
BY_TRAJECTORY = {
    "circle": "radius",
    "square": "side",
    "figure_eight": "size",
    "line": "speed",
    "waypoints": "speed",
    "sinusoid": "wavelength",
}
SWEEP_POSITIVE = [("seeds",), ("chunk",), ("seeds", "count"), ("random", "n")]


def nonpositive(rng: random.Random, base: Base) -> Mutant:
    """A quantity that must be positive (mass, inertia, radius, time step, duration, seeds, chunk) set to 0
    or below."""
    data = copy.deepcopy(base.data)
    if "scenario" in data:  # a sweep file
        paths = [p for p in SWEEP_POSITIVE if p[0] in data and (len(p) == 1 or isinstance(data[p[0]], dict))]
        paths = [p for p in paths if not (p == ("seeds",) and isinstance(data["seeds"], dict))]
    else:
        kind = data["trajectory"]["kind"]
        paths = POSITIVE + [("trajectory", BY_TRAJECTORY[kind])]
    path = rng.choice(paths)
    value = rng.choice([0, 0.0, -0.0, -1, -1e-9, -1e300, -(10**30)])
    put(data, path, value)
    return mutant("nonpositive", base, data, accepted_fields(path), note=f"{dotted(path)} = {value}")


def window_outside(rng: random.Random, base: Base) -> Mutant:
    """A metric window outside the run, reversed, empty, or of the wrong length."""
    data = copy.deepcopy(base.data)
    section = data.setdefault("set", {}) if "scenario" in data else data.setdefault("simulation", {})
    duration = section.get("duration", section.get("simulation.duration", 40.0))
    value = rng.choice(
        [
            [-1.0, duration],
            [0.0, duration + rng.uniform(0.01, 100.0)],
            [duration, duration],
            [duration / 2, duration / 4],
            [duration + 1, duration + 2],
            [0.0],
            [],
            [0.0, 1.0, 2.0],
            [-1e308, 1e308],
        ]
    )
    if "scenario" in data:
        section["simulation.metric_window"] = value
        fields = ("simulation.metric_window",)
    else:
        section["metric_window"] = value
        fields = ("simulation.metric_window",)
    return mutant("window_outside", base, data, fields, note=str(value))


GAINED = [
    "backstepping",
    "nn_adaptive_backstepping",
    "sliding_mode_backstepping",
    "kinematic_backstepping",
    "adaptive_backstepping",
]


def gains_out_of_range(rng: random.Random, base: Base) -> Mutant:
    """Controller gains (or other bounded controller values) zero, negative, too many, too few, or outside
    their bounds; bounded integers past their limits."""
    data = copy.deepcopy(base.data)
    if "scenario" in data:  # a sweep: through [set]
        data.setdefault("set", {})
        value = rng.choice([[0.0, 55.0, 15.0], [-1.0, 55.0, 15.0], [1.0, 55.0], [1.0, 55.0, 15.0, 1.0]])
        data["set"]["controller.gains"] = value
        return mutant("gains_out_of_range", base, data, ("controller.gains",), note=str(value))
    controller = data.setdefault("controller", {})
    choice = rng.randrange(5)
    if choice == 0:
        value = rng.choice(
            [[0.0, 55.0, 15.0], [1.0, -55.0, 15.0], [1.0, 55.0], [1.0, 55.0, 15.0, 1.0], [1.0, 55.0, -1e-300]]
        )
        controller["gains"] = value
        fields: tuple[str, ...] = ("controller.gains",)
    elif choice == 1:  # outside the NN-adaptive bounds
        controller.clear()
        controller.update(kind="nn_adaptive_backstepping", identification=False)
        value = rng.choice([[1000.0, 55.0, 15.0], [0.01, 55.0, 15.0], [1.0, 601.0, 15.0]])
        controller["gains"] = value
        fields = ("controller.gains",)
    elif choice == 2:
        key, value = rng.choice(
            [("kc", [0.0, 10.0]), ("kc", [10.0, -1.0]), ("max_yaw_rate", -4.0), ("max_velocity", 0.0)]
        )
        controller[key] = value
        fields = (f"controller.{key}",)
    elif choice == 3:
        key, value = rng.choice([("substeps", 0), ("substeps", 1001), ("seed", -1), ("seed", 2**63)])
        data.setdefault("simulation", {})[key] = value
        fields = (f"simulation.{key}",)
    else:
        key, value = rng.choice([("com_offset", 1.5), ("com_offset", -2.0), ("wheel_radius", 3.0), ("half_axle", 6.0)])
        data.setdefault(rng.choice(["robot", "plant"]), {})[key] = value
        fields = (f"robot.{key}", f"plant.{key}")
    return mutant("gains_out_of_range", base, data, fields, note=str(value))


def bad_waypoints(rng: random.Random, base: Base) -> Mutant:
    """A waypoints trajectory with no point, one point (perhaps repeated), malformed points, times that do not
    increase or an unknown column, or a file that does not exist, is a folder, is not CSV, is not UTF-8 or is a
    device (a repeated point among others is dropped with a warning, not refused)."""
    data = copy.deepcopy(base.data)
    if "scenario" in data:  # a sweep: its scenario file is missing, a folder, or not a scenario
        how = rng.choice(["missing", "folder", "csv"])
        data["scenario"] = {"missing": "nope.toml", "folder": "sub", "csv": "points.csv"}[how]
        return mutant(
            "bad_waypoints",
            base,
            data,
            ("scenario", "nope.toml", "sub", "points.csv"),
            values_only=False,
            note=how,
            extra={"points.csv": b"x,y\n0,0\n1,1\n"},
            folders=("sub",),
        )
    old = data.get("trajectory", {})
    trajectory: dict[str, Any] = {"kind": "waypoints", "speed": old.get("speed", 0.5)}
    if rng.random() < 0.3:
        trajectory["corner_radius"] = rng.choice([0.0, 1.0, 5.0])
    extra: dict[str, bytes] = {}
    folders: tuple[str, ...] = ()
    how = rng.choice(["inline", "file"])
    if how == "inline":
        points = rng.choice(
            [
                [],
                [[0.0, 0.0]],
                [[0.0, 0.0], [0.0, 0.0]],
                [[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]],
                [[0.0, 0.0], [1.0, 1.0], [1e308, 0.0]],
                [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]],
                [[0.0], [1.0]],
                [[0.0, 0.0], [math.nan, 1.0]],
                [[0.0, 0.0], ["a", 1.0]],
            ]
        )
        trajectory["points"] = points
        note = f"points = {points}"
    else:
        content = rng.choice(
            [
                b"",
                b"x,y\n",
                b"x,y\n3,4\n",
                b"1,1\n1,1\n1,1\n",
                b"t,x,y\n0,0,0\n1,5,5\n1,9,0\n",
                b"x,y,z\n0,0,0\n1,1,1\n",
                b"0,0,0\n1,1,1\n",
                b"0;0\n1;1\n",
                b"0,0\n1,zz\n",
                b"\xff\xfe0,0\n1,1\n",
                b"0,0\n\xc3\x28,1\n",
                b"name = 'x'\n[robot]\nmass = 1\n",
                b"0,0\nnan,1\n",
                b"0,0\ninf,1\n",
                b"\x00\x01\x02\x03",
            ]
        )
        target = rng.choice(["points.csv", "points.csv", "points.csv", "missing", "folder", "/dev/null"])
        if target == "points.csv":
            extra["points.csv"] = content
        elif target == "missing":
            target = "nope.csv"
        elif target == "folder":
            target, folders = "sub", ("sub",)
        trajectory["file"] = target
        note = f"file = {target} {content[:20]!r}"
    data["trajectory"] = trajectory
    return mutant(
        "bad_waypoints",
        base,
        data,
        ("trajectory.points", "trajectory.file", "trajectory.corner_radius"),
        values_only=False,
        note=note,
        extra=extra,
        folders=folders,
    )


INVALID_UTF8 = [
    b"\xff",
    b"\xfe\xff",
    b"\xc3\x28",
    b"\xa0\xa1",
    b"\xe2\x28\xa1",
    b"\xed\xa0\x80",
    b"\xf8\x88\x80\x80\x80",
    b"\xc0\xaf",
    b"\x80",
]


def invalid_utf8(rng: random.Random, base: Base) -> Mutant:
    """Bytes that are not UTF-8, spliced into the file (in a comment, a string, a key or anywhere)."""
    text = toml_bytes(base.data)
    cut = rng.randrange(len(text) + 1)
    bad = rng.choice(INVALID_UTF8)
    files = dict(base.extra) | {"input": text[:cut] + bad + text[cut:]}
    return Mutant("invalid_utf8", files, fields=("input", "UTF-8"), values_only=False, note=f"{bad!r} at {cut}")


def toml_syntax(rng: random.Random, base: Base) -> Mutant:
    """The file cut short, or a stray character inserted: not TOML any more (or, by chance, still TOML)."""
    text = toml_bytes(base.data)
    cut = rng.randrange(1, len(text))
    how = rng.choice(["truncate", "insert", "duplicate"])
    if how == "truncate":
        new = text[:cut]
    elif how == "insert":
        new = text[:cut] + rng.choice([b"=", b"[", b"]", b'"', b"{", b",", b"\x00", b"\n[[", b"\t=\t"]) + text[cut:]
    else:  # a section or key given twice
        new = text + b"\n" + text[:cut]
    files = dict(base.extra) | {"input": new}
    # cut short, the file can still be TOML, which then lacks a key or holds a shortened value: any field
    return Mutant("toml_syntax", files, fields=("input", ANY_FIELD), values_only=False, note=f"{how} at {cut}")


ANY_FIELD = "*"  #: in Mutant.fields: any message of the form "error: section.key: ..."
HUGE = [1e308, -1e308, 1.7976931348623157e308, 1e300, 10**30, 2**63, 2**64, -(2**63), 10**7, 5e-324]


def huge(rng: random.Random, base: Base) -> Mutant:
    """A number replaced by a huge (or tiny) one: 1e308, 2**64, 10**30, 5e-324."""
    data = copy.deepcopy(base.data)
    path = rng.choice(numeric_leaves(data))
    value = rng.choice(HUGE)
    with_element(rng, data, path, value)
    return mutant("huge", base, data, accepted_fields(path), note=f"{dotted(path)} = {value}")


def bad_design(rng: random.Random, base: Base) -> Mutant:
    """Sweep files only: empty grid or value list, low >= high, both or neither design, a repeated or unknown
    controller, a grid key the scenario does not have. (On a scenario: an unknown kind.)"""
    data = copy.deepcopy(base.data)
    if "scenario" not in data:
        section = rng.choice(["trajectory", "controller", "disturbance"])
        value = rng.choice(["nope", "Circle", "back_stepping", "", "line "])
        data.setdefault(section, {})["kind"] = value
        return mutant("bad_design", base, data, (f"{section}.kind",), note=f"{section}.kind = {value!r}")
    how = rng.randrange(7)
    fields: tuple[str, ...]
    if how == 0:
        data["grid"] = {} if "grid" in data else None
        data.pop("random", None)
        if data["grid"] is None:
            del data["grid"]
        fields = ("grid",)
    elif how == 1:
        data["controllers"] = rng.choice([["backstepping", "backstepping"], ["nope"], [], ["mppi", "Mppi"], [""]])
        fields = ("controllers", "controller.kind", *data.get("grid", {}))  # a grid key the new kind lacks
    elif how == 2:
        if "grid" in data:
            data["grid"]["robot.mass"] = []
            fields = ("grid.robot.mass",)
        else:
            data["random"]["plant.mass"] = rng.choice(
                [
                    {"low": 14.0, "high": 8.0},
                    {"low": 1.0, "high": 1.0},
                    {"low": 1.0},
                    {"low": 1.0, "high": 2.0, "mid": 1.5},
                ]
            )
            fields = ("random.plant.mass", "plant.mass")
    elif how == 3:
        data["grid"] = {"robot.mass": [1.0]}
        data["random"] = {"n": 1, "plant.mass": {"low": 1.0, "high": 2.0}}
        fields = ("grid",)
    elif how == 4:
        key = rng.choice(["robot.mas", "nope.mass", "robot", "robot.mass.x", "simulation.seed"])
        value = {"robot": [1.0], "simulation.seed": [-1]}.get(key, [1.0, 2.0])
        if "grid" in data:
            data["grid"][key] = value
        else:
            data["random"][key] = {"low": -2.0, "high": -1.0} if key == "simulation.seed" else {"low": 1.0, "high": 2.0}
        fields = (key, key.split(".")[0], f"grid.{key}", f"random.{key}")
    elif how == 5:
        data["set"] = {rng.choice(["robot.mas", "nope.x", "controller.gains"]): rng.choice(["a", [1.0], -1.0])}
        fields = (
            tuple(data["set"]) + tuple(f"set.{k}" for k in data["set"]) + tuple(k.split(".")[0] for k in data["set"])
        )
    else:
        data.pop("grid", None)
        data.pop("random", None)
        fields = ("grid",)
    return mutant("bad_design", base, data, fields, values_only=False, note=str(how))


KINDS: dict[str, Callable[[random.Random, Base], Mutant]] = {
    f.__name__: f
    for f in (
        wrong_type,
        unknown_key,
        misspelt_key,
        missing_section,
        nan_inf,
        nonpositive,
        window_outside,
        gains_out_of_range,
        bad_waypoints,
        invalid_utf8,
        toml_syntax,
        huge,
        bad_design,
    )
}


# --- --set overrides ---------------------------------------------------------------------------------

BAD_PATHS = [
    "robot.nope",
    "nope.mass",
    "robot.mass.x",
    "robot..mass",
    ".mass",
    "robot.",
    "robot",
    "name.x",
    "controller.gains.x",
    "simulation.seed.x",
    "trajectory.kind.x",
    "robot.Mass",
    "Robot.mass",
    "plant.mas",
    "randomize.mass.relativ",
    "trajectory.radiuss",
    " robot . mass ",
    "robot.mass\x00",
]
BAD_VALUES = [
    "nan",
    "inf",
    "-inf",
    "1e999",
    "-1e999",
    "[1,",
    "'abc",
    '"',
    "{a=1}",
    "[]",
    "[1,2,3]",
    "true",
    "''",
    "",
    "abc",
    "1e308",
    "-1e308",
    str(2**64),
    str(-(2**64)),
    "0",
    "-1",
    "0x10",
    "1_000",
    "[nan,1,1]",
    "[[1,2]]",
    "{}",
    "1979-05-27",
    "\xff",
    "\u202e1",
]
SET_TARGETS = [
    "robot.mass",
    "robot.inertia",
    "robot.wheel_radius",
    "simulation.duration",
    "simulation.control_period",
    "simulation.metric_window",
    "simulation.seed",
    "simulation.substeps",
    "controller.gains",
    "controller.kind",
    "controller.inner",
    "trajectory.kind",
    "trajectory.speed",
    "initial.pose",
    "disturbance.kind",
    "noise.position_std",
    "plant.com_offset",
    "name",
]


def set_override(rng: random.Random, base: Base) -> Mutant:
    """A ``--set`` override with a bad path (``robot.nope=1``), a value that is not TOML, NaN, huge, or of the
    wrong type; or no ``=`` at all."""
    how = rng.randrange(3)
    if how == 0:
        path = rng.choice(BAD_PATHS)
        override = f"{path}={rng.choice(['1', '1.0', '[1,2]', 'x'])}"
        parts = [p.strip() for p in path.split(".")]
        fields = ["--set", dotted(tuple(p for p in parts if p)), parts[0]] + [
            dotted(tuple(parts[:i])) for i in range(1, len(parts) + 1)
        ]
        fields = [f for f in fields if f]
    elif how == 1:
        target = rng.choice(SET_TARGETS)
        override = f"{target}={rng.choice(BAD_VALUES)}"
        fields = list(accepted_fields(tuple(target.split("."))))
    else:
        override = rng.choice(["robot.mass", "robot.mass:12", "=12", "=", "", ".=1", "robot.mass 12"])
        fields = ["--set"]
    data = copy.deepcopy(base.data)
    return mutant("set_override", base, data, fields, overrides=(override,), note=override)


# --- judging ---------------------------------------------------------------------------------------


class ClusterStarted(Exception):
    """Raised by the stub that replaces the sweep's cluster: the sweep file was accepted."""


@contextlib.contextmanager
def no_cluster() -> Iterator[None]:
    """Replace the sweep command's ``dask_client`` with a stub that raises :class:`ClusterStarted`."""
    from ddtrack.cli import studies as cli

    def stub(*args: Any, **kwargs: Any) -> Any:
        raise ClusterStarted

    saved = cli.dask_client
    cli.dask_client = stub
    try:
        yield
    finally:
        cli.dask_client = saved


def call(args: list[str]) -> tuple[Any, str, str]:
    """``ddtrack ARGS`` in-process: (exit code or the escaped exception, stdout, stderr)."""
    from ddtrack.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code: Any = main(args)
        except ClusterStarted:
            code = "cluster"
        except BaseException as exc:
            code = exc
    return code, out.getvalue(), err.getvalue()


def refusal_problem(code: Any, out: str, err: str, fields: tuple[str, ...], folder: Path) -> str | None:
    """Why a refusal is not clean (None when it is): exit code 2, 1-2 non-empty lines naming a field, nothing
    written."""
    lines = err.splitlines()
    if code != 2:
        return f"exit code {code!r}"
    if "Traceback" in err or "Traceback" in out:
        return "traceback"
    if out:
        return f"stdout not empty: {out[:80]!r}"
    if not 1 <= len(lines) <= 2 or not all(line.strip() for line in lines):
        return f"stderr is not one or two lines: {err[:200]!r}"
    if not any(f in lines[0] for f in fields) and not (ANY_FIELD in fields and re.match(r"error: \S+: ", lines[0])):
        return f"message does not name {fields}: {lines[0][:200]!r}"
    if folder.exists():
        return "output folder written"
    return None


def materialise(m: Mutant, folder: Path) -> Path:
    """Write the mutant's files into ``folder``; return the input file's path."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in m.folders:
        (folder / name).mkdir(exist_ok=True)
    for name, content in m.files.items():
        if name != "input":
            (folder / name).write_bytes(content)
    suffix = "sweep.toml" if b"scenario =" in m.files["input"] or b"scenario=" in m.files["input"] else "case.toml"
    path = folder / suffix
    path.write_bytes(m.files["input"])
    return path


def judge(m: Mutant, folder: Path, *, sweep: bool = False, run: bool = False) -> tuple[str, str]:
    """Try one mutant in ``folder``; return (outcome, detail), outcome one of "ran", "refused", "bad"."""
    path = materialise(m, folder)
    fields = tuple(path.name if f == "input" else f for f in m.fields) + ((path.name,) if "input" in m.fields else ())
    out_dir = folder / "out"
    if sweep:
        started = time.perf_counter()
        with no_cluster():
            code, out, err = call(["sweep", str(path), "--out", str(out_dir), "--workers", "1"])
        elapsed = time.perf_counter() - started
        if code == "cluster":
            return "ran", "reached the cluster"
        problem = refusal_problem(code, out, err, fields, out_dir)
        if problem is None and elapsed > 10.0:
            problem = f"refused only after {elapsed:.1f} s"
        return ("bad", f"{problem} [{m.note}]") if problem else ("refused", err.splitlines()[0])
    overrides = [a for o in m.overrides for a in ("--set", o)]
    code, out, err = call(["validate", str(path), *overrides])
    warned_only = all(line.startswith("warning: ") for line in err.splitlines())  # accepted, with a warning
    if code == 0 and warned_only and out.startswith("ok: "):
        if not run:
            return "ran", "validated"
        short = (
            [a for o in SHORT for a in ("--set", o)]
            if m.values_only and not any("simulation" in o for o in m.overrides) and "simulation" not in m.note
            else []
        )
        code, out, err = call(["run", str(path), *overrides, *short, "--out", str(out_dir)])
        if code in (0, 1) and "Traceback" not in err:
            return "ran", f"run exit {code}"
        problem = refusal_problem(code, out, err, fields + tuple(s.split("=")[0] for s in SHORT), out_dir)
        return ("bad", f"run: {problem} [{m.note}]") if problem else ("refused", err.splitlines()[0])
    problem = refusal_problem(code, out, err, fields, out_dir)
    if problem:
        return "bad", f"validate: {problem} [{m.note}]"
    code2, out2, err2 = call(["run", str(path), *overrides, "--out", str(out_dir)])
    problem = refusal_problem(code2, out2, err2, fields, out_dir)
    if problem:
        return "bad", f"run: {problem} [{m.note}]"
    if err2 != err:
        return "bad", f"run and validate disagree: {err2!r} vs {err!r}"
    return "refused", err.splitlines()[0]


SCENARIO_KINDS = [*KINDS, "set_override"]
SWEEP_KINDS = [k for k in KINDS if k != "set_override"]


def make(kind: str, rng: random.Random, base: Base) -> Mutant:
    """One mutant of ``base`` of the named kind."""
    return set_override(rng, base) if kind == "set_override" else KINDS[kind](rng, base)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=3000, help="Cases in all (scenario and sweep) [3000].")
    parser.add_argument("--runs", type=int, default=12, help="Accepted scenario mutants also run (shortened) [12].")
    parser.add_argument("--seed", type=int, default=0, help="Seed of the mutations [0].")
    parser.add_argument("--workdir", type=Path, help="Folder for the cases' files [default: a temporary one].")
    args = parser.parse_args(argv)
    import ddtrack

    ddtrack.enable_float64()

    rng = random.Random(args.seed)
    scenarios, sweeps = scenario_bases(), sweep_bases()
    tally: dict[tuple[str, str], Counter] = {}
    bad: list[str] = []
    runs_left = args.runs
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="ddtrack-fuzz-", dir=args.workdir) as tmp:
        for i in range(args.cases):
            sweep = i % 4 == 3  # a quarter of the cases are sweep files
            base = rng.choice(sweeps if sweep else scenarios)
            kind = rng.choice(SWEEP_KINDS if sweep else SCENARIO_KINDS)
            m = make(kind, rng, base)
            run = not sweep and runs_left > 0 and m.values_only  # runs only if it validates
            folder = Path(tmp) / f"case{i}"
            outcome, detail = judge(m, folder, sweep=sweep, run=run)
            if run and detail.startswith("run exit"):
                runs_left -= 1
            shutil.rmtree(folder, ignore_errors=True)
            row = tally.setdefault(("sweep" if sweep else "scenario", kind), Counter())
            row[outcome] += 1
            row["run"] += detail.startswith("run exit")
            if outcome == "bad":
                bad.append(f"{kind} on {base.name}: {detail}")
    elapsed = time.perf_counter() - started
    print("| input | mutation kind | cases | ran (of which run) | exit 2 naming the field | anything else |")
    print("|---|---|---:|---:|---:|---:|")
    total = Counter()
    for (what, kind), row in sorted(tally.items()):
        cases = sum(row[o] for o in ("ran", "refused", "bad"))
        total.update(row | {"cases": cases})
        print(f"| {what} | {kind} | {cases} | {row['ran']} ({row['run']}) | {row['refused']} | {row['bad']} |")
    print(f"| all | all | {total['cases']} | {total['ran']} ({total['run']}) | {total['refused']} | {total['bad']} |")
    print(f"\n{total['cases']} cases in {elapsed:.0f} s (seed {args.seed})")
    for line in bad[:50]:
        print("BAD:", line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
