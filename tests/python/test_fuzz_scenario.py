"""Fuzzing scenario keys (issue 11): random ``--set key=value`` over every known key (and some
unknown ones) with huge, tiny, NaN, infinite, negative, textual, table and array values.

Each assignment either builds a scene that the engine then accepts, or raises a one-line
ScenarioError (a ValueError) naming the key, at load/build time, never later and never
another exception. Budget: test_fuzz_engine.FUZZ (``EVSTWIN_FUZZ_EXAMPLES``).
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import event, given
from hypothesis import strategies as st
from test_fuzz_engine import FUZZ, tick

from evstwin.scenario import SCHEMA, ScenarioError, build, load, parse_assignment, set_value
from evstwin.scenario.schema import _TARGET_KEYS
from evstwin.simulate import simulate

BASES = ("geo-stare", "mcreynolds")

KEYS = sorted(
    [k for k, spec in SCHEMA.items() if spec is not list]
    + [f"{k}.{sub}" for k, spec in SCHEMA.items() if isinstance(spec, dict) for sub in spec]
    + [f"targets.0.{k}" for keys in _TARGET_KEYS.values() for k in keys]
    + ["targets.0.kind", "targets.0.label", "targets.0.frame", "targets.0.flux_ph_s", "targets.0.magnitude", "targets.0.light_curve",
       "targets", "targets.0", "targets.7.x_px", "targets.x.x_px", "pixel.nope", "nope", "sensor.width.x", ""]
)
"""Every key a scenario knows, one target's fields of every kind, and a few it does not."""

VALUES = [
    "0", "-0", "1", "-1", "2", "1.5", "0.25", "346", "65535", "65536", "1e7", "1e20", "1e25", "1e300", "-1e300",
    "1e-300", "5e-324", "nan", "inf", "-inf", "1" + "0" * 400, "-" + "9" * 30, "true", "false", '"abc"', "abc",
    '""', "", "{a = 1}", "{}", "[1, 2]", "[]", "[[1]]", '["x"]', "[1e300, -1e300]", "none",
    "{t_s = [0.0, 1.0], flux_ph_s = [1.0, 2.0]}", "{t_s = [1.0, 0.0], magnitude = [1e300, 2]}",
    '"poisson"', '"euler"', '"field"', '"sensor"', "[-3.0, 3.2]", '"davis346"', '"imx636"', '"linear"', '"static"', '"tabulated"', "1979-05-27",
]
"""TOML value texts: the edges of every type."""

values = st.one_of(
    st.sampled_from(VALUES),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(2**70), 2**70).map(str),
    st.text(max_size=12),
    st.floats(-3.0, 3.0),  # the key's current value times 10 to this power: mostly plausible scenarios
)


def _current(scenario: dict[str, Any], key: str) -> Any:
    node: Any = scenario
    for part in key.split("."):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            return None
    return node


def _text(scenario: dict[str, Any], key: str, value: str | float) -> str:
    if isinstance(value, str):
        return value
    current = _current(scenario, key)
    if isinstance(current, bool) or not isinstance(current, (int, float)):
        return repr(10.0**value)
    scaled = current * 10.0**value
    return str(round(scaled)) if isinstance(current, int) else repr(scaled)


def _names(key: str) -> list[str]:
    """What an error about key may call it: the key, any dotted prefix, its last part, and
    targets.N as targets[N]."""
    parts = key.split(".")
    out = [".".join(parts[: i + 1]) for i in range(len(parts))] + [parts[-1]]
    if len(parts) > 1 and parts[0] == "targets":
        out.append(f"targets[{parts[1]}]")
    return [n for n in out if n] + [repr(key)]


def _cheap(scene: Any) -> bool:
    """Whether two base samples of the scene are a quick engine run (< ~3e6 pixel-updates)."""
    speed = max((t.max_speed_px_s(0.0, 2.0 / scene.rate_hz) for t in scene.targets), default=0.0)
    n_sub = max(1.0, math.ceil(speed / scene.rate_hz / scene.max_shift_px))
    return len(scene.targets) <= 2000 and 2 * n_sub * scene.width * scene.height <= 3e6


@FUZZ
@given(st.sampled_from(BASES), st.lists(st.tuples(st.sampled_from(KEYS), values), min_size=1, max_size=3))
def test_fuzzed_assignments_build_and_run_or_are_one_line_naming_the_key(base: str, sets: list) -> None:
    tick("scenario.set")
    scenario = load(base)
    key = ""
    try:
        for key, given_value in sets:
            k, value = parse_assignment(f"{key}={_text(scenario, key, given_value)}")
            scenario = set_value(scenario, k, value)
        key = "*"  # a failure in build may come from any of the keys set
        scene = build(scenario, duration_s=0.01)
    except ScenarioError as exc:
        message = str(exc)
        assert "\n" not in message, f"a multi-line error: {message!r}"
        names = [n for k, _ in sets for n in _names(k)] if key == "*" else _names(key)
        assert any(n in message for n in names), f"the error names none of {names}: {message!r}"
        event("refused at " + ("build" if key == "*" else "set"))
        return
    # What build accepts the engine runs: two base samples, when that is quick.
    if not _cheap(scene):
        event("built (not run: too many pixel-updates)")
        return
    result = simulate(scene.scenario, duration_s=2.0 / scene.rate_hz, num_threads=1)
    assert (result.events["x"] < scene.width).all() and (result.events["y"] < scene.height).all()
    event("built and ran")


@pytest.mark.parametrize("base", BASES)
def test_every_known_key_is_in_the_fuzzed_set(base: str) -> None:
    scenario = load(base)
    for table, spec in SCHEMA.items():
        if isinstance(spec, dict):
            assert all(f"{table}.{sub}" in KEYS for sub in spec)
    assert {f"targets.0.{k}" for k in scenario["targets"][0]} <= set(KEYS)
