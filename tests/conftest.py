"""Shared fixtures: small sensor files and logs built in a temp dir."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, settings

# Hypothesis: the same verdict on every run by default ("ci": examples derived from each test's
# own code, no example database); `pytest --hypothesis-profile explore` searches afresh with ten
# times the examples (and remembers what it finds in .hypothesis/) for developers hunting bugs.
# A test states its budget as @settings(max_examples=examples(N)): N under "ci", 10 N under
# "explore".
settings.register_profile(
    "ci",
    derandomize=True,
    database=None,
    max_examples=100,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "explore",
    derandomize=False,
    max_examples=1000,
    deadline=None,
    phases=tuple(Phase),
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def examples(n: int) -> int:
    """A property test's example budget: ``n`` (fixed, CI), ten times that when exploring."""
    return n * 10 if settings.get_current_profile_name() == "explore" else n


ROOT = Path(__file__).resolve().parent.parent
SAMPLE_LOG = ROOT / "sample_logs" / "demo.mcap"
SHARED_DATA = Path(os.environ.get("TRACKCTL_SHARED_DATA", ROOT.parent / "shared" / "data"))
"""Real data beside the repository (read at test time, never copied in)."""


def shared_file(*parts: str) -> Path:
    """A file of the shared real data; the test is skipped, saying why, when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data {path} is absent (set TRACKCTL_SHARED_DATA to its folder)")
    return path


def vtest_video() -> Path:
    """PETS 2009 S2L1 view 001 (OpenCV's vtest.avi); skipped when absent. Not committed: get it
    with `apt-get download opencv-doc` (see ../shared/data/footage/README.md) and point
    TRACKCTL_VTEST at it."""
    candidates = [
        os.environ.get("TRACKCTL_VTEST", ""),
        "/usr/share/doc/opencv-doc/examples/data/vtest.avi",
    ]
    for c in candidates:
        if c and Path(c).is_file():
            return Path(c)
    pytest.skip("vtest.avi (PETS 2009 S2L1 view 001) is absent: set TRACKCTL_VTEST")


def trackctl_exe() -> list[str]:
    """The installed console script (how users and pipelines call trackctl)."""
    exe = Path(sys.executable).parent / "trackctl"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("trackctl")
    return [found] if found else [sys.executable, "-m", "trackctl.cli.main"]


SUBPROCESS_TIMEOUT_S = 900.0
"""How long a trackctl child may run before the test fails: generous, since a loaded CI
machine may run it many times slower than a quiet one; the test fails on it, never on speed."""


def run_cli(
    *args: str,
    input: bytes | None = None,
    timeout: float = SUBPROCESS_TIMEOUT_S,
    check: bool = False,
) -> subprocess.CompletedProcess[bytes]:
    """Run trackctl as a real subprocess; a child that hangs fails the test with its stderr."""
    env = dict(os.environ, COLUMNS="200")
    try:
        proc = subprocess.run(
            [*trackctl_exe(), *args], input=input, capture_output=True, timeout=timeout, env=env
        )
    except subprocess.TimeoutExpired as err:
        stderr = (err.stderr or b"").decode(errors="replace")[-4000:]
        raise AssertionError(
            f"trackctl {' '.join(args)} still running after {timeout:.0f} s; stderr:\n{stderr}"
        ) from None
    if check and proc.returncode != 0:
        raise AssertionError(
            f"trackctl {' '.join(args)} exited {proc.returncode}: {proc.stderr.decode()}"
        )
    return proc


@pytest.fixture
def imu_csv(tmp_path: Path) -> Path:
    path = tmp_path / "IMU.csv"
    t = np.arange(50) * 0.2
    rows = ["t_s,ax,ay,az,gx,gy,gz,qw,qx,qy,qz,extra"]
    for i, ti in enumerate(t):
        rows.append(f"{ti:.3f},{0.1 * i:.3f},0.0,9.81,0.0,0.0,0.05,1,0,0,0,ignored")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture
def rssi_csv(tmp_path: Path) -> Path:
    path = tmp_path / "RSSI.csv"
    rows = ["t_s,observer,eid,rssi_dbm"]
    for k in range(10):
        rows.append(f"{k:.1f},ap1,aa:bb:cc:00:00:01,{-50 - k}")
        rows.append(f"{k:.1f},ap1,aa:bb:cc:00:00:02,{-60 - k}")
        rows.append(f"{k:.1f},ap2,aa:bb:cc:00:00:01,{-70 + k}")
    path.write_text("\n".join(rows) + "\n")
    return path  # 10 times x 2 observers = 20 scans


@pytest.fixture
def odom_csv(tmp_path: Path) -> Path:
    path = tmp_path / "ODOM.csv"
    rows = ["t_s,left_ticks,right_ticks"]
    for k in range(40):
        rows.append(f"{k * 0.04:.2f},{10 * k},{11 * k}")
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture
def video_mp4(tmp_path: Path) -> Path:
    """A 12-frame 10 fps mp4 written by OpenCV."""
    path = tmp_path / "V.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (64, 48))
    assert writer.isOpened()
    for i in range(12):
        frame = np.full((48, 64, 3), 40, np.uint8)
        cv2.circle(frame, (5 + 4 * i, 24), 6, (0, 200, 255), -1)
        writer.write(frame)
    writer.release()
    return path


# a camera 3 m above the floor at (0, 0) looking at (4, 1) on the floor, as OpenCV's rvec/tvec
CALIB_RVEC = np.array([1.8129, -1.4154, 0.7206])
CALIB_TVEC = np.array([0.0, 2.4258, 1.765])


@pytest.fixture
def calib_yaml(tmp_path: Path) -> Path:
    path = tmp_path / "cam0.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 64)
    fs.write("image_height", 48)
    fs.write("camera_matrix", np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[0.01, -0.02, 0.0, 0.0, 0.0]]))
    fs.write("rvec", CALIB_RVEC.reshape(3, 1))
    fs.write("tvec", CALIB_TVEC.reshape(3, 1))
    fs.release()
    return path


@pytest.fixture(scope="session")
def sample_log() -> Path:
    assert SAMPLE_LOG.exists(), "sample_logs/demo.mcap missing: run `make sample-logs`"
    return SAMPLE_LOG


@pytest.fixture
def recorded(
    tmp_path: Path, imu_csv: Path, rssi_csv: Path, odom_csv: Path, video_mp4: Path, calib_yaml: Path
) -> Path:
    """A log recorded from every file source (IMU, RSSI, odometry, video + calibration), by a
    real ``trackctl record``: built once per code version and shared (read-only) by its tests."""
    from tests.cache import cached_file

    def record(out: Path) -> None:
        run_cli(
            "record",
            str(out),
            "--imu",
            f"phone1={imu_csv}",
            "--rssi",
            str(rssi_csv),
            "--odom",
            f"robot1={odom_csv}",
            "--video",
            f"cam0={video_mp4}",
            "--calib",
            f"cam0={calib_yaml}",
            "--quiet",
            check=True,
        )

    # the sources are this file's fixtures: its bytes are part of the key
    return cached_file("recorded.mcap", record, Path(__file__).read_bytes())


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: one worker more than the cores this process may use. Many tests wait on a
    child (a trackctl subprocess, Spark's JVM, a paced replay, a signal) and leave their core
    idle; a spare worker fills it."""
    return len(os.sched_getaffinity(0)) + 1


HEAVY_FIRST = ("tests/vmtrack/", "tests/evmatch/test_spark.py")
"""Where the longest tests live: scheduled first, so that the run does not end on one worker
finishing a long test while the others are idle."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Heavy folders first (a stable sort: the same order on every worker, as xdist needs), and
    on a worker under ``--dist loadgroup``, each ``xdist_group`` named in the node id.

    pytest-xdist 3.8 names the group by setting ``item._nodeid``, which pytest 9.2 no longer
    reads (node ids are structured, ``item._id``): each worker then took its share of the Spark
    tests and started a JVM of its own. This names the group where pytest 9.2 reads it, unless
    xdist's own hook already did.
    """
    items.sort(key=lambda item: not item.nodeid.startswith(HEAVY_FIRST))
    if not getattr(config.option, "loadgroup", False):
        return
    for item in items:
        groups = sorted({str(m.args[0]) for m in item.iter_markers("xdist_group") if m.args})
        if not groups or "@" in item.nodeid:
            continue
        grouped = f"{item.nodeid}@{'_'.join(groups)}"
        node_id = getattr(item, "_id", None)
        if node_id is not None and hasattr(type(node_id), "parse"):
            item._id = type(node_id).parse(grouped)  # type: ignore[attr-defined]
        else:
            item._nodeid = grouped
