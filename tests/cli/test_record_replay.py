"""Acceptance paths of record / info / replay, through real subprocesses (as pipelines call us)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from tests.conftest import SUBPROCESS_TIMEOUT_S, run_cli, trackctl_exe
from trackctl.logs import LogReader


def _info(path: Path) -> dict:
    proc = run_cli("info", str(path), "--json", check=True)
    return json.loads(proc.stdout)


def test_record_then_info_lists_every_topic_with_counts(recorded: Path) -> None:
    info = _info(recorded)
    counts = {t: v["count"] for t, v in info["topics"].items()}
    assert counts == {
        "/phone/phone1/imu": 50,
        "/rssi": 20,
        "/robot/robot1/odom": 40,
        "/cam0/image": 12,
        "/cam0/calibration": 1,
        "/cam0/camera_model": 1,
    }
    assert info["topics"]["/cam0/image"]["schema"] == "foxglove.CompressedImage"
    assert info["topics"]["/cam0/image"]["encoding"] == "protobuf"
    assert info["topics"]["/phone/phone1/imu"]["rate_hz"] == pytest.approx(5.0)
    assert info["start_ns"] == 0 and info["end_ns"] == 9_800_000_000
    assert info["warnings"] == []
    assert "calibration/cam0.yaml" in info["attachments"]


def test_replay_jsonl_piped_into_record_reproduces_the_log(recorded: Path, tmp_path: Path) -> None:
    copy = tmp_path / "r2.mcap"
    replay = subprocess.Popen(
        [*trackctl_exe(), "replay", str(recorded), "--speed", "0", "--format", "jsonl"],
        stdout=subprocess.PIPE,
    )
    rec = subprocess.run(
        [*trackctl_exe(), "record", str(copy), "--stdin", "--quiet"],
        stdin=replay.stdout,
        capture_output=True,
        timeout=120,
    )
    replay.stdout.close()  # type: ignore[union-attr]
    assert replay.wait(timeout=60) == 0
    assert rec.returncode == 0, rec.stderr.decode()
    a, b = LogReader(recorded), LogReader(copy)
    assert {t: (i.schema_name, i.count) for t, i in a.topics().items()} == {
        t: (i.schema_name, i.count) for t, i in b.topics().items()
    }
    for ma, mb in zip(a.messages(), b.messages(), strict=True):
        assert (ma.topic, ma.log_time_ns, ma.message) == (mb.topic, mb.log_time_ns, mb.message)


def test_replay_filters_topics_and_time(recorded: Path) -> None:
    proc = run_cli(
        "replay",
        str(recorded),
        "--speed",
        "0",
        "--topics",
        "/rssi,/cam0/image",
        "--start",
        "0.5",
        "--end",
        "4",
        check=True,
    )
    lines = [json.loads(x) for x in proc.stdout.splitlines()]
    assert {x["topic"] for x in lines} == {"/rssi", "/cam0/image"}
    assert all(0.5e9 <= x["log_time_ns"] < 4e9 for x in lines)
    assert len([x for x in lines if x["topic"] == "/rssi"]) == 6  # 2 observers x t=1,2,3
    assert len([x for x in lines if x["topic"] == "/cam0/image"]) == 7  # frames 5..11 at 10 fps
    img = next(x for x in lines if x["topic"] == "/cam0/image")
    assert img["schema"] == "foxglove.CompressedImage" and img["message"]["format"] == "jpeg"
    assert set(img) == {"topic", "log_time_ns", "schema", "message"}


def test_replay_is_paced_by_speed(recorded: Path) -> None:
    """Each line leaves when its log time comes, ``--speed`` times real time: no line arrives
    before the child was started plus its log time since the first line over the speed. Waiting
    can only make a line later, so a loaded machine cannot fail this; the exact schedule is
    checked with a fake clock in tests/logs/test_replay_jsonl.py."""
    speed = 3.0
    spawned = time.monotonic()
    proc = subprocess.Popen(
        [*trackctl_exe(), "replay", str(recorded), "--topics", "/rssi", "--speed", str(speed)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None
    arrivals = [(time.monotonic(), json.loads(line)["log_time_ns"]) for line in proc.stdout]
    _, err = proc.communicate(timeout=SUBPROCESS_TIMEOUT_S)
    assert proc.returncode == 0, err.decode()
    assert len(arrivals) == 20  # 9 s of log: the last line no sooner than 3 s after the start
    t0 = arrivals[0][1]
    assert [t for _, t in arrivals] == sorted(t for _, t in arrivals)
    for wall, t in arrivals:
        assert wall - spawned >= (t - t0) / 1e9 / speed, (wall - spawned, (t - t0) / 1e9)


def test_replay_table_format(recorded: Path) -> None:
    proc = run_cli("replay", str(recorded), "--speed", "0", "--format", "table", check=True)
    rows = {}
    for line in proc.stdout.decode().splitlines():
        cells = [c.strip() for c in line.split("│")]
        if len(cells) == 5 and cells[0].startswith("/"):
            rows[cells[0]] = cells
    assert sorted(rows) == sorted(
        [
            "/cam0/calibration",
            "/cam0/camera_model",
            "/cam0/image",
            "/phone/phone1/imu",
            "/rssi",
            "/robot/robot1/odom",
        ]
    )
    imu = rows["/phone/phone1/imu"]
    assert imu[1] == "trackctl.Imu" and imu[2] == "50" and imu[4] == "9.800"
    assert rows["/rssi"][2] == "20" and rows["/cam0/image"][1] == "foxglove.CompressedImage"


def test_replay_sends_udp_datagrams(recorded: Path) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(5)
    port = sock.getsockname()[1]
    run_cli(
        "replay",
        str(recorded),
        "--speed",
        "0",
        "--topics",
        "/rssi",
        "--udp",
        f"127.0.0.1:{port}",
        check=True,
    )
    got = [json.loads(sock.recv(65535)) for _ in range(20)]
    sock.close()
    assert {g["topic"] for g in got} == {"/rssi"}


def _wait_listening(proc: subprocess.Popen[bytes]) -> int:
    line = proc.stderr.readline().decode()  # type: ignore[union-attr]
    assert line.startswith("listening on udp"), line
    return int(line.strip().rsplit(":", 1)[1])


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.parametrize("started_as_background_job", [False, True])
def test_udp_record_stopped_by_sigint_keeps_every_message(
    tmp_path: Path, started_as_background_job: bool
) -> None:
    # A shell starts `cmd &` with SIGINT ignored; `kill -INT` must still stop the recording.
    out = tmp_path / "live.mcap"
    proc = subprocess.Popen(
        [*trackctl_exe(), "record", str(out), "--udp", "0"],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        preexec_fn=_ignore_sigint if started_as_background_job else None,
    )
    try:
        port = _wait_listening(proc)
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        n = 300
        for i in range(n):
            msg = {
                "topic": "/phone/p1/imu",
                "log_time_ns": i * 10_000_000,
                "schema": "trackctl.Imu",
                "message": {
                    "timestamp": {"sec": 0, "nsec": i * 10_000_000},
                    "frame_id": "phone/p1",
                    "accel_mps2": {"x": 0, "y": 0, "z": 9.8},
                    "gyro_rps": {"x": 0, "y": 0, "z": i * 0.001},
                },
            }
            sender.sendto(json.dumps(msg).encode(), ("127.0.0.1", port))
            if i % 50 == 0:
                time.sleep(0.01)
        # two lines in one datagram, one of them bad: the bad one is rejected, the other kept
        sender.sendto(
            b'{"topic":"/rssi","schema":"trackctl.RssiScan","log_time_ns":5,'
            b'"message":{"timestamp":{"sec":0,"nsec":5},"observer":"ap","readings":[]}}'
            b"\nnot json\n",
            ("127.0.0.1", port),
        )
        sender.close()
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err.decode()
    assert "rejected" in err.decode()
    info = _info(out)
    assert info["topics"]["/phone/p1/imu"]["count"] == n
    assert info["topics"]["/rssi"]["count"] == 1
    assert info["warnings"] == []
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_stdin_record_stopped_by_sigterm_is_valid(tmp_path: Path) -> None:
    out = tmp_path / "live.mcap"
    proc = subprocess.Popen(
        [*trackctl_exe(), "record", str(out), "--stdin"],
        stdin=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    line = json.dumps(
        {
            "topic": "/robot/r/odom",
            "log_time_ns": 1,
            "schema": "trackctl.WheelOdometry",
            "message": {
                "timestamp": {"sec": 0, "nsec": 1},
                "frame_id": "robot/r",
                "v_mps": 0.5,
                "omega_rps": 0.0,
            },
        }
    )
    proc.stdin.write((line + "\n").encode() * 5)  # type: ignore[union-attr]
    proc.stdin.flush()  # type: ignore[union-attr]
    ready = proc.stderr.readline().decode()  # type: ignore[union-attr]
    assert ready.startswith("recording JSON lines from stdin"), ready
    time.sleep(0.5)
    os.kill(proc.pid, signal.SIGTERM)
    proc.wait(timeout=30)
    assert proc.returncode == 0
    assert _info(out)["topics"]["/robot/r/odom"]["count"] == 5


def test_truncated_log_info_and_replay_warn_and_succeed(sample_log: Path, tmp_path: Path) -> None:
    data = sample_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    info = run_cli("info", str(cut), "--json")
    assert info.returncode == 0
    obj = json.loads(info.stdout)
    assert obj["truncated"] and obj["message_count"] > 0
    assert any("recovered from the cut-off chunk" in w for w in obj["warnings"])
    assert b"warning:" in info.stderr
    replay = run_cli("replay", str(cut), "--speed", "0")
    assert replay.returncode == 0
    assert b"warning:" in replay.stderr
    assert len(replay.stdout.splitlines()) == obj["message_count"]


def _pipe(replay_args: list[str], out: Path) -> dict:
    replay = subprocess.Popen([*trackctl_exe(), "replay", *replay_args], stdout=subprocess.PIPE)
    rec = subprocess.run(
        [*trackctl_exe(), "record", str(out), "--stdin", "--json", "-q"],
        stdin=replay.stdout,
        capture_output=True,
        timeout=120,
    )
    replay.stdout.close()  # type: ignore[union-attr]
    assert replay.wait(timeout=60) == 0
    assert rec.returncode == 0, rec.stderr.decode()
    return json.loads(rec.stdout)


def test_replay_records_piped_into_record_keeps_metadata_and_attachments(
    recorded: Path, tmp_path: Path
) -> None:
    copy = tmp_path / "r2.mcap"
    summary = _pipe([str(recorded), "--speed", "0", "--records"], copy)
    assert summary["attachments"] == 1 and summary["rejected"] == 0
    a, b = LogReader(recorded), LogReader(copy)
    assert a.attachments() == b.attachments()
    assert a.metadata() == b.metadata()
    assert [(m.topic, m.log_time_ns, m.data) for m in a.raw()] == [
        (m.topic, m.log_time_ns, m.data) for m in b.raw()
    ]


def test_round_tripped_smirror_sample_is_accepted_by_smirror(tmp_path: Path) -> None:
    sample = Path(__file__).resolve().parents[2] / "sample_logs" / "smirror.mcap"
    copy = tmp_path / "sm.mcap"
    summary = _pipe([str(sample), "--speed", "0", "--records"], copy)
    assert summary["metadata"] == len(LogReader(sample).metadata()) > 0
    original = run_cli("smirror", str(sample), "--json", "-q", check=True)
    again = run_cli("smirror", str(copy), "--json", "-q", check=True)
    a, b = json.loads(original.stdout), json.loads(again.stdout)
    assert a["error_m_mean"] == b["error_m_mean"] and a["fixes"] == b["fixes"]
