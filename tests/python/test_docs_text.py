"""The README and the documentation pages as a user meets them: short landing page, the test
command CI runs, no path outside the repository, every figure made by the figure script,
and the scenarios the guides show load."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md") if "generated" not in p.parts and "_build" not in p.parts)


def test_the_readme_is_a_landing_page() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 200
    text = "\n".join(lines)
    for part in ("## Two commands", "## Quick start", "## Presets", "## Documentation", "## Citing", "## Licence"):
        assert part in text
    assert "Event-based Vision Sensor Physics-Based Digital Twin for Tuning SSA Use" in text


def test_ci_runs_exactly_the_readme_s_test_command() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()[-1]
    blocks = re.findall(r"```bash\n(.*?)\n```", readme, re.S)
    assert ci in blocks, "the last line of .ci/run is not one of the README's bash blocks"
    assert "python -m pytest" in ci and "sphinx -W" in ci


def _user_facing_files() -> list[Path]:
    files = [ROOT / "README.md", *PAGES]
    files += sorted((ROOT / "python" / "evstwin").rglob("*.py")) + sorted((ROOT / "python" / "evstwin").rglob("*.toml"))
    files += sorted((ROOT / "cpp" / "include").rglob("*.hpp")) + sorted((ROOT / "cpp" / "examples").rglob("*"))
    return [f for f in files if f.is_file()]


@pytest.mark.parametrize("needle", ["../shared", "shared/data", "shared/seed", "DESIGN.md"])
def test_no_user_facing_text_names_a_path_outside_the_repository(needle: str) -> None:
    offenders = [str(f.relative_to(ROOT)) for f in _user_facing_files() if needle in f.read_text(encoding="utf-8")]
    assert offenders == []


def _images(page: Path) -> list[Path]:
    text = page.read_text(encoding="utf-8")
    return [(page.parent / m).resolve() for m in re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", text)]


def test_every_figure_the_pages_show_exists_and_is_made_by_the_figure_script() -> None:
    sys.path.insert(0, str(DOCS))
    try:
        import make_figures
    finally:
        sys.path.remove(str(DOCS))
    made = {f.name for f in make_figures.figures(workers=1)}
    shown = {img for page in [ROOT / "README.md", *PAGES] for img in _images(page)}
    assert shown, "no figure found: the pattern is wrong"
    for img in shown:
        assert img.exists(), f"missing figure {img}"
        assert img.parent == DOCS / "figures" and img.name in made, f"{img.name} is made by no command"
    on_disk = {p.name for p in (DOCS / "figures").glob("*.png")}
    assert on_disk == made, "docs/figures holds a figure the script does not make, or lacks one it does"
    for name in on_disk:
        assert (DOCS / "figures" / name).stat().st_size < 1 << 20


def _scenario_examples() -> list[tuple[str, str]]:
    out = []
    for page in PAGES:
        for block in re.findall(r"```toml\n(.*?)\n```", page.read_text(encoding="utf-8"), re.S):
            if re.search(r"^(base|preset) *=", block, re.M) and "[[targets]]" in block or block.startswith("base"):
                out.append((page.name, block))
    return out


@pytest.mark.parametrize(("page", "toml_text"), _scenario_examples())
def test_the_scenarios_the_guides_show_load(page: str, toml_text: str, tmp_path: Path) -> None:
    from evstwin import scenario

    path = tmp_path / "example.toml"
    path.write_text(toml_text, encoding="utf-8")
    loaded = scenario.load(path)
    assert loaded["sensor"]["preset"]
    # and builds: a key that loads can still be refused with the rest (a DAVIS bias set on the IMX636)
    built = scenario.build(path, duration_s=0.05)
    assert built.params.theta_on > 0
