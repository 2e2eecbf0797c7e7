"""File format versions: a scenario, campaign or robot.toml says which semantics it was written
for, and one written for other semantics is refused with what to change."""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import pytest

import wholebody
from wholebody import ConfigError
from wholebody.formats import CAMPAIGN, ROBOT, SCENARIO, FileFormat, check_format
from wholebody.resources import robots_dir, tasks_dir
from wholebody.scenarios import load_scenario
from wholebody.sweep import load_campaign
from wholebody.tomlreader import TomlReader, load_toml

ROOT = Path(__file__).resolve().parents[1]


def _copy(tmp_path: Path, kind: str) -> tuple[Path, FileFormat, object]:
    """A shipped file of ``kind`` copied into ``tmp_path``, its format and its reader."""
    if kind == "scenario":
        shutil.copytree(tasks_dir() / "demos", tmp_path / "demos")
        path = tmp_path / "coordinated_carry.toml"
        shutil.copy(tasks_dir() / path.name, path)
        return path, SCENARIO, load_scenario
    if kind == "campaign":
        path = tmp_path / "carry_weights.toml"
        shutil.copy(tasks_dir() / "campaigns" / path.name, path)
        return path, CAMPAIGN, load_campaign
    shutil.copytree(robots_dir() / "dual_arm_torso", tmp_path / "robot")
    return tmp_path / "robot" / "robot.toml", ROBOT, wholebody.load_robot


def _with_format(path: Path, line: str) -> None:
    """``path`` with its ``format = N`` line replaced by ``line`` (empty: removed)."""
    text = path.read_text()
    new, count = re.subn(r"^format = .*\n", line, text, flags=re.M)
    assert count == 1, f"no format line in {path}"
    path.write_text(new)


def _refused(path: Path, reader) -> str:
    with pytest.raises(ConfigError) as info:
        reader(path)
    message = str(info.value)
    assert message.startswith(f"{path}: [format]"), message  # the file and the key
    return message


@pytest.mark.parametrize("kind", ["scenario", "campaign", "robot.toml"])
def test_a_file_without_the_key_is_refused_with_what_to_change(tmp_path, kind):
    path, fmt, reader = _copy(tmp_path, kind)
    _with_format(path, "")
    message = _refused(path, reader)
    assert "missing key" in message and f"put `format = {fmt.current}` at the top" in message
    for change in fmt.changes.values():
        assert change in message


def test_a_scenario_written_before_start_existed_is_told_about_start(tmp_path):
    """The issue's example: the carry written for the neutral posture, without ``start`` and
    without the key, would start at home and miss by 345 mm. It is refused, and the message
    says what changed and what to add."""
    path, _, _ = _copy(tmp_path, "scenario")
    path.write_text(path.read_text().replace('start = "neutral"\n', ""))
    _with_format(path, "")
    message = _refused(path, load_scenario)
    assert "`[scenario] start` now defaults to home" in message
    assert 'need `start = "neutral"`' in message and "`format = 2`" in message
    _with_format_added = path.read_text().replace("[scenario]\n", "format = 2\n[scenario]\n", 1)
    path.write_text(_with_format_added)
    assert load_scenario(path).start == "home"  # the edit is the user's to make: as written


@pytest.mark.parametrize("kind", ["scenario", "campaign", "robot.toml"])
def test_an_older_a_newer_or_a_malformed_number_is_refused(tmp_path, kind):
    path, fmt, reader = _copy(tmp_path, kind)
    _with_format(path, f"format = {fmt.current + 1}\n")
    message = _refused(path, reader)
    assert "written for a newer wholebody" in message and f"format {fmt.current}" in message
    if fmt.current > 1:
        _with_format(path, f"format = {fmt.current - 1}\n")
        message = _refused(path, reader)
        assert f"written for format {fmt.current - 1}" in message
        assert fmt.changes[fmt.current] in message and fmt.line in message
    for bad in ('"2"', "2.0", "true", "0"):
        _with_format(path, f"format = {bad}\n")
        assert "expected the" in _refused(path, reader)


def test_a_campaigns_scenario_has_its_own_format(tmp_path):
    """A campaign at the current format whose base scenario file has none: the scenario file
    is named."""
    campaign, _, _ = _copy(tmp_path, "campaign")
    scenario, _, _ = _copy(tmp_path, "scenario")
    _with_format(scenario, "")
    with pytest.raises(ConfigError) as info:
        load_campaign(campaign)
    assert str(info.value).startswith(f"{scenario}: [format] missing key"), str(info.value)


def test_a_campaigns_fingerprint_leaves_the_scenario_format_out(tmp_path):
    """Resuming a sweep started before the files carried the key: the same cases."""
    path, _, _ = _copy(tmp_path, "campaign")
    campaign = load_campaign(path)
    unnumbered = {k: v for k, v in campaign.scenario.items() if k != "format"}
    assert campaign.scenario["format"] == SCENARIO.current
    assert (
        dataclasses.replace(campaign, scenario=unnumbered).fingerprint() == campaign.fingerprint()
    )


SHIPPED = [
    *((p, SCENARIO) for p in sorted(tasks_dir().glob("*.toml"))),
    *((p, CAMPAIGN) for p in sorted((tasks_dir() / "campaigns").glob("*.toml"))),
    *((p, ROBOT) for p in sorted(robots_dir().glob("*/robot.toml"))),
]


@pytest.mark.parametrize(
    ("path", "fmt"), SHIPPED, ids=[f"{p.parent.name}/{p.name}" for p, _ in SHIPPED]
)
def test_every_shipped_file_is_at_the_current_format(path, fmt):
    check_format(TomlReader(path), load_toml(path, fmt.kind), fmt)
    if fmt is SCENARIO:
        load_scenario(path)


def test_the_documentations_files_carry_the_key():
    """Every whole-file TOML example of the READMEs, the guides and the readers' docstrings
    (its first table ``[scenario]``, ``[campaign]`` or ``[robot]``) starts with the current
    key."""
    from wholebody.robot import config
    from wholebody.scenarios import spec
    from wholebody.sweep import campaign

    formats = {"scenario": SCENARIO, "campaign": CAMPAIGN, "robot": ROBOT}
    pages = [ROOT / "README.md", ROOT / "tasks" / "README.md", *(ROOT / "docs").rglob("*.md")]
    texts = [page.read_text() for page in pages]
    blocks = [b for t in texts for b in re.findall(r"```toml\n(.*?)```", t, flags=re.S)]
    blocks += [m.__doc__.split("::", 1)[1] for m in (config, spec, campaign)]
    seen = set()
    for block in blocks:
        first = re.search(r"^\s*\[(\w+)\]", block, flags=re.M)
        if first is None or first.group(1) not in formats:
            continue
        seen.add(first.group(1))
        head = block[: first.start()]
        assert re.search(rf"^\s*{formats[first.group(1)].line}\b", head, flags=re.M), block
    assert seen == set(formats)
