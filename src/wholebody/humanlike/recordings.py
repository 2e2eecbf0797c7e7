"""Human arm recordings: shoulder, elbow and wrist centres per frame of one trial.

A :class:`Recording` holds one trial of one arm in the **lab frame** of the recordings:
``+x`` to the participant's right, ``+y`` forward (away from the participant), ``+z`` up,
positions in **metres**, time in seconds from the trial's first frame. This is the frame of
the bundled data set (``data/human_reaching``, see its README) and of the synthetic
generator (:mod:`wholebody.humanlike.synthetic`). The bundled data hold four tasks
(:data:`TASKS`): seated reaches ``forward`` and ``across`` at table height, ``drinking`` (the
cup to the mouth) and ``combing`` (the hand over the head); :func:`load_recordings` reads
them all or, with ``tasks=``, some.

File layouts
------------
CSV (the layout of ``data/human_reaching/joint_centres/*.csv``)
    Header row, then one row per frame. Required columns ``time_s``, ``shoulder_x``,
    ``shoulder_y``, ``shoulder_z``, ``elbow_x`` ... ``wrist_z``; the optional markers
    ``sternum_*`` (the facing check below) and ``fingertip_*`` (the index fingertip of the
    moving arm: a hand direction) are read when all three columns are there; other columns
    are ignored. The file name
    ``{participant}_{task}_{side}{trial}.csv`` (for example ``ADL001_forward_R1.csv``) gives the
    participant, the task, the moving arm (``R``/``L``) and the trial number; a file with
    another name needs them passed explicitly.
NPZ (``numpy.savez``, no pickled objects)
    ``time_s`` (T,) s; ``shoulder``, ``elbow``, ``wrist`` (T, 3) in the lab frame above;
    ``units`` (0-d string, ``"m"`` or ``"mm"``); ``side`` (``"L"``/``"R"``); optional
    ``participant``, ``task``, ``trial`` (int), ``source`` (``"real"``/``"synthetic"``),
    ``sternum`` (T, 3), ``fingertip`` (T, 3) and ``note`` (free text).
    :func:`save_npz_recording` writes it (always in metres).

Units
-----
A CSV file has no unit field; ``units="auto"`` (the default) decides from the median
shoulder-elbow distance: above :data:`MM_DETECTION_THRESHOLD` (5.0) it is millimetres (a
human upper arm is 0.15-0.45 m, i.e. 150-450 mm), otherwise metres. Pass ``units="mm"`` or
``"m"`` to declare them. An NPZ file states its units; ``"auto"`` then uses the file's.

Facing
------
Participants face +y. With ``facing="auto"`` (the default), a file that also has the
sternum (``sternum_*`` columns or key) is checked: the sternum must lie medial of the moving
arm's shoulder (towards -x for a right arm, +x for a left one) on average. If it lies
lateral, the participant faced -y (participant ADL009 of the bundled data), and the
recording is turned by 180 deg about z (x and y negated; the arm angle does not change) and
says so in its ``note``. Samples where the sternum marker is missing (empty values) are left
out of that mean, and the recording then keeps no sternum (its ``note`` says how many
samples had it); with no complete sample the check is impossible, and the ``note`` says
so. ``facing="as-is"`` skips the check. A fingertip marker is turned with the rest; like the
sternum, a recording keeps it only when it was seen in every sample (its ``note`` says when
it was not).

Validation
----------
Every fault raises :class:`~wholebody.errors.DataError` naming the file, the data row
(1-based, the header not counted) and the column: missing columns, non-numeric, empty or
non-finite values, time not strictly increasing, an upper arm outside
:data:`UPPER_ARM_RANGE` or a forearm outside :data:`FOREARM_RANGE` in any frame, a forearm
length that varies by more than :data:`FOREARM_VARIATION_MAX` within the trial (the
elbow and the wrist are carried by different marker clusters, so a little variation is
normal: at most 38 mm in the bundled data), and fewer than :data:`MIN_FRAMES` frames.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from wholebody.errors import DataError
from wholebody.files import read_npz, write_npz
from wholebody.resources import data_dir, npz_path

__all__ = [
    "FOREARM_RANGE",
    "FOREARM_VARIATION_MAX",
    "JOINTS",
    "MIN_FRAMES",
    "MM_DETECTION_THRESHOLD",
    "TASKS",
    "UPPER_ARM_RANGE",
    "Participant",
    "Recording",
    "load_csv_recording",
    "load_npz_recording",
    "load_participants",
    "load_recording",
    "load_recordings",
    "parse_trial_name",
    "real_recordings_dir",
    "save_npz_recording",
]

JOINTS = ("shoulder", "elbow", "wrist")
UPPER_ARM_RANGE = (0.15, 0.45)  # m, shoulder-elbow distance in every frame
FOREARM_RANGE = (0.15, 0.40)  # m, elbow-wrist distance in every frame
FOREARM_VARIATION_MAX = 0.06  # m, max - min of the forearm length within one trial
MIN_FRAMES = 10
MM_DETECTION_THRESHOLD = 5.0  # median upper-arm length above this (in file units) -> mm
TASKS = ("forward", "across", "drinking", "combing")  # the bundled data's tasks (file names)
_MARKERS = ("sternum", "fingertip")  # optional markers, kept when seen in every sample
_COLUMNS = ("time_s", *(f"{j}_{a}" for j in JOINTS for a in "xyz"))
_NAME = re.compile(
    r"^(?P<participant>[A-Za-z0-9]+)_(?P<task>[A-Za-z0-9-]+)_(?P<side>[RL])(?P<trial>\d+)$"
)


@dataclass(frozen=True, eq=False)
class Recording:
    """One reaching trial of one arm (lab frame, metres, seconds; see the module docstring).

    Attributes
    ----------
    time_s
        (T,) strictly increasing, s.
    shoulder, elbow, wrist
        (T, 3) joint centres, m, lab frame (+x participant's right, +y forward, +z up).
    participant, task, side, trial
        Identity: ``side`` is ``"R"`` or ``"L"``, the moving arm.
    source
        ``"real"`` (recorded people) or ``"synthetic"`` (generated).
    path
        The file it was read from, if any.
    note
        Free text (how the trial was made or corrected).
    sternum
        (T, 3) sternum marker, m, if the file has one (used to check the facing).
    fingertip
        (T, 3) index fingertip of the moving arm, m, if the file has it: ``fingertip - wrist``
        is a hand direction.
    """

    time_s: np.ndarray
    shoulder: np.ndarray
    elbow: np.ndarray
    wrist: np.ndarray
    participant: str
    task: str
    side: str
    trial: int
    source: str = "real"
    path: str | None = None
    note: str = ""
    sternum: np.ndarray | None = None
    fingertip: np.ndarray | None = None

    @property
    def name(self) -> str:
        """``{participant}_{task}_{side}{trial}``, the trial's identifier."""
        return f"{self.participant}_{self.task}_{self.side}{self.trial}"

    @property
    def n_frames(self) -> int:
        return len(self.time_s)

    @property
    def side_sign(self) -> float:
        """+1 for a left arm, -1 for a right arm (the convention of ``arm_angle``)."""
        return 1.0 if self.side == "L" else -1.0

    def upper_arm_lengths(self) -> np.ndarray:
        """(T,) shoulder-elbow distances, m."""
        return np.linalg.norm(self.elbow - self.shoulder, axis=1)

    def forearm_lengths(self) -> np.ndarray:
        """(T,) elbow-wrist distances, m."""
        return np.linalg.norm(self.wrist - self.elbow, axis=1)


JOINT_CENTRES = "joint_centres"
"""The bundled data's directory of recordings (beside its ``participants.csv``)."""


def real_recordings_dir() -> Path:
    """The bundled real recordings: ``data_dir() / "human_reaching" / "joint_centres"``."""
    return data_dir() / "human_reaching" / JOINT_CENTRES


@dataclass(frozen=True)
class Participant:
    """A recorded person: id, sex (``"F"``/``"M"``) and stature (m)."""

    id: str
    sex: str
    stature: float


_STATURE_M = (0.5, 2.6)  # m: the heights a participants table may hold


def load_participants(path: str | Path | None = None) -> dict[str, Participant]:
    """The participants table (``participants.csv`` of the bundled data: columns
    ``participant``, ``sex``, ``height_m``), keyed by id."""
    path = Path(path) if path is not None else data_dir() / "human_reaching" / "participants.csv"
    out: dict[str, Participant] = {}
    try:
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            for r, row in enumerate(reader, start=1):
                for col in ("participant", "sex", "height_m"):
                    if not row.get(col):
                        raise DataError(f"{path}: row {r}, column {col!r}: missing value")
                try:
                    h = float(row["height_m"])
                except ValueError:
                    raise DataError(
                        f"{path}: row {r}, column 'height_m': {row['height_m']!r} is not a number"
                    ) from None
                if not _STATURE_M[0] <= h <= _STATURE_M[1]:  # (NaN fails too)
                    lo, hi = _STATURE_M
                    raise DataError(
                        f"{path}: row {r}, column 'height_m': {h} is not a person's "
                        f"height in metres ({lo}-{hi} m)"
                    )
                out[row["participant"]] = Participant(row["participant"], row["sex"], h)
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return out


def parse_trial_name(path: str | Path) -> dict[str, object]:
    """Participant, task, side and trial from ``{participant}_{task}_{side}{trial}.ext``.

    Raises
    ------
    DataError
        The file name does not follow the pattern.
    """
    stem = Path(path).stem
    m = _NAME.match(stem)
    if m is None:
        raise DataError(
            f"{path}: file name {Path(path).name!r} does not follow "
            "'{participant}_{task}_{R|L}{trial}' (for example ADL001_forward_R1.csv); pass "
            "participant, task, side and trial explicitly"
        )
    return {
        "participant": m["participant"],
        "task": m["task"],
        "side": m["side"],
        "trial": int(m["trial"]),
    }


def _identity(path: Path, given: dict[str, object]) -> dict[str, object]:
    missing = [k for k in ("participant", "task", "side", "trial") if given.get(k) is None]
    ident = parse_trial_name(path) if missing else {}
    ident.update({k: v for k, v in given.items() if v is not None})
    if ident["side"] not in ("R", "L"):
        raise DataError(f"{path}: side must be 'R' or 'L', got {ident['side']!r}")
    return ident


def _scale(path: Path, S: np.ndarray, E: np.ndarray, units: str) -> float:
    """Factor from file units to metres."""
    if units == "m":
        return 1.0
    if units == "mm":
        return 1e-3
    if units != "auto":
        raise DataError(f"{path}: units must be 'm', 'mm' or 'auto', got {units!r}")
    median = float(np.median(np.linalg.norm(E - S, axis=1)))
    return 1e-3 if median > MM_DETECTION_THRESHOLD else 1.0


def _validate(path: Path, t: np.ndarray, P: dict[str, np.ndarray], rows: np.ndarray) -> None:
    """Check a recording in metres; ``rows[i]`` is the 1-based data row of frame i."""
    n = len(t)
    if n < MIN_FRAMES:
        raise DataError(f"{path}: {n} data rows; a recording needs at least {MIN_FRAMES} frames")
    dt = np.diff(t)
    bad = np.flatnonzero(~(dt > 0))
    if bad.size:
        i = bad[0] + 1
        raise DataError(
            f"{path}: row {rows[i]}, column 'time_s': time {t[i]:g} s is not after the "
            f"previous row's {t[i - 1]:g} s (time must increase strictly)"
        )
    checks = (
        ("upper-arm", "shoulder", "elbow", UPPER_ARM_RANGE),
        ("forearm", "elbow", "wrist", FOREARM_RANGE),
    )
    for what, a, b, (lo, hi) in checks:
        length = np.linalg.norm(P[b] - P[a], axis=1)
        out = np.flatnonzero((length < lo) | (length > hi))
        if out.size:
            i = out[0]
            raise DataError(
                f"{path}: row {rows[i]}, columns '{a}_*'/'{b}_*': {what} length {length[i]:.3f} m "
                f"is implausible (expected {lo:.2f}-{hi:.2f} m; check the units and the "
                "column order)"
            )
    L = np.linalg.norm(P["wrist"] - P["elbow"], axis=1)
    spread = float(L.max() - L.min())
    if spread > FOREARM_VARIATION_MAX:
        i = int(np.argmax(np.abs(L - np.median(L))))
        raise DataError(
            f"{path}: row {rows[i]}, columns 'elbow_*'/'wrist_*': the forearm length varies "
            f"by {spread * 1000:.0f} mm within the trial ({L.min():.3f}-{L.max():.3f} m; at "
            f"most {FOREARM_VARIATION_MAX * 1000:.0f} mm expected); this row is farthest "
            "from the median"
        )


def _recording(
    path: Path,
    t: np.ndarray,
    P: dict[str, np.ndarray],
    units: str,
    ident: dict[str, object],
    source: str,
    note: str = "",
    markers: Mapping[str, np.ndarray | None] | None = None,
    facing: str = "auto",
) -> Recording:
    """A validated :class:`Recording` in metres from positions in file units; ``markers``:
    the optional ``sternum`` and ``fingertip`` (rows x 3, NaN where a sample is missing)."""
    rows = np.arange(1, len(t) + 1)
    s = _scale(path, P["shoulder"], P["elbow"], units)
    P = {k: v * s for k, v in P.items()}
    _validate(path, t, P, rows)
    if source not in ("real", "synthetic"):
        raise DataError(f"{path}: source must be 'real' or 'synthetic', got {source!r}")
    if facing not in ("auto", "as-is"):
        raise DataError(f"{path}: facing must be 'auto' or 'as-is', got {facing!r}")
    M = {k: v * s for k, v in (markers or {}).items() if v is not None}
    notes = [note] if note else []
    side = str(ident["side"])
    if (
        "sternum" in M
        and facing == "auto"
        and _faces_minus_y(M["sternum"], P["shoulder"], side, notes)
    ):
        turn = np.array([-1.0, -1.0, 1.0])
        P = {k: v * turn for k, v in P.items()}
        M = {k: v * turn for k, v in M.items()}
        notes.append(
            "turned 180 deg about z: the sternum lay lateral of the shoulder, "
            "so the participant faced -y"
        )
    for name, v in list(M.items()):  # a Recording's marker is complete or absent
        whole = np.isfinite(v).all(axis=1)
        if whole.all():
            continue
        del M[name]
        if name == "sternum" and facing == "auto" and whole.any():
            notes.append(
                f"sternum seen in {int(whole.sum())} of {len(t)} samples: used "
                "for the facing check only"
            )
        elif name != "sternum":
            notes.append(f"{name} seen in {int(whole.sum())} of {len(t)} samples: left out")
    return Recording(
        t.copy(),
        P["shoulder"],
        P["elbow"],
        P["wrist"],
        str(ident["participant"]),
        str(ident["task"]),
        str(ident["side"]),
        int(ident["trial"]),  # type: ignore[arg-type]
        source,
        str(path),
        "; ".join(notes),
        M.get("sternum"),
        M.get("fingertip"),
    )


def _faces_minus_y(sternum: np.ndarray, shoulder: np.ndarray, side: str, notes: list[str]) -> bool:
    """Whether the participant faced -y: the sternum lies lateral of the moving arm's shoulder
    on average over the samples where it was seen (a note if it never was)."""
    whole = np.isfinite(sternum).all(axis=1)
    if not whole.any():
        notes.append("sternum never seen: facing not checked")
        return False
    medial = -1.0 if side == "R" else 1.0
    return float(np.mean(sternum[whole, 0] - shoulder[whole, 0])) * medial < 0


def load_csv_recording(
    path: str | Path,
    *,
    units: str = "auto",
    participant: str | None = None,
    task: str | None = None,
    side: str | None = None,
    trial: int | None = None,
    source: str = "real",
    facing: str = "auto",
) -> Recording:
    """Read one trial from a CSV file (layout, units, facing and validation in the module
    docstring).

    Raises
    ------
    DataError
        A malformed file; the message names the file, row and column.
    """
    path = Path(path)
    ident = _identity(
        path, {"participant": participant, "task": task, "side": side, "trial": trial}
    )
    header, body = _csv_rows(path)
    A = _csv_numbers(path, header, body)
    t = A[:, 0]
    P = {j: A[:, 1 + 3 * k : 4 + 3 * k] for k, j in enumerate(JOINTS)}
    markers = {m: _csv_marker(path, header, body, m) for m in _MARKERS}
    return _recording(path, t, P, units, ident, source, "", markers, facing)


def _csv_rows(path: Path) -> tuple[list[str], list[list[str]]]:
    """The header (stripped) and the data rows of a recording's CSV, every required column
    present once and every row as long as the header."""
    try:
        with path.open(newline="") as fh:
            lines = [line for line in csv.reader(fh) if line]  # blank lines carry nothing
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise DataError(f"{path}: not a readable CSV text file ({exc})") from None
    if not lines:
        raise DataError(f"{path}: empty file; expected a header row with {', '.join(_COLUMNS)}")
    header = [h.strip() for h in lines[0]]
    missing = [c for c in _COLUMNS if c not in header]
    if missing:
        raise DataError(
            f"{path}: header row: missing column(s) {', '.join(repr(c) for c in missing)} "
            f"(required: {', '.join(_COLUMNS)})"
        )
    dup = sorted({c for c in _COLUMNS if header.count(c) > 1})
    if dup:
        raise DataError(f"{path}: header row: column(s) {', '.join(map(repr, dup))} repeated")
    body = lines[1:]
    for r, line in enumerate(body, start=1):
        if len(line) < len(header):
            raise DataError(
                f"{path}: row {r}: {len(line)} fields, the header has {len(header)} "
                f"(column {header[len(line)]!r} is missing)"
            )
    return header, body


def _csv_numbers(path: Path, header: list[str], body: list[list[str]]) -> np.ndarray:
    """The required columns as finite numbers (rows x columns), or the first bad cell named."""
    idx = [header.index(c) for c in _COLUMNS]
    cells = [[line[i].strip() for i in idx] for line in body]
    try:
        A = np.array(cells, dtype=float).reshape(len(body), len(_COLUMNS))
    except ValueError:
        for r, row in enumerate(cells, start=1):
            for c, v in enumerate(row):
                _csv_number(path, r, _COLUMNS[c], v, empty="empty value (missing marker?)")
        raise  # pragma: no cover - numpy and float() disagree
    bad = np.argwhere(~np.isfinite(A))
    if bad.size:
        r, c = bad[0]
        raise DataError(
            f"{path}: row {r + 1}, column {_COLUMNS[c]!r}: value {A[r, c]} is not finite"
        )
    return A


def _csv_number(path: Path, row: int, column: str, v: str, empty: str) -> float:
    """A cell as a number, or DataError naming the file, row and column."""
    if v == "":
        raise DataError(f"{path}: row {row}, column {column!r}: {empty}")
    try:
        return float(v)
    except ValueError:
        raise DataError(f"{path}: row {row}, column {column!r}: {v!r} is not a number") from None


def _csv_marker(
    path: Path, header: list[str], body: list[list[str]], marker: str
) -> np.ndarray | None:
    """An optional marker (rows x 3), None without its three columns: an empty value is a
    missing sample (NaN)."""
    cols = [f"{marker}_{a}" for a in "xyz"]
    if not all(c in header for c in cols):
        return None
    idx = [header.index(c) for c in cols]
    out = np.full((len(body), 3), np.nan)
    for r, line in enumerate(body):
        for k, c in enumerate(idx):
            v = line[c].strip() if c < len(line) else ""
            if v:
                out[r, k] = _csv_number(path, r + 1, cols[k], v, empty="")
    return out


def _npz_str(path: Path, z: dict[str, np.ndarray], key: str, default: str | None) -> str | None:
    if key not in z:
        return default
    v = z[key]
    if v.ndim != 0 or v.dtype.kind not in "US":
        raise DataError(f"{path}: key {key!r}: expected a 0-d string, got {v.dtype} {v.shape}")
    return str(v)


def load_npz_recording(
    path: str | Path, *, units: str = "auto", source: str | None = None, facing: str = "auto"
) -> Recording:
    """Read one trial from the NPZ layout of the module docstring.

    Raises
    ------
    DataError
        A malformed file: missing key, wrong shape or type, or any fault of the CSV checks
        (rows then mean frame indices, 1-based).
    """
    path = Path(path)
    z = read_npz(path, "recording (.npz)")
    required = ("time_s", *JOINTS, "units", "side")
    missing = [k for k in required if k not in z]
    if missing:
        raise DataError(
            f"{path}: missing key(s) {', '.join(map(repr, missing))} (required: "
            f"{', '.join(required)})"
        )
    try:
        t = np.asarray(z["time_s"], dtype=float)
        P = {j: np.asarray(z[j], dtype=float) for j in JOINTS}
    except ValueError as exc:
        raise DataError(f"{path}: positions and time must be numeric arrays ({exc})") from None
    if t.ndim != 1:
        raise DataError(f"{path}: key 'time_s': expected shape (T,), got {t.shape}")
    for j, v in P.items():
        if v.shape != (len(t), 3):
            raise DataError(
                f"{path}: key {j!r}: expected shape ({len(t)}, 3) to match 'time_s', got {v.shape}"
            )
    for key, v in (("time_s", t[:, None]), *P.items()):
        bad = np.argwhere(~np.isfinite(v))
        if bad.size:
            r, c = bad[0]
            col = key if key == "time_s" else f"{key}_{'xyz'[c]}"
            raise DataError(f"{path}: row {r + 1}, column {col!r}: value {v[r, c]} is not finite")
    file_units = _npz_str(path, z, "units", None)
    if file_units not in ("m", "mm"):
        raise DataError(f"{path}: key 'units': expected 'm' or 'mm', got {file_units!r}")
    if units not in ("auto", file_units):
        raise DataError(f"{path}: the file is in {file_units!r}, the caller declared {units!r}")
    name = parse_trial_name(path) if _NAME.match(path.stem) else {}
    ident: dict[str, object] = {
        "participant": _npz_str(path, z, "participant", name.get("participant", "unknown")),
        "task": _npz_str(path, z, "task", name.get("task", "unknown")),
        "side": _npz_str(path, z, "side", None),
        "trial": name.get("trial", 1),
    }
    if "trial" in z:
        tr = z["trial"]
        if tr.ndim != 0 or tr.dtype.kind not in "iu":
            raise DataError(f"{path}: key 'trial': expected a 0-d integer, got {tr.dtype}")
        ident["trial"] = int(tr)
    if ident["side"] not in ("R", "L"):
        raise DataError(f"{path}: key 'side': expected 'R' or 'L', got {ident['side']!r}")
    src = source or _npz_str(path, z, "source", "real")
    note = _npz_str(path, z, "note", "") or ""
    markers = {m: _npz_marker(path, z, m, len(t)) for m in _MARKERS if m in z}
    return _recording(path, t, P, str(file_units), ident, str(src), note, markers, facing)


def _npz_marker(path: Path, z: dict[str, np.ndarray], key: str, n: int) -> np.ndarray:
    """An optional marker of an NPZ recording: finite, (n, 3)."""
    v = np.asarray(z[key], dtype=float)
    if v.shape != (n, 3) or not np.isfinite(v).all():
        raise DataError(
            f"{path}: key {key!r}: expected finite values of shape ({n}, 3), got {v.shape}"
        )
    return v


def load_recording(path: str | Path, *, units: str = "auto", **identity: object) -> Recording:
    """Read a ``.csv`` or ``.npz`` recording (dispatch on the suffix)."""
    path = Path(path)
    if path.suffix == ".npz":
        options = {k: identity.pop(k) for k in ("source", "facing") if k in identity}
        rec = load_npz_recording(path, units=units, **options)  # type: ignore[arg-type]
        return replace(rec, **identity) if identity else rec  # type: ignore[arg-type]
    if path.suffix == ".csv":
        return load_csv_recording(path, units=units, **identity)  # type: ignore[arg-type]
    raise DataError(f"{path}: unknown recording format {path.suffix!r}; expected .csv or .npz")


def load_recordings(
    paths: str | Path | Iterable[str | Path] | None = None,
    *,
    units: str = "auto",
    progress: bool = False,
    tasks: Iterable[str] | None = None,
) -> list[Recording]:
    """Read many recordings: a directory (every ``*.csv`` and ``*.npz`` in it, sorted; a
    directory laid out like the bundled data, its recordings in ``joint_centres/`` beside
    ``participants.csv`` and ``quality_check.csv``, is read from ``joint_centres/``), or an
    iterable of files. ``None`` reads the bundled real recordings (all four :data:`TASKS`).

    ``tasks`` keeps only the recordings of those tasks (for example ``("forward",
    "across")``, the seated reaches); a file whose name gives its task (``{participant}_
    {task}_{side}{trial}``) and is not wanted is not read.

    Raises
    ------
    DataError
        No recording there, or none of the tasks asked for.
    """
    if paths is None:
        paths = real_recordings_dir()
    if isinstance(paths, (str, Path)):
        root = Path(paths)
        if not root.is_dir():
            raise DataError(f"{root}: not a directory of recordings")
        if (root / JOINT_CENTRES).is_dir() and (root / "participants.csv").is_file():
            root = root / JOINT_CENTRES  # the bundled data's layout
        files = sorted([*root.glob("*.csv"), *root.glob("*.npz")])
        if not files:
            raise DataError(f"{root}: no .csv or .npz recordings in this directory")
    else:
        files = [Path(p) for p in paths]
    wanted = None if tasks is None else set(tasks)
    if wanted is not None:  # skip the files whose names say they are of another task
        files = [f for f in files if (m := _NAME.match(f.stem)) is None or m["task"] in wanted]
    if progress:
        from tqdm.auto import tqdm

        files = tqdm(files, desc="reading recordings", unit="file")
    recs = [load_recording(f, units=units) for f in files]
    if wanted is not None:
        recs = [r for r in recs if r.task in wanted]
        if not recs:
            raise DataError(
                f"no recording of task(s) {', '.join(sorted(wanted))} in {paths} "
                f"(the bundled data have {', '.join(TASKS)})"
            )
    return recs


def save_npz_recording(rec: Recording, path: str | Path) -> Path:
    """Write ``rec`` in the NPZ layout (metres), with its identity and source; returns the
    file written (``.npz`` appended if missing)."""
    arrays = dict(
        time_s=rec.time_s,
        shoulder=rec.shoulder,
        elbow=rec.elbow,
        wrist=rec.wrist,
        units=np.array("m"),
        side=np.array(rec.side),
        participant=np.array(rec.participant),
        task=np.array(rec.task),
        trial=np.array(rec.trial, dtype=np.int64),
        source=np.array(rec.source),
        note=np.array(rec.note),
        **{m: getattr(rec, m) for m in _MARKERS if getattr(rec, m) is not None},
        frame=np.array(json.dumps({"x": "participant's right", "y": "forward", "z": "up"})),
    )
    return write_npz(npz_path(path), arrays)
