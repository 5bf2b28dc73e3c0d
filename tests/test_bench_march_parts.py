"""bench/march_parts.py: each variant replaces one part of the march's step in the shaders
as they are now (a substitution that stopped matching would measure nothing)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import tetvr.gl.shaders as shaders
from tetvr.gl.shaders import assemble, shader_dir

from .test_bench_speed_charts import _load


def test_every_substitution_matches_its_shader_once():
    march_parts = _load("march_parts")
    # Importing it leaves the path alone: Dask's workers, started later by other tests,
    # would import bench/distributed.py as their own package.
    assert not any(Path(p).resolve() == Path(march_parts.__file__).parent for p in sys.path if p)
    assert "whole" in march_parts.VARIANTS and len(march_parts.VARIANTS) > 1
    for variant, edits in march_parts.VARIANTS.items():
        for name, pairs in edits.items():
            text = (shader_dir() / name).read_text()
            for old, _ in pairs:
                assert text.count(old) == 1, (variant, name, old)


def test_a_variant_s_shaders_are_read_with_its_substitution(monkeypatch):
    march_parts = _load("march_parts")
    monkeypatch.setattr(shaders, "_read", shaders._read)  # restored after the test
    whole, _ = assemble("march.frag")
    march_parts.patch_shaders("table fetch")
    patched, _ = assemble("march.frag")
    assert "trilinear(u_table, vec3(z, st))" in whole and "trilinear(u_table, vec3(z, st))" not in patched
    assert "vec4 t = vec4(z, st, z * st.x + st.y);" in patched
    monkeypatch.setitem(march_parts.VARIANTS, "stale", {"march.frag": [("no such text", "")]})
    march_parts.patch_shaders("stale")
    with pytest.raises(RuntimeError, match="no longer holds"):
        assemble("march.frag")
