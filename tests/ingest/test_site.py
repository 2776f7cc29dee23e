"""Site files: parsed strictly into the metadata records processors read; ``record --site``
stores them; ``smirror/bridgeloc --site`` lay them over a log."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from tests.conftest import ROOT
from tests.ingest.ros2_bags import smirror_log_to_bag
from trackctl.cli.main import app
from trackctl.errors import InputError
from trackctl.ingest.site import read_site, site_records
from trackctl.logs import LogReader

SMIRROR = ROOT / "sample_logs" / "smirror.mcap"
BRIDGELOC = ROOT / "sample_logs" / "bridgeloc.mcap"


def _sample_site() -> dict:
    """The site of the S-Mirror sample log, as a user would write it."""
    md = LogReader(SMIRROR).metadata()
    robot = {k: float(v) for k, v in md["robot/r1"].items()}
    return {
        "robots": {"r1": robot},
        "smirror": {"requesters": 1, "floorplan": json.loads(md["smirror/floorplan"]["plan"])},
    }


def test_records_match_what_the_simulator_writes() -> None:
    records = site_records(_sample_site(), "site.yaml")
    md = LogReader(SMIRROR).metadata()
    assert {k: float(v) for k, v in records["robot/r1"].items()} == {
        k: float(v) for k, v in md["robot/r1"].items()
    }
    assert json.loads(records["smirror/floorplan"]["plan"]) == json.loads(
        md["smirror/floorplan"]["plan"]
    )
    assert records["smirror/requesters"] == {"count": "1"}
    bl = site_records({"bridgeloc": {"tag_n": 3, "robot_camera": "front"}})["bridgeloc"]
    assert bl == {"tag_n": "3", "robot_camera": "front"}


def test_led_colours_reach_the_robot(tmp_path: Path) -> None:
    from trackctl.smirror import SmirrorConfig
    from trackctl.smirror.site import load_site

    records = site_records({"robots": {"r1": {"front_hue": [20, 34], "back_hue": [100, 125]}}})
    assert records["robot/r1"] == {"front_hue": "20-34", "back_hue": "100-125"}
    with pytest.warns(Warning):
        site = load_site(LogReader(SMIRROR), SmirrorConfig(site=records))
    (robot,) = site.robots
    assert (robot.led.front_hue, robot.led.back_hue) == ((20, 34), (100, 125))


@pytest.mark.parametrize(
    "data, message",
    [
        ({"robot": {}}, "unknown key 'robot'"),
        ({"robots": {"r1": {"wheelbase": 0.3}}}, r"robots.r1: unknown key 'wheelbase'"),
        ({"robots": {"r1": {"ticks_per_m": "many"}}}, r"robots.r1.ticks_per_m: 'many' is not"),
        ({"robots": {"r1": {"wheel_base_m": -0.3}}}, "must be positive"),
        ({"robots": {"r1": {"led_height_m": float("nan")}}}, "is not finite"),
        ({"robots": {"r1": {"front_hue": [30]}}}, r"robots.r1.front_hue: \[30\] is not a hue"),
        ({"robots": {"r1": {"back_hue": [100, 200]}}}, r"back_hue.*need 0 <= LO <= HI <= 180"),
        ({"smirror": {"requesters": 0}}, "must be >= 1"),
        ({"smirror": {"floorplan": {"walls": 3}}}, "smirror.floorplan"),
        ({"bridgeloc": {"tag_n": 2.5}}, "is not an integer"),
        ({"bridgeloc": {"robot_camera": 5}}, "expected a name"),
        ([1, 2], "expected a mapping"),
        ({"bridgeloc": {"tag_n": 0}}, r"bridgeloc.tag_n: 0 is out of range; expected an integer"),
        ({"bridgeloc": {"tag_n": -3}}, r"bridgeloc.tag_n: -3 is out of range"),
        ({"robots": {"r1": {"ticks_per_m": 1e-300}}}, r"ticks_per_m: 1e-300 is out of range"),
        ({"robots": {"r1": {"led_height_m": 10**400}}}, r"led_height_m: .* is out of range"),
        ({"smirror": {"floorplan": {"size_m": [1], "walls": []}}}, r"size_m: \[1\] is not a"),
        (
            {"smirror": {"floorplan": {"size_m": [9, 9], "walls": [[[0, 0], [1, 1]]] * 5001}}},
            r"smirror.floorplan.walls: 5,001 walls; expected at most 5,000",
        ),
        (
            {"smirror": {"floorplan": {"size_m": [9, 9], "walls": [[[0, 0], [1, "x"]]]}}},
            r"smirror.floorplan.walls\[0\]\[1\]\[1\]: 'x' is not a number",
        ),
    ],
)
def test_bad_sites_name_file_and_key(data: object, message: str) -> None:
    with pytest.raises(InputError, match=message) as err:
        site_records(data, "site.yaml")
    assert str(err.value).startswith("site.yaml")


def test_log_metadata_is_checked_like_a_site_file() -> None:
    from trackctl.ingest.site import record_number

    assert record_number({"tag_n": "3"}, "tag_n", 2, "log") == 3
    assert record_number({}, "tag_n", 2, "log") == 2
    for bad in ("0", "nan", "1e400", "x", "9" * 5000):
        with pytest.raises(InputError, match=r"^log: tag_n"):
            record_number({"tag_n": bad}, "tag_n", 2, "log")


def test_a_fifo_site_is_refused_without_waiting(tmp_path: Path) -> None:
    fifo = tmp_path / "site.yaml"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="is a FIFO; expected a regular file"):
        read_site(fifo)


def test_read_site_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        read_site(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("robots: [unclosed\n")
    with pytest.raises(InputError, match="not valid YAML at line"):
        read_site(bad)


def test_recorded_site_silences_the_defaults_warning(tmp_path: Path) -> None:
    bag, site = tmp_path / "bag", tmp_path / "site.yaml"
    smirror_log_to_bag(SMIRROR, bag)
    site.write_text(yaml.safe_dump(_sample_site()))
    runner = CliRunner()
    log = tmp_path / "with_site.mcap"
    rec = runner.invoke(app, ["record", str(log), "--ros2", str(bag), "--site", str(site), "-q"])
    assert rec.exit_code == 0, rec.output
    reader = LogReader(log)
    assert "robot/r1" in reader.metadata() and "site/site.yaml" in reader.attachments()
    stored = runner.invoke(app, ["smirror", str(log), "--json", "-q"])
    assert stored.exit_code == 0 and "site defaults used" not in stored.output
    bare = tmp_path / "bare.mcap"
    runner.invoke(app, ["record", str(bare), "--ros2", str(bag), "-q"])
    overlaid = runner.invoke(app, ["smirror", str(bare), "--site", str(site), "--json", "-q"])
    assert overlaid.exit_code == 0 and "site defaults used" not in overlaid.output
    plain = runner.invoke(app, ["smirror", str(bare), "--json", "-q"])
    assert "site defaults used" in plain.output


def test_bridgeloc_reads_the_site(tmp_path: Path) -> None:
    site = tmp_path / "site.yaml"
    site.write_text("bridgeloc:\n  robot_camera: frontcam\n")
    result = CliRunner().invoke(app, ["bridgeloc", "eval", str(BRIDGELOC), "--site", str(site)])
    assert result.exit_code == 2
    assert "frontcam" in result.output


def test_bridgeloc_names_its_defaults_once(tmp_path: Path) -> None:
    from trackctl.logs import LogWriter

    bare = tmp_path / "bare.mcap"
    reader = LogReader(BRIDGELOC)
    with LogWriter(bare) as w:
        for raw in reader.raw():
            w.write_raw(raw)
    runner = CliRunner()
    plain = runner.invoke(app, ["bridgeloc", "eval", str(bare), "--json", "-q"])
    lines = [x for x in plain.output.splitlines() if "site defaults used" in x]
    assert plain.exit_code == 0 and len(lines) == 1
    assert "tag_size_m=0.3" in lines[0] and "robot/r1 ticks_per_m=2000.0" in lines[0]
    site = tmp_path / "site.yaml"
    md = reader.metadata()
    site.write_text(
        yaml.safe_dump(
            {
                "robots": {"r1": {k: float(v) for k, v in md["robot/r1"].items()}},
                "bridgeloc": {
                    "robot": "r1",
                    "robot_camera": md["bridgeloc"]["robot_camera"],
                    "tag_n": int(md["bridgeloc"]["tag_n"]),
                    "tag_size_m": float(md["bridgeloc"]["tag_size_m"]),
                    "ir_height_m": float(md["bridgeloc"]["ir_height_m"]),
                },
            }
        )
    )
    given = runner.invoke(app, ["bridgeloc", "eval", str(bare), "--site", str(site), "--json"])
    assert given.exit_code == 0 and "site defaults used" not in given.output
