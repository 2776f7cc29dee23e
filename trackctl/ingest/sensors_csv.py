"""CSV readers for IMU, RSSI and wheel odometry (``trackctl record --imu/--rssi/--odom``).

Column contract (header row required, extra columns ignored, ``t_s`` in seconds on the log's
clock, non-decreasing):

* IMU: ``t_s,ax,ay,az,gx,gy,gz`` (m/s^2 incl. gravity, rad/s) + optional ``qw,qx,qy,qz``;
  or an Android/iOS "Sensor Logger" export (a folder or .zip holding ``TotalAcceleration.csv`` or
  ``Accelerometer.csv`` [+ ``Gravity.csv``], ``Gyroscope.csv`` and optionally ``Orientation.csv``,
  each with ``time`` in UTC nanoseconds and ``x,y,z`` / ``qx,qy,qz,qw`` columns);
* RSSI: ``t_s,observer,eid,rssi_dbm`` (rows with equal ``t_s`` and ``observer`` form one scan);
* odometry: ``t_s,left_ticks,right_ticks`` or ``t_s,v_mps,omega_rps``.

Files are read in chunks, so memory does not grow with file length (Sensor Logger exports are
merged in memory: they come as separate per-sensor files that must be aligned).
"""

from __future__ import annotations

import io
import math
import zipfile
from collections.abc import Iterator, Sequence
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
    "RSSI_COLUMNS",
    "ODOM_TICK_COLUMNS",
    "ODOM_VEL_COLUMNS",
]

IMU_COLUMNS = ("t_s", "ax", "ay", "az", "gx", "gy", "gz")
IMU_QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
RSSI_COLUMNS = ("t_s", "observer", "eid", "rssi_dbm")
ODOM_TICK_COLUMNS = ("t_s", "left_ticks", "right_ticks")
ODOM_VEL_COLUMNS = ("t_s", "v_mps", "omega_rps")
CHUNK_ROWS = 50_000


def seconds_to_ns(t_s: float) -> int:
    """Seconds to integer nanoseconds, rounded (float seconds carry ~0.2 us at epoch scale)."""
    return int(round(t_s * 1e9))


def _open_csv(path: Path) -> Iterator[pd.DataFrame]:
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    try:
        yield from pd.read_csv(path, chunksize=CHUNK_ROWS, skipinitialspace=True)
    except pd.errors.EmptyDataError as err:
        raise InputError(f"{path}: empty file; a header row is required") from err
    except (pd.errors.ParserError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: not a readable CSV file ({err})") from err


def _need(path: Path, df: pd.DataFrame, columns: Sequence[str], what: str) -> None:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise InputError(
            f"{path}: {what} CSV lacks column(s) {', '.join(missing)}; expected header "
            f"{','.join(columns)} (found {','.join(map(str, df.columns))})"
        )


def _numeric(path: Path, df: pd.DataFrame, columns: Sequence[str], first_line: int) -> np.ndarray:
    """The columns as a float array; error naming row and column for text, NaN or inf."""
    out = np.empty((len(df), len(columns)), dtype=float)
    for j, col in enumerate(columns):
        values = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            raw = df[col].iloc[i]
            raise NonFiniteValueError(
                f"{path}: line {first_line + i}, column {col}: {raw!r} is not a finite number"
            )
        out[:, j] = values
    return out


class _TimeCheck:
    """Non-decreasing time across chunks of one file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.last = -math.inf

    def __call__(self, t_s: np.ndarray, first_line: int) -> None:
        if len(t_s) == 0:
            return
        prev = np.concatenate(([self.last], t_s[:-1]))
        back = t_s < prev
        if back.any():
            i = int(np.argmax(back))
            raise NonMonotonicTimeError(
                f"{self.path}: line {first_line + i}, column t_s: {t_s[i]} is earlier than the "
                f"previous row ({prev[i]}); timestamps must not decrease"
            )
        if t_s[0] < 0:
            raise InputError(f"{self.path}: line {first_line}, column t_s: negative time {t_s[0]}")
        self.last = float(t_s[-1])


def read_imu(path: str | Path, name: str) -> Iterator[Imu]:
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
        has_q = all(c in df.columns for c in IMU_QUAT_COLUMNS)
        cols = IMU_COLUMNS + (IMU_QUAT_COLUMNS if has_q else ())
        a = _numeric(path, df, cols, line)
        check(a[:, 0], line)
        for row in a:
            yield Imu(
                t_ns=seconds_to_ns(row[0]),
                frame_id=frame,
                accel_mps2=Vec3(row[1], row[2], row[3]),
                gyro_rps=Vec3(row[4], row[5], row[6]),
                orientation=Quat(row[8], row[9], row[10], row[7]) if has_q else None,
            )
        line += len(df)


def _sensor_logger_table(files: dict[str, bytes], stem: str, where: Path) -> pd.DataFrame | None:
    data = files.get(stem.lower())
    if data is None:
        return None
    df = pd.read_csv(io.BytesIO(data))
    if "time" not in df.columns:
        raise InputError(f"{where}/{stem}.csv: Sensor Logger file lacks the 'time' column")
    return df.sort_values("time", kind="stable").reset_index(drop=True)


def _read_sensor_logger(path: Path, name: str) -> Iterator[Imu]:
    files: dict[str, bytes] = {}
    if path.is_dir():
        for f in path.glob("*.csv"):
            files[f.stem.lower()] = f.read_bytes()
    else:
        try:
            with zipfile.ZipFile(path) as zf:
                for info in zf.infolist():
                    p = Path(info.filename)
                    if p.suffix.lower() == ".csv":
                        files[p.stem.lower()] = zf.read(info)
        except (zipfile.BadZipFile, OSError) as err:
            raise InputError(f"{path}: not a readable zip file ({err})") from err
    acc = _sensor_logger_table(files, "TotalAcceleration", path)
    gravity_needed = acc is None
    if acc is None:
        acc = _sensor_logger_table(files, "Accelerometer", path)
    gyro = _sensor_logger_table(files, "Gyroscope", path)
    if acc is None or gyro is None:
        raise InputError(
            f"{path}: not a Sensor Logger export: need TotalAcceleration.csv (or Accelerometer.csv "
            f"+ Gravity.csv) and Gyroscope.csv; found {', '.join(sorted(files)) or 'no CSV files'}"
        )
    t = acc["time"].to_numpy(dtype=np.int64)
    accel = _numeric(path / "accelerometer.csv", acc, ("x", "y", "z"), 2)
    if gravity_needed:
        # Sensor Logger's Accelerometer.csv is user acceleration (gravity removed); our Imu
        # carries specific force including gravity, so add Gravity.csv back when it is there.
        grav = _sensor_logger_table(files, "Gravity", path)
        if grav is None:
            raise InputError(
                f"{path}: Accelerometer.csv has gravity removed and Gravity.csv is missing; "
                "export TotalAcceleration or Gravity too"
            )
        g = _numeric(path / "Gravity.csv", grav, ("x", "y", "z"), 2)
        gt = grav["time"].to_numpy(dtype=np.int64)
        accel = accel + np.column_stack([np.interp(t, gt, g[:, k]) for k in range(3)])
    gt = gyro["time"].to_numpy(dtype=np.int64)
    g = _numeric(path / "Gyroscope.csv", gyro, ("x", "y", "z"), 2)
    gyro_i = np.column_stack([np.interp(t, gt, g[:, k]) for k in range(3)])
    ori = _sensor_logger_table(files, "Orientation", path)
    quat = None
    if ori is not None and all(c in ori.columns for c in ("qx", "qy", "qz", "qw")):
        q = _numeric(path / "Orientation.csv", ori, ("qx", "qy", "qz", "qw"), 2)
        ot = ori["time"].to_numpy(dtype=np.int64)
        # Nearest sample rather than component-wise interpolation, which would leave the unit
        # sphere and mix q with -q across sign flips.
        idx = np.clip(np.searchsorted(ot, t), 0, len(ot) - 1)
        prev = np.clip(idx - 1, 0, len(ot) - 1)
        idx = np.where(np.abs(ot[prev] - t) < np.abs(ot[idx] - t), prev, idx)
        quat = q[idx]
    frame = f"phone/{name}"
    for i in range(len(t)):
        yield Imu(
            t_ns=int(t[i]),
            frame_id=frame,
            accel_mps2=Vec3(*map(float, accel[i])),
            gyro_rps=Vec3(*map(float, gyro_i[i])),
            orientation=None if quat is None else Quat(*map(float, quat[i])),
        )


def read_rssi_csv(path: str | Path) -> Iterator[RssiScan]:
    """RSSI scans: consecutive rows with equal ``t_s`` and ``observer`` make one scan."""
    path = Path(path)
    check = _TimeCheck(path)
    line = 2
    pending: tuple[float, str] | None = None
    readings: list[RssiReading] = []
    for df in _open_csv(path):
        _need(path, df, RSSI_COLUMNS, "RSSI")
        num = _numeric(path, df, ("t_s", "rssi_dbm"), line)
        check(num[:, 0], line)
        observers = df["observer"].astype(str).to_numpy()
        eids = df["eid"].astype(str).to_numpy()
        for i in range(len(df)):
            key = (float(num[i, 0]), str(observers[i]))
            if pending is not None and key != pending:
                yield RssiScan(seconds_to_ns(pending[0]), pending[1], tuple(readings))
                readings = []
            pending = key
            readings.append(RssiReading(str(eids[i]), float(num[i, 1])))
        line += len(df)
    if pending is not None:
        yield RssiScan(seconds_to_ns(pending[0]), pending[1], tuple(readings))


def read_odometry_csv(path: str | Path, name: str) -> Iterator[WheelOdometry]:
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
        cols = (
            ("t_s",)
            + (ODOM_TICK_COLUMNS[1:] if ticks else ())
            + (ODOM_VEL_COLUMNS[1:] if vel else ())
        )
        a = _numeric(path, df, cols, line)
        check(a[:, 0], line)
        for row in a:
            k = 1
            left = right = v = w = None
            if ticks:
                left, right = int(row[1]), int(row[2])
                k = 3
            if vel:
                v, w = float(row[k]), float(row[k + 1])
            yield WheelOdometry(seconds_to_ns(row[0]), frame, left, right, v, w)
        line += len(df)
