"""What a pass module asks of the renderer that owns it.

The tet-marching passes (:mod:`tetvr.gl.raymarch`), the opaque surfaces
(:mod:`tetvr.gl.surfaces`) and VTK parity (:mod:`tetvr.gl.vtkpt`) each live in one
:class:`~tetvr.gl.renderer.Renderer` and use its context, its compiled programs and, for
parity, its classification and drawing. They are typed against these protocols rather than
the ``Renderer`` class, so the renderer imports them and they never import it back.
"""

from __future__ import annotations

from typing import Any, Iterator, Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["ProgramHost", "DrawHost"]


class ProgramHost(Protocol):
    """A GL context and the programs compiled in it, one per shader and set of defines."""

    ctx: Any

    def _program(self, kind: str, **defines: int) -> Any: ...


class DrawHost(ProgramHost, Protocol):
    """A :class:`ProgramHost` that also classifies and draws the cells of a mesh in chunks into
    its targets (the projected-tetrahedra pipeline, which VTK parity reuses with its own shaders)."""

    settings: Any
    _clock: Any

    def _chunks(self, mesh: Any, order: NDArray[np.uint32]) -> Iterator[int]: ...

    def _use_target(self, size: tuple[int, int], components: int, dtype: str = "f4") -> Any: ...

    def _classify(self, n_tets: int, uniforms: dict[str, Any], *, perspective_correct: int,
                  count_exact: bool = False, program: Any = None) -> range: ...

    def _draw(self, prog: Any, fbo: Any, n_tets: int, blend: tuple[Any, ...], first: int = 0) -> None: ...

    def _read(self, fbo: Any, size: tuple[int, int], components: int, dtype: str = "f4") -> NDArray[np.float32]: ...
