"""ROS 2 bags in: ``record --ros2`` maps topics by type, and S-Mirror runs on the result as on a
native log; ``info`` and ``replay`` decode CDR channels."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from typer.testing import CliRunner

from tests.conftest import ROOT, run_cli
from tests.ingest.ros2_bags import TS, T, _header, smirror_log_to_bag
from trackctl.cli.main import app
from trackctl.errors import IncompleteInputWarning, InputError
from trackctl.ingest.ros2 import _name_from_topic, parse_maps, plan_ros2
from trackctl.logs import LogReader
from trackctl.processing import run_processors
from trackctl.smirror import SmirrorProcessor, pose_topic

SAMPLE = ROOT / "sample_logs" / "smirror.mcap"


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("ros2") / "smirror_bag"
    smirror_log_to_bag(SAMPLE, path)
    return path


def _poses(log: Path, tmp: Path) -> dict[int, tuple[float, float]]:
    out = tmp / f"{log.stem}-poses.mcap"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IncompleteInputWarning)
        run_processors(log, out, [SmirrorProcessor()], outputs_only=True)
    return {
        m.log_time_ns: (m.message.pose.position.x, m.message.pose.position.y)
        for m in LogReader(out).messages([pose_topic("r1")])
    }


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_recorded_bag_localizes_like_the_native_log(
    bag: Path, tmp_path: Path, storage: str
) -> None:
    if storage == "sqlite3":
        src = tmp_path / "db3_bag"
        smirror_log_to_bag(SAMPLE, src, StoragePlugin.SQLITE3)
    else:
        src = bag
    log = tmp_path / "from_ros.mcap"
    proc = run_cli("record", str(log), "--ros2", str(src), check=True)
    table = proc.stderr.decode()
    assert "/r1/odom" in table and "/robot/r1/odom" in table  # the mapping table
    native, converted = _poses(SAMPLE, tmp_path), _poses(log, tmp_path)
    assert len(converted) == len(native) > 100
    assert native.keys() == converted.keys()
    diff = max(
        float(np.hypot(native[t][0] - converted[t][0], native[t][1] - converted[t][1]))
        for t in native
    )
    assert diff < 0.01


def test_plan_by_type_and_overrides(bag: Path) -> None:
    plan = {p.ros_topic: p for p in plan_ros2(bag)}
    assert plan["/r1/odom"].targets == ("/robot/r1/odom", "/robot/r1/reference/odom")
    assert plan["/node0/image/compressed"].targets == ("/node0/image",)
    assert plan["/node0/camera_info"].targets == ("/node0/calibration", "/node0/camera_model")
    assert plan["/tf_static"].targets == ("/tf_static",)
    assert plan["/r1/imu"].targets == ("/robot/r1/imu",)
    mapped = {
        p.ros_topic: p
        for p in plan_ros2(bag, parse_maps(["/r1/odom=odometry:base", "/r1/imu=ignore"]))
    }
    # the source keeps the topic's meaningful segments without its robot's name: r1 (not base)
    assert mapped["/r1/odom"].targets == ("/robot/base/odom", "/robot/base/reference/r1")
    assert mapped["/r1/odom"].why == "--map"
    assert mapped["/r1/imu"].targets == ()
    with pytest.raises(InputError, match="--map /nope: the bag has no such topic"):
        plan_ros2(bag, parse_maps(["/nope=odometry:x"]))
    with pytest.raises(InputError, match="role image takes sensor_msgs/msg/CompressedImage"):
        plan_ros2(bag, parse_maps(["/r1/odom=image:x"]))
    with pytest.raises(InputError, match="both map to /node0/image"):
        plan_ros2(bag, parse_maps(["/node1/image/compressed=image:node0"]))


@pytest.mark.parametrize(
    "value, message",
    [
        ("odom=odometry:r1", "expected ROS_TOPIC=ROLE:NAME"),
        ("/odom=wheels:r1", "role 'wheels' is not one of"),
        ("/odom=odometry", "NAME is required"),
    ],
)
def test_bad_maps_are_one_line_errors(value: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_maps([value])


@pytest.mark.parametrize(
    "topic, role, name",
    [
        ("/cam0/image_raw/compressed", "image", "cam0"),
        ("/camera/color/image_raw", "image", "camera"),
        ("/camera_info", "camera_info", "camera"),
        ("/odom", "odometry", "robot"),
        ("/tb3/odom", "odometry", "tb3"),
        ("/imu/data", "imu", "robot"),
    ],
)
def test_names_come_from_the_namespace(topic: str, role: str, name: str) -> None:
    assert _name_from_topic(topic, role) == name


def test_info_and_replay_decode_cdr(bag: Path) -> None:
    mcap = next(bag.glob("*.mcap"))
    info = run_cli("info", str(mcap), check=True)
    assert b"nav_msgs/msg/Odometry" in info.stdout and b"cdr" in info.stdout
    out = run_cli(
        "replay", str(mcap), "--speed", "0", "--format", "jsonl", "--topics", "/r1/odom", check=True
    )
    first = json.loads(out.stdout.splitlines()[1])
    assert first["schema"] == "nav_msgs/msg/Odometry"
    assert first["message"]["header"]["frame_id"] == "odom"
    assert isinstance(first["message"]["twist"]["twist"]["linear"]["x"], float)


def test_raw_images_are_encoded_losslessly(tmp_path: Path) -> None:
    src = tmp_path / "raw_bag"
    rgb = np.random.default_rng(0).integers(0, 255, (6, 8, 3), dtype=np.uint8)
    with Writer(src, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/cam0/image_raw", "sensor_msgs/msg/Image", typestore=TS)
        msg = T["sensor_msgs/msg/Image"](
            header=_header(1_000, "cam0_optical"),
            height=6,
            width=8,
            encoding="rgb8",
            is_bigendian=0,
            step=24,
            data=rgb.ravel(),
        )
        w.write(conn, 5_000, TS.serialize_cdr(msg, conn.msgtype))
    log = tmp_path / "raw.mcap"
    result = CliRunner().invoke(app, ["record", str(log), "--ros2", str(src), "-q"])
    assert result.exit_code == 0, result.output
    (img,) = [m for m in LogReader(log).messages(["/cam0/image"])]
    import cv2

    decoded = cv2.imdecode(np.frombuffer(img.message.data, np.uint8), cv2.IMREAD_COLOR)
    assert img.message.format == "png" and img.log_time_ns == 5_000
    assert img.message.timestamp.ToNanoseconds() == 1_000
    assert np.array_equal(decoded[:, :, ::-1], rgb)


def test_cli_errors(tmp_path: Path, bag: Path) -> None:
    runner = CliRunner()
    gone = runner.invoke(app, ["record", str(tmp_path / "o.mcap"), "--ros2", str(tmp_path / "x")])
    assert gone.exit_code == 2 and "no such file or directory" in gone.output
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a bag")
    bad = runner.invoke(app, ["record", str(tmp_path / "o.mcap"), "--ros2", str(junk)])
    assert bad.exit_code == 2 and "not a readable ROS bag" in bad.output
    nomap = runner.invoke(app, ["record", str(tmp_path / "o.mcap"), "--map", "/a=ignore"])
    assert nomap.exit_code == 2 and "--map needs --ros BAG" in nomap.output
    assert not (tmp_path / "o.mcap").exists()


def test_a_log_without_site_metadata_warns_once(bag: Path, tmp_path: Path) -> None:
    log = tmp_path / "from_ros.mcap"
    CliRunner().invoke(app, ["record", str(log), "--ros2", str(bag), "-q"])
    proc = run_cli("smirror", str(log), "--json", "-q", check=True)
    lines = [x for x in proc.stderr.decode().splitlines() if "site defaults used" in x]
    assert len(lines) == 1
    assert "ticks_per_m=2000" in lines[0] and "no smirror/floorplan" in lines[0]
    assert b"Traceback" not in proc.stderr
