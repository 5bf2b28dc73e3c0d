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


def test_first_hour_values_say_what_the_json_holds(monkeypatch):
    """The install and notebook times in README.md and docs/quickstart.md come from
    bench/results/first_hour.json: a package built from source is named, every notebook is
    listed, and no value is written by hand where the docs quote them."""
    values = _module().doc_values
    machine = {"cpu_count": 2}
    run = {"total_s": 600.0, "cpu_s": 90.0, "built_from_source": ["slowpkg"], "largest_downloads_mb": {"vtk": 140.0}}
    install = {"machine": machine, "loadavg_before": [3.0], "created": "2026-11-28 00:00 UTC",
               "no_cache": run, "full_cache": {**run, "total_s": 60.0},
               "installed_size": {"base_mb": 200.0, "all_mb": 1500.0,
                                  "extras": {"compare": {"only_this_extra_mb": 400.0},
                                             "test": {"only_this_extra_mb": 5.0},
                                             "notebooks": {"only_this_extra_mb": 0.0}}}}
    book = {"wall_s": 12.0, "kernel_cpu_s": 8.0, "cold_shader_cache": {"wall_s": 20.0}}
    notebooks = {"machine": machine, "loadavg_before": [3.0], "created": "2026-11-28 00:00 UTC", "repeats": 2,
                 "notebooks": {"01_a.ipynb": book, "02_b.ipynb": {**book, "wall_s": 31.0}}}
    monkeypatch.setattr(values, "_first_hour", {"install": install, "notebooks": notebooks}.__getitem__)
    text = values.install_time()
    assert text.startswith("10.0 min with pip's cache off and 60 s with it full")
    assert "built from source: slowpkg" in text
    sizes = values.extras_sizes()
    assert sizes.index("`compare` adds 400 MB") < sizes.index("`test` adds 5 MB")
    assert "(`notebooks` needs nothing" in sizes
    assert values.notebook_times().startswith("12 s, 31 s (01–02, best of 2 runs")
    for doc, name in ((ROOT / "README.md", "install_time"), (ROOT / "docs" / "quickstart.md", "notebook_times"),
                      (ROOT / "docs" / "quickstart.md", "extras_sizes")):
        assert f"<!-- value:{name} -->" in doc.read_text(), f"{doc.name} quotes {name} by hand"
