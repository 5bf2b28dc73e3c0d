"""The files a cluster reads and writes, with no file system shared with the client.

A **path** names a file on the client's machine (relative to the client's working
directory): the client reads it, with the files it names (a ``.pvd`` step's parts, a
``.pvtu``'s pieces, an XDMF file's HDF5 data), and sends the bytes to the worker, which
reads them from a temporary folder of its own (:func:`local_files`, :func:`materialised`).
A **URL** (``s3://``, ``gs://``, ``https://``, ``file:///shared/...``: any protocol of
`fsspec <https://filesystem-spec.readthedocs.io>`_, which Dask installs) names data the
workers reach themselves: each worker reads it through fsspec (:func:`url_files`), and a
``file://`` URL is read in place on the worker's own file system. A worker that cannot
reach a URL fails naming it and the worker.

Frames go back the same way: to a path, the client writes the PNG bytes a worker encoded;
to a URL, the worker writes them there (:func:`write_bytes`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import posixpath
import re
import socket
import tempfile
import xml.etree.ElementTree as ET
from typing import Any, Iterator, Sequence

from tetvr.core.checks import check_input_file, short_path

__all__ = ["Files", "is_url", "local_files", "url_files", "materialised", "read_error", "named_error", "write_bytes",
           "url_pvd_steps", "url_leaf_files", "url_glob", "fetch_bytes"]

# The temporary folders of the files a worker was sent or fetched.
_COPY = "tetvr-files-"
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]+(::[A-Za-z][A-Za-z0-9+.\-]+)*://")


def is_url(name: Any) -> bool:
    """Whether ``name`` is a URL (``protocol://...``) rather than a path on this machine.

    Examples
    --------
    >>> is_url("s3://bucket/run.pvd"), is_url("file:///data/a.vtu"), is_url("data/a.vtu"), is_url("C:\\\\a.vtu")
    (True, True, False, False)
    """
    return isinstance(name, str) and _URL.match(name) is not None


@dataclasses.dataclass(frozen=True)
class Files:
    """A file for a worker to read and the files beside it that it names: each sent as
    bytes or fetched by URL, under a name relative to one folder (``/``-separated).
    ``shown`` is the file as the user named it, for messages."""

    main: str
    sent: tuple[tuple[str, bytes], ...] = ()
    fetched: tuple[tuple[str, str], ...] = ()
    shown: str = ""

    @property
    def nbytes(self) -> int:
        return sum(len(b) for _, b in self.sent)


def _relative(names: Sequence[str], folder_of: Any) -> tuple[str, list[str]]:
    root = folder_of.commonpath([folder_of.dirname(n) for n in names])
    return root, [folder_of.relpath(n, root).replace(os.sep, "/") for n in names]


def local_files(path: str | os.PathLike[str], what: str, companions: Sequence[str] = (), *,
                replace: dict[str, bytes] | None = None) -> Files:
    """``path``, a file on this machine (relative to the working directory here), and the
    files it names (``companions``), read here for a worker: a :class:`Files` of bytes.
    ``replace`` gives the bytes of some of them (absolute path -> bytes) instead."""
    shown = os.fspath(path)
    full = os.path.abspath(shown)
    try:
        check_input_file(full, what)
    except FileNotFoundError:
        relative = "" if shown == full else f" (in {os.getcwd()!r}, the client's working directory)"
        raise FileNotFoundError(
            f"{what} not found on the client: {short_path(shown)!r}{relative}. A path names a file on the "
            "machine that runs tetvr, which sends its bytes to the workers; for data that only the workers "
            "reach, give a URL (file:///shared/..., s3://...)") from None
    names = list(dict.fromkeys([full] + [os.path.abspath(c) for c in companions]))
    _, rel = _relative(names, os.path)
    given = replace or {}
    sent = []
    for name, r in zip(names, rel):
        if name in given:
            sent.append((r, given[name]))
            continue
        check_input_file(name, f"file named by {os.path.basename(full)}")
        with open(name, "rb") as f:
            sent.append((r, f.read()))
    return Files(main=rel[0], sent=tuple(sent), shown=shown)


def _split(url: str) -> tuple[str, str]:
    head, _, path = url.rpartition("://")
    return head + "://", path


def url_files(url: str, companions: Sequence[str] = (), *, sent: dict[str, bytes] | None = None) -> Files:
    """``url`` and the URLs it names (``companions``), for each worker to fetch itself;
    ``sent`` gives some of them (URL -> bytes) to send instead (a collection rewritten
    here)."""
    names = list(dict.fromkeys([url, *companions]))
    protocols = {_split(n)[0] for n in names}
    if len(protocols) > 1:
        raise ValueError(f"{url!r} names files through other protocols ({sorted(protocols)}): not supported")
    _, rel = _relative([_split(n)[1] for n in names], posixpath)
    given = sent or {}
    return Files(main=rel[0], sent=tuple((r, given[n]) for n, r in zip(names, rel) if n in given),
                 fetched=tuple((r, n) for n, r in zip(names, rel) if n not in given), shown=url)


def _where() -> str:
    try:
        from distributed import get_worker

        return f"worker {get_worker().address} on {socket.gethostname()}"
    except (ImportError, ValueError):
        return f"{socket.gethostname()}"


def _fs(url: str) -> tuple[Any, str]:
    import fsspec

    return fsspec.core.url_to_fs(url)


@contextlib.contextmanager
def materialised(files: Files) -> Iterator[str]:
    """The path, on this machine, to read ``files.main`` from: in place where every file is
    a URL of a local file system (``file://``), else in a temporary folder where the sent
    bytes are written and the URLs fetched (removed at the end of the block)."""
    from fsspec.implementations.local import LocalFileSystem

    if not files.sent and files.fetched:
        fs, main = _fs(dict(files.fetched)[files.main])
        if isinstance(fs, LocalFileSystem):
            for _, url in files.fetched:
                if not os.path.isfile(_fs(url)[1]):
                    raise FileNotFoundError(f"{url!r} is not a file on the file system of {_where()} "
                                            f"(working directory {os.getcwd()!r})")
            yield main
            return
    with tempfile.TemporaryDirectory(prefix=_COPY) as tmp:
        for rel, data in files.sent:
            _put(tmp, rel, data)
        for rel, url in files.fetched:
            try:
                data = fetch_bytes(url)
            except FileNotFoundError:
                raise FileNotFoundError(f"{url!r} could not be read by {_where()}: not found") from None
            _put(tmp, rel, data)
        yield os.path.join(tmp, *files.main.split("/"))


def _put(folder: str, rel: str, data: bytes) -> None:
    path = os.path.join(folder, *rel.split("/"))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


def fetch_bytes(url: str) -> bytes:
    """The bytes at ``url`` (through fsspec)."""
    fs, path = _fs(url)
    return bytes(fs.cat_file(path))


def read_error(exc: BaseException, files: Files, path: str, what: str) -> str:
    """The message for ``exc``, raised reading ``path`` (see :func:`materialised`): it
    names ``files`` as the user gave them, not the worker's temporary copy."""
    text = str(exc)
    root = next((p for p in [path, *_parents(path)] if os.path.basename(p).startswith(_COPY)), None)
    if root is not None:
        shown = files.shown
        text = text.replace(root + os.sep, shown[:len(shown) - len(files.main)] if shown.endswith(files.main) else "")
    return f"{what} {short_path(files.shown)!r} could not be read on {_where()}: {text}"


def _parents(path: str) -> list[str]:
    out = []
    while os.path.dirname(path) != path:
        path = os.path.dirname(path)
        out.append(path)
    return out


def named_error(exc: BaseException, files: Files, path: str, what: str) -> BaseException:
    """``exc`` as an error of the same kind with the message of :func:`read_error`."""
    message = read_error(exc, files, path, what)
    try:
        return type(exc)(message)
    except Exception:  # an error type that takes other arguments
        return RuntimeError(message)


def write_bytes(data: bytes, url: str) -> str:
    """Write ``data`` to ``url`` (through fsspec; on a local file system atomically, as
    :func:`tetvr.core.image.atomic_output`). Returns ``url``."""
    from fsspec.implementations.local import LocalFileSystem

    from tetvr.core.image import atomic_output

    fs, path = _fs(url)
    if isinstance(fs, LocalFileSystem):
        with atomic_output(path) as f:
            f.write(data)
    else:
        fs.pipe_file(path, data)
    return url


# ---- collections named by URL: their XML read here, their files fetched by the workers ----

def _xml(url: str, tag: str) -> ET.Element:
    try:
        root = ET.fromstring(fetch_bytes(url))
    except ET.ParseError as exc:
        raise ValueError(f"cannot read collection file {url!r}: not valid XML ({exc})") from None
    body = root.find(tag)
    if root.tag != "VTKFile" or body is None:
        raise ValueError(f"cannot read collection file {url!r}: not a VTK XML file with <{tag}>")
    return body


def _beside(url: str, name: str | None) -> str:
    if not name or not name.strip():
        raise ValueError(f"{url!r}: a data set has no file name")
    head, path = _split(url)
    return head + posixpath.normpath(posixpath.join(posixpath.dirname(path), name.strip()))


def url_pvd_steps(url: str) -> list[tuple[float, list[str]]]:
    """The time steps of a ``.pvd`` at ``url``: (time, the URLs of its parts), in time order."""
    by_time: dict[float, list[str]] = {}
    for ds in _xml(url, "Collection").iter("DataSet"):
        by_time.setdefault(float(ds.get("timestep", "0")), []).append(_beside(url, ds.get("file")))
    if not by_time:
        raise ValueError(f"{url!r}: the collection has no DataSet with a file")
    return sorted(by_time.items())


def url_leaf_files(url: str, _depth: int = 0) -> list[str]:
    """The mesh files (URLs) of a ``.pvtu`` or ``.vtm`` at ``url``, down to the leaves."""
    suffix = posixpath.splitext(url)[1].lower()
    if _depth > 16:
        raise ValueError(f"collection files nested deeper than 16 levels at {url!r}")
    if suffix == ".pvtu":
        named = [_beside(url, p.get("Source")) for p in _xml(url, "PUnstructuredGrid").iter("Piece")]
    elif suffix == ".vtm":
        named = [_beside(url, d.get("file")) for d in _xml(url, "vtkMultiBlockDataSet").iter("DataSet")
                 if d.get("file")]
    else:
        return [url]
    return [leaf for n in named for leaf in url_leaf_files(n, _depth + 1)]


def url_glob(pattern: str) -> list[str]:
    """The URLs matching a glob ``pattern`` (``s3://bucket/run/step_*.vtu``), unsorted."""
    fs, path = _fs(pattern)
    return [fs.unstrip_protocol(p) for p in fs.glob(path)]
