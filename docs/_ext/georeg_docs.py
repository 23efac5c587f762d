"""Pages of the documentation generated at build time: the API reference, the command
line and the TOML configuration reference.

Each page is computed from the code itself, so it cannot drift from it:

- the API reference walks every module of the packages and lists the names of its
  ``__all__`` (a name defined in the module is documented there with autodoc, a name the
  module re-exports links to the module that defines it);
- the command-line page walks :func:`georeg_app.cli.build_parser` (every subcommand, every
  option, its default and help);
- the configuration reference reads the dataclasses the TOML readers fill
  (:mod:`georeg_app.config.measure`, :mod:`georeg_app.config.track`: keys, types, defaults)
  and the complete examples of their module docstrings.

``setup(app)`` writes the pages into ``docs/generated/`` when the build starts;
``tests/test_docs.py`` calls the same functions into a temporary folder.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import importlib.util
import inspect
import pkgutil
import textwrap
import types
import typing
from pathlib import Path

PACKAGES = ("fesdic_core", "georeg_plugin", "adapters", "georeg_app", "georeg")

#: modules that are not part of the public API (compiled kernel, ``python -m`` entry)
SKIPPED = ("__main__", "_bspline")


def public_modules(packages: tuple[str, ...] = PACKAGES) -> list[str]:
    """Every importable module of ``packages`` (those that exist), parents first."""
    names: list[str] = []
    for package in packages:
        if importlib.util.find_spec(package) is None:     # e.g. ``georeg`` before it exists
            continue
        root = importlib.import_module(package)
        names.append(package)
        if hasattr(root, "__path__"):
            for info in pkgutil.walk_packages(root.__path__, package + "."):
                if info.name.rsplit(".", 1)[-1] in SKIPPED:
                    continue
                names.append(info.name)
    return names


def exported_names(module_name: str) -> list[str]:
    """The ``__all__`` of a module (empty when it has none)."""
    return list(getattr(importlib.import_module(module_name), "__all__", ()))


def _home(name: str, obj: object, module_name: str, modules: list[str]) -> str:
    """The module whose page documents ``obj`` (exported as ``name`` by ``module_name``)."""
    if isinstance(obj, types.ModuleType):
        return obj.__name__
    defined = getattr(obj, "__module__", None)
    if isinstance(obj, (type, types.FunctionType)) and defined in modules \
            and name in exported_names(defined):
        return defined
    module = importlib.import_module(module_name)
    if not hasattr(module, "__path__"):
        return module_name                       # a plain module documents its own names
    for candidate in modules:                    # data re-exported by a package
        if candidate.startswith(module_name + ".") and name in exported_names(candidate):
            sub = importlib.import_module(candidate)
            if getattr(sub, name, None) is obj and not hasattr(sub, "__path__"):
                return candidate
    return module_name


def summary(obj: object) -> str:
    """The first paragraph of the docstring of a module, class or function, on one line."""
    if not isinstance(obj, (types.ModuleType, type, types.FunctionType)):
        return ""
    doc = inspect.getdoc(obj) or ""
    return " ".join(doc.split("\n\n", 1)[0].split())


def _link_table(rows: list[tuple[str, object]]) -> list[str]:
    lines = [".. list-table::", "   :widths: 35 65", ""]
    for link, obj in rows:
        lines += [f"   * - {link}", f"     - {summary(obj) or ' '}"]
    return lines + [""]


def _title(text: str, mark: str = "=") -> str:
    return f"{text}\n{mark * len(text)}\n"


def module_page(module_name: str, modules: list[str]) -> str:
    """The reST source of one module's API page."""
    module = importlib.import_module(module_name)
    names = exported_names(module_name)
    own, linked, submodules = [], [], []
    for name in names:
        obj = getattr(module, name)
        home = _home(name, obj, module_name, modules)
        if isinstance(obj, types.ModuleType):
            submodules.append((name, obj))
        elif home == module_name:
            own.append(name)
        else:
            linked.append((name, home))
    lines = [_title(f"``{module_name}``"), f".. automodule:: {module_name}", "   :no-members:", ""]
    if submodules:
        lines += [_title("Subpackages and modules", "-"),
                  *_link_table([(f":mod:`{name} <{sub.__name__}>`", sub)
                                for name, sub in submodules])]
    if linked:
        lines += [_title("Exported names", "-"),
                  "Defined in the modules linked; exported here too.", "",
                  *_link_table([(f":obj:`{name} <{home}.{name}>`", getattr(module, name))
                                for name, home in linked])]
    if own:
        lines += [_title("Defined here", "-"), f".. currentmodule:: {module_name}", ""]
        for name in own:
            obj = getattr(module, name)
            if inspect.isclass(obj):
                directive = "autoclass"
                options = ["   :members:", "   :show-inheritance:"]
            elif callable(obj) and not isinstance(obj, typing.TypeVar):
                directive, options = "autofunction", []
            else:
                directive, options = "autodata", ["   :no-value:"]
            lines += [f".. {directive}:: {name}", *options, ""]
    if not names:
        lines += ["This module exports no names of its own (no ``__all__``).", ""]
    return "\n".join(lines)


def write_api_pages(out_dir: Path, packages: tuple[str, ...] = PACKAGES) -> list[Path]:
    """Write ``api/index.rst`` and one ``api/<module>.rst`` per module; return the paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    modules = public_modules(packages)
    written = []
    for name in modules:
        path = out_dir / f"{name}.rst"
        _write(path, module_page(name, modules))
        written.append(path)
    index = [_title("API reference"),
             "Every module of the packages, with the names of its ``__all__``. The package",
             "layout (which subpackage holds which step of the paper's pipeline) is in each",
             "package's docstring, at the top of its page.", ""]
    for package in packages:
        members = [m for m in modules if m == package or m.startswith(package + ".")]
        if not members:
            continue
        index += [_title(f"``{package}``", "-"), ".. toctree::", "   :maxdepth: 1", ""]
        index += [f"   {m}" for m in members] + [""]
    index_path = out_dir / "index.rst"
    _write(index_path, "\n".join(index))
    return [index_path, *written]


# --------------------------------------------------------------------------- command line

def _option_row(action: argparse.Action) -> tuple[str, str]:
    if action.option_strings:
        flags = ", ".join(action.option_strings)
        if action.nargs != 0:
            flags += " " + (action.metavar or action.dest.upper())
    else:
        flags = action.metavar or action.dest
    help_text = (action.help or "").replace("%(prog)s", "georeg")
    if action.default not in (None, False, argparse.SUPPRESS) and action.nargs != 0 \
            and "default" not in help_text:
        help_text += f" (default: {action.default})"
    return flags, help_text


def _options_table(parser: argparse.ArgumentParser) -> list[str]:
    rows = [_option_row(a) for a in parser._actions
            if not isinstance(a, argparse._SubParsersAction)]
    lines = [".. list-table::", "   :header-rows: 1", "   :widths: 30 70", "",
             "   * - argument", "     - meaning"]
    for flags, text in rows:
        lines += [f"   * - ``{flags}``", f"     - {_escape(text) or ' '}"]
    return lines + [""]


def _escape(text: str) -> str:
    return text.replace("*", r"\*").replace("`", r"\`").replace("|", r"\|")


def cli_page() -> str:
    """The reST source of the command-line page, from :func:`georeg_app.cli.build_parser`."""
    from georeg_app.cli import build_parser
    parser = build_parser()
    lines = [".. This page is generated from georeg_app.cli.build_parser() at build time.", "",
             _title("Command line: ``georeg``"), _escape(parser.description or ""), "",
             ".. code-block:: text", "", textwrap.indent(parser.format_usage().strip(), "   "), "",
             _title("Global options", "-"), *_options_table(parser)]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {choice.dest: choice.help for choice in sub._choices_actions}
    for name, subparser in sub.choices.items():
        lines += [_title(f"``georeg {name}``", "-"), _escape(helps.get(name) or ""), "",
                  ".. code-block:: text", "",
                  textwrap.indent(subparser.format_usage().strip(), "   "), "",
                  *_options_table(subparser)]
    return "\n".join(lines)


# --------------------------------------------------------------------------- configuration

def _type_name(annotation: object) -> str:
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__",
                                                                   str(annotation))
    return text.replace("typing.", "").replace("pathlib.", "")


def _default(field: dataclasses.Field) -> str:
    if field.default is not dataclasses.MISSING:
        value = field.default
    elif field.default_factory is not dataclasses.MISSING:
        value = field.default_factory()
    else:
        return "required"
    if isinstance(value, bool):
        return "``true``" if value else "``false``"
    if isinstance(value, str):
        return f'``"{value}"``'
    if isinstance(value, tuple):
        return "``[" + ", ".join(f'"{v}"' if isinstance(v, str) else f"{v:g}" for v in value) + "]``"
    return "not set" if value is None else f"``{value:g}``" if isinstance(value, float) \
        else f"``{value}``"


def _section_table(section: str, cls: type, skip: tuple[str, ...] = ()) -> list[str]:
    lines = [f"``[{section}]``", "", ".. list-table::", "   :header-rows: 1",
             "   :widths: 25 35 40", "", "   * - key", "     - type", "     - default"]
    for field in dataclasses.fields(cls):
        if field.name in skip:
            continue
        lines += [f"   * - ``{field.name}``", f"     - ``{_type_name(field.type)}``",
                  f"     - {_default(field)}"]
    return lines + [""]


def _docstring_example(module: types.ModuleType) -> list[str]:
    """The complete TOML example of a reader's docstring (the indented block after ``::``)."""
    doc = inspect.getdoc(module) or ""
    block = doc.split("::\n", 2)[-1]             # the last literal block: the example
    example = textwrap.dedent("\n".join(line for line in block.splitlines()))
    return [".. code-block:: toml", "", textwrap.indent(example.strip("\n"), "   "), ""]


def config_page() -> str:
    """The reST source of the TOML reference, from the readers' dataclasses and docstrings."""
    from georeg_app.calibrate import config as calibrate
    from georeg_app.config import measure, track
    lines = [".. This page is generated from georeg_app.config.measure, .track and "
             "georeg_app.calibrate.config at build time.",
             "", _title("TOML reference"),
             "Keys, types and defaults are read from the dataclasses that the readers",
             "(:func:`georeg_app.config.measure.load_config`,",
             ":func:`georeg_app.config.track.load_track_config`) fill; a key without a default is",
             "required. Unknown keys, wrong types, missing keys and missing files are errors that",
             "name the file, the section and the key. The types are those of the fields the",
             "readers fill: ``str`` is a TOML string, ``Path`` a string naming a file (relative",
             "to the configuration's folder), ``tuple[...]`` an array, ``bool`` ``true`` or",
             "``false``, ``ndarray`` an array of numbers.", "",
             _title("``georeg measure`` and ``georeg compare``", "-"),
             *_docstring_example(measure),
             *_section_table("images", measure.ImagesConfig),
             *_section_table("cameras", measure.CamerasConfig),
             "``[[landmarks]]`` (one table per landmark; also accepted as ``[[cameras.landmarks]]``)",
             "", *_section_table("landmarks", measure.Landmark)[2:],
             *_section_table("geometry", measure.GeometryConfig),
             *_section_table("method", measure.MethodConfig),
             *_section_table("output", measure.OutputConfig),
             f"``[output] dir`` defaults to ``\"{measure.DEFAULT_OUTPUT_DIR}\"``; ``--out`` "
             "overrides it.", "",
             _title("``georeg track``", "-"),
             "The sections of ``georeg measure`` (``[images]`` is the reference pair), plus:", "",
             *_docstring_example(track),
             *_section_table("series", track.SeriesConfig),
             *_section_table("displacement", track.DisplacementConfig),
             f"``[output] dir`` defaults to ``\"{track.DEFAULT_TRACK_DIR}\"``.", "",
             "Allowed values: ``[method] name`` one of "
             + ", ".join(f'``"{v}"``' for v in measure.METHOD_NAMES)
             + "; ``[geometry] kind`` one of "
             + ", ".join(f'``"{v}"``' for v in measure.GEOMETRY_KINDS)
             + "; ``[method] normalisation`` one of "
             + ", ".join(f'``"{v}"``' for v in measure.NORMALISATIONS)
             + "; ``[cameras]`` exactly one of "
             + ", ".join(f"``{v}``" for v in measure.CAMERA_SOURCES)
             + "; ``[displacement] method`` one of "
             + ", ".join(f'``"{v}"``' for v in track.DISPLACEMENT_METHODS) + ".", "",
             _title("``georeg calibrate``", "-"),
             *_docstring_example(calibrate),
             "``[target]`` fills :class:`fesdic_core.cameras.targets.target.Target`, ``[model]``",
             ":class:`fesdic_core.cameras.targets.calibration.CalibrationModel`; ``[compare]`` takes",
             "one key of ``[cameras]`` (no landmarks), ``[check]`` a speckle pair ``cam0``, ``cam1``.",
             "", *_section_table("target", calibrate.Target),
             *_section_table("model", calibrate.CalibrationModel),
             f"``[output] dir`` defaults to ``\"{calibrate.DEFAULT_CALIBRATION_DIR}\"``.", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- Sphinx

def _write(path: Path, text: str) -> None:
    """Write only when the text changed (Sphinx then rebuilds only what changed)."""
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def generate(docs_dir: Path) -> None:
    """Write every generated page under ``docs_dir/generated``."""
    out = docs_dir / "generated"
    out.mkdir(exist_ok=True)
    write_api_pages(out / "api")
    _write(out / "cli.rst", cli_page())
    _write(out / "config_reference.rst", config_page())


def titled_example(text: str) -> str:
    """A sphinx-gallery page whose example docstring has no reST title: its first line
    underlined (the examples' docstrings open with a one-line summary, used by ``--help``)."""
    lines = text.split("\n")
    for i, line in enumerate(lines):
        if line.startswith(".. _sphx_glr_") and line.endswith(".py:"):
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            if j + 1 < len(lines) and lines[j].strip() and not (
                    lines[j + 1].strip() and set(lines[j + 1].strip()) <= set("=-~^*#")):
                lines.insert(j + 1, "=" * len(lines[j]))
                lines.insert(j + 2, "")
            break
    return "\n".join(lines)


def _source_read(app, docname: str, source: list[str]) -> None:  # noqa: ANN001
    if docname.startswith("auto_examples/"):
        source[0] = titled_example(source[0])


def _resolve(target: str) -> object | None:
    """The object a dotted name points to (``a.b.Name.method``), or None."""
    parts = target.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        return obj
    return None


def _missing_reference(app, env, node, contnode):  # noqa: ANN001, ANN201
    """A name re-exported by a package (``fesdic_core.solve.StepSolver``) links to the page
    of the module that defines it (``fesdic_core.solve.solvers.StepSolver``)."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    module = node.get("py:module")
    candidates = [target] + ([f"{module}.{target}"] if module else [])
    for candidate in candidates:
        if not candidate.split(".")[0] in PACKAGES:
            continue
        obj = _resolve(candidate)
        home, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
        if isinstance(home, str) and isinstance(qualname, str) and f"{home}.{qualname}" != target:
            return env.get_domain("py").resolve_xref(env, node["refdoc"], app.builder,
                                                     node["reftype"], f"{home}.{qualname}",
                                                     node, contnode)
    return None


def setup(app):  # noqa: ANN001, ANN201 (Sphinx's extension entry point)
    app.connect("missing-reference", _missing_reference)
    app.connect("builder-inited", lambda app: generate(Path(app.srcdir)))
    app.connect("source-read", _source_read)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
