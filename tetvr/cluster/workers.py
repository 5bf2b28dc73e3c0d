"""The Dask cluster tetvr renders on, and the renderer each of its workers keeps.

Both ways of rendering on more than one process (:mod:`tetvr.cluster.timeseries`, one task
per time step, and :mod:`tetvr.cluster.distributed`, one mesh as sort-last bricks) run on
``dask.distributed`` (pip install "tetvr[dask]"), so one code path runs on a laptop (a
:class:`~distributed.LocalCluster`), a cluster or an HPC batch system (dask-jobqueue):
:func:`cluster_client` opens the client, and :func:`worker_renderer` is the one
:class:`~tetvr.gl.Renderer` a worker process keeps for the run, on the worker's own GPU
(:func:`worker_egl_device`). :func:`gather` waits for a frame's tasks as long as the cluster
has workers, and fails with a clear error once it has had none for a while.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from typing import Any, Callable, Iterator, Mapping, Sequence

from tetvr.settings import RenderSettings

__all__ = ["cluster_client", "worker_renderer", "worker_egl_device", "gather", "wait", "as_completed", "wait_for_workers",
           "EGL_DEVICE_VARIABLE", "NO_WORKERS_TIMEOUT"]

_EXTRA = 'tetvr.cluster.distributed needs dask.distributed: pip install "tetvr[dask]"'


def _dask() -> Any:
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(f"{_EXTRA} ({exc})") from exc
    return distributed


@contextlib.contextmanager
def cluster_client(client: Any = None, *, n_workers: int | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` for the duration of the block.

    ``client``: a ``Client`` (used as is, left open), a scheduler address
    (``"tcp://host:8786"``), or None: the ``TETVR_SCHEDULER`` environment variable's
    address, else an in-process ``LocalCluster`` of ``n_workers`` worker processes (default:
    the CPU count, at most 4), one thread each, started by *spawn*: a worker forked from a
    process holding a GL context could not make its own (tetvr raises ForkedProcessError).
    """
    distributed = _dask()
    if isinstance(client, distributed.Client):
        yield client
        return
    address = client if client is not None else os.environ.get("TETVR_SCHEDULER") or None
    if address is not None:
        if not isinstance(address, str):
            raise TypeError(f"client must be a distributed.Client, a scheduler address or None, got {client!r}")
        with distributed.Client(address) as c:
            yield c
        return
    import dask

    n = n_workers or min(os.cpu_count() or 1, 4)
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers: every large temporary
    # array of a frame is then unmapped and faulted in again (measured: the first frame of a
    # 48k-tet step 0.65-0.75 s in a worker, 0.33-0.44 s with glibc's default).
    with dask.config.set({"distributed.worker.multiprocessing-method": "spawn",
                          "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        with distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                      silence_logs=logging.ERROR) as cluster, distributed.Client(cluster) as c:
            yield c


# One renderer per worker process and settings, kept across tasks: one GL context, its
# shaders, tables and mesh buffers, never one per frame.
_RENDERERS: dict[RenderSettings, Any] = {}
_RENDERERS_LOCK = threading.Lock()

#: The environment variable that names a worker's EGL device (an index into EGL's device list).
EGL_DEVICE_VARIABLE = "TETVR_EGL_DEVICE"


def worker_renderer(settings: RenderSettings | None = None) -> Any:
    """This process's :class:`~tetvr.gl.Renderer` for ``settings``, made on first use, on
    this worker's GPU (:func:`worker_egl_device`)."""
    from tetvr.gl.renderer import Renderer

    settings = settings or RenderSettings()
    with _RENDERERS_LOCK:
        r = _RENDERERS.get(settings)
        if r is None:
            r = _RENDERERS[settings] = Renderer(settings, device=worker_egl_device())
        return r


def worker_egl_device(environ: Mapping[str, str] | None = None,
                      cuda_devices: Sequence[int | None] | None = None) -> int | None:
    """The EGL device this process renders on: None for the driver's first, as a single
    process has it.

    1. ``TETVR_EGL_DEVICE`` (:data:`EGL_DEVICE_VARIABLE`), when set: that EGL device, as
       given (an index into EGL's device list).
    2. Else ``CUDA_VISIBLE_DEVICES``, when it names a GPU: the worker's GPU is the first
       it lists (dask-cuda gives each worker its own list, its GPU first; a batch system
       gives a job its GPUs), which this process numbers CUDA device 0. The EGL device
       that is CUDA device 0 (NVIDIA's EGL says which, :func:`tetvr.gl.context.egl_cuda_devices`;
       EGL's own order need not follow CUDA's) is chosen; where no EGL device says it is
       one (Mesa's llvmpipe), the driver's first.

    ``environ`` (default ``os.environ``) and ``cuda_devices`` (default
    :func:`~tetvr.gl.context.egl_cuda_devices`) are for tests.

    Examples
    --------
    >>> worker_egl_device({"TETVR_EGL_DEVICE": "1"})
    1
    >>> worker_egl_device({"CUDA_VISIBLE_DEVICES": "2,3,0,1"}, cuda_devices=[1, 0, 2, 3])
    1
    >>> worker_egl_device({}) is None
    True
    """
    env = os.environ if environ is None else environ
    given = env.get(EGL_DEVICE_VARIABLE, "").strip()
    if given:
        try:
            device = int(given)
        except ValueError:
            device = -1
        if device < 0:
            raise ValueError(f"{EGL_DEVICE_VARIABLE} must be a non-negative integer (an EGL device index), "
                             f"got {given!r}")
        return device
    visible = env.get("CUDA_VISIBLE_DEVICES", "").strip()
    if not visible or visible.split(",")[0].strip() in ("-1", "NoDevFiles"):
        return None
    if cuda_devices is None:
        from tetvr.gl.context import egl_cuda_devices

        cuda_devices = egl_cuda_devices()
    return next((k for k, cuda in enumerate(cuda_devices) if cuda == 0), None)


#: Seconds a frame waits while the cluster has no worker before it fails (environment:
#: ``TETVR_NO_WORKERS_TIMEOUT``).
NO_WORKERS_TIMEOUT = 60.0


def no_workers_timeout() -> float:
    """:data:`NO_WORKERS_TIMEOUT`, or ``TETVR_NO_WORKERS_TIMEOUT`` (seconds) where set."""
    given = os.environ.get("TETVR_NO_WORKERS_TIMEOUT", "").strip()
    if not given:
        return NO_WORKERS_TIMEOUT
    try:
        value = float(given)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise ValueError(f"TETVR_NO_WORKERS_TIMEOUT must be a positive number of seconds, got {given!r}")
    return value


def wait_for_workers(client: Any, what: str, timeout: float | None = None) -> list[str]:
    """The addresses of ``client``'s workers, waiting up to ``timeout`` seconds (default
    :func:`no_workers_timeout`) for one; ``TimeoutError`` naming ``what`` could not run."""
    limit = no_workers_timeout() if timeout is None else timeout
    deadline = time.monotonic() + limit
    while True:
        workers = sorted(client.nthreads())
        if workers:
            return workers
        if time.monotonic() >= deadline:
            raise TimeoutError(_no_workers(client, what, limit))
        time.sleep(min(0.2, limit))


class _NoWorkerTimer:
    """How long ``client``'s cluster has had no worker: :meth:`check` raises a
    ``TimeoutError`` naming ``what`` once none has been seen for ``limit`` seconds (counted
    from the first check that found none; a worker seen, or :meth:`reset`, starts it again).
    ``clock`` is for tests."""

    def __init__(self, client: Any, what: str, limit: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.client, self.what, self.limit, self.clock = client, what, limit, clock
        self.since: float | None = None

    def reset(self) -> None:
        self.since = None

    def check(self) -> None:
        if self.client.nthreads():
            self.since = None
            return
        now = self.clock()
        if self.since is None:
            self.since = now
        elif now - self.since >= self.limit:
            raise TimeoutError(_no_workers(self.client, self.what, self.limit))


def wait(client: Any, futures: list[Any], what: str, timeout: float | None = None) -> None:
    """Wait until ``futures`` are done (finished, failed or cancelled), or raise a
    ``TimeoutError`` naming ``what`` once the cluster has had no worker for ``timeout``
    seconds (default :func:`no_workers_timeout`): with every worker gone, Dask waits for
    ever. A frame that is only slow, with workers at it, is waited for."""
    distributed = _dask()
    limit = no_workers_timeout() if timeout is None else timeout
    timer = _NoWorkerTimer(client, what, limit)
    while True:
        try:
            distributed.wait(futures, timeout=min(0.5, limit))
            return
        except TimeoutError:
            timer.check()


def gather(client: Any, futures: list[Any], what: str, timeout: float | None = None) -> list[Any]:
    """``client.gather(futures)`` after :func:`wait`: a ``TimeoutError`` naming ``what``
    instead of waiting for ever where the cluster has no worker left."""
    wait(client, futures, what, timeout)
    return list(client.gather(futures))


def as_completed(client: Any, futures: list[Any], what: str, timeout: float | None = None) -> Iterator[Any]:
    """``futures`` as each is done, in the order they finish; a ``TimeoutError`` naming
    ``what`` once the cluster has had no worker for ``timeout`` seconds (:func:`wait`)."""
    distributed = _dask()
    limit = no_workers_timeout() if timeout is None else timeout
    timer = _NoWorkerTimer(client, what, limit)
    pending = list(futures)
    while pending:
        try:
            done, _ = distributed.wait(pending, timeout=min(0.5, limit), return_when="FIRST_COMPLETED")
        except TimeoutError:
            done = set()
        if not done:
            timer.check()
            continue
        timer.reset()
        yield from (f for f in pending if f in done)
        pending = [f for f in pending if f not in done]


def _no_workers(client: Any, what: str, limit: float) -> str:
    address = getattr(client.scheduler, "address", "?")
    return (f"{what}: no Dask worker has been connected to the scheduler at {address} for {limit:g} s, so its tasks "
            f"cannot run (every worker exited, was killed or lost its connection). Start workers "
            f"(`dask worker {address}`), or give them longer with TETVR_NO_WORKERS_TIMEOUT=<seconds>")
