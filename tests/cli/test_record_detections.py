"""``trackctl record --detections`` then ``vm-track --mode v-af``, through Typer's runner."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.cache import simulated
from tests.ingest.mot_scene import JUNK_LINES, MotScene, build_scene
from tests.ingest.test_mot_detections import SCENE, score
from trackctl.cli.main import app
from trackctl.sim.vm import simulate_vm

runner = CliRunner()


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> MotScene:
    log = simulated("mot-office.mcap", simulate_vm, SCENE)
    return build_scene(log, tmp_path_factory.mktemp("mot-cli"), fps=SCENE.fps)


def _sources(scene: MotScene) -> list[str]:
    args = []
    for cam in sorted(scene.det):
        args += ["--detections", f"{cam}={scene.det[cam]}", "--calib", f"{cam}={scene.calib[cam]}"]
    return args


def test_record_public_detections_of_two_cameras_then_vm_track(
    scene: MotScene, tmp_path: Path
) -> None:
    out = tmp_path / "det.mcap"
    rec = runner.invoke(
        app,
        ["record", str(out), *_sources(scene), "--fps", str(scene.fps), "--min-score", "0.5"]
        + ["--json"],
    )
    assert rec.exit_code == 0, rec.output
    summary = json.loads(rec.stdout)
    assert summary["skipped_lines"] == {
        str(scene.det["cam0"]): len(JUNK_LINES),
        str(scene.det["cam1"]): 0,
    }
    assert set(summary["topics"]) == {
        f"/{c}/{kind}"
        for c in ("cam0", "cam1")
        for kind in ("detections", "detections/annotations", "camera_model", "calibration")
    }
    warned = [line for line in rec.stderr.splitlines() if "warning" in line]
    assert len(warned) == 1 and f"skipped {len(JUNK_LINES)} unusable line(s)" in warned[0]
    tracked = tmp_path / "tracked.mcap"
    run = runner.invoke(
        app, ["vm-track", str(out), "--mode", "v-af", "--out", str(tracked), "--json"]
    )
    assert run.exit_code == 0, run.output
    report = json.loads(run.stdout)
    assert report["source"] == "detections" and report["mode"] == "v-af"
    mot, n_tracks = score(scene, tracked)
    assert 3 <= n_tracks <= 4 and mot.mota > 0.9, (n_tracks, mot)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([], "camera cam0 has no --calib cam0=FILE"),
        (["--calib", "cam0=CALIB"], "--detections needs --fps"),
    ],
)
def test_record_detections_errors_are_one_line(
    scene: MotScene, tmp_path: Path, extra: list[str], message: str
) -> None:
    extra = [e.replace("CALIB", str(scene.calib["cam0"])) for e in extra]
    out = tmp_path / "o.mcap"
    res = runner.invoke(
        app, ["record", str(out), "--detections", f"cam0={scene.det['cam0']}", *extra]
    )
    assert res.exit_code == 2
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], res.stderr
    assert not out.exists()


def test_a_detections_file_with_no_usable_line_is_one_error(
    scene: MotScene, tmp_path: Path
) -> None:
    junk = tmp_path / "junk.txt"
    junk.write_text("\n".join(JUNK_LINES) + "\n")
    res = runner.invoke(
        app,
        ["record", str(tmp_path / "o.mcap"), "--detections", f"cam0={junk}"]
        + ["--calib", f"cam0={scene.calib['cam0']}", "--fps", "5"],
    )
    assert res.exit_code == 2
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "junk.txt: no usable line" in errors[0], res.stderr
