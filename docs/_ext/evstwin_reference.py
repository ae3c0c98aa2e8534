"""The reference pages, generated from the code at every build: nothing here is written by hand.

* the CLI, from ``evstwin.cli.build_parser()`` (every command and option with its help);
* the scenario keys, from ``evstwin.scenario.SCHEMA``, each described by the docstring the code
  gives it (a dataclass field's own docstring, else the sentence of the module docstring that
  names the key), its unit from its name's suffix and its default where the code has one;
* ``PixelParams``, from the dataclass, its field docstrings and its defaults (read from C++);
* the presets, from ``evstwin.presets.PRESETS`` (every field of each ``SensorPreset``, its
  sources and assumptions);
* the C++ headers, from ``cpp/include/evstwin/*.hpp`` (each file's opening comment);
* the event file formats, from ``evstwin.io``'s registry and the modules' docstrings.

``undocumented()`` lists what has no documentation text; the Sphinx build fails on it, and
``tests/python/test_docs_reference.py`` asserts it is empty.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import math
import re
import textwrap
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
GENERATED = "generated"  # folder under docs/reference/, ignored by git


# -- helpers ------------------------------------------------------------------------------------


def attribute_docs(cls: type) -> dict[str, str]:
    """The docstrings written under the fields of a class (``x: int = 0`` then ``\"\"\"...\"\"\"``)."""
    source = textwrap.dedent(inspect.getsource(cls))
    body = ast.parse(source).body[0]
    assert isinstance(body, ast.ClassDef)
    docs: dict[str, str] = {}
    stmts = body.body
    for a, b in zip(stmts, stmts[1:]):
        if isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name):
            if isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant) and isinstance(b.value.value, str):
                docs[a.target.id] = inspect.cleandoc(b.value.value)
    return docs


def one_line(text: str) -> str:
    """Docstring text as one line for a table cell (pipes escaped)."""
    return " ".join(text.split()).replace("|", "\\|")


_UNITS = [  # longest suffix first
    ("_mag_per_arcsec2", "mag/arcsec²"), ("_mag_per_airmass", "mag/airmass"), ("_hz_per_a", "Hz/A"),
    ("_e_per_s", "e⁻/s"), ("_ph_s_m2", "photons/s/m²"), ("_ph_s", "photons/s"), ("_arcsec_s", "arcsec/s"),
    ("_px_s", "px/s"), ("_per_deg2", "1/deg²"), ("_rad_s", "rad/s"), ("_m_s", "m/s"), ("_per_m", "1/m"),
    ("_arcsec", "arcsec"), ("_deg", "deg"), ("_rad", "rad"), ("_hz", "Hz"), ("_px", "px"), ("_s", "s"),
    ("_m", "m"), ("_a", "A"),
]


def unit_of(name: str) -> str:
    """The unit a name states by its suffix (the project's naming rule), or '' (dimensionless)."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def fmt_value(value: Any) -> str:
    if value is dataclasses.MISSING:
        return ""
    if isinstance(value, float):
        if math.isinf(value):
            return "inf"
        return f"{value:.6g}"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "none"
    return str(value)


def code(text: str) -> str:
    return f"`{text}`" if text else ""


# -- the CLI -------------------------------------------------------------------------------------


@dataclass
class CliOption:
    command: str
    names: str
    help: str
    default: Any
    required: bool
    choices: Any
    metavar: str


def cli_commands() -> list[tuple[str, str, argparse.ArgumentParser]]:
    """(name, help, parser) of each ``evstwin`` command, in the parser's order."""
    from evstwin.cli import build_parser

    ap = build_parser()
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help or "" for c in sub._choices_actions}
    return [(name, helps.get(name, ""), p) for name, p in sub.choices.items()]


def cli_options(parser: argparse.ArgumentParser, command: str) -> list[CliOption]:
    out = []
    for a in parser._actions:
        if isinstance(a, argparse._HelpAction):
            continue
        names = ", ".join(a.option_strings) if a.option_strings else (a.metavar or a.dest).upper()
        out.append(CliOption(command, names, a.help or "", a.default, a.required or not a.option_strings,
                             a.choices, a.metavar if isinstance(a.metavar, str) else ""))
    return out


def cli_markdown() -> str:
    import os

    from evstwin.cli import build_parser

    # argparse wraps usage lines at the terminal's width: the same width wherever it is built
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"
    try:
        return _cli_markdown(build_parser())
    finally:
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved


def _cli_markdown(ap: argparse.ArgumentParser) -> str:
    lines = ["# Command line", "",
             "Generated from `evstwin.cli.build_parser()`: every command and option, with the help",
             "text the parser prints (`evstwin COMMAND --help`). `python -m evstwin` is the same command.",
             "", "```text", ap.format_usage().strip(), "```", ""]
    for name, help_text, p in cli_commands():
        options = cli_options(p, name)
        lines += [f"## `evstwin {name}`", "", help_text[:1].upper() + help_text[1:] + ".", "",
                  "```text", p.format_usage().strip(), "```", ""]
        if options:
            lines += ["| argument | meaning | default |", "|---|---|---|"]
        for o in options:
            default = "" if o.required or o.default in (None, False, argparse.SUPPRESS, []) else fmt_value(o.default)
            choices = f" One of: {', '.join(map(str, o.choices))}." if o.choices else ""
            meta = f" `{o.metavar}`" if o.metavar and o.names.startswith("-") else ""
            req = " (required)" if o.required and o.names.startswith("-") else ""
            lines.append(f"| `{o.names}`{meta}{req} | {one_line(o.help)}{choices} | {code(default)} |")
        lines.append("")
    return "\n".join(lines)


# -- PixelParams and other dataclasses ------------------------------------------------------------


@dataclass
class Field:
    name: str
    type: str
    default: Any
    doc: str


def dataclass_fields(cls: type) -> list[Field]:
    docs = attribute_docs(cls)
    out = []
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else dataclasses.MISSING
        t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        out.append(Field(f.name, str(t), default, docs.get(f.name, "")))
    return out


def pixel_markdown() -> str:
    from evstwin.pixel import PixelParams

    lines = ["# `PixelParams`", "",
             "Generated from `evstwin.PixelParams` (the Python face of the C++ `evstwin::PixelParams`,",
             "whose defaults, the paper's DAVIS346 pixel, it reads). Each description is the field's own",
             "docstring; the unit is in the name (`_s`, `_hz`, `_a`...). A scenario sets any of them in",
             "`[pixel]` (see [scenario keys](scenario.md)); a preset sets its own values",
             "([presets](presets.md)). Values are checked when the object is made: a bad one is a",
             "`ValueError` naming the field and the value.", "",
             "| field | type | default | unit | description |", "|---|---|---|---|---|"]
    for f in dataclass_fields(PixelParams):
        lines.append(f"| `{f.name}` | `{f.type}` | {code(fmt_value(f.default))} | {unit_of(f.name)} | "
                     f"{one_line(f.doc)} |")
    lines.append("")
    return "\n".join(lines)


# -- scenario keys --------------------------------------------------------------------------------


@dataclass
class ScenarioKey:
    table: str  # "" for the top level, "targets" for [[targets]] (with kind)
    key: str
    type: str
    default: Any
    doc: str
    source: str  # where the doc text comes from

    @property
    def path(self) -> str:
        return f"{self.table}.{self.key}" if self.table else self.key


def _module_doc_blocks(doc: str) -> dict[str, str]:
    """The paragraphs of a module docstring that start with ````[table]````, ``[[table]]`` or a
    top-level key in double backticks, keyed by the table (or key) name."""
    blocks: dict[str, str] = {}
    current = None
    for line in doc.splitlines():
        m = re.match(r"^``\[\[?([a-z_]+)\]\]?``|^``([a-z_]+)``\s", line)
        if m:
            current = m.group(1) or m.group(2)
            blocks[current] = blocks.get(current, "") + " " + line
        elif current and (line.startswith(" ") or (current.startswith("__") and line.strip())):
            blocks[current] += " " + line
        else:
            current = None
        if line.startswith("Top level:") or line.startswith("The sky ("):
            current = "__top__" if line.startswith("Top level:") else "__sky__"
            blocks[current] = blocks.get(current, "") + " " + line
    return {k: " ".join(v.split()) for k, v in blocks.items()}


def _clause_end(text: str, i: int, seps: tuple[str, ...]) -> int:
    """The end of the clause from ``i``: the first separator outside parentheses and brackets."""
    depth = 0
    for j in range(i, len(text)):
        c = text[j]
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth = max(0, depth - 1)
        elif depth == 0 and any(text.startswith(sep, j) for sep in seps):
            return j + 1
    return len(text)


def _sentence_naming(text: str, key: str) -> str:
    """The clause of ``text`` that names ``key`` in double backticks: from the key to the next
    ', ', '; ' or '. ' outside parentheses; where that says nothing but names (an enumeration
    of keys), the whole sentence."""
    for pattern in (rf"``{re.escape(key)}``", rf"``{re.escape(key)} ?=", rf"``\[{re.escape(key)}\]``"):
        m = re.search(pattern, text)
        if m:
            break
    else:
        return ""
    end = _clause_end(text, m.start(), (", ", "; ", ". "))
    clause = text[m.start():end].strip().rstrip(",;")
    words = [w for w in re.sub(r"``[^`]*``", " ", clause).split() if re.search(r"[a-z]{2}", w)]
    if len(words) < 3:
        cuts = [text.rfind(sep, 0, m.start()) for sep in (". ", "; ")]
        start = max([c + 2 for c in cuts if c >= 0] + [0])
        end = _clause_end(text, m.start(), (". ", ";"))
        clause = text[start:end].strip()
    return clause.replace("``", "`")


# Keys the code reads but no docstring names: the target geometry a scenario converts before
# making a target. Each line here is documentation; a key added to the schema with neither a
# docstring nor a line here fails the build and tests/python/test_docs_reference.py.
KEY_NOTES: dict[str, str] = {
    "targets.label": "The target's name in the ground truth, the figures and `--target` (default: its kind).",
    "targets.halo": "`\"follows\"` (default) or `\"steady\"`: with `\"steady\"` the target's core follows its "
                    "light curve and its share of `optics.halo_fraction` keeps the mean flux.",
    "targets.wx_arcsec_s": "Velocity on the sky [arcsec/s], converted through the plate scale; "
                           "instead of `vx_px_s`.",
    "targets.wy_arcsec_s": "Velocity on the sky [arcsec/s]; instead of `vy_px_s`.",
    "targets.radius_m": "Radius at `distance_m` [m], converted through the optics; instead of "
                        "`radius_px`.",
    "targets.radii_m": "Signed distances along the bar at `distance_m` [m]; instead of `radii_px`.",
    "targets.distance_m": "Distance of the scene from the lens [m], for `radius_m` / "
                          "`radii_m`.",
    "star_field.path": "A table `{t_s, dx_px, dy_px}` of the field's offset [px] on top of its drift "
                       "(`evstwin.targets.FieldPath`): every field-frame target and random star follows it.",
    "targets.t_s": "Times [s] of a position table, strictly increasing, with `x_px` and `y_px` arrays of "
                   "the same length (`evstwin.targets.TabulatedTarget`).",
    "targets.period_s": "Time of one turn [s]; instead of `angular_rate_rad_s`.",
}


def _target_classes() -> dict[str, Any]:
    from evstwin import targets

    return {"static": targets.StaticTarget, "linear": targets.LinearTarget, "circular": targets.CircularTarget,
            "rotating_bar": targets.aligned_rotating_targets, "tabulated": targets.TabulatedTarget,
            "ghost": targets.MirroredTarget}


def _package_modules(package: Any) -> list[Any]:
    """A package and each of its modules (a plain module: itself alone)."""
    import importlib
    import pkgutil

    found = [importlib.import_module(f"{package.__name__}.{m.name}")
             for m in pkgutil.iter_modules(getattr(package, "__path__", []))]
    return [package, *found]


def _all_docstrings(module: Any) -> str:
    """Every docstring of a module (module, classes, functions), as one text."""
    tree = ast.parse(inspect.getsource(module))
    docs = [ast.get_docstring(n) or "" for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef))]
    return " ".join(" ".join(d.split()) for d in docs if d)


def scenario_keys() -> list[ScenarioKey]:
    """Every key of ``evstwin.scenario.SCHEMA`` (and of each target kind), with its documentation."""
    from evstwin import readout, scenario, targets
    from evstwin.optics import Optics
    from evstwin.pixel import PixelParams
    from evstwin.presets import BiasSet
    from evstwin.sky import atmosphere, scene

    blocks = _module_doc_blocks(scenario.__doc__ or "")
    sky_blocks = _module_doc_blocks(scene.__doc__ or "")
    atm_doc = " ".join((atmosphere.__doc__ or "").split())
    pixel = {f.name: f for f in dataclass_fields(PixelParams)}
    optics = {f.name: f for f in dataclass_fields(Optics)}
    readout_doc = " ".join((readout.ReadoutParams.__doc__ or "").split())
    biases = {f.name: f for f in dataclass_fields(BiasSet)}
    scenario_all = " ".join(_all_docstrings(m) for m in _package_modules(scenario))
    targets_all = _all_docstrings(targets)
    target_fields: dict[str, str] = {}
    for kind, obj in _target_classes().items():
        params = inspect.signature(obj).parameters
        for p in params:
            target_fields.setdefault(p, f"parameter `{p}` of `evstwin.targets.{obj.__name__}`")
    sampling_defaults = dict(scenario.DEFAULT_SAMPLING)

    def describe(table: str, key: str) -> tuple[str, str, Any]:
        if table == "pixel" and key in pixel:
            return pixel[key].doc, "`PixelParams` field docstring", pixel[key].default
        if table == "optics" and key in optics:
            return optics[key].doc, "`Optics` field docstring", optics[key].default
        if table == "biases" and key in biases:
            return biases[key].doc, "`BiasSet` field docstring", dataclasses.MISSING
        path = f"{table}.{key}" if table else key
        if path in KEY_NOTES:
            return KEY_NOTES[path], "this page", dataclasses.MISSING
        texts = [(blocks.get(table or "__top__", ""), "`evstwin.scenario` docstring")]
        if table in ("site", "pointing", "star_field", "targets", ""):
            texts.append((sky_blocks.get(table or "start_utc", ""), "`evstwin.sky.scene` docstring"))
            texts.append((blocks.get("__sky__", ""), "`evstwin.scenario` docstring"))
        if table == "atmosphere":
            texts.append((atm_doc, "`evstwin.sky.atmosphere` docstring"))
        if table == "readout":
            texts.append((readout_doc, "`ReadoutParams` docstring"))
        if table == "targets":
            texts.append((targets_all, "`evstwin.targets` docstrings"))
        texts.append((scenario_all, "`evstwin.scenario` docstrings"))
        for text, source in texts:
            s = _sentence_naming(text, key)
            if s:
                return s, source, sampling_defaults.get(key, dataclasses.MISSING) if table == "sampling" \
                    else dataclasses.MISSING
        if table == "targets" and key in target_fields:
            return target_fields[key], "the target's signature", dataclasses.MISSING
        return "", "", dataclasses.MISSING

    def type_name(t: Any) -> str:
        if isinstance(t, dict):
            return "table"
        if t is Any:
            return "any"
        return {str: "string", int: "integer", float: "number", bool: "boolean", list: "array",
                dict: "table"}.get(t, str(t))

    out: list[ScenarioKey] = []
    for top, spec in scenario.SCHEMA.items():
        if isinstance(spec, dict):
            for key, t in spec.items():
                doc, source, default = describe(top, key)
                out.append(ScenarioKey(top, key, type_name(t), default, doc, source))
        elif top == "targets":
            kinds: dict[str, tuple[str, ...]] = dict(scenario.schema._TARGET_KEYS)
            seen: set[str] = set()
            common = ("kind", "label", "frame", "halo", *scenario.schema._BRIGHTNESS_KEYS, *scenario.schema._TARGET_PSF_KEYS)
            for key in common + tuple(k for ks in kinds.values() for k in ks):
                if key in seen:
                    continue
                seen.add(key)
                doc, source, default = describe("targets", key)
                which = sorted(k for k, ks in kinds.items() if key in ks)
                prefix = f"({', '.join(which)}) " if which and key not in common else ""
                out.append(ScenarioKey("targets", key, "", default, prefix + doc if doc else "", source))
        else:
            doc, source, default = describe("", top)
            out.append(ScenarioKey("", top, type_name(spec), default, doc, source))
    return out


def scenario_markdown() -> str:
    keys = scenario_keys()
    lines = ["# Scenario keys", "",
             "Generated from the scenario schema (`evstwin.scenario.SCHEMA`): every key a scenario TOML",
             "file, or `--set key=value`, accepts. Each description is the code's own text: a",
             "dataclass field's docstring (`PixelParams`, `Optics`) or the sentence of the module",
             "docstring that names the key (`evstwin.scenario`, `evstwin.sky.scene`,",
             "`evstwin.sky.atmosphere`). The unit is in the key's name (`_s` seconds, `_hz` hertz,",
             "`_px` pixels, `_ph_s` photons/s...); limits are stated in the descriptions and checked",
             "when a scenario is loaded, a bad value being one `ScenarioError` line naming the key.",
             "Defaults shown are the code's; a preset sets its own `[pixel]` values. How the tables",
             "fit together, with examples: [simulate my lens and camera](../../guides/simulate-lens-camera.md).",
             ""]
    by_table: dict[str, list[ScenarioKey]] = {}
    for k in keys:
        by_table.setdefault(k.table, []).append(k)
    for table, items in by_table.items():
        title = "Top level" if not table else ("`[[targets]]`" if table == "targets" else f"`[{table}]`")
        lines += [f"## {title}", "", "| key | type | default | unit | description | from |", "|---|---|---|---|---|---|"]
        for k in items:
            lines.append(f"| `{k.path}` | {k.type} | {code(fmt_value(k.default))} | {unit_of(k.key)} | "
                         f"{one_line(k.doc)} | {k.source} |")
        lines.append("")
    return "\n".join(lines)


# -- presets ---------------------------------------------------------------------------------------


def _preset_value_md(name: str, value: Any, depth: int) -> list[str]:
    from evstwin.pixel import PixelParams

    if isinstance(value, PixelParams):
        base = PixelParams()
        rows = [f"| `{f.name}` | {code(fmt_value(getattr(value, f.name)))} | {unit_of(f.name)} | "
                f"{'' if getattr(value, f.name) == getattr(base, f.name) else 'yes'} |"
                for f in dataclasses.fields(value)]
        return [f"**{name}** (`PixelParams`; the last column marks a value other than the paper's pixel):", "",
                "| field | value | unit | set by the preset |", "|---|---|---|---|", *rows, ""]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = [f"**{name}** (`{type(value).__name__}`):", ""]
        scalars = []
        nested = []
        for f in dataclasses.fields(value):
            v = getattr(value, f.name)
            inline = isinstance(v, (tuple, list)) and all(isinstance(x, (int, float)) for x in v)
            if (isinstance(v, (tuple, list)) and not inline) or dataclasses.is_dataclass(v):
                nested.append((f.name, v))
            else:
                scalars.append(f"| `{f.name}` | {code(fmt_value(v))} | {unit_of(f.name)} |")
        if scalars:
            out += ["| field | value | unit |", "|---|---|---|", *scalars, ""]
        for n, v in nested:
            out += _preset_value_md(f"{name}.{n}", v, depth + 1)
        return out
    if isinstance(value, (tuple, list)):
        if not value:
            return [f"**{name}**: none", ""]
        out = [f"**{name}**:", ""]
        for item in value:
            if dataclasses.is_dataclass(item):
                out += _preset_value_md(name + " entry", item, depth + 1)
            else:
                out.append(f"- {one_line(str(item))}")
        return out + [""]
    return [f"**{name}**: {one_line(fmt_value(value))}", ""]


def presets_markdown() -> str:
    from evstwin import presets

    lines = ["# Presets", "",
             "Generated from `evstwin.presets.PRESETS`: every field of each `SensorPreset`, with the",
             "sources and assumptions the code carries for its numbers. `[sensor] preset = NAME` in a",
             "scenario, `--preset NAME` on the command line, `evstwin.presets.get_preset(NAME)` in Python.", ""]
    lines += ["| preset | size | description |", "|---|---|---|"]
    for name, p in presets.PRESETS.items():
        size = f"{getattr(p, 'width', '?')} x {getattr(p, 'height', '?')}"
        lines.append(f"| [`{name}`](#preset-{name.replace('_', '-')}) | {size} | "
                     f"{one_line(str(getattr(p, 'description', '')))} |")
    lines.append("")
    for name, p in presets.PRESETS.items():
        lines += [f"(preset-{name.replace('_', '-')})=", f"## `{name}`", ""]
        fields = [f for f in dataclasses.fields(p) if f.name != "name"]
        scalar = [f for f in fields if not isinstance(getattr(p, f.name), (tuple, list))
                  and not dataclasses.is_dataclass(getattr(p, f.name))]
        lines += ["| field | value | unit |", "|---|---|---|"]
        lines += [f"| `{f.name}` | {one_line(fmt_value(getattr(p, f.name)))} | {unit_of(f.name)} |" for f in scalar]
        lines.append("")
        for f in fields:
            if f not in scalar:
                lines += _preset_value_md(f.name, getattr(p, f.name), 0)
    if getattr(presets, "BIAS_SETS", None):
        lines += ["## Bias sets", "",
                  "`[sensor] bias_set = NAME`; the thresholds follow from eq. 8-9. They are the DAVIS pixel's "
                  "bias currents: the Prophesee presets refuse them (their own biases are `[biases] bias_diff_on` "
                  "...), and `bias_set = \"none\"` drops a `base` scenario's set.", "",
                  "| name | I_on [A] | I_off [A] | I_diff [A] | I_pr [A] | I_sf [A] | I_refr [A] | source |",
                  "|---|---|---|---|---|---|---|---|"]
        for n, b in presets.BIAS_SETS.items():
            vals = " | ".join(fmt_value(getattr(b, k)) for k in ("i_on_a", "i_off_a", "i_diff_a", "i_pr_a",
                                                                 "i_sf_a", "i_refr_a"))
            lines.append(f"| `{n}` | {vals} | {one_line(getattr(b, 'source', ''))} |")
        lines.append("")
    return "\n".join(lines)


# -- C++ headers -------------------------------------------------------------------------------------


def header_comment(path: Path) -> str:
    """The comment a header opens with (``//`` lines before the first non-comment line)."""
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        s = line.strip()
        if s.startswith("//"):
            out.append(s.lstrip("/").strip())
        elif s == "" and out:
            out.append("")
        elif s.startswith("#pragma") or s == "":
            if out:
                break
        else:
            break
    return "\n".join(out).strip()


def headers() -> list[Path]:
    return sorted((ROOT / "cpp" / "include" / "evstwin").rglob("*.hpp"))


def cpp_markdown() -> str:
    lines = ["# C++ headers", "",
             "Generated from `cpp/include/evstwin/`: each public header with the comment it opens",
             "with. `#include <evstwin/evstwin.hpp>` includes them all; the CMake target is",
             "`evstwin::evstwin` ([embedding guide](../../guides/cpp-pipeline.md)).", ""]
    for h in headers():
        rel = h.relative_to(ROOT / "cpp" / "include")
        lines += [f"## `{rel}`", "", "```text", header_comment(h) or "(no opening comment)", "```", ""]
    return "\n".join(lines)


# -- event file formats ------------------------------------------------------------------------------


def formats_markdown() -> str:
    import evstwin.io as eio
    from evstwin.io import _registry

    read = set(_registry.supported_read_suffixes())
    write = set(_registry.supported_write_suffixes())
    lines = ["# Event file formats", "",
             "Generated from `evstwin.io`'s registry of formats by suffix and the docstrings of the",
             "modules that read and write them. `evstwin.read_events(path)` and",
             "`evstwin.write_events(path, events, meta)` choose the format by the suffix;",
             "`iter_events` and `open_event_writer` stream any of them.", "",
             "## The event record", "", "```text", ("EVENT_DTYPE = " + str(eio_dtype())), "```", "",
             "`t` in integer microseconds from the start of the simulation, `p` 1 = ON, 0 = OFF, sorted",
             "by `t`; declared once, in `cpp/include/evstwin/event.hpp`, and exported to Python.", "",
             "## Suffixes", "", "| suffix | read | write | module |", "|---|---|---|---|"]
    modules: dict[str, Any] = {}
    for suffix, fmt in _registry.FORMATS.items():
        mod = _format_module(fmt)
        modules[mod.__name__] = mod
        lines.append(f"| `{suffix}` | {'yes' if suffix in read else 'no'} | {'yes' if suffix in write else 'no'} | "
                     f"`{mod.__name__}` |")
    lines.append("")
    from evstwin import EVENT_LABELS

    lines += ["## Per-event labels", "", "Why each event fired (`evstwin.EVENT_LABELS`, `--labels`):", "",
              "| code | name |", "|---|---|"]
    labels = EVENT_LABELS.items() if isinstance(EVENT_LABELS, dict) else enumerate(EVENT_LABELS)
    for c, n in labels:
        lines.append(f"| {c} | `{n}` |")
    lines.append("")
    for name, mod in modules.items():
        lines += [f"## `{name}`", "", "```text", (mod.__doc__ or "").strip() or "(no docstring)", "```", ""]
    del eio
    return "\n".join(lines)


def eio_dtype() -> Any:
    from evstwin import EVENT_DTYPE

    return EVENT_DTYPE.descr if hasattr(EVENT_DTYPE, "descr") else EVENT_DTYPE


def _format_module(fmt: Any) -> Any:
    import importlib

    for attr in ("open_source", "open_encoder"):
        fn = getattr(fmt, attr, None)
        if fn is not None and getattr(fn, "__module__", None):
            return importlib.import_module(fn.__module__)
    raise RuntimeError(f"format {fmt!r} has no reader or writer")


# -- what has no documentation ----------------------------------------------------------------------


def undocumented() -> list[str]:
    """Every CLI option, scenario key and PixelParams field without documentation text."""
    from evstwin.pixel import PixelParams

    missing = []
    for name, help_text, p in cli_commands():
        if not help_text.strip():
            missing.append(f"CLI command `evstwin {name}` has no help")
        for o in cli_options(p, name):
            if not o.help.strip():
                missing.append(f"CLI option `evstwin {name} {o.names}` has no help")
    for k in scenario_keys():
        if not k.doc.strip():
            missing.append(f"scenario key `{k.path}` is named in no docstring")
    for f in dataclass_fields(PixelParams):
        if not f.doc.strip():
            missing.append(f"PixelParams.{f.name} has no docstring")
    return missing


PAGES = {
    "cli": cli_markdown,
    "scenario": scenario_markdown,
    "pixelparams": pixel_markdown,
    "presets": presets_markdown,
    "cpp-headers": cpp_markdown,
    "file-formats": formats_markdown,
}


def write_pages(folder: Path) -> Iterator[Path]:
    """Write every generated page into ``folder`` (only where its text changed, so Sphinx's
    incremental build stays incremental)."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, make in PAGES.items():
        path = folder / f"{name}.md"
        text = make()
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        yield path


def _on_builder_inited(app: Any) -> None:
    from sphinx.errors import ExtensionError

    missing = undocumented()
    if missing:
        raise ExtensionError("undocumented (give each a docstring or help text):\n  " + "\n  ".join(missing))
    list(write_pages(Path(app.srcdir) / "reference" / GENERATED))


def setup(app: Any) -> dict[str, Any]:
    app.connect("builder-inited", _on_builder_inited)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
