"""The examples in the docstrings run, and give what they show (doctest over every module)."""
import doctest
import importlib
import pkgutil

import pytest

PACKAGES = ("fesdic_core", "georeg_plugin", "adapters", "georeg_app", "georeg")


def _modules():
    for name in PACKAGES:
        try:
            package = importlib.import_module(name)
        except ImportError:
            continue
        yield package.__name__
        for info in pkgutil.walk_packages(package.__path__, prefix=f"{name}."):
            if not info.name.endswith("__main__"):          # `python -m georeg_app` runs the CLI
                yield info.name


def _with_examples():
    finder = doctest.DocTestFinder(exclude_empty=True)
    for name in _modules():
        module = importlib.import_module(name)
        tests = [t for t in finder.find(module, name) if t.examples
                 and getattr(t, "filename", None) == getattr(module, "__file__", None)]
        if tests:
            yield pytest.param(name, id=name)


@pytest.mark.parametrize("module_name", list(_with_examples()))
def test_docstring_examples_run(module_name):
    module = importlib.import_module(module_name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, result                # (an example marked +SKIP is not attempted)


def test_a_wrong_example_is_caught():
    def shown_wrong():
        """>>> 1 + 1
        3
        """
    test = doctest.DocTestFinder().find(shown_wrong, "shown_wrong", globs={})[0]
    runner = doctest.DocTestRunner(verbose=False)
    runner.run(test, out=lambda _: None)
    assert runner.failures == 1
