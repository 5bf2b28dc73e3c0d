"""Headless OpenGL contexts through EGL (or the platform's default context where EGL is
absent), with errors that say how to get one.

A context is current in at most one thread at a time (EGL), and a GL driver does not
survive ``fork``. So a context made here is left current nowhere: every use makes it
current in the calling thread, holding the context's lock, and releases it again
(:func:`current_in_thread`). A process forked from one that made a context refuses GL
with :class:`ForkedProcessError` instead of hanging in the driver.
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import os
import threading
import weakref
from typing import Any, Iterator

__all__ = ["GLUnavailableError", "ForkedProcessError", "create_context", "current_in_thread", "context_lock",
           "context_alive", "context_device", "egl_cuda_devices", "check_not_forked", "REQUIRED_GL", "BACKENDS"]

#: Compute shaders and shader storage buffers need OpenGL 4.3.
REQUIRED_GL = 430

_INSTALL_HINT = (
    "tetvr renders through a headless EGL context, or else the platform's default one. On "
    "Debian/Ubuntu install Mesa's EGL and software rasteriser:  sudo apt-get install libegl1 libegl-mesa0 "
    "libgl1-mesa-dri libgbm1  (on an NVIDIA machine the driver's libEGL_nvidia is used instead). On "
    "Windows the GPU driver's OpenGL (WGL) serves; macOS stops at OpenGL 4.1, without compute shaders."
)

#: The context backends tried in turn: headless EGL, then the platform's default
#: (GLX on Linux with a display, WGL on Windows, CGL on macOS), for machines without EGL.
BACKENDS: tuple[str | None, ...] = ("egl", None)

_FORK_MESSAGE = (
    "this process was forked (os.fork, or multiprocessing's 'fork' start method, the default on Linux "
    "before Python 3.14) from a process that had made an OpenGL context. The GL driver's threads and "
    "locks do not survive a fork, so GL here would hang. Start worker processes with the 'spawn' or "
    "'forkserver' method instead, e.g. multiprocessing.get_context('spawn').Pool() or "
    "concurrent.futures.ProcessPoolExecutor(mp_context=multiprocessing.get_context('spawn')), "
    "and make the Renderer inside the worker."
)


class GLUnavailableError(RuntimeError):
    """No usable OpenGL >= 4.3 context could be created."""


class ForkedProcessError(RuntimeError):
    """GL was asked for in a process forked from one that had made an OpenGL context."""


# ---- fork: the child of a GL process must not touch GL ----
_forked_from_gl = False
_fork_guard_registered = False


def check_not_forked() -> None:
    """Raise :class:`ForkedProcessError` in a process forked from one that made a GL context."""
    if _forked_from_gl:
        raise ForkedProcessError(_FORK_MESSAGE)


def _after_fork_in_child() -> None:
    global _forked_from_gl, _registry_lock
    _forked_from_gl = True
    # Locks held by the parent's other threads at the fork stay held for ever in the child:
    # replace them so that what needs no GL (and release()) cannot deadlock there.
    _registry_lock = threading.Lock()
    for state in list(_states.values()):
        state.lock = threading.RLock()
        state.depth = 0


def _guard_fork() -> None:
    global _fork_guard_registered
    if not _fork_guard_registered and hasattr(os, "register_at_fork"):
        os.register_at_fork(after_in_child=_after_fork_in_child)
        _fork_guard_registered = True


# ---- EGL, through ctypes: make current, release, and ask what is current ----
_EGL_DRAW, _EGL_READ = 0x3059, 0x305A
_EGL_BAD_ACCESS = 0x3002


def _load_egl() -> Any:
    for name in ("libEGL.so.1", "libEGL.so", "libEGL.dylib", "libEGL.dll"):
        try:
            lib = ctypes.CDLL(name)
        except OSError:
            continue
        for fn in ("eglGetCurrentDisplay", "eglGetCurrentContext", "eglGetCurrentSurface"):
            getattr(lib, fn).restype = ctypes.c_void_p
        lib.eglGetCurrentSurface.argtypes = [ctypes.c_int32]
        lib.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
        lib.eglMakeCurrent.restype = ctypes.c_uint
        lib.eglGetError.restype = ctypes.c_int32
        lib.eglGetProcAddress.restype = ctypes.c_void_p
        lib.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        return lib
    return None


_egl_lib: Any = None
_egl_loaded = False


def _egl() -> Any:
    global _egl_lib, _egl_loaded
    if not _egl_loaded:
        _egl_lib, _egl_loaded = _load_egl(), True
    return _egl_lib


_Binding = tuple[Any, Any, Any, Any]  # EGL (display, draw surface, read surface, context)


def _egl_current() -> _Binding | None:
    """What EGL has current in this thread, or None if EGL is not loaded."""
    egl = _egl()
    if egl is None:
        return None
    return (egl.eglGetCurrentDisplay(), egl.eglGetCurrentSurface(_EGL_DRAW), egl.eglGetCurrentSurface(_EGL_READ),
            egl.eglGetCurrentContext())


@dataclasses.dataclass(eq=False)
class _ContextState:
    """Per context: its lock, its EGL binding (learnt the first time it is current), and
    the nesting depth and previous binding of the thread that holds the lock."""

    lock: threading.RLock = dataclasses.field(default_factory=threading.RLock)
    binding: _Binding | None = None  # None: not learnt yet, or not an EGL context
    foreign: bool = False  # not EGL (or EGL not loadable): moderngl's own enter/exit
    depth: int = 0
    prior: _Binding | None = None
    device: int | None = None  # the EGL device it was made on, when one was asked for


_states: "weakref.WeakKeyDictionary[Any, _ContextState]" = weakref.WeakKeyDictionary()
_registry_lock = threading.Lock()


def _state(ctx: Any) -> _ContextState:
    with _registry_lock:
        state = _states.get(ctx)
        if state is None:
            state = _states[ctx] = _ContextState()
            _guard_fork()  # a borrowed context made elsewhere is a GL context all the same
        return state


def context_lock(ctx: Any) -> "threading.RLock":
    """The re-entrant lock that serialises every use of ``ctx`` (one per context, so a
    Raycaster that borrows a Renderer's context shares the Renderer's lock)."""
    return _state(ctx).lock


def context_alive(ctx: Any) -> bool:
    """Whether ``ctx`` has not been released."""
    mglo = getattr(ctx, "mglo", None)
    return mglo is not None and type(mglo).__name__ != "InvalidObject"


@contextlib.contextmanager
def current_in_thread(ctx: Any) -> Iterator[Any]:
    """Hold ``ctx``'s lock with ``ctx`` current in the calling thread; on leaving the
    outermost block, make current again what this thread had before (usually nothing),
    so that another thread can take the context next. Re-entrant.

    Raises :class:`ForkedProcessError` in a forked child of a GL process and
    :class:`RuntimeError` if the context is released or current in another thread.
    """
    check_not_forked()
    state = _state(ctx)
    with state.lock:
        if state.depth == 0:
            if not context_alive(ctx):
                raise RuntimeError("this OpenGL context has been released")
            state.prior = _egl_current()
            _make_current(ctx, state)
        state.depth += 1
        try:
            yield ctx
        finally:
            state.depth -= 1
            if state.depth == 0:
                prior, state.prior = state.prior, None
                _restore(ctx, state, prior)


def _make_current(ctx: Any, state: _ContextState) -> None:
    egl = _egl()
    if state.binding is None and not state.foreign:
        # A context made elsewhere: let moderngl make it current the way its backend does
        # and note what EGL then has current (nothing, for a GLX or WGL context).
        ctx.__enter__()
        now = _egl_current()
        if now is not None and now[3]:
            state.binding = now
        else:
            state.foreign = True
        return
    if state.foreign:
        ctx.__enter__()
        return
    assert state.binding is not None
    if not egl.eglMakeCurrent(*state.binding):
        code = egl.eglGetError()
        where = ("it is current in another thread (made current there outside tetvr's lock, e.g. by "
                 "`with ctx:` or by creating it there with moderngl); leave it there first"
                 if code == _EGL_BAD_ACCESS else f"EGL error 0x{code:04x}")
        raise RuntimeError(f"could not make the OpenGL context current in this thread: {where}")


def _restore(ctx: Any, state: _ContextState, prior: _Binding | None) -> None:
    if state.foreign:
        if context_alive(ctx):
            ctx.__exit__(None, None, None)
        return
    egl = _egl()
    if state.binding is None or egl is None:
        return
    if prior is not None and prior[3] and egl.eglMakeCurrent(*prior):
        return  # what this thread had current before (e.g. inside the caller's `with ctx:`)
    # Nothing was current here: release the context from this thread, so that any thread
    # can make it current next.
    egl.eglMakeCurrent(state.binding[0], None, None, None)


# ---- creation ----
def create_context(device: int | None = None) -> Any:
    """A standalone moderngl context (OpenGL >= 4.3 core), current in no thread: use it
    inside :func:`current_in_thread` (or moderngl's ``with ctx:``).

    EGL first (headless: no display needed); where EGL is absent or fails, the
    platform's default context (:data:`BACKENDS`). If neither can be made, the error
    names what each attempt said and how to install a driver.

    ``device``: the EGL device to make it on (an index into EGL's device list, as
    ``eglQueryDevicesEXT`` gives it; :func:`egl_cuda_devices` says which GPU each is).
    None: the driver's first. With a device, only EGL is tried: a context elsewhere would
    be on another GPU than the one asked for."""
    check_not_forked()
    if device is not None and (isinstance(device, bool) or not isinstance(device, int) or device < 0):
        raise ValueError(f"device must be a non-negative integer (an EGL device index) or None, got {device!r}")
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a hard dependency
        raise GLUnavailableError(f"moderngl is not installed ({exc}); pip install moderngl") from exc
    prior = _egl_current()
    failures: list[str] = []
    ctx = None
    for backend in (("egl",) if device is not None else BACKENDS):
        try:
            kwargs: dict[str, Any] = {"backend": backend} if backend else {}
            if device is not None:
                kwargs["device_index"] = device
            ctx = moderngl.create_standalone_context(require=REQUIRED_GL, **kwargs)
            break
        except Exception as exc:
            failures.append(f"{'EGL' if backend == 'egl' else backend or 'the platform default'}: "
                            f"{type(exc).__name__}: {exc}")
    if ctx is None:
        on = f" on EGL device {device}" if device is not None else ""
        raise GLUnavailableError(
            f"could not create an OpenGL {REQUIRED_GL // 100}.{REQUIRED_GL % 100 // 10} context{on} "
            f"({'; '.join(failures)}). {_INSTALL_HINT}"
        )
    state = _state(ctx)
    state.device = device
    with state.lock:
        # moderngl left the new context current in this thread: note its EGL binding, read
        # (and cache) the info strings that owners read outside the lock, then release it.
        now = _egl_current()
        if now is not None and now[3]:
            state.binding = now
        else:  # pragma: no cover - EGL not loadable through ctypes
            state.foreign = True
        info = ctx.info
        if state.binding is not None:
            _restore(ctx, state, prior)
    if ctx.version_code < REQUIRED_GL:
        found = info.get("GL_VERSION", ctx.version_code)
        ctx.release()
        raise GLUnavailableError(
            f"OpenGL {found} was found, but tetvr needs {REQUIRED_GL // 100}.{REQUIRED_GL % 100 // 10} "
            f"(compute shaders). {_INSTALL_HINT}"
        )
    return ctx


def context_device(ctx: Any) -> int | None:
    """The EGL device ``ctx`` was made on by :func:`create_context`, None where none was
    asked for (the driver's first) or the context was made elsewhere."""
    return _state(ctx).device


# EGL_NV_device_cuda: the CUDA device an EGL device is (NVIDIA's driver says; Mesa's does not).
_EGL_CUDA_DEVICE_NV = 0x323A


def egl_cuda_devices() -> list[int | None]:
    """For each EGL device (``eglQueryDevicesEXT``'s order, the index :func:`create_context`
    takes), the CUDA device it is, as this process numbers CUDA devices (after
    ``CUDA_VISIBLE_DEVICES``); None for a device that is no CUDA device (Mesa's, or a GPU
    this process does not see). Empty where EGL cannot list its devices.

    Examples
    --------
    >>> all(d is None or d >= 0 for d in egl_cuda_devices())
    True
    """
    egl = _egl()
    if egl is None:
        return []
    query_devices = egl.eglGetProcAddress(b"eglQueryDevicesEXT")
    query_attrib = egl.eglGetProcAddress(b"eglQueryDeviceAttribEXT")
    if not query_devices or not query_attrib:
        return []
    devices_fn = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int32, ctypes.POINTER(ctypes.c_void_p),
                                  ctypes.POINTER(ctypes.c_int32))(query_devices)
    attrib_fn = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_void_p, ctypes.c_int32,
                                 ctypes.POINTER(ctypes.c_ssize_t))(query_attrib)
    count = ctypes.c_int32(0)
    if not devices_fn(0, None, ctypes.byref(count)) or count.value <= 0:
        return []
    devices = (ctypes.c_void_p * count.value)()
    if not devices_fn(count.value, devices, ctypes.byref(count)):
        return []
    out: list[int | None] = []
    for k in range(count.value):
        value = ctypes.c_ssize_t(-1)
        ok = attrib_fn(devices[k], _EGL_CUDA_DEVICE_NV, ctypes.byref(value))
        out.append(int(value.value) if ok and value.value >= 0 else None)
    egl.eglGetError()  # a device that is no CUDA device left EGL_BAD_ATTRIBUTE: not ours to keep
    return out


def describe(ctx: Any) -> dict[str, str]:
    """Renderer, vendor and version strings, for benchmark reports."""
    with current_in_thread(ctx):
        return {k: str(ctx.info.get(k, "")) for k in ("GL_RENDERER", "GL_VENDOR", "GL_VERSION")}
