"""The house rules of the layout (docs/architecture.md), checked on the source tree.

* The layers import only downward and no two modules or packages of one package import each
  other: the import-linter contracts in pyproject.toml, run as CI runs them (``lint-imports``).
* No module over 600 lines; no function over 80 lines unless its docstring says why it is kept
  whole (a sentence starting "Kept whole:").
* Only ``tetvr.gl`` imports moderngl, and ``import tetvr`` loads no GL and no package above the
  facade.
"""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "tetvr"
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80
MODULES = sorted(PACKAGE.rglob("*.py"))


def _lint_imports() -> str:
    exe = Path(sys.executable).with_name("lint-imports")
    if exe.exists():
        return str(exe)
    found = shutil.which("lint-imports")
    if found is None:
        pytest.fail("lint-imports (import-linter) is not installed: it is in the test extras, "
                    'pip install -e ".[test]"')
    return found


def test_the_import_contracts_hold():
    run = subprocess.run([_lint_imports(), "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    assert "2 kept, 0 broken" in run.stdout, run.stdout[-2000:]


def test_the_contracts_name_every_package():
    # A new sub-package has to be placed in a layer: one left out is checked by nothing.
    text = (ROOT / "pyproject.toml").read_text()
    packages = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))
    assert packages, "no sub-packages found"
    for name in packages:
        assert f'"tetvr.{name}' in text or f"| tetvr.{name}" in text, f"tetvr.{name} is in no layer"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_module_and_function_sizes(path: Path):
    lines = path.read_text().count("\n")
    assert lines <= MAX_MODULE_LINES, f"{path.relative_to(ROOT)} has {lines} lines (limit {MAX_MODULE_LINES})"
    tree = ast.parse(path.read_text())
    long = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = node.end_lineno - node.lineno + 1  # type: ignore[operator]
            if n > MAX_FUNCTION_LINES and "Kept whole:" not in (ast.get_docstring(node) or ""):
                long.append(f"{node.name} ({n} lines, line {node.lineno})")
    assert not long, (f"{path.relative_to(ROOT)}: functions over {MAX_FUNCTION_LINES} lines without a "
                      f"'Kept whole:' reason in their docstring: {', '.join(long)}")


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
    return found


def test_only_the_gl_package_imports_moderngl():
    outside = [str(p.relative_to(ROOT)) for p in MODULES
               if "gl" not in p.relative_to(PACKAGE).parts[:1] and any(m.split(".")[0] == "moderngl" for m in _imports(p))]
    assert not outside, f"moderngl imported outside tetvr/gl: {outside}"


def test_import_tetvr_loads_no_gl_and_nothing_above_the_facade():
    code = ("import sys, tetvr; "
            "print(' '.join(sorted(m for m in sys.modules if m == 'moderngl' or m.startswith(('tetvr.gl', "
            "'tetvr.cluster', 'tetvr.apps.viewer', 'tetvr.apps.cli')))))")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == [], f"import tetvr loaded {run.stdout.split()}"
