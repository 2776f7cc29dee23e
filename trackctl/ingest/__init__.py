"""Getting data into MCAP: CSV sensors, video, calibration, live JSON lines (`record`)."""

from trackctl.ingest.calibration import read_calibration, to_foxglove_calibration
from trackctl.ingest.record import LiveStats, RecordConfig, record_files, record_live
from trackctl.ingest.sensors_csv import read_imu, read_odometry_csv, read_rssi_csv
from trackctl.ingest.video import read_frames

__all__ = [
    "LiveStats",
    "RecordConfig",
    "read_calibration",
    "read_frames",
    "read_imu",
    "read_odometry_csv",
    "read_rssi_csv",
    "record_files",
    "record_live",
    "to_foxglove_calibration",
]
