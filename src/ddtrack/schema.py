"""The scenario file's JSON Schema and its Markdown reference (``ddtrack schema``).

Both are generated from the pydantic models that validate scenario files (:mod:`ddtrack.scenario`), so the
reference cannot drift from the validator: ``docs/reference.md`` is ``ddtrack schema --markdown`` and a test
checks that it is current. Units are those of the fields' descriptions, in brackets (SI throughout).
"""

from __future__ import annotations

import json
from typing import Any

from .scenario import Scenario

SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
TITLE = "ddtrack scenario file"
REGENERATE = "ddtrack schema --markdown > docs/reference.md"
DESCRIPTION = (
    "A scenario for ddtrack (TOML): the run's timing, the nominal robot the controller believes in, the "
    "true plant, its random draws, the disturbance and noise, the reference, the initial state and the "
    "controller. Units are SI, given in brackets in the descriptions."
)


def scenario_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scenario file, from :meth:`Scenario.model_json_schema`.

    Returns
    -------
    dict
        The schema: ``properties`` are the file's top-level keys and sections, ``$defs`` the section models;
        a section with kinds (``[trajectory]``, ``[disturbance]``, ``[controller]``) is a ``oneOf`` with a
        ``discriminator`` on ``kind``. Descriptions carry the units in brackets.
    """
    schema = Scenario.model_json_schema()
    schema["description"] = DESCRIPTION  # not the class docstring's numpydoc sections
    return {"$schema": SCHEMA_DIALECT, "title": TITLE, **{k: v for k, v in schema.items() if k != "title"}}


def resolve(schema: dict[str, Any], node: dict[str, Any]) -> dict[str, Any]:
    """``node`` with a local ``$ref`` (``#/$defs/Name``) replaced by the definition it points to."""
    if "$ref" in node:
        return schema["$defs"][node["$ref"].rsplit("/", 1)[-1]]
    return node


def kinds(schema: dict[str, Any], node: dict[str, Any]) -> dict[str, dict[str, Any]] | None:
    """For a section with kinds (a ``oneOf`` with a ``discriminator``), kind -> that kind's model; else None."""
    if "discriminator" not in node:
        return None
    tag = node["discriminator"]["propertyName"]
    models = [resolve(schema, option) for option in node["oneOf"]]  # in the registry's order
    return {model["properties"][tag]["const"]: model for model in models}


def _optional(node: dict[str, Any]) -> dict[str, Any]:
    """``X`` of an ``anyOf [X, null]`` (an optional key), else the node itself."""
    options = [o for o in node.get("anyOf", []) if o.get("type") != "null"]
    if "anyOf" in node and len(options) == 1:
        return {**options[0], **{k: v for k, v in node.items() if k not in ("anyOf", "default")}}
    return node


def _type(schema: dict[str, Any], node: dict[str, Any]) -> str:
    node = _optional(node)
    if "$ref" in node:
        return "table"
    if "enum" in node:
        return " \\| ".join(f'`"{value}"`' for value in node["enum"])
    if "const" in node:
        return f'`"{node["const"]}"`'
    kind = node.get("type")
    if kind == "array" and "prefixItems" in node:
        return "[" + ", ".join(_type(schema, item) for item in node["prefixItems"]) + "]"
    if kind == "array":
        return f"list of {_type(schema, node['items'])}"
    return {"number": "float", "integer": "int", "boolean": "bool", "string": "string"}.get(str(kind), str(kind))


BOUNDS = (("exclusiveMinimum", "> "), ("minimum", ">= "), ("exclusiveMaximum", "< "), ("maximum", "<= "))


def _bounds(node: dict[str, Any]) -> str:
    node = _optional(node)
    parts = [f"{sign}{_value(node[key])}" for key, sign in BOUNDS if key in node]
    if "minLength" in node or "maxLength" in node:
        parts.append(f"{node.get('minLength', 0)} to {node.get('maxLength', 'any')} characters")
    if node.get("type") == "array" and "prefixItems" in node:
        items = {_bounds(item) for item in node["prefixItems"]}
        if len(items) == 1 and "" not in items:
            parts.append(f"each {items.pop()}")
    return ", ".join(parts)


def _value(value: Any) -> str:
    """A default as it is written in TOML."""
    if value is None:
        return "none"
    if isinstance(value, dict):
        return "table"
    return json.dumps(value)


def _cell(text: str) -> str:
    # "[v, omega] [m/s, rad/s]" would read as a reference link "[text][label]" to Python-Markdown (the site):
    # the second bracket escaped reads as plain text there and on GitHub alike
    return _markdown(text).replace("|", "\\|").replace("] [", "] \\[")


def _markdown(text: str) -> str:
    """Docstring text on one line, its reStructuredText literals (``x``) as Markdown code (`x`)."""
    return " ".join(text.split()).replace("``", "`")


def _table(schema: dict[str, Any], model: dict[str, Any], *, skip: tuple[str, ...] = ()) -> list[str]:
    lines = ["| key | type | default | allowed | description |", "|---|---|---|---|---|"]
    required = set(model.get("required", ()))
    for key, node in model["properties"].items():
        if key in skip:
            continue
        default = "required" if key in required else (_value(node["default"]) if "default" in node else "")
        described = node.get("description", "")
        if "$ref" in _optional(node) and not described:
            described = "An inline table, below."
        lines.append(
            f"| `{key}` | {_type(schema, node)} | {_cell(default)} | {_cell(_bounds(node))} | {_cell(described)} |"
        )
    return lines


def _description(model: dict[str, Any]) -> list[str]:
    text = model.get("description", "")
    return [_markdown(text), ""] if text else []


def schema_markdown(schema: dict[str, Any] | None = None) -> str:
    """The scenario reference in Markdown (``docs/reference.md``): one table per section and per kind.

    Parameters
    ----------
    schema : dict, optional
        A schema as :func:`scenario_schema` returns it (the default).

    Returns
    -------
    str
        The Markdown text, ending with a newline.
    """
    schema = scenario_schema() if schema is None else schema
    top = {k: v for k, v in schema["properties"].items() if "$ref" not in v and "oneOf" not in v}
    out = [
        f"<!-- Generated by `{REGENERATE}`; do not edit by hand (tests/test_schema.py checks it is current). -->",
        "",
        "# Scenario file reference",
        "",
        "Every key of a scenario file, generated from the models that validate it (`ddtrack schema` prints the "
        "same as a JSON Schema). The narrative guide, with the rules and examples, is [scenarios.md](scenarios.md); "
        "the commands are in [guide.md](guide.md).",
        "",
        "Types: `float` and `int` are TOML numbers (an integer is accepted for a float), `[float, float]` a TOML "
        "array of that many numbers, `table` a TOML table. Units are in brackets. A key left out takes its default; "
        "`none` means unset. Unknown keys, NaN and infinity are errors.",
        "",
        "## Top level",
        "",
        *_table(schema, {"properties": top, "required": schema.get("required", [])}),
        "",
    ]
    for section, node in schema["properties"].items():
        if section in top:
            continue
        by_kind = kinds(schema, node)
        if by_kind is None:
            model = resolve(schema, node)
            out += [f"## [{section}]", "", *_description(model), *_table(schema, model), ""]
            out += _nested(schema, section, model)
            continue
        default = node.get("default", {}).get("kind")
        required = section in schema.get("required", [])
        choice = "required" if required else f"default `{_value(default)}`" if default else ""
        out += [
            f"## [{section}]",
            "",
            f"One of the kinds below, chosen by `kind` ({choice}): "
            + ", ".join(f'`"{kind}"`' for kind in by_kind)
            + ".",
            "",
        ]
        for kind, model in by_kind.items():
            out += [f'### [{section}] kind = "{kind}"', "", *_description(model)]
            if set(model["properties"]) == {"kind"}:
                out += ["No other keys.", ""]
            else:
                out += [*_table(schema, model, skip=("kind",)), ""]
    return "\n".join(out).rstrip("\n") + "\n"


def _nested(schema: dict[str, Any], section: str, model: dict[str, Any]) -> list[str]:
    """Sub-tables of a section (each ``[randomize]`` entry is a ParameterDraw table), once per model."""
    out, seen = [], set()
    for _key, node in model["properties"].items():
        inner = _optional(node)
        if "$ref" not in inner or inner["$ref"] in seen:
            continue
        seen.add(inner["$ref"])
        users = [k for k, n in model["properties"].items() if _optional(n).get("$ref") == inner["$ref"]]
        nested = resolve(schema, inner)
        out += [
            f"### [{section}] entries ({', '.join(f'`{k}`' for k in users)})",
            "",
            *_description(nested),
            *_table(schema, nested),
            "",
        ]
    return out


__all__ = ["REGENERATE", "kinds", "resolve", "scenario_schema", "schema_markdown"]
