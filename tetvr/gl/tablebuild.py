"""The pre-integration table's runs built on the GPU (``shaders/table_runs.comp``).

:func:`tetvr.optics.preintegrate.build_table` spends most of its time on the off-diagonal
entries: along every diagonal of every thickness slice a recurrence over the scalar bins
(:func:`~tetvr.optics.preintegrate._fill_runs`), O(N^2 K) steps that numpy runs as N
Python iterations over arrays of N K, with some 200 MB of temporaries for a 512-bin table
(page faults on a first build cost as much as the arithmetic). The diagonals are
independent, so a compute shader runs each (run length, slice, direction) as one
invocation, in double precision, and writes the entries already encoded; the CPU keeps
the cheap O(N^2) parts (the nodes, the extinctions, slice 0, the diagonal).

The GPU's table equals the CPU's to float32 rounding (``tests/test_table_gpu.py``); the
build is used for "normalized" float32 tables with even nodes (the default), and the CPU
builds the others.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from tetvr.gl.context import current_in_thread
from tetvr.gl.shaders import ShaderCompileError, assemble, explain
from tetvr.gl.util import clear_gl_errors

__all__ = ["TableRuns", "compile_runs", "ring_size"]

#: Invocations per work group (``local_size_x`` in table_runs.comp).
_GROUP = 64


def ring_size(n_bins: int) -> int:
    """``table_runs.comp``'s ``RING`` for a table of ``n_bins`` bins: the least power of two
    at least the bins (a bin's colour is read back at most ``n_bins`` steps after it is
    kept), and at least 256, so that few programs serve every table."""
    return max(256, 1 << max(int(n_bins) - 1, 1).bit_length())


def compile_runs(ctx: Any, ring: int) -> Any:
    """``table_runs.comp`` compiled in ``ctx`` with ``RING`` ``ring`` (:func:`ring_size`;
    the caller owns the program)."""
    src, files = assemble("table_runs.comp", {"RING": ring})
    try:
        return ctx.compute_shader(src)
    except Exception as exc:
        raise ShaderCompileError(f"table_runs.comp: {explain(exc, files)}") from exc


class TableRuns:
    """Builds the runs of pre-integration tables with a GL context and the compiled
    ``table_runs.comp`` (``program()`` gives it), neither of which it owns.

    ``program(ring)`` gives the program compiled with ``RING`` ``ring`` (:func:`ring_size`).
    An instance is what :func:`~tetvr.optics.preintegrate.build_table` takes as ``runs``:
    called with each bin's colour at its start and end, its mean extinction, the prefix
    sum of those, and the slices' thicknesses, it writes slices 1..K's off-diagonal entries
    into ``out`` (N, N, K + 1, RGBA float32, indexed [back, front, slice]: the table
    texture's layout); what it leaves there (slice 0, the diagonal) is undefined.
    """

    def __init__(self, ctx: Any, program: Callable[[int], Any]) -> None:
        self.ctx = ctx
        self._program = program

    def __call__(self, start: NDArray[np.float64], end: NDArray[np.float64], tau_bin: NDArray[np.float64],
                 prefix: NDArray[np.float64], thick: NDArray[np.float64], out: NDArray[np.float32]) -> None:
        nb, n_slices = tau_bin.size, thick.size
        if out.shape != (nb + 1, nb + 1, n_slices + 1, 4) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous float32 array of shape {(nb + 1, nb + 1, n_slices + 1, 4)}, "
                             f"got {out.dtype} {out.shape}")
        bins = np.zeros((nb, 2, 4))
        bins[:, 0, :3], bins[:, 0, 3], bins[:, 1, :3] = start, tau_bin, end
        with current_in_thread(self.ctx):
            program = self._program(ring_size(nb))
            objects: list[Any] = []
            try:
                # Doubles as pairs of uints: 4 RGBA texels a bin, one RG texel per prefix or thickness.
                for unit, (data, components) in enumerate(((bins, 4), (prefix, 2), (thick, 2))):
                    words = np.ascontiguousarray(data, dtype=np.float64).view(np.uint32).reshape(-1)
                    tex = self.ctx.texture((words.size // components, 1), components, words.tobytes(), dtype="u4")
                    objects.append(tex)
                    tex.bind_to_image(unit, read=True, write=False)
                out_buffer = self.ctx.buffer(reserve=out.nbytes)
                objects.append(out_buffer)
                out_buffer.bind_to_storage_buffer(3)
                program["u_count"] = nb
                program.run(math.ceil(nb / _GROUP), n_slices, 2)
                self.ctx.memory_barrier()
                out_buffer.read_into(memoryview(out).cast("B"))
            except Exception as exc:
                errors = clear_gl_errors(self.ctx)
                if any("OUT_OF_MEMORY" in e for e in errors):
                    raise MemoryError(f"the GL could not hold a {nb + 1} x {nb + 1} x {n_slices + 1} "
                                      f"pre-integration table ({out.nbytes / 2**20:.0f} MiB)") from exc
                raise
            finally:
                for obj in objects:
                    obj.release()
