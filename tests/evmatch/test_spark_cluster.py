"""A real Spark standalone cluster on localhost (master + one worker, both shipped with pyspark):
``ev-match --engine spark --master spark://...`` gives the local engine's matches, with the
executors reading the log themselves."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import run_cli
from trackctl.logs import LogReader, topics

# a master and a worker JVM on top of the engine tests' local session (test_spark.py): the
# engine's equality with the local one is checked there on every run, a real cluster on demand
pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _spark_class() -> Path:
    import pyspark

    return Path(pyspark.__file__).parent / "bin" / "spark-class"


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    work = tmp_path_factory.mktemp("spark")
    env = {
        **os.environ,
        "SPARK_HOME": str(_spark_class().parent.parent),
        "PYSPARK_PYTHON": sys.executable,
        "SPARK_LOCAL_IP": "127.0.0.1",
    }
    port = _free_port()
    url = f"spark://127.0.0.1:{port}"
    master_log = (work / "master.log").open("wb")
    procs = [
        subprocess.Popen(
            [
                str(_spark_class()),
                "org.apache.spark.deploy.master.Master",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--webui-port",
                str(_free_port()),
            ],
            env=env,
            stdout=master_log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    ]
    try:
        _wait_for(work / "master.log", b"I have been elected leader")
        worker_log = (work / "worker.log").open("wb")
        procs.append(
            subprocess.Popen(
                [
                    str(_spark_class()),
                    "org.apache.spark.deploy.worker.Worker",
                    url,
                    "--host",
                    "127.0.0.1",
                    "--cores",
                    "2",
                    "--memory",
                    "2g",
                    "--webui-port",
                    str(_free_port()),
                    "--work-dir",
                    str(work / "work"),
                ],
                env=env,
                stdout=worker_log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        )
        _wait_for(work / "master.log", b"Registering worker")
        yield url
    finally:
        for proc in procs:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            proc.wait(timeout=30)


def _wait_for(log: Path, text: bytes, timeout_s: float = 90.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if text in log.read_bytes():
            return
        time.sleep(0.5)
    raise AssertionError(f"Spark did not say {text!r} in {timeout_s} s: {log.read_text()[-2000:]}")


def _matches(out: Path) -> list[tuple[str, str | None, str, tuple[str, ...]]]:
    (msg,) = [m.message for m in LogReader(out).messages([topics.EV_MATCHES])]
    return [(m.eid, m.vid, m.status, m.scenarios) for m in msg.matches]


def test_standalone_cluster_matches_equal_the_local_engine(
    cluster: str, small_log: Path, tmp_path: Path
) -> None:
    local, remote = tmp_path / "local.mcap", tmp_path / "cluster.mcap"
    a = run_cli("ev-match", str(small_log), "--out", str(local), "--json")
    assert a.returncode == 0, a.stderr.decode()
    env = {**os.environ, "PYSPARK_PYTHON": sys.executable, "SPARK_LOCAL_IP": "127.0.0.1"}
    b = subprocess.run(
        [
            sys.executable,
            "-m",
            "trackctl",
            "ev-match",
            str(small_log),
            "--out",
            str(remote),
            "--engine",
            "spark",
            "--master",
            cluster,
            "--json",
        ],
        capture_output=True,
        env=env,
        timeout=600,
        check=False,
    )
    assert b.returncode == 0, b.stderr.decode()[-3000:]
    assert _matches(remote) == _matches(local)
    ra, rb = json.loads(a.stdout), json.loads(b.stdout)
    for key in ("matched", "accuracy", "v_scenarios_read", "v_bytes_read", "e_scenarios_total"):
        assert ra[key] == rb[key], key
    assert rb["engine"] == "spark" and rb["v_scenarios_read"] > 0
