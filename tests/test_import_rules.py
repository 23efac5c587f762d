"""The dependency rule of the architecture: core and plugin never import each other.

The non-invasive claim is structural: ``fesdic_core`` (the legacy FE-DIC code) and
``georeg_plugin`` (the spline spaces and operators) must not know each other; only
``adapters`` (and the application on top of it) import both. Nothing imports the Python
front ``georeg``, which may import all four.
"""
import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
BANNED = {
    "fesdic_core": {"georeg_plugin", "adapters", "georeg_app", "georeg"},
    "georeg_plugin": {"fesdic_core", "adapters", "georeg_app", "georeg"},
    "adapters": {"georeg_app", "georeg"},
    "georeg_app": {"georeg"},          # the Python front (georeg) sits on top of everything
}


def _imported_roots(path: pathlib.Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name.split(".")[0]) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module.split(".")[0]))
    return found


@pytest.mark.parametrize("package", sorted(BANNED))
def test_package_does_not_import_banned_packages(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"package {package} has no modules"
    bad = [f"{p.relative_to(ROOT)}:{line} imports {name}"
           for p in files for line, name in _imported_roots(p) if name in BANNED[package]]
    assert not bad, "\n".join(bad)


def test_rule_checker_detects_a_violation(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("import os\nfrom georeg_plugin.levels.operators import x\n")
    assert (2, "georeg_plugin") in _imported_roots(probe)
