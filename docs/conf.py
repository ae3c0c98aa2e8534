"""Sphinx configuration: MyST pages, the reference generated from the code (``_ext``), autodoc."""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))

import evstwin  # noqa: E402  (the installed package: the API pages document what users import)

project = "evstwin"
author = "the evstwin developers"
copyright = "the evstwin developers, MIT licence"
version = release = evstwin.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "evstwin_reference",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
exclude_patterns = ["_build", "README.md"]
nitpicky = False
suppress_warnings: list[str] = []

autodoc_default_options = {"members": True}
autodoc_typehints = "description"
autodoc_member_order = "bysource"
autodoc_preserve_defaults = True

html_theme = "pydata_sphinx_theme"
html_title = f"evstwin {release}"
html_static_path = ["_static"]
html_css_files = ["evstwin.css"]
html_theme_options = {
    "navbar_align": "left",
    "show_toc_level": 2,
    "navigation_with_keys": False,
    "footer_start": ["copyright"],
    "footer_end": [],
    # the generated tables are wide: they get the whole width
    "secondary_sidebar_items": {
        "index": ["page-toc"], "getting-started": ["page-toc"], "guides/*": ["page-toc"],
        "explanation/*": ["page-toc"], "development/*": ["page-toc"], "reference/index": ["page-toc"],
        "reference/python-api": ["page-toc"], "reference/generated/*": [],
    },
}
html_sidebars = {"index": [], "getting-started": []}
html_show_sourcelink = False


def _docstring_as_text(app, what, name, obj, options, lines):  # noqa: ANN001
    """The project's docstrings are plain text (units in brackets, ``|x|``, hand-made tables),
    not reStructuredText: show them as written, in a literal block, instead of letting docutils
    misread them."""
    if not lines:
        return
    text = list(lines)
    lines[:] = [".. code-block:: text", "   :class: evstwin-docstring", ""] + ["   " + line for line in text] + [""]


def _package_attr_docs(app) -> None:  # noqa: ANN001
    """Give each package that re-exports its submodules' constants (``__all__``) their doc
    comments: autodoc reads a constant's docstring, and decides that it is one to document,
    from the source of the module it documents, here the package's ``__init__``, where it is
    not. The submodule's text is added to the package's (cached) analyzer."""
    import importlib
    import pkgutil

    from sphinx.errors import PycodeError
    from sphinx.pycode import ModuleAnalyzer

    for name in ("evstwin.presets", "evstwin.targets", "evstwin.psf", "evstwin.scenario"):
        package = importlib.import_module(name)
        analyzer = ModuleAnalyzer.for_module(name)
        analyzer.analyze()
        exported = set(getattr(package, "__all__", ()))
        for info in pkgutil.iter_modules(package.__path__):
            try:
                sub = ModuleAnalyzer.for_module(f"{name}.{info.name}")
                sub.analyze()
            except PycodeError:  # pragma: no cover - every submodule here is source
                continue
            for (namespace, attr), doc in sub.attr_docs.items():
                if namespace == "" and attr in exported and ("", attr) not in analyzer.attr_docs:
                    analyzer.attr_docs[("", attr)] = doc
                    analyzer.tagorder.setdefault(attr, len(analyzer.tagorder))


def setup(app):  # noqa: ANN001, ANN201
    app.connect("builder-inited", _package_attr_docs)
    app.connect("autodoc-process-docstring", _docstring_as_text)
