"""The documentation site builds from ``docs/`` with warnings as errors: every page, and the
API reference generated from the docstrings (their reStructuredText, their sections)."""

from __future__ import annotations

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
