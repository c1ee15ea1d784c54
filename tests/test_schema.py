"""``ddtrack schema``: the scenario file's JSON Schema, and docs/reference.md generated from it."""

from __future__ import annotations

import json
import tomllib

import pytest
from conftest import ROOT, SCENARIOS

from ddtrack import load_scenario
from ddtrack.scenario import CONTROLLERS, DISTURBANCES, TRAJECTORIES, to_toml_dict
from ddtrack.schema import kinds, resolve, scenario_schema

JSON_TYPES = {
    "number": (int, float),
    "integer": (int,),
    "string": (str,),
    "boolean": (bool,),
    "array": (list,),
    "object": (dict,),
    "null": (type(None),),
}


def schema_errors(schema: dict, node: dict, value, path: str = "") -> list[str]:
    """A small JSON Schema check of a TOML value: every key known (recursively, through ``$ref``, optional
    ``anyOf`` and the ``kind`` unions), required keys present, types, tuple lengths and enums."""
    node = resolve(schema, node)
    by_kind = kinds(schema, node)
    if by_kind is not None:
        kind = value.get("kind", "backstepping" if path == "controller" else None)  # as validate_scenario reads it
        if kind not in by_kind:
            return [f"{path}.kind: {kind!r} is not one of {sorted(by_kind)}"]
        return schema_errors(schema, by_kind[kind], {"kind": kind, **value}, path)
    if "anyOf" in node:
        options = [o for o in node["anyOf"] if not schema_errors(schema, o, value, path)]
        return [] if options else [f"{path}: {value!r} matches none of {node['anyOf']}"]
    if ("const" in node and value != node["const"]) or ("enum" in node and value not in node["enum"]):
        return [f"{path}: {value!r} is not allowed"]
    kind = node.get("type")
    if kind is not None and (
        not isinstance(value, JSON_TYPES[kind]) or (kind != "boolean" and isinstance(value, bool))
    ):
        return [f"{path}: {value!r} is not of type {kind}"]
    errors = []
    if kind == "object":
        properties = node["properties"]
        errors += [f"{path}.{key}: unknown key" for key in value if key not in properties]
        errors += [f"{path}.{key}: required" for key in node.get("required", ()) if key not in value]
        for key in value:
            if key in properties:
                errors += schema_errors(schema, properties[key], value[key], f"{path}.{key}".lstrip("."))
    elif kind == "array":
        items = node.get("prefixItems")
        if items is not None and len(items) != len(value):
            return [f"{path}: {len(value)} items, expected {len(items)}"]
        for i, item in enumerate(value):
            errors += schema_errors(schema, items[i] if items is not None else node["items"], item, f"{path}[{i}]")
    return errors


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scenarios_and_their_resolved_form_satisfy_the_schema(path):
    schema = scenario_schema()
    raw = tomllib.loads(path.read_text())
    assert schema_errors(schema, schema, raw) == []
    resolved = to_toml_dict(load_scenario(path))  # every key, defaults included: what `ddtrack run` writes
    assert schema_errors(schema, schema, resolved) == []


def test_the_schema_check_can_fail():
    schema = scenario_schema()
    raw = tomllib.loads((SCENARIOS / "paper_line.toml").read_text())
    raw["robot"]["mas"] = 10.0
    raw["controller"]["gains"] = [1.0, 55.0]
    raw["trajectory"] = {"kind": "spiral"}
    raw["randomize"] = {"mass": {"distribution": "uniform", "spread": 0.2}}
    errors = schema_errors(schema, schema, raw)
    assert sorted(error.split(": ")[0] for error in errors) == [
        "controller.gains",
        "randomize.mass",
        "robot.mas",
        "trajectory.kind",
    ]
    assert "robot.mas: unknown key" in errors and "controller.gains: 2 items, expected 3" in errors


def test_schema_command_prints_the_json_schema(cli):
    code, out, err = cli("schema")
    assert code == 0 and err == ""
    schema = json.loads(out)
    assert schema == json.loads(json.dumps(scenario_schema()))
    assert schema["$schema"].endswith("2020-12/schema") and schema["title"] == "ddtrack scenario file"
    assert schema["required"] == ["name", "trajectory"] and schema["additionalProperties"] is False
    for section, registry in (("trajectory", TRAJECTORIES), ("disturbance", DISTURBANCES), ("controller", CONTROLLERS)):
        assert list(kinds(schema, schema["properties"][section])) == list(registry)  # one model per kind
    mass = resolve(schema, schema["properties"]["robot"])["properties"]["mass"]
    assert mass == {
        "default": 10.0,
        "description": "Total mass m [kg].",
        "exclusiveMinimum": 0.0,
        "title": "Mass",
        "type": "number",
    }


def test_the_committed_reference_is_what_the_command_prints(cli):
    code, out, _ = cli("schema", "--markdown")
    assert code == 0
    committed = (ROOT / "docs" / "reference.md").read_text()
    assert committed == out, "docs/reference.md is stale: run `ddtrack schema --markdown > docs/reference.md`"
    assert out.startswith("<!-- Generated by `ddtrack schema --markdown > docs/reference.md`")


def test_the_reference_has_every_key_with_its_unit():
    text = (ROOT / "docs" / "reference.md").read_text()
    schema = scenario_schema()
    for section, node in schema["properties"].items():
        by_kind = kinds(schema, node)
        if by_kind is not None:
            assert all(f'### [{section}] kind = "{kind}"' in text for kind in by_kind)
        elif "$ref" in node:
            assert f"## [{section}]" in text
    assert "| `mass` | float | 10.0 | > 0.0 | Total mass m [kg]. |" in text
    assert '| `inner` | `"computed_torque"` \\| `"pd"` \\| `"none"` | "computed_torque" |  | Inner (dynamic' in text
    assert "| `std` | [float, float] | required | each >= 0.0 | [right, left] standard deviation [N m]. |" in text
