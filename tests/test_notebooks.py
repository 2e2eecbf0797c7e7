"""The notebooks ship executed and are the files ``notebooks/make_notebooks.py`` writes: their
cells are the script's, every code cell has its outputs (none an error), and executing them
again gives the same outputs, numbers, paths and figures' pixels aside (so editing one
without the other, or changing what the code prints without regenerating them, is
caught)."""

from __future__ import annotations

import copy
import importlib.util
import re
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat", reason="notebooks need the 'dev' extra")
nbclient = pytest.importorskip("nbclient", reason="notebooks need the 'dev' extra")

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
NAMES = ["quickstart", "compare_solvers"]


def _generator():
    spec = importlib.util.spec_from_file_location("make_notebooks", NOTEBOOKS / "make_notebooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _code(nb) -> list:
    return [c for c in nb.cells if c.cell_type == "code"]


_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_PATH = re.compile(r"(/[\w.+-]+)+/?")


def _normalised(text: str) -> str:
    """``text`` with its absolute paths and numbers masked and runs of spaces made one: they
    change with the machine, the checkout's place and the timing (a table's column widths
    follow its numbers), not with what the code does."""
    return re.sub(r"[ \t]+", " ", _NUMBER.sub("#", _PATH.sub("<path>", text)))


def _outputs(cell) -> list[tuple]:
    """What a cell showed, comparable across runs: each stdout text (normalised), each
    result's or display's MIME types and plain text (normalised); stderr (a compile notice
    on a cold cache, warnings) left out."""
    out = []
    for o in cell.get("outputs", []):
        if o.output_type == "stream" and o.name == "stdout":
            out.append(("stdout", _normalised(o.text)))
        elif o.output_type in ("execute_result", "display_data"):
            out.append(
                (o.output_type, tuple(sorted(o.data)), _normalised(o.data.get("text/plain", "")))
            )
        elif o.output_type == "error":
            out.append(("error", o.ename, o.evalue))
    return out


@pytest.mark.parametrize("name", NAMES)
def test_shipped_notebooks_are_executed(name):
    """Opened, a notebook shows what it computes: every code cell has run, in order, and has
    outputs, none of them an error; the figures are there as PNGs."""
    nb = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
    code = _code(nb)
    assert code, f"{name} has no code"
    assert [c.execution_count for c in code] == list(range(1, len(code) + 1)), (
        f"notebooks/{name}.ipynb is not executed top to bottom: run notebooks/make_notebooks.py"
    )
    for i, cell in enumerate(code):
        assert cell.outputs, f"{name}: code cell {i} has no output"
        assert all(o.output_type != "error" for o in cell.outputs), f"{name}: cell {i} failed"
    pngs = [o for c in code for o in c.outputs if "image/png" in o.get("data", {})]
    assert pngs, f"{name} ships no figure"


def test_notebooks_are_the_generated_ones():
    gen = _generator()
    for name, cells in (("quickstart", gen.QUICKSTART), ("compare_solvers", gen.COMPARE)):
        nb = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
        assert [c.source for c in nb.cells] == [c.source for c in cells], (
            f"notebooks/{name}.ipynb differs from make_notebooks.py: run the script"
        )


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_notebook_executes_to_its_shipped_outputs(name, tmp_path, monkeypatch):
    """Executed again (as make_notebooks.py does, the inline backend capturing figures), a
    notebook runs without error and shows what it ships."""
    monkeypatch.delenv("MPLBACKEND", raising=False)  # the kernel's inline backend draws
    shipped = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
    nb = copy.deepcopy(shipped)
    _generator().execute(nb, cwd=tmp_path, timeout=300)  # CellExecutionError names the cell
    for i, (old, new) in enumerate(zip(_code(shipped), _code(nb), strict=True)):
        assert _outputs(new) == _outputs(old), (
            f"{name}: code cell {i} shows something else than the shipped notebook: run "
            "notebooks/make_notebooks.py"
        )


def test_the_dev_extra_installs_what_opens_the_notebooks():
    """``pip install ".[dev]"`` brings a notebook application, not only the runner."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    project = tomllib.loads((NOTEBOOKS.parent / "pyproject.toml").read_text())["project"]
    dev = {
        re.split(r"[<>=!~ ;\[]", r, maxsplit=1)[0].lower()
        for r in project["optional-dependencies"]["dev"]
    }
    assert {"jupyterlab", "notebook"} & dev
    assert {"nbclient", "nbformat", "ipykernel"} <= dev
