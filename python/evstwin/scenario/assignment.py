"""``--set key=value``: a dotted key of a resolved scenario set to a TOML value, re-validated."""

from __future__ import annotations

import copy
from typing import Any

from .schema import SCHEMA, ScenarioError, resolve, tomllib


def parse_assignment(text: str) -> tuple[str, Any]:
    """``'pixel.theta_on=0.25'`` -> ``('pixel.theta_on', 0.25)``; the value is read as a TOML
    value (numbers, booleans, strings in quotes, arrays), else taken as a bare string."""
    if "=" not in text:
        raise ScenarioError(f"--set takes key=value (e.g. pixel.theta_on=0.25); got {text!r}")
    key, _, value_text = text.partition("=")
    key = key.strip()
    try:
        value = tomllib.loads(f"v = {value_text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = value_text.strip()
    return key, value


def set_value(scenario: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    """A copy of the (resolved) scenario with one dotted key set, re-validated.
    ``targets.0.flux_ph_s`` addresses the first target."""
    out = copy.deepcopy(scenario)
    parts = key.split(".")
    node: Any = out
    for depth, part in enumerate(parts[:-1]):
        path = ".".join(parts[: depth + 1])
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ScenarioError(f"{path}: index must be 0..{len(node) - 1}; got {part!r}")
            node = node[int(part)]
        elif not isinstance(node, dict):
            parent = ".".join(parts[:depth])
            raise ScenarioError(f"{parent} is a value ({node!r}), not a table: {key!r} does not exist")
        else:
            if part not in node:
                if depth == 0 and part in SCHEMA and isinstance(SCHEMA[part], dict):
                    node[part] = {}
                else:
                    allowed = SCHEMA if depth == 0 else node
                    raise ScenarioError(f"unknown scenario key {path!r}; allowed: {', '.join(allowed)}")
            node = node[part]
    last = parts[-1]
    if isinstance(node, list):
        raise ScenarioError(f"{key}: give a field of one element, e.g. {key}.0.<field>")
    if not isinstance(node, dict):
        raise ScenarioError(f"{'.'.join(parts[:-1])} is a value ({node!r}), not a table: {key!r} does not exist")
    if last == "cutoff_hz" and parts[0] == "pixel" and value in ("none", "None", "off"):
        value = None
    if node is out and last not in SCHEMA:
        raise ScenarioError(f"unknown scenario key {key!r}; allowed: {', '.join(SCHEMA)}")
    if node is out and isinstance(SCHEMA[last], dict) and not isinstance(value, dict):
        raise ScenarioError(f"{key} is a table: set one of its keys, e.g. {key}.{next(iter(SCHEMA[last]))}=...")
    node[last] = value
    if out.get("pixel", {}).get("cutoff_hz", 0) is None:
        # TOML has no null: a cutoff of None is written as the string "none" in the dict.
        out["pixel"]["cutoff_hz"] = "none"
    return resolve(out)
