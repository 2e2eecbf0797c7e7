"""A sweep's directory: nothing finished is lost, nothing finished is run again.

::

    DIR/campaign.json        the campaign (its fingerprint: a directory holds one campaign)
    DIR/cases/case_00012.json one file per finished case (its result), written atomically
                              as soon as the case ends
    DIR/results.csv          one row per finished case, rebuilt from the case files
    DIR/best.md, DIR/*.png   the best cases and the plots (wholebody.sweep.report)

A sweep started again on the same directory reads the case files and runs only the cases
without one (failed cases are finished too, unless ``retry_failed``); a file that does not
read back as its case's result is named in a warning and its case runs again.
"""

from __future__ import annotations

import csv
import io
import json
import warnings
from pathlib import Path
from typing import Any

from wholebody.errors import ConfigError
from wholebody.files import write_json, write_text
from wholebody.sweep.campaign import Campaign, Case

__all__ = ["SweepStore", "flatten"]


class SweepStore:
    """The files of one campaign's sweep in ``out``."""

    def __init__(self, out: Path, campaign: Campaign) -> None:
        self.out, self.campaign = Path(out), campaign
        self.cases_dir = self.out / "cases"
        self.cases_dir.mkdir(parents=True, exist_ok=True)
        described = self.out / "campaign.json"
        mine = {
            "fingerprint": campaign.fingerprint(),
            "campaign": campaign.describe(),
            "versions": _versions(),
        }
        if described.is_file():
            theirs = json.loads(described.read_text())
            if theirs.get("fingerprint") != mine["fingerprint"]:
                raise ConfigError(
                    f"{self.out} holds the results of another campaign "
                    f"({theirs.get('campaign', {}).get('name')!r}, or this one "
                    "changed since): give another --out"
                )
        else:
            write_json(described, mine, indent=2, default=str)

    def path(self, case: Case | int) -> Path:
        index = case if isinstance(case, int) else case.index
        return self.cases_dir / f"case_{index:05d}.json"

    def finished(self, cases: list[Case], retry_failed: bool = False) -> dict[int, dict]:
        """The results on disk of ``cases``, by case index: a file that cannot be read, or
        whose values are not its case's (a campaign edited by hand), is left out with a
        warning naming it, and so is a failed case with ``retry_failed``."""
        out = {}
        by_index = {c.index: c for c in cases}
        for path in sorted(self.cases_dir.glob("case_*.json")):
            try:
                result = json.loads(path.read_text())
                case = by_index.get(int(result["index"]))
                known = case is not None and result["values"] == _plain(case.values)
            except (OSError, ValueError, KeyError, TypeError) as exc:
                warnings.warn(
                    f"{path}: not a case result ({exc}); its case runs again", stacklevel=2
                )
                continue
            if not known:
                warnings.warn(
                    f"{path}: its values are not those of this campaign's case "
                    f"{result['index']}; it runs again",
                    stacklevel=2,
                )
                continue
            if retry_failed and result.get("status") != "ok":
                continue
            out[case.index] = result
        return out

    def write(self, result: dict[str, Any]) -> Path:
        """One case's result, atomically."""
        return write_json(self.path(result["index"]), result, indent=1)

    def table(self, results: dict[int, dict[str, Any]]) -> tuple[Path, list[dict]]:
        """``results.csv``: a row per finished case (index order), the varied values, status,
        error, wall time and every scalar metric (nested ones as ``a/b/c``); and the rows."""
        rows = [flatten(results[i]) for i in sorted(results)]
        columns: list[str] = []
        seen: set[str] = set()
        for row in rows:
            for c in row:
                if c not in seen:
                    seen.add(c)
                    columns.append(c)
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        return write_text(self.out / "results.csv", buffer.getvalue()), rows


def _versions() -> dict[str, str]:
    """The versions that decide a case's numbers (numpy's random streams among them)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("wholebody", "numpy", "pin", "mujoco"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def _plain(values: dict[str, Any]) -> dict[str, Any]:
    """``values`` as they read back from JSON (tuples become lists)."""
    return json.loads(json.dumps(values))


def flatten(result: dict[str, Any]) -> dict[str, Any]:
    """A case's result as one table row: ``index``, the varied values, ``status``,
    ``error``, ``wall_s``, then every scalar metric (``metrics/...`` nested as ``a/b``)."""
    row: dict[str, Any] = {"index": result["index"]}
    row.update(result["values"])
    row.update(status=result["status"], error=result.get("error", ""), wall_s=result["wall_s"])

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{prefix}/{k}" if prefix else str(k), v)
        elif isinstance(value, bool | int | float | str) or value is None:
            row[prefix] = value

    walk("", result.get("metrics", {}))
    return row
