"""The generated reference documents everything a user can set: every CLI option, every
scenario key and every ``PixelParams`` field has documentation text in the code, and the
generated pages show it. The generator is ``docs/_ext/evstwin_reference.py`` (the Sphinx build
runs it too, and stops on the same list)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))

import evstwin_reference as ref  # noqa: E402

from evstwin import scenario  # noqa: E402
from evstwin.cli import build_parser  # noqa: E402
from evstwin.pixel import PixelParams  # noqa: E402


def test_everything_a_user_sets_is_documented() -> None:
    assert ref.undocumented() == []


def test_the_walk_reaches_every_cli_option() -> None:
    # Independently of the generator: every option string of every subcommand, from argparse.
    ap = build_parser()
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    expected = {(name, s) for name, p in sub.choices.items() for a in p._actions
                if not isinstance(a, argparse._HelpAction) for s in a.option_strings}
    walked = {(name, s) for name, _, p in ref.cli_commands() for o in ref.cli_options(p, name)
              for s in o.names.split(", ") if s.startswith("-")}
    assert expected == walked
    assert len(expected) > 50  # the parser's commands really were walked


def test_the_walk_reaches_every_scenario_key() -> None:
    expected = set()
    for top, spec in scenario.SCHEMA.items():
        if isinstance(spec, dict):
            expected |= {f"{top}.{k}" for k in spec}
        elif top == "targets":
            expected |= {f"targets.{k}" for ks in scenario.schema._TARGET_KEYS.values() for k in ks}
        else:
            expected.add(top)
    walked = {k.path for k in ref.scenario_keys()}
    assert expected <= walked
    assert {"pixel.theta_on", "optics.psf", "sampling.pre_roll_s", "targets.line1", "pointing.mode"} <= walked


def test_the_walk_reaches_every_pixel_field() -> None:
    names = [f.name for f in ref.dataclass_fields(PixelParams)]
    assert names == [f.name for f in dataclasses.fields(PixelParams)]


def test_a_field_without_a_docstring_is_reported() -> None:
    @dataclasses.dataclass
    class Example:
        documented: float = 1.0
        """A value [s]."""
        bare: float = 2.0

    docs = ref.attribute_docs(Example)
    assert docs == {"documented": "A value [s]."}


def test_a_cli_option_without_help_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    real = ref.cli_commands

    def with_bare_option() -> list[tuple[str, str, argparse.ArgumentParser]]:
        out = real()
        out[0][2].add_argument("--undocumented-option")
        return out

    monkeypatch.setattr(ref, "cli_commands", with_bare_option)
    assert any("--undocumented-option" in m for m in ref.undocumented())


def test_a_scenario_key_no_docstring_names_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    schema = dict(scenario.SCHEMA)
    schema["sampling"] = {**schema["sampling"], "made_up_rate_hz": float}
    monkeypatch.setattr(scenario, "SCHEMA", schema)
    assert "scenario key `sampling.made_up_rate_hz` is named in no docstring" in ref.undocumented()


def test_the_generated_pages_show_the_code_s_own_text(tmp_path: Path) -> None:
    pages = {p.stem: p.read_text(encoding="utf-8") for p in ref.write_pages(tmp_path)}
    assert set(pages) == set(ref.PAGES)
    # the CLI: an option with its help, as the parser has them
    assert "`--bin-width`" in pages["cli"] and "evstwin compare" in pages["cli"]
    # a PixelParams field with its docstring's first words and its C++ default
    assert "| `theta_on` |" in pages["pixelparams"]
    assert f"`{PixelParams().theta_on:.6g}`" in pages["pixelparams"]
    # every preset, with its sources
    from evstwin.presets import PRESETS

    for name, preset in PRESETS.items():
        assert f"## `{name}`" in pages["presets"]
        for source in getattr(preset, "sources", ())[:1]:
            assert ref.one_line(str(source))[:40] in pages["presets"]
    # every public header
    for h in ref.headers():
        assert f"`{h.relative_to(ROOT / 'cpp' / 'include')}`" in pages["cpp-headers"]
    # every suffix the registry reads
    from evstwin.io._registry import supported_read_suffixes

    for suffix in supported_read_suffixes():
        assert f"| `{suffix}` |" in pages["file-formats"]


@pytest.mark.parametrize(("name", "unit"), [("refractory_s", "s"), ("cutoff_hz", "Hz"), ("x0_px", "px"),
                                            ("vx_px_s", "px/s"), ("dark_rate_e_per_s", "e⁻/s"),
                                            ("leak_photocurrent_hz_per_a", "Hz/A"), ("theta_on", "")])
def test_units_follow_the_naming_rule(name: str, unit: str) -> None:
    assert ref.unit_of(name) == unit
