"""CSV export: read back by pandas."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from tests.export.conftest import SAMPLES
from trackctl.export import ExportConfig, ExportFormat, export
from trackctl.export import csv as csv_export
from trackctl.logs.messages import Imu, Tracks
from trackctl.logs.reader import LogReader


def _csv(log: Path, topic: str, out: Path) -> pd.DataFrame:
    export(log, out, ExportConfig(topic, ExportFormat.CSV))
    return pd.read_csv(out)


def test_tracks_are_one_row_per_track(
    vm_office_tracked: tuple[dict[str, Any], Path], tmp_path: Path
) -> None:
    _, log = vm_office_tracked
    table = _csv(log, "/vmtrack/tracks", tmp_path / "tracks.csv")
    msgs = list(LogReader(log).messages(["/vmtrack/tracks"]))
    tracks = [(m, t) for m in msgs if isinstance(m.message, Tracks) for t in m.message.tracks]
    assert list(table.columns[:8]) == [
        "log_time_ns", "t_ns", "frame_id", "track_id",
        "position_m.x", "position_m.y", "position_m.z", "velocity_mps.x",
    ]  # fmt: skip
    assert {"covariance_m2", "state", "visual_id", "score"} <= set(table.columns)
    assert len(table) == len(tracks)
    assert table["log_time_ns"].tolist() == [m.log_time_ns for m, _ in tracks]
    assert table["t_ns"].tolist() == [m.message.t_ns for m, _ in tracks]
    assert table["track_id"].tolist() == [t.track_id for _, t in tracks]
    assert table["position_m.x"].tolist() == pytest.approx([t.position_m.x for _, t in tracks])
    assert set(table["state"]) <= {"tracked", "predicted", "tentative", "lost"}


def test_imu_is_one_row_per_message(tmp_path: Path) -> None:
    log = SAMPLES / "demo.mcap"
    table = _csv(log, "/phone/p1/imu", tmp_path / "imu.csv")
    msgs = [m.message for m in LogReader(log).messages(["/phone/p1/imu"])]
    assert isinstance(msgs[0], Imu)
    assert list(table.columns) == [
        "log_time_ns", "t_ns", "frame_id", "accel_mps2.x", "accel_mps2.y", "accel_mps2.z",
        "gyro_rps.x", "gyro_rps.y", "gyro_rps.z",
        "orientation.x", "orientation.y", "orientation.z", "orientation.w",
    ]  # fmt: skip
    assert len(table) == len(msgs) == 400
    assert table["accel_mps2.z"].tolist() == pytest.approx([m.accel_mps2.z for m in msgs])


def test_protobuf_topics_flatten_too(tmp_path: Path) -> None:
    log = SAMPLES / "demo.mcap"
    table = _csv(log, "/cam0/image", tmp_path / "image.csv")
    assert list(table.columns) == ["log_time_ns", "timestamp", "frame_id", "data", "format"]
    assert len(table) == 60 and (table["data"] > 0).all()  # the JPEG's size, not its bytes
    calib = _csv(log, "/cam0/calibration", tmp_path / "calib.csv")
    assert len(calib) == 1 and {"width", "height", "K"} <= set(calib.columns)


def test_streams_in_chunks(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(csv_export, "ROWS_PER_CHUNK", 7)
    log = SAMPLES / "demo.mcap"
    chunked = _csv(log, "/robot/r1/odom", tmp_path / "odom.csv")
    assert len(chunked) == 500 and chunked.columns[0] == "log_time_ns"
    assert chunked["log_time_ns"].is_monotonic_increasing
    assert chunked["left_ticks"].dtype.kind == "i"  # integers stay integers
