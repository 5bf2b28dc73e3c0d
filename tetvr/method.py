"""Which GPU method renders a scene: projected tetrahedra or tet marching.

Both methods take the same (mesh, camera, transfer function, settings), read the same
pre-integration table and return the same premultiplied image; they differ in what their
cost follows. Projected tetrahedra pay per cell (classify, sort, 3-4 triangles each) plus
per fragment; tet marching pays per ray--tet segment (~40-60 ns each on llvmpipe) plus a
small per-frame cost for the boundary passes, and needs no sort, so it is exact in
visibility where a cell order is not. ``RenderSettings(method="auto")`` asks
:func:`choose`; bench/README.md has the measurements behind the rule.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .settings import RenderSettings

if TYPE_CHECKING:
    from .mesh import TetMesh

__all__ = ["choose", "RAYMARCH_ONLY", "PROJECTED_ONLY"]

#: Settings only projected tetrahedra implement: VTK's fragment formula (parity mode with
#: VTK's screen-linear interpolation) and an 8-bit compositing target.
PROJECTED_ONLY = ("optics='vtk'", "framebuffer='uint8'", "perspective_correct=False")
#: Settings only the ray caster implements (none so far).
RAYMARCH_ONLY: tuple[str, ...] = ()


def choose(settings: RenderSettings, mesh: "TetMesh | None" = None) -> str:
    """The method a frame with these settings (and this mesh) uses: ``"projected"`` or
    ``"raymarch"``.

    ``"auto"`` picks tet marching, which measured faster than projected tetrahedra on every
    mesh and size of the benchmarks on llvmpipe (bench/README.md) and is exact in visibility
    order, except where a setting exists only for projected tetrahedra
    (:data:`PROJECTED_ONLY`: VTK parity, 8-bit compositing, screen-linear interpolation)
    or where the mesh is tangled (cells that overlap in space:
    :func:`tetvr.marching.folded_faces`), which a walk from cell to cell cannot follow.

    Examples
    --------
    >>> choose(RenderSettings())
    'raymarch'
    >>> choose(RenderSettings(optics="vtk"))
    'projected'
    """
    if settings.method != "auto":
        return settings.method
    if settings.optics == "vtk" or settings.framebuffer != "float32" or not settings.perspective_correct:
        return "projected"
    if mesh is not None:
        from .marching import folded_faces

        if folded_faces(mesh):
            return "projected"
    return "raymarch"
