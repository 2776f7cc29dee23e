"""Video/image-folder frames and calibration files."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from tests.conftest import CALIB_RVEC, CALIB_TVEC
from trackctl.errors import InputError
from trackctl.ingest.calibration import read_calibration, to_foxglove_calibration
from trackctl.ingest.video import read_frames


def test_video_frames_are_jpeg_stamped_by_fps(video_mp4: Path) -> None:
    frames = list(read_frames(video_mp4, "cam0", start_ns=1_000))
    assert len(frames) == 12
    assert frames[3][0] == 1_000 + 300_000_000
    t, img = frames[3]
    assert img.format == "jpeg" and img.frame_id == "cam0"
    assert img.timestamp.ToNanoseconds() == t
    decoded = cv2.imdecode(np.frombuffer(img.data, np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (48, 64, 3)


def test_fps_overrides_video_rate(video_mp4: Path) -> None:
    with pytest.warns(UserWarning, match="restamps"):
        frames = list(read_frames(video_mp4, "cam0", fps=2.0))
    assert frames[1][0] == 500_000_000


def test_image_folder_needs_fps_and_keeps_bytes(tmp_path: Path) -> None:
    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"{i:03d}.png"), np.full((8, 8, 3), i * 50, np.uint8))
    with pytest.raises(InputError, match="needs --fps"):
        list(read_frames(folder, "cam1"))
    frames = list(read_frames(folder, "cam1", fps=4.0))
    assert [t for t, _ in frames] == [0, 250_000_000, 500_000_000]
    assert frames[2][1].format == "png"
    assert frames[2][1].data == (folder / "002.png").read_bytes()


def test_unreadable_video(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video")
    with pytest.raises(InputError, match="bad.mp4"):
        list(read_frames(bad, "cam0"))


def test_opencv_calibration_with_extrinsics(calib_yaml: Path) -> None:
    model = read_calibration(calib_yaml, "cam0")
    assert (model.width_px, model.height_px) == (64, 48)
    assert (model.fx_px, model.cx_px) == (50.0, 32.0)
    assert model.distortion == pytest.approx((0.01, -0.02, 0.0, 0.0, 0.0))
    # world <- camera is the inverse of OpenCV's camera <- world (rvec, tvec)
    r_cw, _ = cv2.Rodrigues(CALIB_RVEC)
    cam_center = -r_cw.T @ CALIB_TVEC
    t = model.world_from_camera.translation
    assert (t.x, t.y, t.z) == pytest.approx(tuple(cam_center))
    cal = to_foxglove_calibration(model)
    assert list(cal.K) == pytest.approx([50, 0, 32, 0, 50, 24, 0, 0, 1])
    assert len(cal.P) == 12


def test_ros_camera_info(tmp_path: Path) -> None:
    path = tmp_path / "ost.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "image_width": 640,
                "image_height": 480,
                "camera_name": "narrow_stereo",
                "camera_matrix": {
                    "rows": 3,
                    "cols": 3,
                    "data": [500.0, 0, 320, 0, 505.0, 240, 0, 0, 1],
                },
                "distortion_model": "plumb_bob",
                "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.1, 0, 0, 0, 0]},
            }
        )
    )
    model = read_calibration(path, "cam0")
    assert (model.fx_px, model.fy_px, model.cy_px) == (500.0, 505.0, 240.0)
    assert model.world_from_camera is None


def test_calibration_without_matrix(tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text("%YAML:1.0\nimage_width: 10\n")
    with pytest.raises(InputError, match="no camera matrix"):
        read_calibration(path, "cam0")


def test_every_and_rate_subsample_with_true_timestamps(video_mp4: Path) -> None:
    from trackctl.ingest.video import FrameSelection

    every = [t for t, _ in read_frames(video_mp4, "c", select=FrameSelection(every=3))]
    assert every == [0, 300_000_000, 600_000_000, 900_000_000]
    rate = [t for t, _ in read_frames(video_mp4, "c", select=FrameSelection(rate_hz=4))]
    # 10 fps kept at most 4 times a second: the first frame at or after each 0.25 s step
    assert rate == [0, 300_000_000, 500_000_000, 800_000_000, 1_000_000_000]
    window = FrameSelection(start_s=0.35, end_s=0.7)
    assert [t for t, _ in read_frames(video_mp4, "c", select=window)] == [
        400_000_000,
        500_000_000,
        600_000_000,
        700_000_000,
    ]
    with pytest.raises(InputError, match="window"):
        list(read_frames(video_mp4, "c", select=FrameSelection(start_s=5.0)))
    with pytest.raises(InputError, match="--every"):
        list(read_frames(video_mp4, "c", select=FrameSelection(every=0)))


def test_image_folder_stamped_by_names_or_csv(tmp_path: Path) -> None:
    folder = tmp_path / "imgs"
    folder.mkdir()
    for ms in (1000, 1250, 1600):
        cv2.imwrite(str(folder / f"{ms}.png"), np.zeros((8, 8, 3), np.uint8))
    named = list(read_frames(folder, "c", frame_times="names", time_unit="ms"))
    assert [t for t, _ in named] == [0, 250_000_000, 600_000_000]
    csv = tmp_path / "times.csv"
    csv.write_text("file,t_s\n1000.png,10.0\n1250.png,10.5\n1600.png,11.0\n")
    stamped = list(read_frames(folder, "c", frame_times=csv))
    assert [t for t, _ in stamped] == [0, 500_000_000, 1_000_000_000]
    csv.write_text("file,t_s\n1000.png,10.0\n")
    with pytest.raises(InputError, match="no time for image 1250.png"):
        list(read_frames(folder, "c", frame_times=csv))
