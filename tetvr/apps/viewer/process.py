"""A :class:`tetvr.gl.Renderer` in a child process, for the interactive viewer.

moderngl holds Python's global interpreter lock while the GL driver works (measured here:
the interpreter's other threads stop for the whole 350 ms of a 480x360 llvmpipe frame).
In a Jupyter kernel those other threads are the ones that receive the mouse and send the
frames, so a renderer in the kernel's process makes every input wait for the frame being
drawn. In its own process the renderer owns its GL context alone, the kernel waits on a
pipe (which releases the lock), and input keeps flowing while a frame is drawn.

The child is a fresh interpreter (``python -m tetvr.apps.viewer.process``: a forked GL driver
hangs, :mod:`tetvr.gl.context`, and ``multiprocessing``'s spawn would re-run the caller's
main script) talking over two pipes with :mod:`multiprocessing.connection`. It receives the mesh once (again only when another mesh object is drawn) and then per frame
only the camera, transfer function, size and order; it answers the float image or the
error. :meth:`ProcessRenderer.release` ends it, which frees all its GL memory.

Examples
--------
>>> r = ProcessRenderer()                                             # doctest: +SKIP
>>> image = r.render(mesh, camera, tf, size=(256, 256))               # doctest: +SKIP
>>> r.release()                                                       # doctest: +SKIP
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import traceback
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera
from tetvr.mesh.tetmesh import TetMesh
from tetvr.settings import RenderSettings
from tetvr.optics.transfer import TransferFunction

__all__ = ["ProcessRenderer", "RenderProcessError"]


class RenderProcessError(RuntimeError):
    """A frame failed in the render process (the message names the original error), or
    the process died."""


def _serve(inbox: Connection, conn: Connection) -> None:  # pragma: no cover - runs in the child
    from tetvr.gl.renderer import Renderer

    renderer = None
    raycaster = None
    surfaces: Any = ()
    mesh: Any = None
    volume: Any = None
    try:
        settings = inbox.recv()
        renderer = Renderer(settings)
        while True:
            try:
                msg = inbox.recv()
            except EOFError:
                return
            if msg is None:
                return
            try:
                if "mesh" in msg:
                    mesh = msg["mesh"]
                if "settings" in msg and msg["settings"] != renderer.settings:
                    renderer.settings = msg["settings"]  # a preview's small table, or back
                if "volume" in msg:
                    volume = msg["volume"]
                if msg.get("op") == "gpu_bytes":
                    conn.send(("ok", renderer.gpu_bytes()))
                    continue
                if msg.get("op") == "fuse":
                    from tetvr.fuse import fuse
                    from tetvr.gl.raycaster import Raycaster

                    if raycaster is None:
                        raycaster = Raycaster(ctx=renderer.ctx)
                    conn.send(("ok", fuse(mesh, volume, msg["camera"], msg["tf"], msg["volume_tf"], size=msg["size"],
                                          mode=msg["mode"], renderer=renderer, raycaster=raycaster)))
                    continue
                if "surfaces" in msg:
                    surfaces = msg["surfaces"]
                image = renderer.render(mesh, msg["camera"], msg["tf"], size=msg["size"], order=msg["order"],
                                        clip=msg.get("clip"), surfaces=surfaces)
                conn.send(("ok", image))
            except Exception as exc:  # noqa: BLE001 - sent to the parent, which raises it
                conn.send(("error", f"{type(exc).__name__}: {exc}", traceback.format_exc()))
    except Exception as exc:  # noqa: BLE001 - the renderer could not be made
        try:
            conn.send(("error", f"{type(exc).__name__}: {exc}", traceback.format_exc()))
        except OSError:
            pass
    finally:
        if raycaster is not None:
            raycaster.release()
        if renderer is not None:
            renderer.release()


class ProcessRenderer:
    """``render(mesh, camera, tf, size=, order=)`` as :class:`tetvr.gl.Renderer` does it,
    drawn in a child process. One frame at a time (a lock); thread-safe.

    Parameters
    ----------
    settings : the child's :class:`RenderSettings`; replacing :attr:`settings` between
        frames takes effect with the next frame (as for :class:`tetvr.gl.Renderer`).
    """

    def __init__(self, settings: RenderSettings | None = None) -> None:
        if settings is not None and not isinstance(settings, RenderSettings):
            raise TypeError(f"settings must be a RenderSettings or None, got {type(settings).__name__}")
        self.settings = settings or RenderSettings()
        self._lock = threading.Lock()
        self._proc: Any = None
        self._conn: Any = None
        self._sent_mesh: TetMesh | None = None
        self._sent_surfaces: tuple[Any, ...] = ()
        self._sent_volume: Any = None
        self._released = False

    def _start(self) -> None:
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        try:
            # Its own session: Jupyter interrupts and shuts down a kernel by signalling the kernel's
            # process group, and ipykernel's shutdown waits for that group's children to be reaped
            # (2.5 s, then a SIGTERM to the kernel). The child ends when the pipes close instead.
            proc = subprocess.Popen([sys.executable, "-m", "tetvr.apps.viewer.process", str(to_child_r), str(from_child_w)],
                                    pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL,
                                    start_new_session=True)
        except BaseException:
            for fd in (to_child_w, from_child_r):
                os.close(fd)
            raise
        finally:
            os.close(to_child_r)
            os.close(from_child_w)
        self._proc = proc
        self._conn = (Connection(to_child_w, readable=False), Connection(from_child_r, writable=False))
        self._sent_mesh = self._sent_volume = None
        self._sent_surfaces = ()
        self._conn[0].send(self.settings)

    def _call(self, msg: dict[str, Any]) -> Any:
        if self._released:
            raise RenderProcessError("this ProcessRenderer was released")
        if not self.alive:
            self._start()
        try:
            self._conn[0].send(msg)
            reply = self._conn[1].recv()  # waits without the interpreter lock
        except (EOFError, OSError):
            code = self._proc.poll() if self._proc is not None else None
            self._stop()
            raise RenderProcessError(f"the render process died (exit code {code})") from None
        if reply[0] == "error":
            raise RenderProcessError(reply[1])
        return reply[1]

    def render(self, mesh: TetMesh, camera: Camera, tf: TransferFunction, *, size: tuple[int, int] = (512, 512),
               order: NDArray[np.integer[Any]] | None = None, clip: Any = None,
               surfaces: Any = ()) -> NDArray[np.float32]:
        """One frame: (height, width, 4) float32 premultiplied RGBA, row 0 at the top."""
        with self._lock:
            msg: dict[str, Any] = {"camera": camera, "tf": tf, "size": tuple(size), "order": order,
                                   "settings": self.settings, "clip": clip}
            fresh = not self.alive
            if mesh is not self._sent_mesh or fresh:
                msg["mesh"] = mesh
            surfaces = tuple(surfaces)
            if fresh or surfaces != self._sent_surfaces:  # sent once, as the mesh
                msg["surfaces"] = surfaces
            image = self._call(msg)
            self._sent_mesh, self._sent_surfaces = mesh, surfaces
            return image  # type: ignore[no-any-return]

    def fuse(self, mesh: TetMesh, volume: Any, camera: Camera, tf: TransferFunction, volume_tf: TransferFunction, *,
             size: tuple[int, int] = (512, 512), mode: str = "interleave") -> NDArray[np.float32]:
        """The mesh inside an image volume, as :func:`tetvr.fuse.fuse` draws it (the volume
        crosses the pipe once, as the mesh does)."""
        with self._lock:
            msg: dict[str, Any] = {"op": "fuse", "camera": camera, "tf": tf, "volume_tf": volume_tf,
                                   "size": tuple(size), "mode": mode, "settings": self.settings}
            fresh = not self.alive
            if fresh or mesh is not self._sent_mesh:
                msg["mesh"] = mesh
            if fresh or volume is not self._sent_volume:
                msg["volume"] = volume
            image = self._call(msg)
            self._sent_mesh, self._sent_volume = mesh, volume
            return image  # type: ignore[no-any-return]

    def gpu_bytes(self) -> int:
        """GPU memory held by the child's renderer (0 before the first frame)."""
        with self._lock:
            if self._proc is None:
                return 0
            return int(self._call({"op": "gpu_bytes"}))

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def _stop(self, timeout: float = 10.0) -> None:
        proc, conn = self._proc, self._conn
        self._proc = self._conn = self._sent_mesh = self._sent_volume = None
        self._sent_surfaces = ()
        if conn is not None:
            try:
                conn[0].send(None)
            except OSError:
                pass
        if proc is not None:
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)
        if conn is not None:
            conn[0].close()
            conn[1].close()

    def release(self) -> None:
        """End the child process (its GL context and memory go with it). Idempotent."""
        with self._lock:
            self._released = True
            self._stop()

    def __enter__(self) -> "ProcessRenderer":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.release()


if __name__ == "__main__":  # pragma: no cover - the child: python -m tetvr.apps.viewer.process IN_FD OUT_FD
    _serve(Connection(int(sys.argv[1]), writable=False), Connection(int(sys.argv[2]), readable=False))
