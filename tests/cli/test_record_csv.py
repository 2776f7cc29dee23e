"""``trackctl record --columns / --no-header / --time-unit``: sensor CSVs laid out as the field
writes them (column maps by index or header name, header-less files, time units)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import run_cli
from trackctl.cli.main import app
from trackctl.logs import LogReader

runner = CliRunner()


def _files(tmp_path: Path) -> tuple[Path, Path]:
    """A phone export with its own names in milliseconds, and a header-less odometry file."""
    imu = tmp_path / "accel.csv"
    imu.write_text(
        "time,accX,accY,accZ,gyroZ\n"
        + "".join(f"{1000 + 20 * i},{0.1 * i:.1f},0,9.81,0.5\n" for i in range(10))
    )
    odom = tmp_path / "odom.csv"
    odom.write_text("".join(f"{1.0 + 0.02 * i:.2f},0.5,0.1\n" for i in range(8)))
    return imu, odom


def test_record_maps_columns_by_name_and_by_index(tmp_path: Path) -> None:
    imu, odom = _files(tmp_path)
    out = tmp_path / "out.mcap"
    res = runner.invoke(
        app,
        ["record", str(out), "--imu", f"p1={imu}", "--odom", f"r1={odom}"]
        + ["--columns", "p1:t=time,ax=accX,ay=accY,az=accZ"]
        + ["--columns", "r1:t=0,v_mps=1,omega_rps=2", "--json"],
    )
    assert res.exit_code == 2, res.output  # time is in ms: refused, with the hint
    assert "accel.csv: line 2, column time:" in res.stderr and "--time-unit" in res.stderr
    # one --time-unit for every file: give the odometry in ms too
    odom.write_text("".join(f"{1000 + 20 * i},0.5,0.1\n" for i in range(8)))
    res = runner.invoke(
        app,
        ["record", str(out), "--imu", f"p1={imu}", "--odom", f"r1={odom}", "--time-unit", "ms"]
        + ["--columns", "p1:t=time,ax=accX,ay=accY,az=accZ"]
        + ["--columns", "r1:t=0,v_mps=1,omega_rps=2", "--json"],
    )
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["topics"] == {"/phone/p1/imu": 10, "/robot/r1/odom": 8}
    msgs = list(LogReader(out).messages(["/phone/p1/imu"]))
    assert msgs[1].log_time_ns == 1_020_000_000
    assert msgs[1].message.accel_mps2.x == pytest.approx(0.1)
    assert msgs[1].message.gyro_rps is None  # gyroZ alone is no gyroscope


@pytest.mark.parametrize(
    "extra, expected",
    [
        (["--columns", "q9:t=0"], "--columns q9:...: no --imu/--odom named q9 (names: p1"),
        (["--columns", "t=0,ax"], "'ax' is not KEY=COLUMN"),
        (["--columns", "p1:t=time,ax=accX,ay=nope,az=accZ"], "no column 'nope' in the header"),
        (["--columns", "p1:t=time,ax=accX,ay=accY,az=accZ,v_mps=1"], "v_mps is not a field"),
    ],
)
def test_bad_columns_are_one_line_errors_naming_the_file(
    tmp_path: Path, extra: list[str], expected: str
) -> None:
    imu, _ = _files(tmp_path)
    res = runner.invoke(
        app, ["record", str(tmp_path / "o.mcap"), "--imu", f"p1={imu}", "--time-unit", "ms", *extra]
    )
    assert res.exit_code == 2, res.output
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and expected in errors[0], res.stderr
    assert not (tmp_path / "o.mcap").exists()


def test_columns_without_a_csv_input_is_refused(tmp_path: Path) -> None:
    res = runner.invoke(app, ["record", str(tmp_path / "o.mcap"), "--stdin", "--columns", "t=0"])
    assert res.exit_code == 2 and "--columns describes CSV files" in res.stderr


def test_header_less_imu_through_a_real_subprocess(tmp_path: Path) -> None:
    imu = tmp_path / "imu.txt"
    imu.write_text("".join(f"{0.01 * i:.2f} ,0,0,9.8\n" for i in range(5)) + "0.05,0,x,9.8\n")
    out = tmp_path / "o.mcap"
    bad = run_cli("record", str(out), "--imu", f"p={imu}", "--columns", "t=0,ax=1,ay=2,az=3")
    assert bad.returncode == 2
    assert f"{imu}: line 6, column 2 (0-based): 'x' is not a finite number" in bad.stderr.decode()
    imu.write_text("".join(f"{0.01 * i:.2f},0,0,9.8\n" for i in range(5)))
    ok = run_cli(
        "record", str(out), "--imu", f"p={imu}", "--columns", "t=0,ax=1,ay=2,az=3", "--no-header"
    )
    assert ok.returncode == 0, ok.stderr.decode()
    assert LogReader(out).topics()["/phone/p/imu"].count == 5
