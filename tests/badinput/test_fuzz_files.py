"""Property tests of the scene readers (the meshes and renderers are fuzzed in
``test_fuzz.py``): a ParaView state (``.pvsm``) and a scene JSON with random damage.
Deterministic (``derandomize=True``), small, and each under ~10 s.

1. A ParaView state with some of its numbers, indices or properties replaced by random
   text, numbers, NaN, huge values or nothing, or cut short: :func:`read_state` and
   :func:`state_transfer_function` either succeed or raise a ValueError whose message
   names the state file, at once (never an OverflowError, a MemoryError, a raw ``int()``
   message, or minutes of work).
2. A scene JSON with some of its values replaced by random JSON (numbers of any size,
   NaN, strings, lists, objects, null) or its keys removed or misspelt: :func:`load_scene`
   either returns a scene or raises ValueError / TypeError / KeyError /
   FileNotFoundError with a message; nothing else escapes.
"""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import meshio
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tetvr.scene.load import load_scene
from tetvr.scene.paraview import read_state, state_transfer_function

from ._util import POINTS, REPO, SCALARS, TETS, deadline

STATE_TEXT = (REPO / "tests" / "data" / "post_volume.pvsm").read_text()
FUZZ = settings(max_examples=60, deadline=None, derandomize=True, database=None, print_blob=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

# ---- 1. ParaView states ----------------------------------------------------------------

ELEMENTS = [m.span() for m in re.finditer(r'<Element index="\d+" value="[^"]*"/>', STATE_TEXT)]
PROPERTIES = [m.span() for m in re.finditer(r"<Property [^>]*>.*?</Property>", STATE_TEXT, re.S)]
NUMBER_TEXT = st.one_of(
    st.sampled_from(["nan", "NaN", "inf", "-inf", "1e400", "-1e400", "1e9", "3e7", "1e300", "-1e300", "1e-320",
                     "0", "-0", "1", "-1", "2", "0.5", "2.5", "", " ", "x", "0x10", "1_000", "١", "1e", "True"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(2**80), 2**80).map(str),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters='"<>&'), max_size=6),
)


@st.composite
def damaged_state(draw):
    """The test state with 1-4 pieces of damage, applied from the end so spans stay valid."""
    edits: list[tuple[int, int, str]] = []
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["value"] * 8 + ["index", "drop-property", "cut"]))
        if kind in ("value", "index"):
            start, end = draw(st.sampled_from(ELEMENTS))
            text = draw(NUMBER_TEXT)
            old = STATE_TEXT[start:end]
            attr = r'value="[^"]*"' if kind == "value" else r'index="\d+"'
            new = re.sub(attr, lambda m: f'{m.group(0).split("=")[0]}="{text}"', old)
            edits.append((start, end, new))
        elif kind == "drop-property":
            start, end = draw(st.sampled_from(PROPERTIES))
            edits.append((start, end, ""))
        else:
            at = draw(st.integers(0, len(STATE_TEXT)))
            edits.append((at, len(STATE_TEXT), ""))
    text = STATE_TEXT
    for start, end, new in sorted(set(edits), reverse=True):
        if end <= len(text):
            text = text[:start] + new + text[end:]
    return text


@pytest.fixture(scope="module")
def state_path(tmp_path_factory):
    return tmp_path_factory.mktemp("pvsm") / "fuzzed.pvsm"


@FUZZ
@given(text=damaged_state())
def test_damaged_state_is_read_or_refused_by_name(state_path, text):
    state_path.write_text(text, encoding="utf-8")
    with deadline(5.0, "reading a damaged state"), np.errstate(over="raise", invalid="raise", divide="raise"):
        try:
            st_ = read_state(state_path)
            tf = state_transfer_function(st_)
        except ValueError as exc:
            assert "fuzzed.pvsm" in str(exc), f"the message does not name the file: {exc}"
            event(f"refused: {re.sub(r'[0-9]+', 'N', str(exc).split(': ', 1)[-1])[:50]}")
            return
    assert np.all(np.isfinite(np.asarray(tf.color))) and np.all(np.isfinite(np.asarray(tf.opacity)))
    event("read")


# ---- 2. scene JSON -----------------------------------------------------------------------

BASE_SCENE = {
    "mesh": "tiny.vtu", "scalars": "f", "component": None,
    "transfer_function": {"preset": "viridis", "range": [0, 4], "opacity": 0.5, "unit_distance": None,
                          "log_scale": False},
    "camera": {"position": [3, 2, 1], "focal_point": [0.5, 0.5, 0.5], "view_up": [0, 0, 1], "view_angle": 30,
               "parallel_projection": False, "parallel_scale": 1},
    "size": [8, 8], "background": [1, 1, 1], "settings": {"table_scalar_bins": 64},
    "clip": {"plane": {"origin": [0, 0, 0], "normal": [1, 0, 0]}},
}
FIT_CAMERA = {"fit": {"direction": [-1, -0.6, -1.2], "view_up": [0, 0, 1], "parallel": False, "zoom": 1.5}}
EXPLICIT_TF = {"color": [[0, 0, 0, 1], [4, 1, 1, 0]], "opacity": [[0, 0], [4, 1]], "unit_distance": 0.5}

JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=6)
    | st.sampled_from([[0, 0, 0], ["0", "0", "5"], [1e308, 1e308, 1e308], [1e-320, 0, 0], [0, 0], [8, 8, 8]]),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=8)


def _paths(node, prefix=()):
    """Every key path of a JSON object (the places damage may go)."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield prefix + (k,)
            yield from _paths(v, prefix + (k,))


@st.composite
def damaged_scene(draw):
    data = json.loads(json.dumps(BASE_SCENE))
    if draw(st.booleans()):
        data["camera"] = json.loads(json.dumps(FIT_CAMERA))
    if draw(st.booleans()):
        data["transfer_function"] = json.loads(json.dumps(EXPLICIT_TF))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(sorted(_paths(data), key=str)))
        parent = data
        for k in path[:-1]:
            parent = parent[k]
        if not isinstance(parent, dict) or path[-1] not in parent:
            continue
        kind = draw(st.sampled_from(["replace"] * 4 + ["drop", "misspell"]))
        if kind == "replace":
            parent[path[-1]] = draw(JSON)
        elif kind == "drop":
            del parent[path[-1]]
        else:
            parent[path[-1] + "_"] = parent.pop(path[-1])
    return data


@pytest.fixture(scope="module")
def scene_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scene")
    meshio.write(folder / "tiny.vtu", meshio.Mesh(POINTS, [("tetra", TETS)], point_data={"f": SCALARS}))
    return folder


@FUZZ
@given(data=damaged_scene())
def test_damaged_scene_is_loaded_or_refused_with_a_typed_error(scene_folder, data):
    path = scene_folder / "scene.json"
    path.write_text(json.dumps(data))
    with deadline(5.0, "loading a damaged scene"), warnings.catch_warnings(), \
            np.errstate(over="raise", invalid="raise", divide="raise"):
        warnings.simplefilter("ignore")
        try:
            scene = load_scene(path)
        except (ValueError, TypeError, KeyError, FileNotFoundError) as exc:
            assert len(str(exc)) > 15, f"{type(exc).__name__} without a message: {exc!r}"
            event(f"refused: {type(exc).__name__}: {re.sub(r'[0-9]+', 'N', str(exc))[:40]}")
            return
    assert scene.size[0] >= 1 and np.all(np.isfinite(scene.camera.position))
    event("loaded")


def test_the_undamaged_inputs_load(scene_folder, state_path):
    (scene_folder / "scene.json").write_text(json.dumps(BASE_SCENE))
    assert load_scene(scene_folder / "scene.json").size == (8, 8)
    state_path.write_text(STATE_TEXT)
    assert read_state(state_path).n_table_values == 256
    assert isinstance(Path(state_path), Path)
