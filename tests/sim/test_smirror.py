"""The S-Mirror scenario: deterministic, ~40 m paths, and the shipped sample is regenerable."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from tests.logcompare import assert_same_log
from trackctl.logs import LogReader
from trackctl.sim.smirror import PATHS, SmirrorScenario, path_length_m, simulate_smirror

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_logs" / "smirror.mcap"
SAMPLE_CFG = SmirrorScenario(
    paths=1, width_px=320, height_px=240, fps=2.0, jpeg_quality=70, duration_s=36.0, seed=0
)
"""What `make sample-logs` runs (keep in step with the Makefile)."""


def test_paths_are_about_forty_metres() -> None:
    for k in range(len(PATHS)):
        assert 37.0 <= path_length_m(k) <= 43.0


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    cfg = SmirrorScenario(paths=1, people=2, width_px=160, height_px=120, fps=2.0, duration_s=3.0)
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    simulate_smirror(str(a), cfg)
    simulate_smirror(str(b), cfg)
    assert a.read_bytes() == b.read_bytes()


def test_shipped_sample_log_is_regenerable(tmp_path: Path) -> None:
    assert SAMPLE.stat().st_size < 2_000_000  # all sample logs together stay < 5 MiB
    fresh = tmp_path / "smirror.mcap"
    simulate_smirror(str(fresh), SAMPLE_CFG)
    assert_same_log(fresh, SAMPLE)


def test_sample_has_the_scenario_topics() -> None:
    reader = LogReader(SAMPLE)
    present = reader.topics()
    for node in ("node0", "node1", "node2"):
        assert present[f"/{node}/image"].schema_name == "foxglove.CompressedImage"
        assert present[f"/{node}/camera_model"].schema_name == "trackctl.CameraModel"
    assert present["/robot/r1/odom"].schema_name == "trackctl.WheelOdometry"
    assert present["/ground_truth"].schema_name == "trackctl.GroundTruth"
    assert {"robot/r1", "smirror/floorplan", "smirror/requesters"} <= set(reader.metadata())


def test_lens_distortion_and_led_coloured_clothes(tmp_path: Path) -> None:
    from trackctl.sim.smirror import _clothes

    base = SmirrorScenario(paths=1, people=2, width_px=160, height_px=120, fps=2.0, duration_s=2.0)
    plain, bent = tmp_path / "plain.mcap", tmp_path / "bent.mcap"
    simulate_smirror(str(plain), base)
    simulate_smirror(str(bent), replace(base, distortion_k1=-0.2))
    model = next(iter(LogReader(bent).messages(["/node0/camera_model"]))).message
    assert model.distortion[0] == -0.2
    a = next(iter(LogReader(plain).messages(["/node0/image"]))).message.data
    b = next(iter(LogReader(bent).messages(["/node0/image"]))).message.data
    assert a != b
    shirts = _clothes(replace(base, people=4, led_clothes=0.5))
    assert shirts[:2] == [(70, 200, 60), (200, 60, 200)] and shirts[2] != shirts[0]
