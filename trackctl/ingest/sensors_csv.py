"""CSV readers for IMU, RSSI and wheel odometry (``trackctl record --imu/--rssi/--odom``).

Column contract (header row required, extra columns ignored, ``t_s`` in seconds on the log's
clock, non-decreasing):

* IMU: ``t_s,ax,ay,az`` (m/s^2 incl. gravity) + optional ``gx,gy,gz`` (rad/s; many phone
  datasets are accelerometer-only) + optional ``qw,qx,qy,qz``;
  or an Android/iOS "Sensor Logger" export (a folder or .zip holding ``TotalAcceleration.csv`` or
  ``Accelerometer.csv`` [+ ``Gravity.csv``], ``Gyroscope.csv`` and optionally ``Orientation.csv``,
  each with ``time`` in UTC nanoseconds and ``x,y,z`` / ``qx,qy,qz,qw`` columns);
* RSSI: ``t_s,observer,eid,rssi_dbm`` (rows with equal ``t_s`` and ``observer`` form one scan);
* odometry: ``t_s,left_ticks,right_ticks`` or ``t_s,v_mps,omega_rps``.

Files are read in chunks, so memory does not grow with file length (Sensor Logger exports are
merged in memory: they come as separate per-sensor files that must be aligned).

Parsing is strict: every cell is read as text and converted explicitly. Ids (``observer``,
``eid``) stay exactly as written (``007`` stays ``007``; a blank id is an error); a number column
holding text or a boolean (``true``), NaN or infinity is an error naming file, line and column; a
row with more fields than the header is an error naming the line.

Time unit rule: ``t_s`` is in seconds unless ``time_unit`` says otherwise (``ms``, ``us``, ``ns``
convert exactly, integers without a float round trip). A ``t_s`` above 1e11 (later than the year
5138 in Unix seconds) is refused as "epoch milliseconds or finer", and IMU or odometry whose
samples are a second or more apart with integer stamps is refused as "milliseconds"; both errors
suggest ``--time-unit``.
"""

from __future__ import annotations

import io
import re
import warnings
import zipfile
from collections.abc import Iterator, Sequence
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


def seconds_to_ns(t_s: float) -> int:
    """Seconds to integer nanoseconds, rounded (float seconds carry ~0.2 us at epoch scale)."""
    return int(round(t_s * 1e9))


def _open_csv(path: Path) -> Iterator[pd.DataFrame]:
    """Chunks of the CSV as text cells (no type guessing, no NA guessing)."""
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)
            yield from pd.read_csv(
                path,
                chunksize=CHUNK_ROWS,
                dtype=str,
                keep_default_na=False,
                na_filter=False,
                skipinitialspace=True,
                index_col=False,
                encoding="utf-8",
            )
    except pd.errors.EmptyDataError as err:
        raise InputError(f"{path}: empty file; a header row is required") from err
    except pd.errors.ParserError as err:
        found = _FIELDS.search(str(err))
        if found:
            expected, line, saw = found.groups()
            raise InputError(
                f"{path}: line {line}: {saw} fields, but the header has {expected}"
            ) from None
        raise InputError(f"{path}: not a readable CSV file ({err})") from None
    except pd.errors.ParserWarning:
        raise InputError(
            f"{path}: line 2: more fields than the header (extra columns need a header name)"
        ) from None
    except UnicodeDecodeError as err:
        raise InputError(f"{path}: not UTF-8 text (byte offset {err.start})") from None


def _need(path: Path, df: pd.DataFrame, columns: Sequence[str], what: str) -> None:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise InputError(
            f"{path}: {what} CSV lacks column(s) {', '.join(missing)}; expected header "
            f"{','.join(columns)} (found {','.join(map(str, df.columns))})"
        )


def _numeric(path: Path, df: pd.DataFrame, columns: Sequence[str], first_line: int) -> np.ndarray:
    """The columns as a float array; error naming line and column for text, booleans, NaN, inf."""
    out = np.empty((len(df), len(columns)), dtype=float)
    for j, col in enumerate(columns):
        text = df[col].astype(str)
        values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        # pandas reads "nan"/"inf" as numbers: refuse them with the rest
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            raw = text.iloc[i]
            raise NonFiniteValueError(
                f"{path}: line {first_line + i}, column {col}: {raw!r} is not a finite number"
            )
        out[:, j] = values
    return out


def _ids(path: Path, df: pd.DataFrame, col: str, first_line: int) -> np.ndarray:
    """An id column exactly as written; a blank cell is an error naming its line."""
    values = df[col].astype(str).to_numpy()
    blank = np.char.str_len(np.char.strip(values.astype(str))) == 0
    if blank.any():
        i = int(np.argmax(blank))
        raise InputError(f"{path}: line {first_line + i}, column {col}: empty id")
    return values


def _times_ns(
    path: Path, df: pd.DataFrame, first_line: int, unit: str, sensor_rate: bool
) -> np.ndarray:
    """``t_s`` in integer ns, exact for integer stamps in ms/us/ns; refuses likely unit mistakes.

    Args:
        sensor_rate: the stream is a sensor sampled faster than 1 Hz (IMU, odometry), so integer
            stamps a second or more apart are taken as milliseconds given as seconds.
    """
    if unit not in TIME_UNITS:
        raise InputError(f"--time-unit {unit!r}: expected one of {', '.join(TIME_UNITS)}")
    seconds = _numeric(path, df, ("t_s",), first_line)[:, 0]
    text = df["t_s"].astype(str)
    integral = bool(text.str.fullmatch(r"\s*[+-]?\d+\s*").all())
    hint = "pass --time-unit ms|us|ns (or s) to say what t_s holds"
    if unit == "s":
        if len(seconds) and float(np.max(np.abs(seconds))) > EPOCH_MS_THRESHOLD_S:
            i = int(np.argmax(np.abs(seconds) > EPOCH_MS_THRESHOLD_S))
            raise InputError(
                f"{path}: line {first_line + i}, column t_s: {text.iloc[i]} looks like epoch "
                f"milliseconds or finer, not seconds; {hint}"
            )
        if sensor_rate and integral and len(seconds) >= 3:
            step = float(np.median(np.diff(seconds)))
            if step >= 1.0:
                raise InputError(
                    f"{path}: line {first_line}, column t_s: integer stamps {step:g} apart look "
                    f"like milliseconds (a sensor sampled slower than 1 Hz); {hint}"
                )
        # exact decimal conversion: "1700000000.01" is 10 ms after "1700000000.00", to the ns
        return np.array([_decimal_ns(v, 10**9) for v in text], dtype=np.int64)
    factor = TIME_UNITS[unit]
    if integral:
        ints = [int(v) * factor for v in text]
        if any(not 0 <= v < 1 << 63 for v in ints):
            raise InputError(f"{path}: column t_s: a stamp is outside 0..2^63 ns after conversion")
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

    def __call__(self, t_ns: np.ndarray, first_line: int) -> None:
        if len(t_ns) == 0:
            return
        if t_ns.min() < 0:
            i = int(np.argmax(t_ns < 0))
            raise InputError(f"{self.path}: line {first_line + i}, column t_s: negative time")
        prev = np.concatenate(([t_ns[0] if self.last is None else self.last], t_ns[:-1]))
        back = t_ns < prev
        if back.any():
            i = int(np.argmax(back))
            raise NonMonotonicTimeError(
                f"{self.path}: line {first_line + i}, column t_s: {t_ns[i] / 1e9:.9g} s is "
                f"earlier than the previous row ({prev[i] / 1e9:.9g} s); timestamps must not "
                "decrease"
            )
        self.last = int(t_ns[-1])


def read_imu(path: str | Path, name: str, time_unit: str = "s") -> Iterator[Imu]:
    """IMU samples from a trackctl CSV or a Sensor Logger export (folder or .zip)."""
    path = Path(path)
    if path.is_dir() or path.suffix.lower() == ".zip":
        yield from _read_sensor_logger(path, name)
        return
    check = _TimeCheck(path)
    line = 2
    frame = f"phone/{name}"
    for df in _open_csv(path):
        _need(path, df, IMU_COLUMNS, "IMU")
        has_g = all(c in df.columns for c in IMU_GYRO_COLUMNS)
        has_q = all(c in df.columns for c in IMU_QUAT_COLUMNS)
        t_ns = _times_ns(path, df, line, time_unit, sensor_rate=True)
        check(t_ns, line)
        cols = (
            IMU_COLUMNS[1:]
            + (IMU_GYRO_COLUMNS if has_g else ())
            + (IMU_QUAT_COLUMNS if has_q else ())
        )
        a = _numeric(path, df, cols, line)
        q0 = 6 if has_g else 3
        for t, row in zip(t_ns, a, strict=True):
            yield Imu(
                t_ns=int(t),
                frame_id=frame,
                accel_mps2=Vec3(row[0], row[1], row[2]),
                gyro_rps=Vec3(row[3], row[4], row[5]) if has_g else None,
                orientation=Quat(row[q0 + 1], row[q0 + 2], row[q0 + 3], row[q0]) if has_q else None,
            )
        line += len(df)


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


def read_rssi_csv(path: str | Path, time_unit: str = "s") -> Iterator[RssiScan]:
    """RSSI scans: consecutive rows with equal ``t_s`` and ``observer`` make one scan."""
    path = Path(path)
    check = _TimeCheck(path)
    line = 2
    pending: tuple[int, str] | None = None
    readings: list[RssiReading] = []
    for df in _open_csv(path):
        _need(path, df, RSSI_COLUMNS, "RSSI")
        t_ns = _times_ns(path, df, line, time_unit, sensor_rate=False)
        check(t_ns, line)
        rssi = _numeric(path, df, ("rssi_dbm",), line)[:, 0]
        observers = _ids(path, df, "observer", line)
        eids = _ids(path, df, "eid", line)
        for i in range(len(df)):
            key = (int(t_ns[i]), str(observers[i]))
            if pending is not None and key != pending:
                yield RssiScan(pending[0], pending[1], tuple(readings))
                readings = []
            pending = key
            readings.append(RssiReading(str(eids[i]), float(rssi[i])))
        line += len(df)
    if pending is not None:
        yield RssiScan(pending[0], pending[1], tuple(readings))


def read_odometry_csv(path: str | Path, name: str, time_unit: str = "s") -> Iterator[WheelOdometry]:
    """Wheel odometry from ticks (``left_ticks,right_ticks``) or ``v_mps,omega_rps``."""
    path = Path(path)
    check = _TimeCheck(path)
    line = 2
    frame = f"robot/{name}"
    for df in _open_csv(path):
        ticks = all(c in df.columns for c in ODOM_TICK_COLUMNS)
        vel = all(c in df.columns for c in ODOM_VEL_COLUMNS)
        if not (ticks or vel):
            raise InputError(
                f"{path}: odometry CSV needs columns {','.join(ODOM_TICK_COLUMNS)} or "
                f"{','.join(ODOM_VEL_COLUMNS)} (found {','.join(map(str, df.columns))})"
            )
        t_ns = _times_ns(path, df, line, time_unit, sensor_rate=True)
        check(t_ns, line)
        cols = (ODOM_TICK_COLUMNS[1:] if ticks else ()) + (ODOM_VEL_COLUMNS[1:] if vel else ())
        a = _numeric(path, df, cols, line)
        for t, row in zip(t_ns, a, strict=True):
            left = right = v = w = None
            k = 0
            if ticks:
                left, right = int(row[0]), int(row[1])
                k = 2
            if vel:
                v, w = float(row[k]), float(row[k + 1])
            yield WheelOdometry(int(t), frame, left, right, v, w)
        line += len(df)
