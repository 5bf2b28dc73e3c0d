"""Every Examples section of tetvr's docstrings runs and gives what it shows.

The examples are the first code a reader copies; after a module moves or a function changes,
an example that no longer runs is a defect like any other. (Examples marked
``# doctest: +SKIP`` need files or displays the suite does not have.)
"""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "tetvr"
MODULES = sorted(".".join(("tetvr",) + p.relative_to(PACKAGE).with_suffix("").parts).removesuffix(".__init__")
                 for p in PACKAGE.rglob("*.py") if p.name != "__main__.py")


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    try:
        module = importlib.import_module(name)
    except ImportError as exc:  # an optional dependency (the extras) is missing
        pytest.skip(f"{name} needs {exc.name}: pip install the extra that provides it")
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in finder.find(module, name):
        runner.run(test)
    failed, attempted = runner.summarize(verbose=False)
    assert failed == 0, f"{failed} of {attempted} docstring examples in {name} failed (output above)"
