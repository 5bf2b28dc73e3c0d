"""Headless OpenGL contexts through EGL, with errors that say how to get one."""

from __future__ import annotations

from typing import Any

__all__ = ["GLUnavailableError", "create_context", "REQUIRED_GL"]

#: Compute shaders and shader storage buffers need OpenGL 4.3.
REQUIRED_GL = 430

_INSTALL_HINT = (
    "tetvr renders through a headless EGL context. On Debian/Ubuntu install Mesa's EGL and "
    "software rasteriser:  sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1  "
    "(on an NVIDIA machine the driver's libEGL_nvidia is used instead)."
)


class GLUnavailableError(RuntimeError):
    """No usable OpenGL >= 4.3 context could be created."""


def create_context() -> Any:
    """A standalone moderngl context on EGL (OpenGL >= 4.3 core)."""
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a hard dependency
        raise GLUnavailableError(f"moderngl is not installed ({exc}); pip install moderngl") from exc
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=REQUIRED_GL)  # type: ignore[arg-type]
    except Exception as exc:
        raise GLUnavailableError(
            f"could not create an OpenGL {REQUIRED_GL // 100}.{REQUIRED_GL % 100 // 10} context through EGL: "
            f"{type(exc).__name__}: {exc}. {_INSTALL_HINT}"
        ) from exc
    if ctx.version_code < REQUIRED_GL:
        found = ctx.info.get("GL_VERSION", ctx.version_code)
        ctx.release()
        raise GLUnavailableError(
            f"OpenGL {found} was found, but tetvr needs {REQUIRED_GL // 100}.{REQUIRED_GL % 100 // 10} "
            f"(compute shaders). {_INSTALL_HINT}"
        )
    return ctx


def describe(ctx: Any) -> dict[str, str]:
    """Renderer, vendor and version strings, for benchmark reports."""
    return {k: str(ctx.info.get(k, "")) for k in ("GL_RENDERER", "GL_VENDOR", "GL_VERSION")}
