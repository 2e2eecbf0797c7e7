"""The README's Python examples run as written, in order, in one namespace."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_examples_run(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) >= 3
    namespace: dict = {}
    for i, code in enumerate(blocks):
        exec(compile(code, f"README.md python block {i + 1}", "exec"), namespace)
    # the reach example really reaches the paper's goal
    log, goal = namespace["log"], namespace["goal"]
    assert abs(log.frame_positions["right_tool"][-1] - goal[:3, 3]).max() < 1e-3
    assert namespace["path"].positions.shape == (160, 3)
    # the far reach gets out of its local minimum with one retreat
    assert len(namespace["run"].meta["retreats"]) == 1 and namespace["miss"] < 1e-3
