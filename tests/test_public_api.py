"""The public names of ``import wholebody as wb``: ``wb.__all__``, the lazy-import table and
the type checker's imports name the same things, each name resolves to what its module
defines, and no object has two public names at the top level."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import wholebody as wb

INIT = Path(wb.__file__)


def type_checking_imports() -> dict[str, str]:
    """Name -> module of the ``if TYPE_CHECKING:`` imports of ``wholebody/__init__.py``."""
    tree = ast.parse(INIT.read_text())
    names: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom)
                names.update({alias.name: imp.module for alias in imp.names})
    return names


def test_all_the_lazy_table_and_the_type_checker_agree() -> None:
    lazy = wb._LAZY
    assert sorted(wb.__all__) == sorted(set(wb.__all__)), "a name twice in __all__"
    eager = {n for n in wb.__all__ if n.endswith("Error")} | {"__version__"}
    assert set(wb.__all__) - eager == set(lazy)
    assert type_checking_imports() == lazy


def test_every_name_resolves_to_its_module_and_has_one_name() -> None:
    seen: dict[int, str] = {}
    for name, module in wb._LAZY.items():
        value = getattr(wb, name)
        assert value is getattr(importlib.import_module(module), name)
        assert name in importlib.import_module(module).__all__, f"{module} does not export {name}"
        assert id(value) not in seen, f"wb.{name} and wb.{seen.get(id(value))} are one object"
        seen[id(value)] = name
