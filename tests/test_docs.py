"""The README is the front door and the docs hold the rest: size, commands, no history
outside the changelog, and an API reference that covers every exported name."""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import re
import sys
from pathlib import Path

import pytest

from georeg_app.cli import build_parser
from georeg_app.config.measure import MethodConfig
from georeg_app.config.track import DisplacementConfig

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
CHANGELOG = DOCS / "changelog.md"
#: the two commands a fresh clone needs, as CI runs the second one
DEMO_COMMAND = "python -m pip install -e . && georeg demo --out demo_out"
TEST_COMMAND = 'python -m pip install -e ".[test,pyxel,cad]" && python -m pytest -q -n 2 --dist loadfile'
HISTORY = re.compile(r"\b(stop|issue) \d+\b", re.IGNORECASE)


def _doc_pages() -> list[Path]:
    """The hand-written pages of the site (not the build, not the generated pages)."""
    skipped = {"_build", "generated", "auto_examples"}
    return sorted(p for p in DOCS.rglob("*") if p.suffix in (".md", ".rst")
                  and not skipped & set(p.relative_to(DOCS).parts))


@pytest.fixture(scope="module")
def georeg_docs():
    """The docs' local Sphinx extension (docs/_ext/georeg_docs.py); skipped without Sphinx."""
    pytest.importorskip("sphinx")
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        return importlib.import_module("georeg_docs")
    finally:
        sys.path.remove(str(DOCS / "_ext"))


def test_readme_is_short_and_keeps_the_two_commands_on_their_lines() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 220
    assert lines[5] == DEMO_COMMAND
    assert lines[9] == TEST_COMMAND


def test_readme_has_a_quickstart_block() -> None:
    text = README.read_text(encoding="utf-8")
    block = re.search(r"<!-- quickstart -->\n```python\n(.*?)```\n<!-- /quickstart -->", text,
                      re.DOTALL)
    assert block is not None


def test_readme_figure_exists_and_is_small() -> None:
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", README.read_text(encoding="utf-8"))
    assert images
    for image in images:
        path = ROOT / image
        assert path.is_file(), image
        assert path.stat().st_size < 300_000, image


def test_the_history_is_only_in_the_changelog() -> None:
    pages = [README, *_doc_pages()]
    assert CHANGELOG in pages and len(pages) > 10
    offending = {str(p.relative_to(ROOT)): HISTORY.findall(p.read_text(encoding="utf-8"))
                 for p in pages if p != CHANGELOG}
    assert {k: v for k, v in offending.items() if v} == {}
    assert HISTORY.search(CHANGELOG.read_text(encoding="utf-8"))


def test_the_pages_of_the_toctrees_exist() -> None:
    for index in DOCS.rglob("index.rst"):
        if {"_build", "generated", "auto_examples"} & set(index.relative_to(DOCS).parts):
            continue
        text = index.read_text(encoding="utf-8")
        for block in re.findall(r"\.\. toctree::\n((?:   .*\n|\n)+)", text):
            for entry in re.findall(r"^   ([\w/]+)$", block, re.MULTILINE):
                if entry.startswith("auto_examples") or entry.startswith("generated"):
                    continue
                base = DOCS / entry.lstrip("/") if entry.startswith("/") else index.parent / entry
                assert base.with_suffix(".rst").is_file() or base.with_suffix(".md").is_file(), \
                    f"{index.relative_to(DOCS)}: {entry}"


def test_the_api_pages_name_every_exported_name(georeg_docs, tmp_path: Path) -> None:
    written = georeg_docs.write_api_pages(tmp_path)
    modules = georeg_docs.public_modules()
    assert {"fesdic_core", "georeg_plugin", "adapters", "georeg_app"} <= set(modules)
    assert len(modules) > 50
    index = (tmp_path / "index.rst").read_text()
    missing = []
    for name in modules:
        page = tmp_path / f"{name}.rst"
        assert page in written and re.search(rf"^   {re.escape(name)}$", index, re.MULTILINE)
        text = page.read_text()
        assert f".. automodule:: {name}" in text
        for exported in georeg_docs.exported_names(name):
            if not re.search(rf"(?<![\w]){re.escape(exported)}(?![\w])", text):
                missing.append(f"{name}.{exported}")
    assert missing == []


def test_the_cli_page_has_every_subcommand_and_option(georeg_docs) -> None:
    page = georeg_docs.cli_page()
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, subparser in sub.choices.items():
        assert f"``georeg {name}``" in page
        for action in subparser._actions:
            for flag in action.option_strings:
                assert flag in page, (name, flag)


def test_the_toml_reference_has_every_key_and_default(georeg_docs) -> None:
    page = georeg_docs.config_page()
    for cls in (MethodConfig, DisplacementConfig):
        for field in dataclasses.fields(cls):
            assert f"``{field.name}``" in page, field.name
    from georeg_app.config import measure, track
    for module, classes in ((measure, (measure.GeometryConfig, MethodConfig)),
                            (track, (DisplacementConfig,))):
        example = module.__doc__.split("::\n", 1)[1]         # the docstring's complete example
        for cls in classes:
            for field in dataclasses.fields(cls):
                assert re.search(rf"^\s*#? ?{field.name} = ", example, re.MULTILINE), field.name
    default = MethodConfig().max_fixed_point
    assert f"``max_fixed_point``\n     - ``int``\n     - ``{default}``" in page


def test_a_gallery_page_without_a_title_gets_its_first_line_as_title(georeg_docs) -> None:
    page = ".. _sphx_glr_auto_examples_x.py:\n\n\nSummary line of x.\n\nMore text.\n"
    titled = georeg_docs.titled_example(page).split("\n")
    assert titled[3:6] == ["Summary line of x.", "=" * len("Summary line of x."), ""]
    already = ".. _sphx_glr_auto_examples_x.py:\n\nTitle\n=====\n\nText.\n"
    assert georeg_docs.titled_example(already) == already


def test_the_docs_build_is_in_ci_after_the_test_command() -> None:
    lines = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    test_line = lines.index(TEST_COMMAND)
    docs = [i for i, line in enumerate(lines) if "sphinx" in line and "-W" in line]
    assert docs and docs[0] > test_line
