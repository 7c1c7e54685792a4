"""Sphinx configuration of the simfab documentation (``sphinx-build -W docs docs/_build/html``)."""

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "_ext"))
sys.path.insert(0, os.path.abspath(os.path.join(HERE, "..")))
sys.path.insert(0, os.path.abspath(os.path.join(HERE, "..", "examples")))  # the gallery's _common helpers
os.environ.setdefault("MPLBACKEND", "Agg")

project = "simfab"
author = "simfab contributors"
copyright = "simfab contributors"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx_gallery.gen_gallery",
    "myst_parser",
    "scenekeys",
    "apimodule",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
# docs/decisions.md and docs/benchmarks.md are design and measurement logs kept beside the site (linked
# from it, not rendered); _build is the output
exclude_patterns = ["_build", "decisions.md", "auto_examples/*.ipynb", "auto_examples/*.py",
                    "auto_examples/*.zip"]

napoleon_google_docstring = True
napoleon_numpy_docstring = False
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"show-inheritance": False}
myst_heading_anchors = 3
# the moved measurement pages keep links to repository files (scenes, tools): they are not pages
suppress_warnings = ["myst.xref_missing"]

sphinx_gallery_conf = {
    "examples_dirs": os.path.join("..", "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"_common\.py",
    "abort_on_example_error": True,
    "download_all_examples": False,
    "within_subsection_order": "FileNameSortKey",
    "remove_config_comments": True,
    "image_scrapers": ("matplotlib",),
}

html_theme = "alabaster"
html_title = "simfab"
html_static_path = []
