"""Seeded mutations of calibration files (OpenCV YAML, ROS camera_info YAML, Tsai XML) through
``calib check`` and ``calib import``: never a traceback or a crash of OpenCV's FileStorage."""

from __future__ import annotations

import random
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.conftest import CALIB_RVEC, CALIB_TVEC
from tests.fuzz.common import Fuzz, mutate_text

CASES = 60
ROS_INFO = """image_width: 640
image_height: 480
camera_name: cam0
camera_matrix:
  rows: 3
  cols: 3
  data: [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.01, -0.02, 0.0, 0.0, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0]
"""
TSAI = """<?xml version="1.0" encoding="UTF-8"?>
<Camera name="View_001">
<Geometry width="768" height="576" ncx="7.95e+02" nfx="7.52e+02" dx="4.85e-03" dy="4.65e-03"
 dpx="5.127e-03" dpy="4.65e-03"/>
<Intrinsic focal="5.5549" kappa1="5.1113e-03" cx="3.2422e+02" cy="2.8256e+02" sx="1.0937"/>
<Extrinsic tx="8.287e+02" ty="-3.175e+03" tz="3.546e+04" rx="2.0405" ry="-8.9337e-01"
 rz="-4.3056e-01"/>
</Camera>
"""


def _opencv_yaml(path: Path) -> str:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 64)
    fs.write("image_height", 48)
    fs.write("camera_matrix", np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[0.01, -0.02, 0.0, 0.0, 0.0]]))
    fs.write("rvec", CALIB_RVEC.reshape(3, 1))
    fs.write("tvec", CALIB_TVEC.reshape(3, 1))
    fs.release()
    return path.read_text()


XML_TOKENS = ("0", "-1", "nan", "inf", "1e308", "9" * 5000, "", "x", "1e-300")


def _mutate_xml(text: str, rng: random.Random) -> str:
    """An attribute value replaced, or elements nested deep, or the text cut."""
    kind = rng.choice(["attr", "attr", "attr", "nest", "cut", "entity"])
    if kind == "attr":
        parts = text.split('"')
        i = rng.randrange(1, len(parts), 2) if len(parts) > 2 else 0
        parts[i] = rng.choice(XML_TOKENS)
        return '"'.join(parts)
    if kind == "nest":
        depth = rng.choice([40, 5000])
        return text.replace("</Camera>", "<a>" * depth + "</a>" * depth + "</Camera>")
    if kind == "entity":
        return text.replace(
            '<?xml version="1.0" encoding="UTF-8"?>',
            '<?xml version="1.0"?><!DOCTYPE c [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;">]>',
        ).replace('name="View_001"', 'name="&b;"')
    return text[: rng.randrange(len(text) + 1)]


def test_fuzz_calibration(tmp_path: Path, record_property: pytest.RecordProperty) -> None:
    fuzz = Fuzz("calibration YAML/XML", record_property)
    sources = {
        "opencv.yaml": _opencv_yaml(tmp_path / "base.yaml"),
        "ros.yaml": ROS_INFO,
        "tsai.xml": TSAI,
    }
    names = sorted(sources)
    for case in range(CASES):
        rng = random.Random(f"calib/{case}")
        name = names[case % len(names)]
        text = sources[name]
        mutant = _mutate_xml(text, rng) if name.endswith(".xml") else mutate_text(text, rng)
        path = tmp_path / f"c{case}-{name}"
        path.write_bytes(mutant.encode("utf-8", "surrogateescape"))
        fuzz.cases += 1
        if case % 3 == 0:
            out = tmp_path / f"out{case}.yaml"
            fuzz.invoke(["calib", "import", str(path), "--out", str(out)], [path])
        else:
            fuzz.invoke(["calib", "check", str(path), "--json"], [path])
    deep = tmp_path / "deep.yaml"
    deep.write_text("%YAML:1.0\n---\nimage_width: " + "[" * 10_000 + "]" * 10_000 + "\n")
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(
        "a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
        + "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]\n" for i in range(1, 9))
        + "image_width: *a8\n"
    )
    for path in (deep, bomb):
        fuzz.cases += 1
        fuzz.measure(["calib", "check", str(path)], [path])
    fuzz.check()
