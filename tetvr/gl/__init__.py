"""The OpenGL side of tetvr: the only package that imports moderngl (lazily).

:class:`Renderer` owns an EGL context and every GL object made in it.
"""

from tetvr.gl.context import GLUnavailableError

__all__ = ["GLUnavailableError", "Raycaster", "Renderer"]


def __getattr__(name: str):  # deferred so that `import tetvr.gl` stays cheap
    if name == "Renderer":
        from tetvr.gl.renderer import Renderer

        return Renderer
    if name == "Raycaster":
        from tetvr.gl.raycaster import Raycaster

        return Raycaster
    raise AttributeError(name)
