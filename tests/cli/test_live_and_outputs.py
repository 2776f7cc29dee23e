"""Live recording never loses data; outputs are only regular files, with one writer each."""

from __future__ import annotations

import fcntl
import json
import os
import re
import signal
import socket
import stat
import subprocess
import time
import warnings
from pathlib import Path

import pytest

from tests.conftest import SUBPROCESS_TIMEOUT_S, run_cli, trackctl_exe
from trackctl.errors import OutputError, TrackctlError
from trackctl.logs import LogReader
from trackctl.logs.writer import LogWriter

GOOD = {
    "topic": "/phone/p1/imu",
    "schema": "trackctl.Imu",
    "message": {
        "timestamp": {"sec": 0, "nsec": 0},
        "frame_id": "phone/p1",
        "accel_mps2": {"x": 0.5, "y": 0.1, "z": 9.8},
        "gyro_rps": {"x": 0.0, "y": 0.0, "z": 0.29},
    },
}


def good_line(t: int) -> bytes:
    return json.dumps({**GOOD, "log_time_ns": t}).encode()


def _with_accel_x(text: str, t: int) -> bytes:
    return good_line(t).replace(b'"x": 0.5', b'"x": ' + text.encode())


# Every kind of bad line that used to end a recording (and delete it): the reason each is named.
BAD_LINES = {
    "nan": (_with_accel_x("NaN", 10), "non-finite number NaN"),
    "infinity": (_with_accel_x("Infinity", 11), "non-finite number Infinity"),
    "-infinity": (_with_accel_x("-Infinity", 12), "non-finite number -Infinity"),
    "1e999": (_with_accel_x("1e999", 13), "1e999 overflows a 64-bit float"),
    "not utf-8": (b'{"topic":"/x\xff\xfe"}', "not UTF-8 text"),
    "time >= 2^64": (good_line(1 << 64), "must be an integer in 0..2\\^64-1"),
    "not json": (b"{oops", "not valid JSON"),
    "wrong type deep inside": (
        good_line(14).replace(b'"z": 9.8', b'"z": [1, 2]'),
        "/phone/p1/imu",
    ),
}


def _stdin_payload() -> bytes:
    lines = [good_line(t) for t in (1, 2, 3)]
    lines += [line for line, _ in BAD_LINES.values()]
    lines += [good_line(t) for t in (7, 8, 9)]
    return b"\n".join(lines) + b"\n"


def test_stdin_bad_lines_are_rejected_one_warning_each(tmp_path: Path) -> None:
    out = tmp_path / "live.mcap"
    proc = run_cli("record", str(out), "--stdin", "--json", input=_stdin_payload())
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    assert summary["messages"] == 6 and summary["rejected"] == len(BAD_LINES)
    warnings = [w for w in proc.stderr.decode().splitlines() if w.startswith("warning: rejected")]
    assert len(warnings) == len(BAD_LINES)
    for i, (_, reason) in enumerate(BAD_LINES.values()):
        assert f"<stdin>:{4 + i}:" in warnings[i]
        assert re.search(reason, warnings[i]), warnings[i]
    reader = LogReader(out)
    assert reader.topics()["/phone/p1/imu"].count == 6
    assert [m.log_time_ns for m in reader.raw()] == [1, 2, 3, 7, 8, 9]
    assert not (tmp_path / "live.mcap.partial").exists()


def _wait_listening(proc: subprocess.Popen[bytes]) -> int:
    line = proc.stderr.readline().decode()  # type: ignore[union-attr]
    assert line.startswith("listening on udp"), line
    return int(line.rsplit(":", 1)[1])


def test_udp_bad_datagrams_are_rejected_naming_the_sender(tmp_path: Path) -> None:
    out = tmp_path / "live.mcap"
    proc = subprocess.Popen(
        [*trackctl_exe(), "record", str(out), "--udp", "0", "--json"],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
    )
    try:
        port = _wait_listening(proc)
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for t in (1, 2, 3):
            sender.sendto(good_line(t), ("127.0.0.1", port))
        for line, _ in BAD_LINES.values():
            sender.sendto(line, ("127.0.0.1", port))
        for t in (7, 8, 9):
            sender.sendto(good_line(t), ("127.0.0.1", port))
        local_port = sender.getsockname()[1]
        sender.close()
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        stdout, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err.decode()
    summary = json.loads(stdout)
    assert summary["messages"] == 6 and summary["rejected"] == len(BAD_LINES)
    warnings = [w for w in err.decode().splitlines() if w.startswith("warning: rejected")]
    assert len(warnings) == len(BAD_LINES)
    assert all(f"from 127.0.0.1:{local_port}" in w for w in warnings)
    assert LogReader(out).topics()["/phone/p1/imu"].count == 6


def _wait_durable(
    partial: Path, topic: str, n: int, timeout_s: float = SUBPROCESS_TIMEOUT_S
) -> None:
    """Until ``partial`` (a recording in progress) reads back ``n`` messages on ``topic``."""
    deadline = time.monotonic() + timeout_s
    count = 0
    while time.monotonic() < deadline:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a partial file is truncated by nature
                count = sum(1 for _ in LogReader(partial).raw([topic]))
        except (OSError, TrackctlError):
            count = 0  # not created yet, or not one whole record yet
        if count >= n:
            return
        time.sleep(0.2)
    raise AssertionError(f"{partial}: {count} of {n} messages on disk after {timeout_s:.0f} s")


def test_kill_9_loses_at_most_the_last_second_and_recover_finishes(tmp_path: Path) -> None:
    out = tmp_path / "live.mcap"
    proc = subprocess.Popen(
        [*trackctl_exe(), "record", str(out), "--udp", "0", "-q"],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
    )
    n = 1000
    try:
        port = _wait_listening(proc)
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for t in range(n):
            sender.sendto(good_line(t), ("127.0.0.1", port))
            if t % 100 == 0:
                time.sleep(0.05)
        sender.close()
        # the recorder flushes about once a second: wait until the partial file holds every
        # message (however slow a loaded machine is), then kill it with no chance to clean up
        _wait_durable(tmp_path / "live.mcap.partial", "/phone/p1/imu", n)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    partial = tmp_path / "live.mcap.partial"
    assert not out.exists() and partial.exists()
    info = json.loads(run_cli("info", str(partial), "--json", check=True).stdout)
    assert info["topics"]["/phone/p1/imu"]["count"] == n
    # the next recording of the same output refuses to throw the partial file away
    again = run_cli("record", str(out), "--stdin", input=good_line(1) + b"\n")
    assert again.returncode == 2
    assert b"trackctl recover" in again.stderr and partial.exists()
    rec = run_cli("recover", str(partial), "--json", check=True)
    assert json.loads(rec.stdout)["messages"] == n
    assert not partial.exists()
    reader = LogReader(out)
    assert not reader.truncated and reader.message_count == n


def test_out_onto_a_device_node_is_refused_and_the_node_stays(
    sample_log: Path, tmp_path: Path
) -> None:
    node = tmp_path / "null"
    try:
        os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("mknod needs root")
    proc = run_cli("process", str(sample_log), "--with", "check", "--out", str(node))
    assert proc.returncode == 2
    assert b"is a device" in proc.stderr and b"Traceback" not in proc.stderr
    assert stat.S_ISCHR(os.stat(node).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null"]


@pytest.mark.parametrize("kind", ["fifo", "directory", "symlink-to-fifo"])
def test_out_onto_a_fifo_or_directory_is_refused(tmp_path: Path, kind: str) -> None:
    target = tmp_path / "target"
    if kind == "directory":
        target.mkdir()
    else:
        os.mkfifo(target)
    path = target
    if kind == "symlink-to-fifo":
        path = tmp_path / "link"
        path.symlink_to(target)
    with pytest.raises(OutputError, match="is a (FIFO|directory); trackctl writes logs only"):
        LogWriter(path)
    assert (tmp_path / "target").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".partial")]


def test_record_to_dev_stdout_pipe_is_refused() -> None:
    proc = subprocess.run(
        [*trackctl_exe(), "record", "/dev/stdout", "--stdin"],
        input=good_line(1),
        capture_output=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert b"is a FIFO" in proc.stderr


def test_second_writer_of_the_same_output_fails_at_once(tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    with LogWriter(out) as first:
        with pytest.raises(OutputError, match="another process is writing it"):
            LogWriter(out)
        first.add_metadata("a", {"b": "c"})
    assert LogReader(out).metadata() == {"a": {"b": "c"}}


def test_lock_is_held_by_a_real_second_process(tmp_path: Path, sample_log: Path) -> None:
    out = tmp_path / "o.mcap"
    partial = tmp_path / "o.mcap.partial"
    fd = os.open(partial, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        proc = run_cli("process", str(sample_log), "--with", "check", "--out", str(out))
    finally:
        os.close(fd)
    assert proc.returncode == 2 and b"another process is writing it" in proc.stderr
    assert not out.exists()


def test_full_disk_while_closing_leaves_no_temp_file(tmp_path: Path) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full")
    out = tmp_path / "o.mcap"
    writer = LogWriter(out)
    writer.add_metadata("a", {"b": "c"})
    # swap the stream's fd for /dev/full: the next write fails with ENOSPC
    full = os.open("/dev/full", os.O_WRONLY)
    os.dup2(full, writer._stream.fileno())
    os.close(full)
    with pytest.raises(OutputError, match="No space left on device"):
        writer.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_report_only_and_outputs_only(sample_log: Path, tmp_path: Path) -> None:
    proc = run_cli("process", str(sample_log), "--with", "check", "--json", check=True)
    obj = json.loads(proc.stdout)
    assert obj["out"] is None and obj["reports"][0]["metrics"]["messages"] == 1242
    assert list(tmp_path.iterdir()) == []
    out = tmp_path / "o.mcap"
    run_cli(
        "process",
        str(sample_log),
        "--with",
        "check",
        "--out",
        str(out),
        "--outputs-only",
        check=True,
    )
    topics = LogReader(out).topics()
    assert set(topics) == {"/metrics/check"}
    assert set(LogReader(out).metadata()) == {"metrics/check"}
    assert out.stat().st_size < sample_log.stat().st_size / 50


def test_info_on_the_finished_name_points_to_the_partial_file(tmp_path: Path) -> None:
    out = tmp_path / "live.mcap"
    (tmp_path / "live.mcap.partial").write_bytes(b"\x89MCAP0\r\n")
    proc = run_cli("info", str(out))
    assert proc.returncode == 2
    assert b"no such file (an unfinished recording is in live.mcap.partial" in proc.stderr
    assert b"trackctl recover" in proc.stderr
