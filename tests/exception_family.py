"""Every exception class a package defines, found by importing each of its modules.

Shared by the ``test_<package>_errors.py`` of each package (one basename per test module:
the test folders are not packages): a package's exceptions must all derive from that
package's base (``FesdicCoreError``, ``GeoregPluginError``, ``AdapterError``, ``GeoregError``).
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
import types

#: modules not imported by the walk: running them is a side effect (the command line)
SKIPPED = ("__main__",)


def package_modules(package: types.ModuleType) -> list[types.ModuleType]:
    """The package and every module under it, imported (``pkgutil.walk_packages``).

    A module whose import needs a third-party package that is not installed (an optional
    extra) is left out; any other import error is raised.
    """
    modules = [package]
    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        if info.name.rsplit(".", 1)[-1] in SKIPPED:
            continue
        try:
            modules.append(importlib.import_module(info.name))
        except ModuleNotFoundError as err:
            if (err.name or "").split(".")[0] == package.__name__.split(".")[0]:
                raise
    return modules


def exception_classes(package: types.ModuleType) -> dict[str, type]:
    """``{qualified name: class}`` of the ``Exception`` subclasses whose ``__module__`` is in
    ``package`` (found in the namespace of each of its modules)."""
    root = package.__name__
    found = {}
    for module in package_modules(package):
        for _, obj in inspect.getmembers(module, inspect.isclass):
            if (issubclass(obj, Exception)
                    and (obj.__module__ == root or obj.__module__.startswith(root + "."))):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


def outside_family(package: types.ModuleType, base: type) -> list[str]:
    """Names of the exception classes of ``package`` that do not derive from ``base``."""
    return sorted(name for name, cls in exception_classes(package).items()
                  if not issubclass(cls, base))
