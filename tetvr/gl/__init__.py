"""The OpenGL side of tetvr: the only package that imports moderngl (lazily).

:class:`Renderer` owns an EGL context and every GL object made in it.
"""

from .context import GLUnavailableError

__all__ = ["GLUnavailableError", "Raycaster", "Renderer"]


def __getattr__(name: str):  # deferred so that `import tetvr.gl` stays cheap
    if name == "Renderer":
        from .renderer import Renderer

        return Renderer
    if name == "Raycaster":
        from .raycaster import Raycaster

        return Raycaster
    raise AttributeError(name)
