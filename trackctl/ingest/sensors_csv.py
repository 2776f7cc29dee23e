"""CSV readers for IMU, RSSI and wheel odometry (``trackctl record --imu/--rssi/--odom``).

Column contract (by header name, extra columns ignored, ``t_s`` in seconds on the log's clock,
non-decreasing):

* IMU: ``t_s,ax,ay,az`` (m/s^2 incl. gravity) + optional ``gx,gy,gz`` (rad/s; many phone
  datasets are accelerometer-only) + optional ``qw,qx,qy,qz``;
  or an Android/iOS "Sensor Logger" export (a folder or .zip holding ``TotalAcceleration.csv`` or
  ``Accelerometer.csv`` [+ ``Gravity.csv``], ``Gyroscope.csv`` and optionally ``Orientation.csv``,
  each with ``time`` in UTC nanoseconds and ``x,y,z`` / ``qx,qy,qz,qw`` columns);
* RSSI: ``t_s,observer,eid,rssi_dbm`` (rows with equal ``t_s`` and ``observer`` form one scan);
* odometry: ``t_s,left_ticks,right_ticks`` or ``t_s,v_mps,omega_rps``.

Other files (:class:`CsvLayout`, ``record --columns``/``--no-header``): a column map
``t=0,ax=1,ay=2,az=3`` (0-based indexes) or ``t=time,ax=accX,...`` (the file's header names)
says which column holds each field; fields it leaves out are still found by their contract name
in a header. A file whose first row is all numbers (or, with a map by index, whose first time
cell is a number) has no header (auto-detected, or forced with ``header=False``); such a file
needs the column map by index.

Files are read in chunks, so memory does not grow with file length (Sensor Logger exports are
merged in memory: they come as separate per-sensor files that must be aligned).

Parsing is strict: every cell is read as text and converted explicitly. Ids (``observer``,
``eid``) stay exactly as written (``007`` stays ``007``; a blank id is an error); a number column
holding text or a boolean (``true``), NaN or infinity is an error naming the file, the line
(1-based, as an editor counts them, blank lines included) and the column in the file's own terms
(its header name, or its 0-based index in a header-less file); a row with more fields than the
first row is an error naming the line. Blank lines are skipped. Duplicate header names are never
renamed: a field they would make ambiguous is an error asking for the column's index.

Time unit rule: ``t_s`` is in seconds unless ``time_unit`` says otherwise (``ms``, ``us``, ``ns``
convert exactly, integers without a float round trip). A ``t_s`` above 1e11 (later than the year
5138 in Unix seconds) is refused as "epoch milliseconds or finer", and IMU or odometry whose
samples are a second or more apart with integer stamps is refused as "milliseconds"; both errors
suggest ``--time-unit``.
"""

from __future__ import annotations

import csv
import io
import re
import zipfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from decimal import ROUND_HALF_EVEN, Decimal
from pathlib import Path

import numpy as np
import pandas as pd

from trackctl.errors import InputError, NonFiniteValueError, NonMonotonicTimeError
from trackctl.logs.messages import Imu, Quat, RssiReading, RssiScan, Vec3, WheelOdometry

__all__ = [
    "read_imu",
    "read_rssi_csv",
    "read_odometry_csv",
    "seconds_to_ns",
    "CsvLayout",
    "parse_columns",
    "parse_column_options",
    "CSV_FIELDS",
    "IMU_COLUMNS",
    "IMU_GYRO_COLUMNS",
    "TIME_UNITS",
    "RSSI_COLUMNS",
    "ODOM_TICK_COLUMNS",
    "ODOM_VEL_COLUMNS",
]

IMU_COLUMNS = ("t_s", "ax", "ay", "az")
IMU_GYRO_COLUMNS = ("gx", "gy", "gz")
IMU_QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
RSSI_COLUMNS = ("t_s", "observer", "eid", "rssi_dbm")
ODOM_TICK_COLUMNS = ("t_s", "left_ticks", "right_ticks")
ODOM_VEL_COLUMNS = ("t_s", "v_mps", "omega_rps")
CHUNK_ROWS = 50_000
TIME_UNITS = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
EPOCH_MS_THRESHOLD_S = 1e11
_FIELDS = re.compile(r"Expected (\d+) fields in line (\d+), saw (\d+)")
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_TIME_ALIASES = ("t", "t_s")
"""``--columns`` keys of the time field (``t=0`` or ``t_s=0``)."""


@dataclass(frozen=True, slots=True)
class CsvLayout:
    """How one sensor CSV is laid out (``record --columns``, ``--header/--no-header``).

    Attributes:
        columns: field -> the file's column holding it: a 0-based index (int) or a header name
            (str). Fields: ``t_s`` (or ``t``) and those of :data:`CSV_FIELDS`. Fields left out
            are looked up by their contract name in the header.
        header: whether the first row is a header; None: it is one unless all its cells are
            numbers.
    """

    columns: Mapping[str, int | str] = field(default_factory=dict)
    header: bool | None = None


@dataclass(frozen=True, slots=True)
class _Kind:
    """The fields of one sensor CSV: required ones, and all-or-nothing optional groups."""

    what: str
    required: tuple[str, ...]
    groups: tuple[tuple[str, ...], ...] = ()
    need_group: bool = False
    """At least one group is required (odometry: ticks or velocities)."""

    @property
    def fields(self) -> tuple[str, ...]:
        return self.required + tuple(f for g in self.groups for f in g)

    def example(self) -> str:
        keys = ("t", *(self.required[1:] or self.groups[0]))
        return ",".join(f"{k}={i}" for i, k in enumerate(keys))


_IMU = _Kind("IMU", IMU_COLUMNS, (IMU_GYRO_COLUMNS, IMU_QUAT_COLUMNS))
_RSSI = _Kind("RSSI", RSSI_COLUMNS)
_ODOM = _Kind("odometry", ("t_s",), (ODOM_TICK_COLUMNS[1:], ODOM_VEL_COLUMNS[1:]), need_group=True)
CSV_FIELDS = {"imu": _IMU.fields, "rssi": _RSSI.fields, "odometry": _ODOM.fields}
"""The fields ``--columns`` may map, per kind of file."""


def seconds_to_ns(t_s: float) -> int:
    """Seconds to integer nanoseconds, rounded (float seconds carry ~0.2 us at epoch scale)."""
    return int(round(t_s * 1e9))


def parse_columns(spec: str, option: str = "--columns") -> dict[str, int | str]:
    """``t=0,ax=1,...`` (0-based indexes) or ``t=time,ax=accX,...`` (header names) as a map.

    Raises:
        InputError: an entry without ``KEY=COLUMN``, a key or a column given twice.
    """
    out: dict[str, int | str] = {}
    for entry in spec.split(","):
        key, sep, col = (part.strip() for part in entry.partition("="))
        if not sep or not key or not col:
            raise InputError(
                f"{option} {spec!r}: {entry.strip()!r} is not KEY=COLUMN "
                "(e.g. t=0,ax=1,ay=2,az=3 or t=time,ax=accX)"
            )
        key = "t_s" if key in _TIME_ALIASES else key
        if key in out:
            raise InputError(f"{option} {spec!r}: {key} given twice")
        value: int | str = int(col) if col.isdigit() else col
        if value in out.values():
            raise InputError(f"{option} {spec!r}: column {col} given for two fields")
        out[key] = value
    return out


def parse_column_options(values: Iterable[str]) -> dict[str, dict[str, int | str]]:
    """``--columns [NAME:]SPEC`` values by target: ``""`` (every CSV file), an ``--imu``/``--odom``
    NAME, or ``rssi`` (the ``--rssi`` files).

    Raises:
        InputError: a bad SPEC, or a target given twice.
    """
    out: dict[str, dict[str, int | str]] = {}
    for value in values:
        head, sep, _ = value.partition("=")
        target, colon, spec = value.partition(":") if sep and ":" in head else ("", "", value)
        if colon and not target:
            raise InputError(f"--columns {value!r}: expected [NAME:]KEY=COLUMN,...")
        if target in out:
            which = f"for {target}" if target else "without NAME:"
            raise InputError(f"--columns {value!r}: a second --columns {which}")
        out[target] = parse_columns(spec, f"--columns {target + ':' if target else ''}")
    return out


def _first_row(path: Path) -> list[str]:
    """The first line's cells (for the header decision), checking the file is a readable text."""
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    try:
        with path.open(encoding="utf-8-sig", newline="") as f:
            text = f.readline(1 << 20)
    except UnicodeDecodeError as err:
        raise InputError(f"{path}: not UTF-8 text (byte offset {err.start})") from None
    if not text:
        raise InputError(f"{path}: empty file; a header row is required (or, header-less, samples)")
    if not text.strip():
        raise InputError(f"{path}: line 1 is blank; expected a header row or the first sample")
    return [c.strip() for c in next(csv.reader(io.StringIO(text), skipinitialspace=True))]


def _is_header(row: Sequence[str], layout: CsvLayout) -> bool:
    """Whether the first row is a header: as ``layout.header`` says, else yes when the map
    names a header column, else no when its time cell (with a map by index) or, without a map,
    every cell is a number."""
    if layout.header is not None:
        return layout.header
    if any(isinstance(c, str) for c in layout.columns.values()):
        return True
    t = layout.columns.get("t_s")
    if isinstance(t, int) and t < len(row):
        return not _NUMBER.fullmatch(row[t])
    return not all(_NUMBER.fullmatch(c) for c in row)


def _open_csv(path: Path, has_header: bool) -> Iterator[tuple[pd.DataFrame, np.ndarray]]:
    """Chunks of the CSV as text cells (no type guessing, no NA guessing, no renamed columns:
    cells are labelled by their 0-based index) with the 1-based file line of each row; the
    header and blank lines are left out."""
    line = 1
    try:
        for df in pd.read_csv(
            path,
            header=None,
            chunksize=CHUNK_ROWS,
            dtype=str,
            keep_default_na=False,
            na_filter=False,
            skipinitialspace=True,
            skip_blank_lines=False,  # kept, so that row positions are file lines
            index_col=False,
            encoding="utf-8",
        ):
            lines = line + np.arange(len(df))
            line += len(df)
            keep = np.array((df != "").any(axis=1), dtype=bool)  # blank lines: all cells empty
            if has_header and lines[0] == 1:
                keep[0] = False
            yield df[keep], lines[keep]
    except pd.errors.EmptyDataError as err:
        raise InputError(f"{path}: empty file; a header row is required") from err
    except pd.errors.ParserError as err:
        found = _FIELDS.search(str(err))
        if found:
            expected, bad, saw = found.groups()
            first = "the header" if has_header else "line 1"
            raise InputError(
                f"{path}: line {bad}: {saw} fields, but {first} has {expected}"
            ) from None
        raise InputError(f"{path}: not a readable CSV file ({err})") from None
    except UnicodeDecodeError as err:
        raise InputError(f"{path}: not UTF-8 text (byte offset {err.start})") from None


@dataclass(frozen=True)
class _Columns:
    """Where each field of a sensor CSV is: its column index and its name in the file's terms."""

    index: dict[str, int]
    term: dict[str, str]

    def has(self, fields: Sequence[str]) -> bool:
        return all(f in self.index for f in fields)


def _header_lookup(path: Path, names: Sequence[str], name: str, why: str) -> int | None:
    """The index of header ``name`` (None: absent).

    Raises:
        InputError: ``name`` heads two columns.
    """
    hits = [i for i, n in enumerate(names) if n == name]
    if len(hits) > 1:
        raise InputError(
            f"{path}: line 1: header name {name!r} heads columns {hits[0]} and {hits[1]} "
            f"(0-based); {why} by index, e.g. --columns {name}={hits[0]}"
        )
    return hits[0] if hits else None


def _mapped(
    path: Path, kind: _Kind, layout: CsvLayout, names: Sequence[str] | None, width: int
) -> dict[str, int]:
    """The indexes of the fields ``layout.columns`` names.

    Raises:
        InputError: an unknown field, an index past the last column, a header name the file
            lacks (or a name in a header-less file).
    """
    out: dict[str, int] = {}
    for key, col in layout.columns.items():
        if key not in kind.fields:
            raise InputError(
                f"{path}: --columns {key}={col}: {key} is not a field of an {kind.what} CSV "
                f"(fields: {', '.join(kind.fields)}); give one file's columns with "
                "--columns NAME:KEY=COLUMN,..."
            )
        if isinstance(col, int):
            if col >= width:
                raise InputError(
                    f"{path}: --columns {key}={col}: the file has {width} columns (0..{width - 1})"
                )
            out[key] = col
            continue
        if names is None:
            raise InputError(
                f"{path}: --columns {key}={col} names a header column, but line 1 holds numbers "
                "(no header row): give 0-based indexes, or --header if line 1 is the header"
            )
        index = _header_lookup(path, names, col, "give it")
        if index is None:
            raise InputError(
                f"{path}: --columns {key}={col}: no column {col!r} in the header "
                f"(line 1: {','.join(names)})"
            )
        out[key] = index
    return out


def _resolve(
    path: Path, kind: _Kind, layout: CsvLayout, first: Sequence[str], header: bool
) -> _Columns:
    """Every field's column, from the layout's map and else the header's contract names.

    Raises:
        InputError: a required field has no column, or an optional group is mapped in part.
    """
    names = list(first) if header else None
    index = _mapped(path, kind, layout, names, len(first))
    if names is not None:
        for key in kind.fields:
            if key not in index:
                found = _header_lookup(path, names, key, f"map {key}")
                if found is not None:
                    index[key] = found
    _whole_groups(path, kind, layout, index)
    _require(path, kind, index, names, layout)
    term = {k: names[i] if names is not None else f"{i} (0-based)" for k, i in index.items()}
    return _Columns(index, term)


def _whole_groups(path: Path, kind: _Kind, layout: CsvLayout, index: dict[str, int]) -> None:
    """Raise InputError when the map gives part of an optional group (gx without gy, gz)."""
    for group in kind.groups:
        given = [k for k in group if k in layout.columns]
        if given and not all(k in index for k in group):
            lacking = ", ".join(k for k in group if k not in index)
            raise InputError(f"{path}: --columns gives {', '.join(given)} but not {lacking}")


def _require(
    path: Path, kind: _Kind, index: dict[str, int], names: list[str] | None, layout: CsvLayout
) -> None:
    """Raise InputError, naming what is missing, when a required field has no column."""
    missing = [k for k in kind.required if k not in index]
    no_group = kind.need_group and not any(all(k in index for k in g) for g in kind.groups)
    if not (missing or no_group):
        return
    if names is None:
        raise InputError(
            f"{path}: line 1 holds numbers, so the file has no header row: give its columns by "
            f"0-based index, e.g. --columns {kind.example()}"
            + (f" (missing: {', '.join(missing)})" if layout.columns and missing else "")
            + ", or --header if line 1 is the header"
        )
    found = ",".join(names)
    if kind.need_group and not missing:
        options = " or ".join(",".join(kind.required + g) for g in kind.groups)
        raise InputError(
            f"{path}: {kind.what} CSV needs columns {options} (found {found}); "
            "or map them with --columns"
        )
    raise InputError(
        f"{path}: {kind.what} CSV lacks column(s) {', '.join(missing)}; expected header "
        f"{','.join(kind.required)} (found {found}), or map them with --columns"
    )


@dataclass(frozen=True)
class _Chunk:
    """Rows of a sensor CSV: cells by field, each row's file line, each field's file term."""

    cells: pd.DataFrame
    lines: np.ndarray
    term: dict[str, str]


def _chunks(path: Path, kind: _Kind, layout: CsvLayout | None) -> Iterator[_Chunk]:
    """The CSV's rows by field (columns resolved once, from the first row)."""
    layout = layout or CsvLayout()
    first = _first_row(path)
    header = _is_header(first, layout)
    cols = _resolve(path, kind, layout, first, header)
    labels = {i: k for k, i in cols.index.items()}
    for df, lines in _open_csv(path, header):
        cells = df[list(labels)].rename(columns=labels)
        yield _Chunk(cells, lines, cols.term)


def _numeric(
    path: Path,
    df: pd.DataFrame,
    columns: Sequence[str],
    first_line: int | np.ndarray,
    terms: Mapping[str, str] | None = None,
) -> np.ndarray:
    """The columns as a float array; error naming line and column for text, booleans, NaN, inf.

    ``first_line`` is the line of the first row, or every row's line; ``terms`` the columns'
    names in the file (default: the labels)."""
    lines = first_line + np.arange(len(df)) if isinstance(first_line, int) else first_line
    out = np.empty((len(df), len(columns)), dtype=float)
    for j, col in enumerate(columns):
        text = df[col].astype(str)
        values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        # pandas reads "nan"/"inf" as numbers: refuse them with the rest
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            raw = text.iloc[i]
            what = (
                "empty, expected a finite number"
                if not raw.strip()
                else (f"{raw!r} is not a finite number")
            )
            name = col if terms is None else terms[col]
            raise NonFiniteValueError(f"{path}: line {lines[i]}, column {name}: {what}")
        out[:, j] = values
    return out


def _ids(path: Path, chunk: _Chunk, col: str) -> np.ndarray:
    """An id column exactly as written; a blank cell is an error naming its line."""
    values = chunk.cells[col].astype(str).to_numpy()
    blank = np.char.str_len(np.char.strip(values.astype(str))) == 0
    if blank.any():
        i = int(np.argmax(blank))
        raise InputError(f"{path}: line {chunk.lines[i]}, column {chunk.term[col]}: empty id")
    return values


def _times_ns(path: Path, chunk: _Chunk, unit: str, sensor_rate: bool) -> np.ndarray:
    """``t_s`` in integer ns, exact for integer stamps in ms/us/ns; refuses likely unit mistakes.

    Args:
        sensor_rate: the stream is a sensor sampled faster than 1 Hz (IMU, odometry), so integer
            stamps a second or more apart are taken as milliseconds given as seconds.
    """
    if unit not in TIME_UNITS:
        raise InputError(f"--time-unit {unit!r}: expected one of {', '.join(TIME_UNITS)}")
    seconds = _numeric(path, chunk.cells, ("t_s",), chunk.lines, chunk.term)[:, 0]
    text = chunk.cells["t_s"].astype(str)
    term = chunk.term["t_s"]
    integral = bool(text.str.fullmatch(r"\s*[+-]?\d+\s*").all())
    hint = f"pass --time-unit ms|us|ns (or s) to say what {term} holds"
    if unit == "s":
        if len(seconds) and float(np.max(np.abs(seconds))) > EPOCH_MS_THRESHOLD_S:
            i = int(np.argmax(np.abs(seconds) > EPOCH_MS_THRESHOLD_S))
            raise InputError(
                f"{path}: line {chunk.lines[i]}, column {term}: {text.iloc[i]} looks like epoch "
                f"milliseconds or finer, not seconds; {hint}"
            )
        if sensor_rate and integral and len(seconds) >= 3:
            step = float(np.median(np.diff(seconds)))
            if step >= 1.0:
                raise InputError(
                    f"{path}: line {chunk.lines[0]}, column {term}: integer stamps {step:g} apart "
                    f"look like milliseconds (a sensor sampled slower than 1 Hz); {hint}"
                )
        # exact decimal conversion: "1700000000.01" is 10 ms after "1700000000.00", to the ns
        return np.array([_decimal_ns(v, 10**9) for v in text], dtype=np.int64)
    factor = TIME_UNITS[unit]
    if integral:
        ints = [int(v) * factor for v in text]
        if any(not 0 <= v < 1 << 63 for v in ints):
            raise InputError(
                f"{path}: column {term}: a stamp is outside 0..2^63 ns after conversion"
            )
        return np.array(ints, dtype=np.int64)
    return np.array([_decimal_ns(v, factor) for v in text], dtype=np.int64)


def _decimal_ns(text: str, factor: int) -> int:
    """A decimal number as written times ``factor``, rounded to an integer (no float detour)."""
    return int((Decimal(text.strip()) * factor).to_integral_value(ROUND_HALF_EVEN))


class _TimeCheck:
    """Non-decreasing, non-negative time across chunks of one file (in ns)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.last: int | None = None

    def __call__(self, t_ns: np.ndarray, chunk: _Chunk) -> None:
        if len(t_ns) == 0:
            return
        term = chunk.term["t_s"]
        if t_ns.min() < 0:
            i = int(np.argmax(t_ns < 0))
            raise InputError(f"{self.path}: line {chunk.lines[i]}, column {term}: negative time")
        prev = np.concatenate(([t_ns[0] if self.last is None else self.last], t_ns[:-1]))
        back = t_ns < prev
        if back.any():
            i = int(np.argmax(back))
            raise NonMonotonicTimeError(
                f"{self.path}: line {chunk.lines[i]}, column {term}: {t_ns[i] / 1e9:.9g} s is "
                f"earlier than the previous row ({prev[i] / 1e9:.9g} s); timestamps must not "
                "decrease"
            )
        self.last = int(t_ns[-1])


def read_imu(
    path: str | Path, name: str, time_unit: str = "s", layout: CsvLayout | None = None
) -> Iterator[Imu]:
    """IMU samples from a trackctl CSV (laid out as ``layout`` says) or a Sensor Logger export
    (folder or .zip)."""
    path = Path(path)
    if path.is_dir() or path.suffix.lower() == ".zip":
        if layout is not None and layout.columns:
            raise InputError(
                f"{path}: --columns does not apply to a Sensor Logger export (its files have "
                "fixed columns); give a NAME: prefix to map one CSV file"
            )
        yield from _read_sensor_logger(path, name)
        return
    check = _TimeCheck(path)
    frame = f"phone/{name}"
    has_g = has_q = False
    for chunk in _chunks(path, _IMU, layout):
        has_g = all(c in chunk.cells.columns for c in IMU_GYRO_COLUMNS)
        has_q = all(c in chunk.cells.columns for c in IMU_QUAT_COLUMNS)
        t_ns = _times_ns(path, chunk, time_unit, sensor_rate=True)
        check(t_ns, chunk)
        cols = (
            IMU_COLUMNS[1:]
            + (IMU_GYRO_COLUMNS if has_g else ())
            + (IMU_QUAT_COLUMNS if has_q else ())
        )
        a = _numeric(path, chunk.cells, cols, chunk.lines, chunk.term)
        q0 = 6 if has_g else 3
        for t, row in zip(t_ns, a, strict=True):
            yield Imu(
                t_ns=int(t),
                frame_id=frame,
                accel_mps2=Vec3(row[0], row[1], row[2]),
                gyro_rps=Vec3(row[3], row[4], row[5]) if has_g else None,
                orientation=Quat(row[q0 + 1], row[q0 + 2], row[q0 + 3], row[q0]) if has_q else None,
            )


def _sensor_logger_table(files: dict[str, bytes], stem: str, where: Path) -> pd.DataFrame | None:
    data = files.get(stem.lower())
    if data is None:
        return None
    try:
        df = pd.read_csv(io.BytesIO(data))
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise InputError(f"{where}/{stem}.csv: not a readable CSV file ({err})") from None
    if "time" not in df.columns:
        raise InputError(f"{where}/{stem}.csv: Sensor Logger file lacks the 'time' column")
    return df.sort_values("time", kind="stable").reset_index(drop=True)


def _sensor_logger_files(path: Path) -> dict[str, bytes]:
    """The CSV files of a Sensor Logger export (a folder or a .zip), by lower-case stem."""
    files: dict[str, bytes] = {}
    if path.is_dir():
        for f in path.glob("*.csv"):
            files[f.stem.lower()] = f.read_bytes()
        return files
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                p = Path(info.filename)
                if p.suffix.lower() == ".csv":
                    files[p.stem.lower()] = zf.read(info)
    except (zipfile.BadZipFile, OSError) as err:
        raise InputError(f"{path}: not a readable zip file ({err})") from err
    return files


def _interp_xyz(t: np.ndarray, times: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """The three columns of ``xyz`` (sampled at ``times``) interpolated at ``t``."""
    return np.column_stack([np.interp(t, times, xyz[:, k]) for k in range(3)])


def _gravity(files: dict[str, bytes], path: Path, t: np.ndarray) -> np.ndarray:
    """Gravity.csv at ``t``: Sensor Logger's Accelerometer.csv is user acceleration (gravity
    removed); our Imu carries specific force including gravity, so it is added back."""
    grav = _sensor_logger_table(files, "Gravity", path)
    if grav is None:
        raise InputError(
            f"{path}: Accelerometer.csv has gravity removed and Gravity.csv is missing; "
            "export TotalAcceleration or Gravity too"
        )
    g = _numeric(path / "Gravity.csv", grav, ("x", "y", "z"), 2)
    gt = grav["time"].to_numpy(dtype=np.int64)
    return _interp_xyz(t, gt, g)


def _gyroscope(gyro: pd.DataFrame | None, path: Path, t: np.ndarray) -> np.ndarray | None:
    """Gyroscope.csv at ``t`` (None without one)."""
    if gyro is None:
        return None
    gt = gyro["time"].to_numpy(dtype=np.int64)
    g = _numeric(path / "Gyroscope.csv", gyro, ("x", "y", "z"), 2)
    return _interp_xyz(t, gt, g)


def _orientation(files: dict[str, bytes], path: Path, t: np.ndarray) -> np.ndarray | None:
    """Orientation.csv quaternions (x, y, z, w) at ``t`` (None without them)."""
    ori = _sensor_logger_table(files, "Orientation", path)
    if ori is None or not all(c in ori.columns for c in ("qx", "qy", "qz", "qw")):
        return None
    q = _numeric(path / "Orientation.csv", ori, ("qx", "qy", "qz", "qw"), 2)
    ot = ori["time"].to_numpy(dtype=np.int64)
    # Nearest sample rather than component-wise interpolation, which would leave the unit
    # sphere and mix q with -q across sign flips.
    idx = np.clip(np.searchsorted(ot, t), 0, len(ot) - 1)
    prev = np.clip(idx - 1, 0, len(ot) - 1)
    idx = np.where(np.abs(ot[prev] - t) < np.abs(ot[idx] - t), prev, idx)
    return q[idx]


def _read_sensor_logger(path: Path, name: str) -> Iterator[Imu]:
    files = _sensor_logger_files(path)
    acc = _sensor_logger_table(files, "TotalAcceleration", path)
    gravity_needed = acc is None
    if acc is None:
        acc = _sensor_logger_table(files, "Accelerometer", path)
    gyro = _sensor_logger_table(files, "Gyroscope", path)
    if acc is None:
        raise InputError(
            f"{path}: not a Sensor Logger export: need TotalAcceleration.csv (or Accelerometer.csv "
            f"+ Gravity.csv) [+ Gyroscope.csv]; found {', '.join(sorted(files)) or 'no CSV files'}"
        )
    t = acc["time"].to_numpy(dtype=np.int64)
    accel = _numeric(path / "accelerometer.csv", acc, ("x", "y", "z"), 2)
    if gravity_needed:
        accel = accel + _gravity(files, path, t)
    gyro_i = _gyroscope(gyro, path, t)
    quat = _orientation(files, path, t)
    frame = f"phone/{name}"
    for i in range(len(t)):
        yield Imu(
            t_ns=int(t[i]),
            frame_id=frame,
            accel_mps2=Vec3(*map(float, accel[i])),
            gyro_rps=None if gyro_i is None else Vec3(*map(float, gyro_i[i])),
            orientation=None if quat is None else Quat(*map(float, quat[i])),
        )


def read_rssi_csv(
    path: str | Path, time_unit: str = "s", layout: CsvLayout | None = None
) -> Iterator[RssiScan]:
    """RSSI scans: consecutive rows with equal ``t_s`` and ``observer`` make one scan."""
    path = Path(path)
    check = _TimeCheck(path)
    pending: tuple[int, str] | None = None
    readings: list[RssiReading] = []
    for chunk in _chunks(path, _RSSI, layout):
        t_ns = _times_ns(path, chunk, time_unit, sensor_rate=False)
        check(t_ns, chunk)
        rssi = _numeric(path, chunk.cells, ("rssi_dbm",), chunk.lines, chunk.term)[:, 0]
        observers = _ids(path, chunk, "observer")
        eids = _ids(path, chunk, "eid")
        for i in range(len(t_ns)):
            key = (int(t_ns[i]), str(observers[i]))
            if pending is not None and key != pending:
                yield RssiScan(pending[0], pending[1], tuple(readings))
                readings = []
            pending = key
            readings.append(RssiReading(str(eids[i]), float(rssi[i])))
    if pending is not None:
        yield RssiScan(pending[0], pending[1], tuple(readings))


def read_odometry_csv(
    path: str | Path, name: str, time_unit: str = "s", layout: CsvLayout | None = None
) -> Iterator[WheelOdometry]:
    """Wheel odometry from ticks (``left_ticks,right_ticks``) or ``v_mps,omega_rps``."""
    path = Path(path)
    check = _TimeCheck(path)
    frame = f"robot/{name}"
    for chunk in _chunks(path, _ODOM, layout):
        ticks = all(c in chunk.cells.columns for c in ODOM_TICK_COLUMNS[1:])
        vel = all(c in chunk.cells.columns for c in ODOM_VEL_COLUMNS[1:])
        t_ns = _times_ns(path, chunk, time_unit, sensor_rate=True)
        check(t_ns, chunk)
        cols = (ODOM_TICK_COLUMNS[1:] if ticks else ()) + (ODOM_VEL_COLUMNS[1:] if vel else ())
        a = _numeric(path, chunk.cells, cols, chunk.lines, chunk.term)
        for t, row in zip(t_ns, a, strict=True):
            left = right = v = w = None
            k = 0
            if ticks:
                left, right = int(row[0]), int(row[1])
                k = 2
            if vel:
                v, w = float(row[k]), float(row[k + 1])
            yield WheelOdometry(int(t), frame, left, right, v, w)
