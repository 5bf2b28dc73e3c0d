"""The Dask cluster tetvr renders on, and the renderer each of its workers keeps.

Both ways of rendering on more than one process (:mod:`tetvr.cluster.timeseries`, one task
per time step, and :mod:`tetvr.cluster.distributed`, one mesh as sort-last bricks) run on
``dask.distributed`` (pip install "tetvr[dask]"), so one code path runs on a laptop (a
:class:`~distributed.LocalCluster`), a cluster or an HPC batch system (dask-jobqueue):
:func:`cluster_client` opens the client, and :func:`worker_renderer` is the one
:class:`~tetvr.gl.Renderer` a worker process keeps for the run.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from typing import Any, Iterator

from tetvr.settings import RenderSettings

__all__ = ["cluster_client", "worker_renderer"]

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


def worker_renderer(settings: RenderSettings | None = None) -> Any:
    """This process's :class:`~tetvr.gl.Renderer` for ``settings``, made on first use."""
    from tetvr.gl.renderer import Renderer

    settings = settings or RenderSettings()
    with _RENDERERS_LOCK:
        r = _RENDERERS.get(settings)
        if r is None:
            r = _RENDERERS[settings] = Renderer(settings)
        return r
