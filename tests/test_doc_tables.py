"""The benchmark tables in the docs are the ones bench/doc_tables.py makes from the JSON."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("doc_tables", ROOT / "bench" / "doc_tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_doc_tables_agree_with_the_benchmark_json():
    mod = _module()
    blocks = 0
    for path in mod.DOCS:
        text = path.read_text()
        blocks += len(mod._BLOCK.findall(text))
        assert mod.render(text) == text, f"{path.name}: run python bench/doc_tables.py --write"
    assert blocks >= 2  # the tables exist somewhere


def test_a_changed_number_is_caught():
    mod = _module()
    text = "x\n<!-- table:raymarch_stages -->\n| made up |\n<!-- /table:raymarch_stages -->\n"
    assert mod.render(text) != text
