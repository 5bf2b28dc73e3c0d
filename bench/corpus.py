"""The unstructured meshes the benchmarks run beside the grids split into tets.

Every mesh the grids' benchmarks start from is a structured grid split into 5 or 6 tets
per hexahedron; FEM and CFD results come on unstructured meshes (TetGen, Gmsh, fTetWild,
SimVascular) with graded, stretched and boundary-layer cells. Besides the SimVascular
pipe and beam of ``../shared/data`` (``_common.REAL_MESHES``), this module makes:

* ``torus by fTetWild``: a torus filled by fTetWild (:func:`tetvr.mesh.meshing.tetrahedralize`)
  at two target edge lengths (~200k and ~1M tets), a swirling field on it -- the
  curved-surface mesh a user gets from a CAD or STL surface;
* ``boundary layer``: a pipe whose points crowd towards the wall in a geometric boundary
  layer (first layer 0.2 % of the radius, growth 1.25: cells ~50:1 at the wall),
  joined by a Delaunay tetrahedralisation (``scipy.spatial.Delaunay``; the points jittered
  by 5 % of the thinnest layer, or a tenth of the cells come out flat), with a developing
  pipe-flow profile and a wake -- the graded, stretched cells of a CFD mesh (~920k tets),
  and the same pipe with finer rings (~3M tets): the corpus's mesh past 2M tets (a ~3M
  fTetWild torus would take hours on two cores, below).

The tori take minutes to make on two cores (the pipe ~10 s), so each is kept in a cache
folder (``$TETVR_BENCH_CACHE``, else ``~/.cache/tetvr/bench``) as ``.npz`` and made again
only when it is missing. Neither is shipped: both are made from code here.

    python bench/corpus.py            # make (or load) each mesh and print its size
"""

from __future__ import annotations

import functools
import importlib.util
import os
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tetvr.mesh.tetmesh import TetMesh  # noqa: E402

#: fTetWild's target edge for the torus (major radius 1, minor 0.35): ~200k tets.
TORUS_EDGE = 0.048
#: The finer torus's target edge and name: ~1M tets (the cell count goes as the edge's
#: inverse cube; fTetWild's time grows faster than the count: ~3M tets, edge 0.0198, would
#: take hours on two cores).
FINE_TORI = {"1M": 0.0286}
#: The boundary-layer pipe's points around each ring and rings along it (~920k tets).
PIPE_AROUND, PIPE_ALONG = 64, 80
#: The finer boundary-layer pipes' names and (around, along): the cells go as their product.
FINE_PIPES = {"3M": (104, 128)}


def cache_dir() -> Path:
    """Where made meshes are kept: ``$TETVR_BENCH_CACHE``, else ``~/.cache/tetvr/bench``."""
    env = os.environ.get("TETVR_BENCH_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "tetvr" / "bench"


def _cached(name: str, make: Callable[[], TetMesh]) -> TetMesh:
    path = cache_dir() / f"{name}.npz"
    if path.is_file():
        with np.load(path) as z:
            return TetMesh.from_arrays(z["points"], z["tets"], z["scalars"], scalar_name=str(z["scalar_name"]))
    t0 = time.perf_counter()
    mesh = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, points=mesh.points, tets=mesh.tets, scalars=mesh.scalars, scalar_name=mesh.scalar_name)
    os.replace(tmp, path)
    print(f"made {name}: {mesh.n_tets} tets in {time.perf_counter() - t0:.0f} s (kept in {path})", flush=True)
    return mesh


def _swirl(p: np.ndarray) -> np.ndarray:
    """A smooth field that turns round the torus and through its tube."""
    theta = np.arctan2(p[:, 1], p[:, 0])
    r = np.hypot(p[:, 0], p[:, 1]) - 1.0
    phi = np.arctan2(p[:, 2], r)
    return np.sin(3.0 * theta + phi) * (0.5 + np.hypot(r, p[:, 2]) / 0.35) + 0.3 * np.cos(2.0 * theta)


def torus_tetwild(edge: float = TORUS_EDGE) -> TetMesh:
    """A torus filled by fTetWild with target edge ``edge`` (by default ~200k tets; cached)."""
    def make() -> TetMesh:
        import trimesh

        from tetvr.mesh.meshing import tetrahedralize

        surface = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=96, minor_sections=48)
        return tetrahedralize(surface, edge_length=edge, field=_swirl, scalar_name="swirl",
                              max_cells=10**8).mesh

    return _cached(f"torus_tetwild_{edge:g}", make)


def boundary_layer(around: int = PIPE_AROUND, along: int = PIPE_ALONG) -> TetMesh:
    """A pipe with a graded wall layer, Delaunay-tetrahedralised
    (:func:`tetvr.scene.imperfect.delaunay_pipe`), by default ~920k tets (cached)."""
    from tetvr.scene.imperfect import delaunay_pipe

    return _cached(f"boundary_layer_{around}x{along}_jittered", lambda: delaunay_pipe(around, along))


def meshes() -> list[tuple[str, Callable[[], TetMesh]]]:
    """The made meshes whose makers are installed or that are in the cache: (name, loader)."""
    out: list[tuple[str, Callable[[], TetMesh]]] = []
    makers = all(importlib.util.find_spec(m) is not None for m in ("pytetwild", "trimesh"))
    tori = [("torus by fTetWild (swirl)", TORUS_EDGE),
            *((f"torus by fTetWild, {size} (swirl)", edge) for size, edge in FINE_TORI.items())]
    # A torus already in the cache needs no fTetWild (a machine the cache was carried to).
    out.extend((name, functools.partial(torus_tetwild, edge)) for name, edge in tori
               if makers or (cache_dir() / f"torus_tetwild_{edge:g}.npz").is_file())
    if importlib.util.find_spec("scipy") is not None:
        out.append(("boundary layer (velocity)", boundary_layer))
        out.extend((f"boundary layer, {size} (velocity)", functools.partial(boundary_layer, *rings))
                   for size, rings in FINE_PIPES.items())
    return out


if __name__ == "__main__":
    for name, load in meshes():
        t0 = time.perf_counter()
        m = load()
        print(f"{name}: {m.n_tets} tets, {m.n_points} points, longest edge {m.max_edge:.3g} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
