"""Sphinx configuration: `make docs` builds the site into build/docs with -W (warnings are errors)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))  # the docs' own generators, not the package

import accelnav  # noqa: E402  (the installed package: make setup's editable install)

project = "accelnav"
author = "accelnav contributors"
copyright = "accelnav contributors, MIT licence"
release = accelnav.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "myst_parser",
    "accelnav_docs",
]
# quotes and ellipses only: docutils' smart dashes turn "--fixes" in running text into "–fixes", which a
# reader copies into a shell and gets refused (tests/docs/test_docs_build.py scans the built pages for it)
smartquotes_action = "qe"
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build"]
myst_heading_anchors = 3

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False}
napoleon_numpy_docstring = True
napoleon_google_docstring = False

html_theme = "alabaster"
html_static_path = []
