"""Every ```python and ```bash block of README.md and docs/*.md runs, as a reader would run
it from the repository's root, on the data the repository ships.

* Each document runs in a fresh folder that holds a copy of ``meshes/`` and
  ``tests/data/`` (so no block writes into the repository) and, where it exists, the
  shared real data at ``../shared/data``. Its blocks run in order, in that folder, so a
  block may use what an earlier block made: the python blocks in one namespace, as in a
  notebook; the bash blocks line by line, each line to succeed, a ``tetvr ...`` line as
  bash would pass its arguments but through ``tetvr.apps.cli.main`` in this process (the
  function the ``tetvr`` script calls: no interpreter and GL context to start per command),
  any other line in bash.
* ``<!-- not run: REASON -->`` on the line before a block leaves it out, with its reason
  (software or hardware this machine does not have). Such markers are counted by
  document in :data:`NOT_RUN`, so that a new one is added on purpose.
* A block that names ``../shared/data`` skips the rest of its document where that folder
  is absent, and so does a block that needs an optional package (an extra of
  pyproject.toml) that is not installed: a python block by its ``ModuleNotFoundError``, a
  bash block by the CLI's exit status 3 with ``pip install`` in its message.
* distributed.md's blocks run on one local Dask cluster of 2 workers that the test starts
  and names in ``TETVR_SCHEDULER``, which every function and ``--scheduler local`` then use
  (as the page describes), instead of a cluster per call.
* To keep the suite fast, commands run smaller than written: ``tetvr render`` without
  ``--size`` gets ``--size 200x150``, ``tetvr fusion-demo`` and ``tetvr compare``
  ``--size 160 120`` (``compare`` also ``--views 2``), and ``tetvr animate --orbit N``
  at most 2 frames. ``pip install ...`` installs nothing (the suite runs where tetvr is
  installed): it checks that the extras it names exist in pyproject.toml.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The shared real data (as tests/conftest.py finds it; not imported from there, so that the
#: pip shim can import this module alone).
SHARED = Path(os.environ.get("TETVR_SHARED_DATA", ROOT.parent / "shared" / "data"))
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Languages of fenced blocks: those run, and those only shown.
RUN = {"python", "bash"}
SHOWN = {"json", "text"}
_FENCE = re.compile(r"^```(?P<lang>\S*)\s*$")
_NOT_RUN = re.compile(r"^<!-- not run: (?P<reason>.+?) -->$")

#: Blocks marked ``<!-- not run: ... -->``, by document. Each needs what this machine has
#: not got; keep them few.
NOT_RUN = {"README.md": 1, "quickstart.md": 1, "distributed.md": 3, "interactive.md": 1}


@dataclass(frozen=True)
class Block:
    """One fenced block: where it starts (1-based line of the fence), its language and code,
    and the reason it is not run (None: it runs)."""

    doc: str
    line: int
    lang: str
    code: str
    not_run: str | None


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file, in order."""
    lines = path.read_text().splitlines()
    found, i = [], 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), None)
        assert end is not None, f"{path.name}:{i + 1}: a fenced block that is never closed"
        marker = _NOT_RUN.match(lines[i - 1].strip()) if i else None
        found.append(Block(path.name, i + 1, m["lang"], "\n".join(lines[i + 1:end]),
                           marker["reason"] if marker else None))
        i = end + 1
    return found


# ---------------------------------------------------------------- bash, made smaller
def smaller(line: str) -> str:
    """A bash line with its tetvr commands sized down (the module docstring lists how)."""
    code, hash_, comment = line.partition(" #")
    if re.search(r"\btetvr render\b", code) and "--size" not in code:
        code = re.sub(r"\btetvr render\b", "tetvr render --size 200x150", code)
    for cmd, extra in (("fusion-demo", ""), ("compare", " --views 2")):
        if re.search(rf"\btetvr {cmd}\b", code) and "--size" not in code:
            code = re.sub(rf"\btetvr {cmd}\b", f"tetvr {cmd} --size 160 120{extra}", code)
    code = re.sub(r"(\btetvr animate\b.*--orbit )(\d+)", lambda m: m[1] + str(min(int(m[2]), 2)), code)
    return code + hash_ + comment


def extras() -> set[str]:
    """The optional-dependency groups pyproject.toml declares."""
    text = (ROOT / "pyproject.toml").read_text()
    section = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    return set(re.findall(r"^([\w-]+)\s*=", section, re.M))


def check_pip(args: list[str]) -> str:
    """What ``pip install ...`` in a block asks for, checked instead of run: tetvr itself
    (``.``, ``-e .``, ``tetvr``), with extras that pyproject.toml declares."""
    words = [a for a in args if a not in ("-e", "--editable", "-U", "--upgrade")]
    if words[:1] != ["install"] or len(words) != 2:
        return f"pip {' '.join(args)}: not one package to install"
    m = re.fullmatch(r"(\.|tetvr)(\[([\w,-]+)\])?", words[1].strip("'\""))
    if m is None:
        return f"pip install {words[1]}: not tetvr"
    unknown = set((m[3] or "").split(",")) - extras() - {""}
    return f"pip install {words[1]}: no extra {sorted(unknown)} in pyproject.toml" if unknown else ""


_PIP_SHIM = """import sys
sys.path.insert(0, {tests!r})
from test_docs_run import check_pip
problem = check_pip(sys.argv[1:])
sys.exit(problem or print("checked, not installed: pip", *sys.argv[1:]))
"""


def _bash(script: str, work: Path) -> subprocess.CompletedProcess:
    shim = work.parent / "pip_shim.py"
    shim.write_text(_PIP_SHIM.format(tests=str(Path(__file__).parent)))
    prelude = f'pip() {{ "{sys.executable}" "{shim}" "$@"; }}\n'
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
               MPLBACKEND="Agg")
    return subprocess.run(["bash", "-e", "-c", prelude + script], cwd=work, env=env, capture_output=True,
                          text=True, timeout=300)


def tetvr_argv(line: str, work: Path) -> list[str] | None:
    """The arguments of a ``tetvr ...`` command line as bash would pass them (quotes, globs,
    comments), or None for any other line."""
    if not re.match(r"\s*tetvr\s", line):
        return None
    run = _bash(f"set -- {line.strip()}\nprintf '%s\\0' \"$@\"", work)
    assert run.returncode == 0, f"{line}: {run.stderr}"
    return run.stdout.split("\0")[1:-1]


def run_bash(block: Block, work: Path) -> None:
    """A bash block, line by line: a ``tetvr`` command runs in this process
    (``tetvr.apps.cli.main``, the function behind the ``tetvr`` script: no interpreter and
    GL context to start per command), any other line in bash."""
    from tetvr.apps.cli import main

    for line in block.code.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        line = smaller(line)
        argv = tetvr_argv(line, work)
        if argv is None:
            run = _bash(line, work)
            status, out, err = run.returncode, run.stdout, run.stderr
        else:
            out_io, err_io = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(out_io), contextlib.redirect_stderr(err_io):
                status = main(argv)
            out, err = out_io.getvalue(), err_io.getvalue()
        if status == 3 and "pip install" in err:
            pytest.skip(f"{block.doc}:{block.line} and after: {err.strip().splitlines()[-1]}")
        assert status == 0, (f"{block.doc}:{block.line}: a bash block failed (status {status})\n{line}\n"
                             f"--- stdout\n{out[-3000:]}\n--- stderr\n{err[-3000:]}")


def optional_modules() -> set[str]:
    """The import names of the packages pyproject.toml's extras add (``imageio-ffmpeg`` is
    ``imageio_ffmpeg``; ``dask[distributed]`` also brings ``distributed``)."""
    text = (ROOT / "pyproject.toml").read_text()
    section = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    names = {re.split(r"[<>=\[; ]", req, 1)[0].lower().replace("-", "_") for req in re.findall(r'"([^"]+)"', section)}
    return names | {"distributed"}


def run_python(block: Block, namespace: dict) -> None:
    code = compile(block.code, f"{block.doc}:{block.line}", "exec")
    try:
        exec(code, namespace)
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0].lower() in optional_modules():
            pytest.skip(f"{block.doc}:{block.line} and after: optional package {exc.name} is not installed")
        raise AssertionError(f"{block.doc}:{block.line}: a python block failed: {exc!r}\n{block.code}") from exc
    except Exception as exc:
        raise AssertionError(f"{block.doc}:{block.line}: a python block failed: {exc!r}\n{block.code}") from exc


def _close(namespace: dict) -> None:
    """Close what the blocks left open (viewers, renderers, Dask clients)."""
    for value in list(namespace.values()):
        module = type(value).__module__ or ""
        if module.startswith(("tetvr", "distributed")):
            for name in ("close", "release"):
                if callable(getattr(value, name, None)):
                    getattr(value, name)()
                    break


def _workdir(tmp_path: Path) -> Path:
    work = tmp_path / "tetvr"
    shutil.copytree(ROOT / "meshes", work / "meshes")
    shutil.copytree(ROOT / "tests" / "data", work / "tests" / "data")
    if SHARED.is_dir():
        (tmp_path / "shared").mkdir()
        (tmp_path / "shared" / "data").symlink_to(SHARED)
    return work


DOCS_WITH_CODE = [d for d in DOCS if any(b.lang in RUN for b in blocks(d))]


@pytest.mark.gl
@pytest.mark.parametrize("doc", DOCS_WITH_CODE, ids=lambda p: p.name)
def test_the_blocks_of_a_document_run(doc: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    work = _workdir(tmp_path)
    monkeypatch.chdir(work)
    namespace: dict = {"__name__": "__main__"}
    ran = []
    with contextlib.ExitStack() as stack:
        if doc.name == "distributed.md":
            monkeypatch.setenv("TETVR_SCHEDULER", stack.enter_context(_one_cluster()))
        _run_document(doc, work, namespace, ran)
    print(f"{doc.name}: ran the blocks at lines {ran}")
    assert ran, f"{doc.name}: no block ran"


@contextlib.contextmanager
def _one_cluster() -> Iterator[str]:
    """A local Dask cluster of 2 workers for the document's blocks; yields its address."""
    pytest.importorskip("distributed", reason="distributed.md needs tetvr[dask]")
    from tetvr.cluster.workers import cluster_client

    os.environ.pop("TETVR_SCHEDULER", None)
    with cluster_client(n_workers=2) as client:
        client.wait_for_workers(2, timeout=120)
        yield client.scheduler.address


def _run_document(doc: Path, work: Path, namespace: dict, ran: list[int]) -> None:
    try:
        for block in blocks(doc):
            if block.lang not in RUN or block.not_run:
                continue
            if "../shared/data" in block.code and not SHARED.is_dir():
                pytest.skip(f"{doc.name}:{block.line} and after: shared data not available: {SHARED}")
            (run_python(block, namespace) if block.lang == "python" else run_bash(block, work))
            ran.append(block.line)
    finally:
        _close(namespace)


def test_every_block_is_run_or_marked():
    """A block in another language (``sh``, ``shell``, ``console``) would escape the test."""
    for doc in DOCS:
        for b in blocks(doc):
            assert b.lang in RUN | SHOWN, (f"{doc.name}:{b.line}: a ```{b.lang} block; write ```bash or ```python "
                                           f"(run by this test) or one of {sorted(SHOWN)}")
            assert b.not_run is None or b.lang in RUN, f"{doc.name}:{b.line}: a not-run marker on a {b.lang} block"


def test_not_run_markers_are_few_and_counted():
    found = {}
    for doc in DOCS:
        n = sum(b.not_run is not None for b in blocks(doc))
        if n:
            found[doc.name] = n
        stray = [i + 1 for i, line in enumerate(doc.read_text().splitlines())
                 if "<!-- not run" in line and not _NOT_RUN.match(line.strip())]
        assert not stray, f"{doc.name}: lines {stray}: write the marker as <!-- not run: REASON --> alone on its line"
    assert found == NOT_RUN, f"not-run markers by document: {found}, expected {NOT_RUN}"
    for doc in DOCS:
        lines = doc.read_text().splitlines()
        for i, line in enumerate(lines[:-1]):
            if _NOT_RUN.match(line.strip()):
                assert _FENCE.match(lines[i + 1]), f"{doc.name}:{i + 1}: a not-run marker not right before a block"


def test_smaller_sizes_only_the_commands_it_names():
    assert smaller("tetvr render a.vtu -o a.png  # x --size") == "tetvr render --size 200x150 a.vtu -o a.png  # x --size"
    assert smaller("tetvr render a.vtu --size 9x9") == "tetvr render a.vtu --size 9x9"
    assert smaller("tetvr animate s.json --orbit 72 -o o.mp4") == "tetvr animate s.json --orbit 2 -o o.mp4"
    assert smaller("tetvr compare s.json -o c/") == "tetvr compare --size 160 120 --views 2 s.json -o c/"
    assert smaller("tetvr info m.vtu") == "tetvr info m.vtu"


def test_pip_lines_are_checked_against_the_extras():
    assert check_pip(["install", ".[plot]"]) == "" and check_pip(["install", "-e", ".[test,dask]"]) == ""
    assert check_pip(["install", "tetvr[widget]"]) == ""
    assert "no extra ['plots']" in check_pip(["install", ".[plots]"])
    assert "not tetvr" in check_pip(["install", "numpy"])
