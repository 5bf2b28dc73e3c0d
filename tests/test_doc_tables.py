"""The benchmark tables in the docs are the ones bench/doc_tables.py makes from the JSON."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _bench_off_the_path():
    """bench/doc_tables.py puts bench/ on sys.path (it runs as a script there): taken off
    again after each test, or processes spawned later (Dask's workers) would import
    bench/distributed.py as the ``distributed`` package."""
    saved = list(sys.path)
    yield
    sys.path[:] = saved


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


def test_a_changed_value_in_a_sentence_is_caught():
    mod = _module()
    name = next(iter(mod.doc_values.VALUES()))
    good = mod.render(f"x <!-- value:{name} -->?<!-- /value --> y")
    assert good != f"x <!-- value:{name} -->?<!-- /value --> y"
    assert mod.render(good) == good
    with pytest.raises(KeyError, match="no_such_value"):
        mod.render("<!-- value:no_such_value -->1 dB<!-- /value -->")


def test_a_comparison_is_worded_by_its_numbers():
    verdict = _module().doc_values._verdict
    assert verdict([("a", 70.0, 60.0), ("b", 50.0, 40.0)], "cubic") == "cubic is worse on all 2 scenes (by 10.0 dB)"
    assert verdict([("a", 60.0, 70.0)], "cubic") == "cubic is better on all 1 scenes (by 10.0 dB)"
    assert verdict([("a", 60.0, 70.0), ("b", 60.0, 59.0), ("c", 60.0, 60.0)], "x") == (
        "x is better on 1 (by up to 10.0 dB), worse on 1 (by up to 1.0 dB) and the same on 1 of 3 scenes")


def test_every_method_picture_has_its_numbers():
    """docs/methods.md shows the pictures docs/make_images.py draws, whose numbers it quotes
    from the psnr.json written beside them: one entry per picture, and no stale one."""
    guide = ROOT / "docs" / "images" / "guide" / "methods"
    shown = set(re.findall(r"images/guide/methods/(\w+)\.png", (ROOT / "docs" / "methods.md").read_text()))
    numbers = json.loads((guide / "psnr.json").read_text())
    assert shown == set(numbers), (shown ^ set(numbers))
    for name, p in numbers.items():
        assert (guide / f"{name}.png").is_file()
        assert {"base", "base_psnr", "variant_psnr", "base_settings", "variant_settings"} <= set(p), name


#: What may stand before or after a number of decibels written by hand: the bar a test holds.
_BAR = re.compile(r"(≥|>|at least|hold|asks for|above|bar)")


def test_docs_quote_no_measured_decibels_by_hand():
    """A PSNR in a doc's prose comes from a table or value the JSON makes; a hand-written
    one may only be a bar the tests hold ("≥ 40 dB", "holds it to 40 dB")."""
    docs = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    found = []
    for path in docs:
        text = re.sub(r"<!-- table:([\w-]+) -->.*?<!-- /table:\1 -->", "", path.read_text(), flags=re.S)
        text = re.sub(r"<!-- value:[^>]*-->.*?<!-- /value -->", "", text)
        text = re.sub(r"```.*?```", "", text, flags=re.S)
        for m in re.finditer(r"\d[\d.]*\s*dB", text):
            around = text[max(0, m.start() - 25):m.start()] + text[m.end():m.end() + 25]
            if not _BAR.search(around):
                found.append(f"{path.name}: ...{text[max(0, m.start() - 40):m.end() + 10]!r}")
    assert not found, "numbers of dB written by hand (generate them, bench/doc_values.py):\n" + "\n".join(found)
