"""Recordings: the CSV and NPZ loaders, units, facing and the validation of malformed files."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest

from wholebody.arm.angle import arm_angle
from wholebody.errors import DataError
from wholebody.humanlike.recordings import (
    TASKS,
    load_csv_recording,
    load_npz_recording,
    load_participants,
    load_recording,
    load_recordings,
    real_recordings_dir,
    save_npz_recording,
)
from wholebody.humanlike.synthetic import DEFAULT_PARTICIPANTS, generate_participant

HEADER = ["time_s"] + [f"{j}_{a}" for j in ("shoulder", "elbow", "wrist", "sternum") for a in "xyz"]


def _trial() -> np.ndarray:
    """A valid 40-frame right-arm trial as rows (time s, then mm)."""
    rec = generate_participant(DEFAULT_PARTICIPANTS[3], np.random.default_rng(1))[13]
    n = 40
    assert rec.n_frames >= n
    t = rec.time_s[:n]
    sternum = rec.shoulder[:n] + np.array([-0.2, 0.05, 0.05])
    pos = np.hstack([rec.shoulder[:n], rec.elbow[:n], rec.wrist[:n], sternum]) * 1000.0
    return np.hstack([t[:, None], pos])


def _write(path: Path, rows, header=HEADER) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        if header is not None:
            w.writerow(header)
        for r in rows:
            w.writerow([f"{v:.4f}" if isinstance(v, float) else v for v in r])
    return path


@pytest.fixture
def good(tmp_path: Path) -> Path:
    return _write(tmp_path / "P01_reach_R3.csv", _trial().tolist())


def test_bundled_recording_loads_in_metres():
    path = real_recordings_dir() / "ADL001_forward_R1.csv"
    rec = load_recording(path)
    assert (rec.participant, rec.task, rec.side, rec.trial) == ("ADL001", "forward", "R", 1)
    assert rec.source == "real" and rec.n_frames > 200
    # millimetres detected and converted: an upper arm of a few tenths of a metre
    assert 0.2 < np.median(rec.upper_arm_lengths()) < 0.35
    assert np.all(np.diff(rec.time_s) > 0)
    # start of the trial: shoulder 225.0, -264.4, 285.6 mm in the file
    np.testing.assert_allclose(rec.shoulder[0], [0.225, -0.2644, 0.2856])


def test_units_declared_and_detected_agree(good: Path, tmp_path: Path):
    mm = load_csv_recording(good)
    np.testing.assert_allclose(load_csv_recording(good, units="mm").wrist, mm.wrist)
    rows = _trial()
    rows[:, 1:] /= 1000.0
    metres = _write(tmp_path / "P01_reach_R4.csv", rows.tolist())
    m = load_csv_recording(metres)  # detected as metres
    np.testing.assert_allclose(m.wrist, mm.wrist, atol=1e-4)  # 4 decimals in the file


def test_npz_round_trip(good: Path, tmp_path: Path):
    rec = load_csv_recording(good)
    out = save_npz_recording(rec, tmp_path / "P01_reach_R3.npz")
    back = load_npz_recording(out)
    for name in ("time_s", "shoulder", "elbow", "wrist"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name))
    assert (back.participant, back.task, back.side, back.trial) == ("P01", "reach", "R", 3)


def test_participant_facing_minus_y_is_turned():
    """ADL009 faced -y: its sternum is lateral of the shoulder until the trial is turned."""
    rec = load_recording(real_recordings_dir() / "ADL009_forward_R1.csv")
    raw = load_recording(real_recordings_dir() / "ADL009_forward_R1.csv", facing="as-is")
    assert "turned 180" in rec.note and raw.note == ""
    np.testing.assert_allclose(rec.wrist[:, :2], -raw.wrist[:, :2])
    np.testing.assert_allclose(rec.fingertip[:, :2], -raw.fingertip[:, :2])  # turned with it
    # the reach goes forward (+y) once turned; the arm angle does not change
    assert rec.wrist[-1, 1] - rec.shoulder[-1, 1] > 0.2
    np.testing.assert_allclose(
        arm_angle(rec.shoulder, rec.elbow, rec.wrist, -1),
        arm_angle(raw.shoulder, raw.elbow, raw.wrist, -1),
        atol=1e-12,
    )
    other = load_recording(real_recordings_dir() / "ADL001_forward_R1.csv")
    assert other.note == ""


def test_npz_recordings_take_the_csv_options_and_csv_blank_lines_are_skipped(tmp_path: Path):
    raw = load_recording(real_recordings_dir() / "ADL009_forward_R1.csv", facing="as-is")
    path = save_npz_recording(raw, tmp_path / "ADL009_forward_R1")  # .npz appended
    assert path.name == "ADL009_forward_R1.npz" and path.is_file()
    back = load_recording(path, facing="as-is", source="synthetic")
    np.testing.assert_array_equal(back.wrist, raw.wrist)
    np.testing.assert_array_equal(back.fingertip, raw.fingertip)
    np.testing.assert_array_equal(back.sternum, raw.sternum)
    assert back.source == "synthetic"
    text = (real_recordings_dir() / "ADL001_forward_R1.csv").read_text()
    (tmp_path / "ADL001_forward_R1.csv").write_text(text + "\n\n")
    padded = load_recording(tmp_path / "ADL001_forward_R1.csv")
    assert (
        padded.n_frames == load_recording(real_recordings_dir() / "ADL001_forward_R1.csv").n_frames
    )


@pytest.mark.slow
def test_directory_and_participants():
    recs = load_recordings(real_recordings_dir())
    assert len(recs) == 480
    assert {r.participant for r in recs} == {f"ADL{i:03d}" for i in range(1, 13)}
    for task in TASKS:  # 12 participants x 2 arms x 5 trials of each task
        assert sum(r.task == task for r in recs) == 120, task
    assert all(r.fingertip is not None and r.sternum is not None for r in recs)
    people = load_participants()
    assert people["ADL003"].stature == pytest.approx(1.8)


def test_tasks_are_selected_by_name(tmp_path: Path):
    for name in ("ADL002_forward_R1", "ADL002_across_L2", "ADL002_drinking_L1"):
        (tmp_path / f"{name}.csv").write_text((real_recordings_dir() / f"{name}.csv").read_text())
    seated = load_recordings(tmp_path, tasks=("forward", "across"))
    assert sorted(r.task for r in seated) == ["across", "forward"]
    # a file named otherwise is read and kept by the task it holds
    rec = load_recording(real_recordings_dir() / "ADL002_combing_L3.csv")
    path = save_npz_recording(rec, tmp_path / "some_file")
    got = load_recordings(tmp_path, tasks=["combing"])
    assert [r.path for r in got] == [str(path)] and got[0].task == "combing"
    assert len(load_recordings(tmp_path)) == 4  # all tasks by default
    with pytest.raises(DataError, match="no recording of task"):
        load_recordings(tmp_path, tasks=["reaching"])


def test_a_directory_laid_out_like_the_bundled_data_is_read_from_its_joint_centres(
    tmp_path: Path,
):
    """``--recordings DIR`` with DIR as shipped (``joint_centres/``, ``participants.csv``,
    ``quality_check.csv``): its recordings, not its tables, are read; a flat directory with
    a table among its recordings still says which file is not a recording."""
    bundled = real_recordings_dir().parent
    (tmp_path / "joint_centres").mkdir()
    for name in ("ADL002_forward_R1", "ADL005_combing_L3"):
        shutil.copy(real_recordings_dir() / f"{name}.csv", tmp_path / "joint_centres")
    for table in ("participants.csv", "quality_check.csv"):
        shutil.copy(bundled / table, tmp_path)
    recs = load_recordings(tmp_path)
    assert sorted(r.name for r in recs) == sorted(
        load_recording(real_recordings_dir() / f"{n}.csv").name
        for n in ("ADL002_forward_R1", "ADL005_combing_L3")
    )
    flat = tmp_path / "flat"
    flat.mkdir()
    shutil.copy(real_recordings_dir() / "ADL002_forward_R1.csv", flat)
    shutil.copy(bundled / "participants.csv", flat)
    with pytest.raises(DataError, match=r"participants\.csv"):
        load_recordings(flat)


def test_drinking_and_combing_raise_the_hand_above_the_table():
    """The new tasks are where the robot works: the wrist goes to the mouth (drinking) and
    over the head (combing), above the shoulder, while the seated reaches stay below it
    (the README's per-task table of the highest wrist point, shoulder-relative)."""
    peaks: dict[str, list[float]] = {}
    for task in TASKS:
        for name in (f"ADL005_{task}_R2", f"ADL010_{task}_L4"):
            rec = load_recording(real_recordings_dir() / f"{name}.csv")
            assert rec.task == task and rec.n_frames > 200
            peaks.setdefault(task, []).append(float(np.max(rec.wrist[:, 2] - rec.shoulder[:, 2])))
    assert max(peaks["forward"] + peaks["across"]) < -0.10
    assert min(peaks["combing"]) > 0.15
    assert max(peaks["drinking"]) > 0.0 > max(peaks["forward"])
    # ... and the hand points up the forearm: the fingertip is beyond the wrist
    rec = load_recording(real_recordings_dir() / "ADL005_combing_R2.csv")
    hand = np.linalg.norm(rec.fingertip - rec.wrist, axis=1)
    assert 0.08 < np.median(hand) < 0.25


def _mutate(rows: np.ndarray, r: int, c: str, value) -> list:
    out = rows.tolist()
    out[r - 1][HEADER.index(c)] = value
    return out


def _malformed(tmp_path: Path) -> list[tuple[str, Path, list[str]]]:
    """(case, file, fragments the message must contain)."""
    base = _trial()
    cases = []

    def add(case, rows, expect, name="P02_reach_R1.csv", header=HEADER):
        (tmp_path / case).mkdir()
        cases.append((case, _write(tmp_path / case / name, rows, header), expect))

    hdr = [h for h in HEADER if h != "elbow_y"]
    rows = np.delete(base, HEADER.index("elbow_y"), axis=1).tolist()
    add("missing_column", rows, ["missing column", "'elbow_y'"], header=hdr)
    add("non_numeric", _mutate(base, 5, "wrist_x", "abc"), ["row 5", "'wrist_x'", "'abc'"])
    add("empty_value", _mutate(base, 7, "elbow_z", ""), ["row 7", "'elbow_z'", "empty"])
    add("nan_value", _mutate(base, 3, "shoulder_y", "nan"), ["row 3", "'shoulder_y'", "finite"])
    add("inf_value", _mutate(base, 11, "wrist_z", "inf"), ["row 11", "'wrist_z'", "finite"])
    t = base.copy()
    t[5, 0] = t[4, 0]
    add("time_repeated", t.tolist(), ["row 6", "'time_s'", "increase"])
    t = base.copy()
    t[8, 0] = t[2, 0]
    add("time_backwards", t.tolist(), ["row 9", "'time_s'"])
    b = base.copy()
    b[3, 4:7] = b[3, 1:4] + np.array([0.0, 0.0, -600.0])
    add("long_upper_arm", b.tolist(), ["row 4", "upper-arm length", "'shoulder_*'/'elbow_*'"])
    b = base.copy()
    b[7, 7:10] = b[7, 4:7] + np.array([0.0, 50.0, 0.0])
    add("short_forearm", b.tolist(), ["row 8", "forearm length", "'elbow_*'/'wrist_*'"])
    b = base.copy()
    d = b[:, 7:10] - b[:, 4:7]
    scale = 1.0 + 0.3 * np.linspace(0, 1, len(b))[:, None]  # forearm drifts by 30 %
    b[:, 7:10] = b[:, 4:7] + d * scale
    add("forearm_varies", b.tolist(), ["varies by", "'elbow_*'/'wrist_*'", "row 40"])
    add("too_few_frames", base[:5].tolist(), ["5 data rows", "at least 10"])
    add("empty_file", [], ["empty file"], header=None)
    add("bad_name", base.tolist(), ["does not follow"], name="trial.csv")
    short = base.tolist()
    short[2] = short[2][:5]
    add("short_row", short, ["row 3", "5 fields", "'elbow_y'"])
    add(
        "duplicate_column",
        base.tolist(),
        ["'wrist_x'", "repeated"],
        header=[*HEADER[:-1], "wrist_x"],
    )
    return cases


def test_malformed_csv_files_are_rejected_with_file_row_column(tmp_path: Path):
    cases = _malformed(tmp_path)
    assert len(cases) >= 10
    for case, path, fragments in cases:
        with pytest.raises(DataError) as err:
            load_recording(path)
        msg = str(err.value)
        assert str(path) in msg, case
        for frag in fragments:
            assert frag in msg, f"{case}: {frag!r} not in {msg!r}"


def test_declared_units_that_do_not_fit_are_caught(good: Path):
    with pytest.raises(DataError, match=r"upper-arm length .* check the units"):
        load_csv_recording(good, units="m")  # millimetres read as metres: 280 m arms


def test_malformed_npz_files(good: Path, tmp_path: Path):
    rec = load_csv_recording(good)
    ok = {
        "time_s": rec.time_s,
        "shoulder": rec.shoulder,
        "elbow": rec.elbow,
        "wrist": rec.wrist,
        "units": np.array("m"),
        "side": np.array("R"),
    }
    cases = {
        "missing_key": ({k: v for k, v in ok.items() if k != "elbow"}, ["missing key", "'elbow'"]),
        "bad_shape": ({**ok, "wrist": ok["wrist"][:, :2]}, ["'wrist'", "expected shape"]),
        "bad_units": ({**ok, "units": np.array("cm")}, ["'units'", "'cm'"]),
        "nan": (
            {
                **ok,
                "elbow": np.where(np.arange(len(rec.time_s))[:, None] == 4, np.nan, ok["elbow"]),
            },
            ["row 5", "'elbow_x'"],
        ),
        "bad_side": ({**ok, "side": np.array("X")}, ["'side'", "'R' or 'L'"]),
    }
    for case, (arrays, fragments) in cases.items():
        path = tmp_path / f"P03_{case}_R1.npz"
        np.savez(path, **arrays)
        with pytest.raises(DataError) as err:
            load_recording(path)
        msg = str(err.value)
        assert str(path) in msg
        for frag in fragments:
            assert frag in msg, f"{case}: {frag!r} not in {msg!r}"
    junk = tmp_path / "P03_junk_R1.npz"
    junk.write_bytes(b"not a zip file")
    with pytest.raises(DataError, match="not a readable"):
        load_recording(junk)


def test_a_missing_sternum_sample_does_not_turn_the_facing_check_off(tmp_path: Path):
    """One empty sternum cell left the sternum out and, with it, the facing check: the trial
    stayed turned by 180 deg. The samples where the marker was seen decide."""
    rows = list(csv.reader((real_recordings_dir() / "ADL009_forward_R1.csv").open()))
    header, body = rows[0], rows[1:]
    whole = load_recording(real_recordings_dir() / "ADL009_forward_R1.csv")
    body[50][header.index("sternum_x")] = ""
    gap = load_recording(_write(tmp_path / "ADL009_forward_R1.csv", body, header))
    assert "turned 180" in gap.note and "sternum seen in" in gap.note
    assert gap.sternum is None  # a recording's sternum is complete or absent
    np.testing.assert_allclose(gap.wrist, whole.wrist)
    np.testing.assert_allclose(gap.fingertip, whole.fingertip)  # turned as well
    cell = body[60][header.index("fingertip_z")]
    body[60][header.index("fingertip_z")] = ""  # so is its fingertip, said in the note
    hole = load_recording(_write(tmp_path / "ADL009_forward_R3.csv", body, header))
    body[60][header.index("fingertip_z")] = cell
    assert hole.fingertip is None
    assert f"fingertip seen in {len(body) - 1} of {len(body)} samples: left out" in hole.note
    np.testing.assert_allclose(hole.wrist, whole.wrist)
    for line in body:
        for a in "xyz":
            line[header.index(f"sternum_{a}")] = ""
    blank = _write(tmp_path / "ADL009_forward_R2.csv", body, header)
    unchecked = load_recording(blank)  # a marker never seen: said, not fatal to a dataset
    assert unchecked.note == "sternum never seen: facing not checked"
    assert unchecked.sternum is None
    assert load_recording(blank, facing="as-is").note == ""
