"""``trackctl calib`` and the calibration checks of ``record``, through Typer's runner and a real
subprocess."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from tests.conftest import ROOT, run_cli, shared_file
from trackctl.cli.main import app
from trackctl.geometry.camera import PinholeCamera
from trackctl.ingest.calibration import read_calibration

runner = CliRunner()
POINTS = ROOT / "tests" / "data" / "pets2009_view001_floor_points.csv"


def test_calib_ground_on_pets_floor_points(tmp_path: Path) -> None:
    shipped = shared_file("footage", "pets2009_view001.yaml")
    out = tmp_path / "cam0.yaml"
    result = runner.invoke(
        app,
        ["calib", "ground", "cam0", "--intrinsics", str(shipped), "--points", str(POINTS)]
        + ["--out", str(out), "--json"],
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["points"] == 6
    assert summary["reprojection_rms_px"] < 1.0
    assert abs(summary["height_m"] - 7.07) < 0.05
    # the written YAML is what record --calib reads, and places the floor where the original does
    ours = PinholeCamera(read_calibration(out, "cam0"))
    ref = PinholeCamera(read_calibration(shipped, "cam0"))
    px = np.array([[100.0, 250.0], [400.0, 300.0], [700.0, 500.0], [384.0, 560.0]])
    assert np.linalg.norm(ours.ground_point(px) - ref.ground_point(px), axis=1).max() < 0.2


def test_calib_ground_with_inline_points_and_bad_points(tmp_path: Path) -> None:
    shipped = shared_file("footage", "pets2009_view001.yaml")
    rows = [line.split(",") for line in POINTS.read_text().splitlines()[3:]]
    image = " ".join(f"{r[0]},{r[1]}" for r in rows)
    world = " ".join(f"{r[2]},{r[3]}" for r in rows)
    base = ["calib", "ground", "cam0", "--intrinsics", str(shipped), "--out"]
    ok = runner.invoke(
        app, [*base, str(tmp_path / "a.yaml"), "--image-points", image, "--world-points", world]
    )
    assert ok.exit_code == 0, ok.output
    three = runner.invoke(
        app,
        [*base, str(tmp_path / "b.yaml"), "--image-points", "1,2 3,4 5,6"]
        + ["--world-points", "0,0 1,0 0,1"],
    )
    assert three.exit_code == 2
    assert "at least 4 point pairs" in three.output
    assert not (tmp_path / "b.yaml").exists()
    bad = tmp_path / "bad.csv"
    bad.write_text("u,v,x,y\n1,2,3,4\n5,6,seven,8\n")
    proc = run_cli(*base, str(tmp_path / "c.yaml"), "--points", str(bad))
    assert proc.returncode == 2
    err = proc.stderr.decode()
    assert "bad.csv:3" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_calib_import_tsai_and_check(tmp_path: Path) -> None:
    xml = shared_file("footage", "pets2009_View_001.xml")
    out = tmp_path / "tsai.yaml"
    proc = run_cli("calib", "import", str(xml), "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    assert summary["image"] == "768x576" and abs(summary["height_m"] - 7.07) < 0.01
    check = runner.invoke(app, ["calib", "check", str(out), "--json"])
    assert check.exit_code == 0 and json.loads(check.stdout)["floor_share"] == 1.0
    # Tsai XML read as metres is a unit error, named
    wrong = runner.invoke(app, ["calib", "check", str(xml), "--units", "m"])
    assert wrong.exit_code == 2 and "millimetres" in wrong.output


def _calib(path: Path, size: tuple[int, int], tvec_scale: float = 1.0) -> Path:
    from tests.conftest import CALIB_RVEC, CALIB_TVEC

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", size[0])
    fs.write("image_height", size[1])
    fs.write("camera_matrix", np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]]))
    fs.write("rvec", CALIB_RVEC.reshape(3, 1))
    fs.write("tvec", (CALIB_TVEC * tvec_scale).reshape(3, 1))
    fs.release()
    return path


def test_record_rejects_a_calibration_for_another_size_or_in_mm(
    tmp_path: Path, video_mp4: Path
) -> None:
    out = tmp_path / "r.mcap"
    small = _calib(tmp_path / "small.yaml", (640, 480))
    proc = run_cli("record", str(out), "--video", f"cam0={video_mp4}", "--calib", f"cam0={small}")
    assert proc.returncode == 2
    err = proc.stderr.decode().strip()
    assert "640x480" in err and "64x48" in err and len(err.splitlines()) == 1
    assert not out.exists()
    mm = _calib(tmp_path / "mm.yaml", (64, 48), 1000.0)
    proc = run_cli("record", str(out), "--video", f"cam0={video_mp4}", "--calib", f"cam0={mm}")
    assert proc.returncode == 2 and "millimetres" in proc.stderr.decode()
    proc = run_cli(
        "record",
        str(out),
        "--video",
        f"cam0={video_mp4}",
        "--calib",
        f"cam0={mm}",
        "--calib-units",
        "mm",
        "--every",
        "2",
        "--json",
    )
    assert proc.returncode == 0, proc.stderr.decode()
    counts = json.loads(proc.stdout)
    assert counts["topics"]["/cam0/image"] == 6


def test_record_takes_the_pets_tsai_xml_as_it_is(tmp_path: Path) -> None:
    xml = shared_file("footage", "pets2009_View_001.xml")
    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 7.0, (768, 576))
    for _ in range(3):
        writer.write(np.full((576, 768, 3), 120, np.uint8))
    writer.release()
    out = tmp_path / "r.mcap"
    proc = run_cli("record", str(out), "--video", f"cam0={video}", "--calib", f"cam0={xml}")
    assert proc.returncode == 0, proc.stderr.decode()
    from trackctl.logs.reader import LogReader

    (model,) = [m.message for m in LogReader(out).messages(["/cam0/camera_model"])]
    assert model.world_from_camera.translation.z == pytest.approx(7.07, abs=0.01)
    # read as metres, the same file is a one-line unit error
    proc = run_cli(
        "record",
        str(tmp_path / "m.mcap"),
        "--video",
        f"cam0={video}",
        "--calib",
        f"cam0={xml}",
        "--calib-units",
        "m",
    )
    err = proc.stderr.decode().strip()
    assert proc.returncode == 2 and "millimetres" in err and len(err.splitlines()) == 1
