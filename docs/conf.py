"""Sphinx configuration of wholebody's documentation site (``sphinx-build -W docs OUT``)."""

from __future__ import annotations

import wholebody

project = "wholebody"
author = "wholebody developers"
release = version = wholebody.__version__
extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "myst_parser",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build"]
html_theme = "furo"
html_title = "wholebody"
autosummary_generate = True
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_typehints = "description"
autodoc_member_order = "bysource"
napoleon_numpy_docstring = True
napoleon_google_docstring = False
myst_heading_anchors = 3
napoleon_use_ivar = True
