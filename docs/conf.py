"""Sphinx configuration of the georeg documentation.

Build (from the repository root, after ``python -m pip install -e ".[docs]"``)::

    python -m sphinx -W --keep-going -b html docs docs/_build/html

The API reference, the command-line page and the TOML reference are generated at build
time by the local extension ``docs/_ext/georeg_docs.py`` into ``docs/generated/``. The
build needs no network: intersphinx is not used.
"""
from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path[:0] = [str(ROOT), str(DOCS / "_ext")]

import configparser  # noqa: E402

project = "georeg"
author = "the georeg authors"
copyright = "2026, the georeg authors"
_setup = configparser.ConfigParser()
_setup.read(ROOT / "setup.cfg")
release = _setup["metadata"]["version"]
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx_gallery.gen_gallery",
    "myst_parser",
    "georeg_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "**.ipynb_checkpoints", "auto_examples/*.ipynb",
                    "auto_examples/**/*.ipynb"]
templates_path: list[str] = []

# --- autodoc / napoleon (numpydoc docstrings) -------------------------------------------
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_class_signature = "separated"
autosummary_generate = False          # the pages are written by georeg_docs, not stubs
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_preprocess_types = False

# --- MyST (the Markdown pages) ----------------------------------------------------------
myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 3

# --- sphinx-gallery: the examples are slow, they are shown, never run -------------------
sphinx_gallery_conf = {
    "examples_dirs": [str(ROOT / "examples")],
    "gallery_dirs": ["auto_examples"],
    "filename_pattern": r"^$",        # no example is executed
    "plot_gallery": "False",
    "ignore_pattern": r"(__init__\.py|[/\\]challenge[/\\])",
    "download_all_examples": False,
    "within_subsection_order": "FileNameSortKey",
    "remove_config_comments": True,
    "write_computation_times": False,
}

# --- HTML -------------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"georeg {release}"
html_static_path = ["_static"]
html_theme_options = {"navigation_depth": 3, "show_toc_level": 2, "secondary_sidebar_items": ["page-toc"]}
html_show_sourcelink = False


# --- docstrings: the project's "name : meaning" lists -------------------------------------
# Outside the numpydoc sections, the docstrings describe fields as lines ``name : meaning``
# with hanging indents; rendered as reST definition lists (name as term). Data without a
# docstring of its own (a dict, a tuple) would show its type's docstring: dropped.
# A type that is prose (a shape, "name -> array"), not a class name, is shown as a literal
# instead of being cut into cross-references (which would link words like ``name``).
_TYPE_FIELD = re.compile(r"^(\s*:(?:type|vartype|rtype)(?: [^:]+)?:)(.*)$")
_PLAIN_TYPE = re.compile(r"^\s*[A-Za-z_][\w.]*(\s+or\s+[A-Za-z_][\w.]*)*(,\s*optional)?\s*$")
_ITEM = re.compile(r"^(\s*)([A-Za-z_][\w.,* ]*?) : (\S.*)$")


def _definition_lists(app, what, name, obj, options, lines):  # noqa: ANN001
    if what in ("data", "attribute") and lines and "\n".join(lines).strip() == (
            inspect.getdoc(type(obj)) or "").strip():
        lines[:] = []
        return
    for i, line in enumerate(lines):
        field = _TYPE_FIELD.match(line)
        if field and not _PLAIN_TYPE.match(field.group(2)) and "`" not in field.group(2):
            lines[i] = f"{field.group(1)} ``{field.group(2).strip()}``"
    out: list[str] = []
    in_list = False
    for i, line in enumerate(lines):
        match = _ITEM.match(line)
        if match and not line.lstrip().startswith((":", "..")):
            indent, term, text = match.groups()
            if not in_list and out and out[-1].strip():
                out.append("")
            out += [f"{indent}{term}", f"{indent}    {text}"]
            in_list, list_indent = True, len(indent)
            continue
        if in_list and line.strip() and len(line) - len(line.lstrip()) <= list_indent:
            out.append("")
            in_list = False
        if in_list and not line.strip():
            in_list = False
        out.append(line)
    lines[:] = out


# In the numpydoc sections the docstrings often write ``name : what it is`` in prose, where
# numpydoc expects ``name : type``. Before napoleon reads them, such prose (more than four
# words, or a sentence) moves to the description, so it is not cut into a "type".
_SECTIONS = {"Parameters", "Other Parameters", "Returns", "Yields", "Raises", "Attributes",
             "Warns", "Receives"}
_FIELD = re.compile(r"^(\s*)([^\s:][^:]*?) : (\S.*)$")


def _prose_fields(app, what, name, obj, options, lines):  # noqa: ANN001
    out: list[str] = []
    section_indent = None
    for i, line in enumerate(lines):
        following = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() in _SECTIONS and following.strip() and set(following.strip()) == {"-"}:
            section_indent = len(line) - len(line.lstrip())
            out.append(line)
            continue
        match = _FIELD.match(line) if section_indent is not None else None
        if match and len(match.group(1)) == section_indent:
            indent, field, text = match.groups()
            if len(text.split()) > 4 or text.rstrip().endswith("."):
                out += [f"{indent}{field}", f"{indent}    {text}"]
                continue
        out.append(line)
    lines[:] = out


def setup(app):  # noqa: ANN001, ANN201
    app.connect("autodoc-process-docstring", _prose_fields, priority=400)
    app.connect("autodoc-process-docstring", _definition_lists, priority=600)
