"""The documentation site builds from ``docs/`` with warnings as errors: every page, and the
API reference generated from the docstrings (their reStructuredText, their sections)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_site_builds_without_a_warning(tmp_path: Path) -> None:
    pytest.importorskip("sphinx", reason="the docs extra: pip install '.[docs]'")
    pytest.importorskip("furo", reason="the docs extra: pip install '.[docs]'")
    pytest.importorskip("myst_parser", reason="the docs extra: pip install '.[docs]'")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-W",
            "--keep-going",
            "-b",
            "html",
            "-q",
            str(ROOT / "docs"),
            str(tmp_path / "html"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    pages = {
        p.relative_to(tmp_path / "html").as_posix() for p in (tmp_path / "html").rglob("*.html")
    }
    assert {"index.html", "api/index.html", "api/tasks.html", "api/solvers.html"} <= pages
    tasks = (tmp_path / "html" / "api" / "tasks.html").read_text()
    assert (
        'id="wholebody.tasks.FrameTask"' in tasks
    )  # (the classes are documented, not only listed)


# Every measured figure lives in benchmarks/README.md (dated, with its command); the guides and
# the README link to it or include a section of it. A figure of measured style elsewhere: a
# table row with two or more numeric cells, or a time in us, a time in ms with decimals or a
# range, a speed ratio (``3.1x``, ``1.2-1.5x``), a percentage (a tolerance, "to 1 %" or
# "within 1 %", is a setting and allowed).
_NUM = r"[-−]?\d+(?:\.\d+)?(?:e[-+]?\d+)?"
_NUMERIC_CELL = re.compile(
    rf"^\s*(?:\[?{_NUM}(?:,\s*{_NUM}\])?\s*(?:%|x|us|ms|s|mm|deg|°)?(?:\s*/\s*)?)+\s*$"
)
_MEASURED = {
    "a time in us": re.compile(rf"\b{_NUM}(?:-{_NUM})?\s?(?:us|µs)\b"),
    "a measured time in ms": re.compile(r"\b(?:\d+\.\d+|\d+(?:\.\d+)?-\d+(?:\.\d+)?)\s?ms\b"),
    "a ratio": re.compile(rf"\b{_NUM}(?:-{_NUM})?x\b"),
    "a percentage": re.compile(rf"(?<!to )(?<!within )\b{_NUM}(?:-{_NUM})?\s?%"),
}


def measured_figures(text: str) -> list[str]:
    """The lines of markdown ``text`` that quote a figure of measured style (see above), as
    ``"LINE: what"``."""
    found = []
    for n, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("|"):
            cells = [c for c in line.strip().strip("|").split("|") if c.strip()]
            if sum(bool(_NUMERIC_CELL.match(c)) for c in cells) >= 2:
                found.append(f"{n}: a table row of figures: {line.strip()[:80]}")
        found += [
            f"{n}: {what} {m.group(0)!r}"
            for what, pattern in _MEASURED.items()
            for m in pattern.finditer(line)
        ]
    return found


def test_the_figure_detector_catches_measured_figures_and_passes_settings() -> None:
    measured = {
        "| pseudo-inverse | 39 | 25541 | 1.26e-09 |": "table row",
        "the paper's stack steps in 51 us (projection)": "a time in us",
        "TIAGo++ 3-4 ms and TALOS 8.4 ms per step": "a measured time in ms",
        "wholebody 3.1-7.5x faster than pink": "a ratio",
        "converge on 86-100 % of the targets": "a percentage",
        "| hqp | 9.9 | [8.7, 11.1] | 0.03 / 74 |": "table row",
    }
    for line, what in measured.items():
        assert measured_figures(line), f"missed {what}: {line}"
    settings = [
        "| `ur5` | UR5 | 6 | `ur5_reach` |",  # one number in a row: a definition
        "commands ramped over the 10 ms period, physics at 1 ms",
        "the wheels' placement and radius (to 1 %, the error in base speed)",
        "for _ in range(200):  # 2 s at 100 Hz",
        "a 6 x 23 Jacobian",
    ]
    for line in settings:
        assert not measured_figures(line), line


def test_measured_figures_live_only_in_benchmarks_readme() -> None:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    pages = [p for p in pages if "_build" not in p.parts]
    assert len(pages) > 10  # the README, the index, the guides
    found = [
        f"{p.relative_to(ROOT)}:{hit}" for p in pages for hit in measured_figures(p.read_text())
    ]
    assert not found, (
        "a measured figure outside benchmarks/README.md (move it there, dated with its "
        "command, and link or include it):\n" + "\n".join(found)
    )
