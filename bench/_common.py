"""What the bench scripts share: the data folder, the real meshes, JSON writing, machine info.

The scripts run as ``python bench/<script>.py``, so ``bench/`` is on ``sys.path`` and they
``import _common``. Nothing here imports tetvr at import time (the scripts that need the
checkout on ``sys.path`` put it there first).
"""

from __future__ import annotations

import importlib
import json
import math
import os
import platform
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tetvr.mesh.tetmesh import TetMesh

#: The repository root.
ROOT = Path(__file__).resolve().parents[1]
#: ``../shared/data`` beside the checkout, or ``$TETVR_SHARED_DATA`` (as in tests/conftest.py).
SHARED_DATA = Path(os.environ.get("TETVR_SHARED_DATA", ROOT.parent / "shared" / "data"))
#: The real tetrahedral meshes (``bluntfin_tets.vtu``, ``combustor_tets.vtu``) live here.
TETS_DATA = SHARED_DATA / "tets"

#: Synthetic cubes: cube(n) has 6 n^3 tets (~10k, 105k, 329k, 998k).
CUBE_NS = (12, 26, 38, 55)
#: Real meshes (file in TETS_DATA, point field), used when they are there: two structured
#: CFD grids split into tets, and two unstructured FEM meshes from SimVascular (the pipe's
#: points come in no spatial order; the beam is small and stretched).
REAL_MESHES = (("bluntfin_tets.vtu", "Density"), ("combustor_tets.vtu", "Density"),
               ("pipe_flow_init_flow.vtu", "Pressure"), ("beam_tet4_result_100.vtu", "VonMises_stress"))
#: ``--quick`` keeps the meshes up to this many tets.
QUICK_MAX_TETS = 330_000

#: Environment variables that set llvmpipe's thread count or pick the driver.
_GL_ENV = ("LP_NUM_THREADS", "GALLIUM_DRIVER", "MESA_LOADER_DRIVER_OVERRIDE", "EGL_PLATFORM", "OMP_NUM_THREADS")


def load_quiet(path: Path, field: str) -> TetMesh:
    """``tetvr.read(path, field)`` without its warnings ("dropped N zero-volume tetrahedra")."""
    import tetvr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return tetvr.read(path, field)


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON through a temporary file, so a half-written file never stays behind."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=2, default=float) + "\n")
    os.replace(tmp, path)


def kept_records(old: dict[str, Any], old_date: str, rerun: list[str], date: str,
                 notes: list[str]) -> tuple[list[dict[str, Any]], list[str]]:
    """For a run that reruns some meshes (``--only``) into ``old``'s JSON: ``old``'s mesh
    records but those rerun, each keeping its run's date (``old_date`` where it has none),
    and ``notes`` with ``old``'s, one saying what was rerun when."""
    kept = [m for m in old["meshes"] if m["name"] not in rerun]
    for m in kept:
        m.setdefault("date", old_date)
    return kept, [*notes, *(n for n in old.get("notes", []) if not n.startswith("merged:")),
                  f"merged: {', '.join(rerun)} rerun on {date}; the other meshes' records keep the dates of their "
                  "runs (each mesh's frames are taken in turn within its own run)"]


def versions() -> dict[str, str]:
    """Python and the versions of numpy, tetvr, moderngl and matplotlib ("not installed" when missing)."""
    out = {"python": platform.python_version()}
    for name in ("numpy", "tetvr", "moderngl", "matplotlib"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            out[name] = "not installed"
        else:
            out[name] = getattr(module, "__version__", "?")
    return out


def machine() -> dict[str, Any]:
    """CPU, platform, the GL-related environment and :func:`versions`, so that runs can be compared."""
    info: dict[str, Any] = {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                            "machine": platform.machine(), "processor": platform.processor()}
    try:
        info["cpu_affinity"] = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        pass
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu_model"] = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    # llvmpipe's thread count follows these; record them so runs can be compared.
    info["env"] = {k: os.environ[k] for k in _GL_ENV if k in os.environ}
    info.update(versions())
    return info


def loadavg() -> list[float] | None:
    """The 1, 5 and 15 minute load averages (None where there are none).

    llvmpipe rasterises on the CPU: other work on the same cores shows up in every timing.
    """
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):  # AttributeError: not on Unix
        return None


#: Small meshes and scenes are timed until their frames add up to this many seconds...
MIN_TIMED_S = 1.5


def timed_repeats(frame_s: float, at_least: int, at_most: int) -> int:
    """How many timed frames a benchmark takes: at least ``at_least``, and for fast frames
    more, until they add up to MIN_TIMED_S, but no more than ``at_most`` (with a handful of
    5 ms frames, 5 % differences are chance)."""
    return max(at_least, min(at_most, math.ceil(MIN_TIMED_S / max(frame_s, 1e-6))))
