"""vm-track on rendered camera frames (sim --frames): detection source, errors, bad frames."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from typer.testing import CliRunner

from tests.cache import simulated
from tests.conftest import ROOT, run_cli
from tests.logcompare import assert_same_log
from tests.logs.test_plain_readers import assert_plain_decodable
from trackctl.cli.main import app
from trackctl.logs import LogReader, LogWriter, TopicInfo
from trackctl.processing import run_processors
from trackctl.sim.vm import VmScenario, simulate_vm
from trackctl.vmtrack import FrameConfig, VmTrackConfig, VmTrackProcessor
from trackctl.vmtrack.frames import FrameDetector, detections_topic
from trackctl.vmtrack.pipeline import SCENE_TOPIC, TRACKS_TOPIC
from trackctl.vmtrack.retrack import RetrackConfig

VM_SAMPLE = ROOT / "sample_logs" / "vm-office.mcap"
SAMPLE_SCENARIO = VmScenario(
    field="office", users=2, nonusers=1, duration_s=30, seed=3, frames=True, jpeg_quality=40
)


@pytest.fixture(scope="session")
def frames_log() -> Path:
    return simulated(
        "frames.mcap",
        simulate_vm,
        VmScenario(field="office", users=2, nonusers=0, duration_s=40, seed=4, frames=True),
    )


def test_frames_log_has_images_and_no_simulated_detections(frames_log: Path) -> None:
    schemas = {t: i.schema_name for t, i in LogReader(frames_log).topics().items()}
    assert schemas["/cam0/image"] == "foxglove.CompressedImage"
    assert not any(s == "trackctl.Detections" for s in schemas.values())


def test_vm_track_detects_in_frames_and_identifies_users(frames_log: Path, tmp_path: Path) -> None:
    # detection and the online and offline identities (test_readme_main_job_on_the_sample_log
    # runs frames through the re-tracking too)
    out = tmp_path / "out.mcap"
    cfg = VmTrackConfig(refinement=RetrackConfig(enabled=False))
    (rep,) = run_processors(frames_log, out, [VmTrackProcessor(cfg)])
    m = rep.metrics
    assert m["source"] == "frames"
    assert m["det_recall"] >= 0.9
    assert m["idf1"] >= 0.9
    assert m["error_m_mean"] <= 0.3
    assert m["region_searches"] > m["full_searches"] > 0
    topics = LogReader(out).topics()
    assert topics[detections_topic("cam0")].count == 120
    assert topics[SCENE_TOPIC].schema_name == "foxglove.SceneUpdate"
    counts = assert_plain_decodable(out)
    assert counts["foxglove.SceneUpdate"] == 120
    # tracks carry velocity and covariance from the (smoothed) filter state
    first = next(m.message for m in LogReader(out).messages([TRACKS_TOPIC]) if m.message.tracks)
    assert first.tracks[0].velocity_mps is not None and first.tracks[0].covariance_m2 is not None


def test_shipped_vm_sample_log_is_regenerable(tmp_path: Path) -> None:
    fresh = tmp_path / "vm-office.mcap"
    simulate_vm(str(fresh), SAMPLE_SCENARIO)
    assert_same_log(fresh, VM_SAMPLE)
    assert VM_SAMPLE.stat().st_size < 5_000_000


def test_readme_main_job_on_the_sample_log(tmp_path: Path) -> None:
    out = tmp_path / "vm-tracked.mcap"
    proc = run_cli("vm-track", str(VM_SAMPLE), "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr.decode()
    report = json.loads(proc.stdout)
    # 30 s of realistic phones (pockets, bags, own clocks): the main job runs on frames, finds
    # the people, names both carriers and reports (test_realistic.py measures longer logs)
    assert report["source"] == "frames" and report["det_recall"] >= 0.9
    assert report["idf1"] >= 0.9 and "ambiguous_frames" in report
    from tests.vmtrack.test_realistic import assert_one_track_per_phone

    assert assert_one_track_per_phone(out) == report["frames"]


def test_plot_draws_the_papers_figures(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    runner = CliRunner()
    res = runner.invoke(
        app,
        [
            "vm-track",
            str(VM_SAMPLE),
            "--out",
            str(tmp_path / "o.mcap"),
            "--plot",
            str(tmp_path / "fig"),
            "--no-retrack",  # the figures, not the re-tracking (the main job's test runs that)
            "-q",
        ],
    )
    assert res.exit_code == 0, res.output
    for name in ("error_over_time.png", "tracking_time_cdf.png"):
        png = tmp_path / "fig" / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_full_search_mode_searches_every_frame_whole(frames_log: Path, tmp_path: Path) -> None:
    # the detector's searches (re-tracking, which searches no frame, is left out)
    cfg = VmTrackConfig(
        frames=FrameConfig(predicted=False), refinement=RetrackConfig(enabled=False)
    )
    (rep,) = run_processors(frames_log, tmp_path / "o.mcap", [VmTrackProcessor(cfg)])
    assert rep.metrics["region_searches"] == 0
    assert rep.metrics["full_searches"] == 240


def test_undecodable_frame_is_skipped_and_counted(frames_log: Path, tmp_path: Path) -> None:
    damaged = tmp_path / "damaged.mcap"
    reader = LogReader(frames_log)
    with LogWriter(damaged) as w:
        broken = 0
        for raw in reader.raw():
            if raw.topic == "/cam1/image" and broken < 3 and raw.log_time_ns > 5_000_000_000:
                msg = CompressedImage()
                msg.ParseFromString(raw.data)
                msg.data = b"\xff\xd8 not a jpeg"
                raw = replace(raw, data=msg.SerializeToString())
                broken += 1
            w.write_raw(raw)
    # the detector's skip and count (re-tracking, which decodes no frame, is left out)
    cfg = VmTrackConfig(refinement=RetrackConfig(enabled=False))
    (rep,) = run_processors(damaged, tmp_path / "o.mcap", [VmTrackProcessor(cfg)])
    assert rep.metrics["bad_frames"] == 3
    assert rep.metrics["idf1"] >= 0.9


def test_image_topic_without_calibration_is_a_one_line_error(
    frames_log: Path, tmp_path: Path
) -> None:
    stripped = tmp_path / "nocal.mcap"
    reader = LogReader(frames_log)
    with LogWriter(stripped) as w:
        for raw in reader.raw():
            if raw.topic != "/cam1/camera_model":
                w.write_raw(raw)
    proc = run_cli("vm-track", str(stripped), "--out", str(tmp_path / "o.mcap"))
    assert proc.returncode == 2
    lines = proc.stderr.decode().strip().splitlines()
    assert len(lines) == 1
    assert "/cam1/camera_model is missing" in lines[0] and "/cam1/image" in lines[0]


def test_source_detections_on_a_frames_log_is_a_clear_error(
    frames_log: Path, tmp_path: Path
) -> None:
    proc = run_cli(
        "vm-track", str(frames_log), "--out", str(tmp_path / "o.mcap"), "--source", "detections"
    )
    assert proc.returncode == 2
    assert "no trackctl.Detections topic" in proc.stderr.decode()


S = 1_000_000_000


class _FramesOnly:
    """A log of 60 grey frames at 1 Hz with a dark person standing at one spot for the first
    20 s (what :class:`FrameDetector` reads to build its background)."""

    path = Path("standing.mcap")
    topic = "/cam0/image"

    def topics(self) -> dict[str, TopicInfo]:
        info = TopicInfo(self.topic, "foxglove.CompressedImage", "protobuf", 60, 0, 59 * S)
        return {self.topic: info}

    def messages(self, wanted: list[str]) -> Iterator[SimpleNamespace]:
        for k in range(60):
            img = np.full((48, 64, 3), 150, np.uint8)
            if k < 20:
                img[10:40, 20:30] = 20
            ok, jpg = cv2.imencode(".png", img)
            assert ok
            yield SimpleNamespace(log_time_ns=k * S, message=SimpleNamespace(data=jpg.tobytes()))


def test_the_starting_background_is_the_whole_logs_so_people_standing_first_are_seen() -> None:
    cams = {"cam0": None}
    detector = FrameDetector(_FramesOnly(), cams, FrameConfig())  # type: ignore[arg-type]
    spot = detector.backgrounds["cam0"].image[10:40, 20:30]
    assert abs(float(spot.mean()) - 150) < 3  # the floor: the person is foreground from frame 0
    # sampled from the first 10 s only, the person standing there is in the background
    first = FrameDetector(_FramesOnly(), cams, FrameConfig(background_init_s=10.0))  # type: ignore[arg-type]
    assert abs(float(first.backgrounds["cam0"].image[10:40, 20:30].mean()) - 20) < 3
