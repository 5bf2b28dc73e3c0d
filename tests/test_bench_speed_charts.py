"""bench/speed_accuracy.py's summary and bench/speed_charts.py's charts, on a made-up report
(no GL), and bench/peers.py's account of what it could not measure."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


def _load(name: str):
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCH))
    return module


@pytest.fixture(scope="module")
def sa():
    return _load("speed_accuracy")


@pytest.fixture(scope="module")
def charts():
    pytest.importorskip("matplotlib")
    return _load("speed_charts")


def _row(frame_s: float, max_error: float, psnr: float, **flags) -> dict:
    return {"frame_s": frame_s, "max_error": max_error, "psnr": psnr, "rmse": 10 ** (-psnr / 20), **flags}


def _report(sa) -> dict:
    """Two scenes at 64x64, one at 128x128; a variant identical to the default in one scene;
    one VTK mapper that failed in one scene."""
    vs = sa.variants()
    groups = {k: g for g, members in sa.variant_groups().items() for k in members}

    def scene(scale: float, same: bool, failed: bool) -> dict:
        rows = {k: _row(scale * (1 + 0.1 * i), 1e-3 * (i + 1), 100 - i) for i, k in enumerate(vs)}
        rows["default"] = _row(scale, 1e-4, 110)
        dup = {}
        if same:
            del rows["N=512"]
            dup = {"N=512": "identical to the default here"}
        peer_rows = {"vtk_pt": _row(scale * 0.5, 0.2, 25), "vtk_bunyk": _row(scale * 4, 0.3, 24),
                     "vtk_zsweep": {"failed": "RuntimeError: the VTK process died"} if failed else _row(scale * 3, 0.3, 24)}
        all_rows = {**rows, **peer_rows}
        sa.mark_fronts(all_rows)
        return {"n_tets": 100, "size": [64, 64], "variants": rows, "peers": peer_rows, "same_as_default": dup}

    stab = {"opaque_tf": {k: {"max_error": 1e-5, "psnr": 100.0} for k in vs}}
    stab["opaque_tf"]["tet marching"] = {"psnr": None, "refused": "ValueError: folded faces"}
    stab["opaque_tf"].update(vtk_pt={"max_error": 0.2}, vtk_bunyk={"max_error": 0.3},
                             vtk_zsweep={"psnr": None, "failed": "RuntimeError: died"})
    imperfect = [{"class": "repeated cells", "mesh": m, "view": 0, "methods": {
        "default": {"max_error": e}, "projected tetrahedra": {"max_error": e},
        "tet marching": {"refused": "overlap"} if m == "b" else {"max_error": e},
        "tet marching, no table (integration exact)": {"max_error": e},
        "vtk_pt": {"max_error": 0.1}, "vtk_bunyk": {"max_error": 0.1}, "vtk_zsweep": {"max_error": 0.1}}}
        for m, e in (("a", 1e-5), ("b", 2e-3))]
    return {"created": "2026-01-01T00:00:00", "size": [64, 64], "stability_size": [32, 32],
            "variants": {k: {} for k in vs}, "groups": groups,
            "peers": {"labels": {"vtk_pt": "VTK projected tetrahedra", "vtk_bunyk": "VTK Bunyk ray cast",
                                 "vtk_zsweep": "VTK Z sweep"}},
            "paraview": {"available": False, "reason": "not installed"}, "gl": {"GL_RENDERER": "test"},
            "scenes": {"one": scene(1.0, True, False), "two": scene(2.0, False, True)},
            "scenes_at": {"128x128": {"one": scene(4.0, False, False)}},
            "stability": stab, "imperfect": imperfect}


def test_every_renderer_has_its_own_marker_and_colour(sa, charts):
    st = charts.styles(_report(sa))
    assert set(st) == set(sa.variants()) | {"vtk_pt", "vtk_bunyk", "vtk_zsweep"}
    pairs = [(s["marker"], s["color"]) for s in st.values()]
    assert len(set(pairs)) == len(pairs), "two renderers look alike"
    colours = [s["color"] for s in st.values()]
    assert len(set(colours)) == len(colours), "a colour is used twice"
    by_group: dict[str, set[str]] = {}
    for key, s in st.items():
        if key != "default":
            by_group.setdefault(s["group"], set()).add(s["marker"])
    assert all(len(m) == 1 for m in by_group.values()), by_group  # one marker per group ...
    markers = [next(iter(m)) for m in by_group.values()]
    assert len(set(markers)) == len(markers)  # ... and no two groups share one
    assert st["default"]["marker"] == "*" and st["default"]["marker"] not in markers


def test_summary_is_the_geometric_mean_of_time_ratios_and_the_median_error(sa):
    report = _report(sa)
    s = sa.summarize(report)
    assert list(s) == ["64x64", "128x128"]
    d = s["64x64"]["renderers"]["default"]
    assert d["time_ratio"] == pytest.approx(1.0) and d["max_error_median"] == pytest.approx(1e-4)
    # vtk_bunyk is 4x the default in both scenes; vtk_zsweep failed in one and counts the other only
    assert s["64x64"]["renderers"]["vtk_bunyk"]["time_ratio"] == pytest.approx(4.0)
    assert s["64x64"]["renderers"]["vtk_zsweep"]["n_scenes"] == 1
    # identical to the default in scene "one": counted there with the default's numbers
    n512 = s["64x64"]["renderers"]["N=512"]
    assert n512["same_as_default"] == 1 and n512["n_scenes"] == 2
    assert n512["max_error_median"] == pytest.approx(math.fsum([1e-4, n512["max_error_worst"]]) / 2)
    # the default (fastest at the smallest error among tetvr's) and VTK PT (fastest) are on the front
    assert d["pareto_max"] and s["64x64"]["renderers"]["vtk_pt"]["pareto_max"]
    assert not s["64x64"]["renderers"]["vtk_bunyk"]["pareto_max"]


def test_stability_summary_takes_the_worst_view_and_counts_refusals(sa):
    classes = sa.stability_summary(_report(sa))
    assert [c["name"] for c in classes] == ["opaque_tf", "repeated cells"]
    opaque, repeated = (c["methods"] for c in classes)
    assert opaque["tet marching"]["max_error"] is None and opaque["tet marching"]["refused"] == 1
    assert opaque["vtk_zsweep"]["failed"] == 1 and "died" in opaque["vtk_zsweep"]["why"]
    assert repeated["default"]["max_error"] == pytest.approx(2e-3) and repeated["default"]["of"] == 2
    assert repeated["tet marching"]["max_error"] == pytest.approx(1e-5) and repeated["tet marching"]["refused"] == 1


def test_the_charts_are_drawn_and_stale_ones_removed(sa, charts, tmp_path):
    report = _report(sa)
    report["summary"] = sa.summarize(report)
    report["stability_summary"] = sa.stability_summary(report)
    stale = tmp_path / "speed_accuracy_gone.png"
    stale.write_bytes(b"old")
    written = charts.draw_all(report, tmp_path)
    names = sorted(p.name for p in written)
    assert names == ["speed_accuracy.png", "speed_accuracy_one.png", "speed_accuracy_stability.png",
                     "speed_accuracy_two.png"]
    for p in written:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 20_000
    assert not stale.exists()


def test_scene_names_become_file_names(charts):
    assert charts.slug("bluntfin_tets.vtu, spiky TF") == "bluntfin_spiky_tf"
    assert charts.slug("convex, close perspective") == "convex_close_perspective"
    assert charts.slug("cell data (4 levels)") == "cell_data_4_levels"


def test_paraview_missing_is_skipped_with_a_reason(monkeypatch):
    peers = _load("peers")
    monkeypatch.setattr(peers.shutil, "which", lambda name: None)
    monkeypatch.setattr(peers.importlib.util, "find_spec", lambda name: None)
    status = peers.paraview_status()
    assert status["available"] is False and status["measured"] is False
    assert "not installed" in status["reason"] and "skipped" in status["reason"]


def test_a_vtk_peer_reports_wall_and_cpu_time_per_frame():
    pytest.importorskip("vtkmodules", reason="VTK is optional: pip install -e '.[compare]'")
    peers = _load("peers")
    from tetvr import Camera, TransferFunction
    from tetvr.mesh.synthetic import single_tet

    mesh = single_tet((0.0, 0.3, 0.6, 1.0))
    tf = TransferFunction.preset("grayscale", (0.0, 1.0), opacity=0.9, unit_distance=0.5)
    started, failed = peers.open_peers(mesh, tf, (16, 16), keys=("vtk_pt",))
    if failed:
        pytest.skip(f"VTK cannot render offscreen here: {failed}")
    peer = started["vtk_pt"]
    try:
        image = peer.frame(Camera.fit(mesh, direction=(0.3, -0.2, -1.0)))
        assert image.shape == (16, 16, 4) and image[..., 3].max() > 0
        # the child's own CPU time over the frame, all its threads (tetvr.apps.vtkrender's "cpu_seconds")
        assert math.isfinite(peer.last_cpu) and peer.last_cpu >= 0.0
        assert peer.last_wall > 0.0
    finally:
        peer.release()
