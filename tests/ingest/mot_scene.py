"""A MOTChallenge det.txt built from a simulated scene: the true people seen as boxes.

Each person is a 1.7 m tall box, 0.41 x its height wide, its foot point (bottom centre) at the
true ground position, projected through the scenario's own camera model; boxes not fully in the
image are left out (MOT detectors rarely report cut people). The calibration is written as the
OpenCV YAML ``record --calib`` reads.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trackctl.geometry.camera import PinholeCamera
from trackctl.ingest.calibration import write_calibration
from trackctl.logs import LogReader, topics
from trackctl.logs.messages import CameraModel, GroundTruth

PERSON_HEIGHT_M = 1.7
WIDTH_PER_HEIGHT = 0.41
JUNK_LINES = (
    "frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z",  # a header: not numbers
    "1,-1,100,100,30",  # too few fields
    "2,-1,nan,100,30,80,0.9,-1,-1,-1",  # NaN
    "3,-1,100,100,-30,80,0.9,-1,-1,-1",  # negative width
    "0,-1,100,100,30,80,0.9,-1,-1,-1",  # frame 0
    "4,-1,100,inf,30,80,0.9,-1,-1,-1",  # infinity
    "\x00\xff garbage",
)
"""Lines a det.txt reader must skip: one per rule."""
FALSE_BOX = (40.0, 300.0, 25.0, 60.0)
"""A false detection (a poster) at the same pixels in every frame, at a low score."""
FALSE_SCORE = 0.1


@dataclass(frozen=True)
class MotScene:
    """det.txt and calibration files per camera, and the truth to score against."""

    det: dict[str, Path]
    calib: dict[str, Path]
    fps: float
    truth: list[GroundTruth]
    boxes: int
    """True boxes written (all cameras)."""


def person_box(cam: PinholeCamera, x: float, y: float) -> tuple[float, float, float, float] | None:
    """(left, top, width, height), 0-based pixels, or None unless fully in the image."""
    px, front = cam.project(np.array([[x, y, 0.0], [x, y, PERSON_HEIGHT_M]]))
    if not front.all():
        return None
    (fx, fy), (_, hy) = px
    h = float(fy - hy)
    w = h * WIDTH_PER_HEIGHT
    left, top = float(fx) - w / 2, float(hy)
    m = cam.model
    if h <= 0 or left < 0 or top < 0 or left + w > m.width_px or fy > m.height_px:
        return None
    return left, top, w, h


def _mot_line(frame: int, box: tuple[float, float, float, float], conf: float) -> str:
    left, top, w, h = box
    # MOTChallenge counts pixels from 1
    return f"{frame},-1,{left + 1:.2f},{top + 1:.2f},{w:.2f},{h:.2f},{conf:.3f},-1,-1,-1"


def build_scene(log: Path, out_dir: Path, fps: float, junk: bool = True) -> MotScene:
    """det.txt per camera of the simulated ``log`` (truth at ``fps``), junk lines and a false
    low-score box in every frame of the first camera."""
    reader = LogReader(log)
    present = reader.topics()
    models: dict[str, CameraModel] = {}
    for topic in sorted(t for t in present if t.endswith("/camera_model")):
        for m in reader.messages([topic]):
            models[m.message.camera] = m.message
            break
    truth = [m.message for m in reader.messages([topics.GROUND_TRUTH])]
    rng = np.random.default_rng(7)
    det: dict[str, Path] = {}
    calib: dict[str, Path] = {}
    boxes = 0
    for k, (name, model) in enumerate(sorted(models.items())):
        cam = PinholeCamera(model)
        lines: list[str] = []
        for gt in truth:
            frame = round(gt.t_ns * fps / 1e9) + 1
            for e in gt.entities:
                box = person_box(cam, e.position_m.x, e.position_m.y)
                if box is not None:
                    lines.append(_mot_line(frame, box, float(rng.uniform(0.6, 1.0))))
                    boxes += 1
            if junk and k == 0:
                lines.append(_mot_line(frame, FALSE_BOX, FALSE_SCORE))
        if junk and k == 0:
            for j, bad in enumerate(JUNK_LINES):
                lines.insert(1 + 7 * j, bad)
        det[name] = out_dir / f"{name}-det.txt"
        det[name].write_text("\n".join(lines) + "\n", encoding="utf-8", errors="surrogateescape")
        calib[name] = out_dir / f"{name}.yaml"
        write_calibration(model, calib[name])
    return MotScene(det, calib, fps, truth, boxes)
