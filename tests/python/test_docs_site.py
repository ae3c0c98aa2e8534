"""The built documentation site, opened in headless Chromium: each top-level page renders
with its navigation and without a missing image.

The site is what ``python -m sphinx -W --keep-going -b html docs build/docs`` builds (the
step before pytest in the test command); Chromium is the Debian package ``chromium``. Without
either the test is skipped, saying which is missing. ``EVSTWIN_SCREENSHOTS=DIR`` keeps the
screenshots for a person to look at.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SITE = ROOT / "build" / "docs"
TOP_PAGES = [
    "index.html",
    "getting-started.html",
    "guides/index.html",
    "reference/index.html",
    "explanation/index.html",
    "development/index.html",
]

# Appended to a copy of each page: once everything has loaded, it writes what it found into
# an element that --dump-dom then shows. An image is missing when the browser could not
# decode it (naturalWidth 0); the navigation is the theme's top bar with a link to each part.
CHECK_SCRIPT = """
<script>
window.addEventListener("load", function () {
  var imgs = Array.from(document.images);
  var broken = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); })
                   .map(function (i) { return i.getAttribute("src"); });
  var nav = document.querySelector("nav.navbar-nav, .bd-header nav, header nav");
  var links = nav ? Array.from(nav.querySelectorAll("a")).map(function (a) { return a.textContent.trim(); }) : [];
  var out = document.createElement("pre");
  out.id = "evstwin-check";
  out.textContent = JSON.stringify({images: imgs.length, broken: broken, nav_links: links,
                                    h1: (document.querySelector("h1") || {}).textContent || ""});
  document.body.appendChild(out);
});
</script>
"""


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def _run(browser: str, *args: str) -> subprocess.CompletedProcess[str]:
    cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
           "--disable-dev-shm-usage", "--no-first-run", "--virtual-time-budget=10000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not (SITE / "index.html").exists():
        pytest.skip(f"no built site at {SITE}: run python -m sphinx -W --keep-going -b html docs build/docs")
    if _chromium() is None:
        pytest.skip("no headless Chromium (Debian: apt-get install chromium)")
    copy = tmp_path_factory.mktemp("site") / "docs"
    shutil.copytree(SITE, copy)
    return copy


@pytest.mark.parametrize("page", TOP_PAGES)
def test_top_level_page_renders_with_navigation_and_its_images(site: Path, page: str,
                                                               tmp_path: Path) -> None:
    import json

    browser = _chromium()
    assert browser is not None
    html = site / page
    checked = html.with_name("_check_" + html.name)
    checked.write_text(html.read_text(encoding="utf-8").replace("</body>", CHECK_SCRIPT + "</body>"),
                       encoding="utf-8")
    shot_dir = Path(os.environ.get("EVSTWIN_SCREENSHOTS", tmp_path))
    shot_dir.mkdir(parents=True, exist_ok=True)
    shot = shot_dir / (page.replace("/", "_").replace(".html", ".png"))
    shot.unlink(missing_ok=True)
    # one browser run: the DOM after load (with the check's result) and the screenshot
    dom = _run(browser, "--dump-dom", f"--screenshot={shot}", "--window-size=1280,1000", checked.as_uri())
    m = re.search(r'<pre id="evstwin-check"[^>]*>(.*?)</pre>', dom.stdout, re.S)
    assert m, f"{page}: the page did not finish loading in Chromium: {dom.stderr[-500:]}"
    found = json.loads(m.group(1).replace("&quot;", '"').replace("&amp;", "&"))
    assert found["broken"] == [], f"{page}: images that did not load: {found['broken']}"
    for part in ("Getting started", "Guides", "Reference", "Explanation", "Development"):
        assert part in found["nav_links"], f"{page}: no '{part}' in the navigation bar {found['nav_links']}"
    assert found["h1"].strip(), f"{page}: no title"
    if page in ("index.html", "getting-started.html"):
        assert found["images"] >= 1, f"{page}: its figure is not on the page"

    assert shot.exists(), f"{page}: no screenshot: {dom.stderr[-500:]}"
    import matplotlib.image

    pixels = np.asarray(matplotlib.image.imread(shot))[..., :3]
    assert pixels.shape[:2] == (1000, 1280)
    # A rendered page has text and a header bar: not one flat colour.
    assert float(pixels.std()) > 0.02, f"{page}: the screenshot is blank"
