"""A new mesh's records and walk check, built in the background while the first frame's
table is (tetvr.gl.raymarch takes them)."""

from __future__ import annotations

import threading
from concurrent.futures import Future

from tetvr.mesh.copies import DistinctCells, distinct_cells
from tetvr.mesh.locality import spatially_ordered
from tetvr.mesh.records import MarchRecords, march_records
from tetvr.mesh.tetmesh import TetMesh
from tetvr.order.walkable import walk_check

__all__ = ["Prefetch", "records"]

#: One background thread builds a new mesh's face adjacency and records while the
#: renderer builds the frame's table (both numpy, which lets go of the GIL in its loops),
#: then the rest of the mesh's walk check (overlaps, folds) while the renderer puts the
#: records on the GL: the first frame overlaps them instead of adding them.
#: The thread is a daemon, so that an interpreter leaving (Ctrl-C in a script) does not wait
#: for a build it no longer needs; one build runs at a time.
BUILD_LOCK = threading.Lock()


class Prefetch:
    """A mesh's :func:`records` and then its :func:`~tetvr.order.walkable.walk_check`,
    built in a daemon thread: ``records`` is done as soon as the records are (the check's
    face adjacency with them), ``check`` once the whole check is."""

    def __init__(self, mesh: TetMesh) -> None:
        self.mesh = mesh
        self.records: Future[tuple[DistinctCells, MarchRecords]] = Future()
        self.check: Future[None] = Future()
        threading.Thread(target=self._build, name="tetvr-records", daemon=True).start()

    def _build(self) -> None:
        for future in (self.records, self.check):
            future.set_running_or_notify_cancel()
        with BUILD_LOCK:
            for future, build in ((self.records, lambda: records(self.mesh)), (self.check, lambda: _checked(self.mesh))):
                try:
                    future.set_result(build())
                except BaseException as exc:  # handed to whoever takes the result
                    future.set_exception(exc)


def _checked(mesh: TetMesh) -> None:
    walk_check(mesh)  # cached with the mesh's face adjacency


def records(mesh: TetMesh) -> tuple[DistinctCells, MarchRecords]:
    """The mesh the walk goes through (its points along a space-filling curve,
    :mod:`tetvr.mesh.locality`; each repeated cell once, :mod:`tetvr.mesh.copies`) and its
    records, cached with the mesh."""
    distinct = distinct_cells(spatially_ordered(mesh))
    return distinct, march_records(distinct.mesh, cells=False)  # the per-tet records go to the GL in blocks
