"""CSV readers: the column contract, Sensor Logger exports, and errors naming file/line/column."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import examples
from trackctl.errors import InputError, NonFiniteValueError, NonMonotonicTimeError
from trackctl.ingest.sensors_csv import (
    CsvLayout,
    parse_column_options,
    parse_columns,
    read_imu,
    read_odometry_csv,
    read_rssi_csv,
)
from trackctl.logs.messages import Quat, Vec3


def test_imu_csv(imu_csv: Path) -> None:
    samples = list(read_imu(imu_csv, "p1"))
    assert len(samples) == 50
    assert samples[1].t_ns == 200_000_000
    assert samples[1].accel_mps2.x == pytest.approx(0.1)
    assert samples[0].gyro_rps.z == pytest.approx(0.05)
    assert samples[0].orientation == Quat(0.0, 0.0, 0.0, 1.0)  # qw first in CSV, last in Quat
    assert samples[0].frame_id == "phone/p1"


def test_imu_csv_without_quaternion(tmp_path: Path) -> None:
    path = tmp_path / "imu.csv"
    path.write_text("t_s,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n0.1,0,0,9.8,0,0,0\n")
    samples = list(read_imu(path, "p"))
    assert [s.orientation for s in samples] == [None, None]


def test_rssi_rows_group_into_scans(rssi_csv: Path) -> None:
    scans = list(read_rssi_csv(rssi_csv))
    assert len(scans) == 20
    assert scans[0].observer == "ap1"
    assert [r.eid for r in scans[0].readings] == ["aa:bb:cc:00:00:01", "aa:bb:cc:00:00:02"]
    assert scans[1].observer == "ap2" and len(scans[1].readings) == 1


def test_odometry_ticks_and_velocities(odom_csv: Path, tmp_path: Path) -> None:
    ticks = list(read_odometry_csv(odom_csv, "r1"))
    assert len(ticks) == 40 and ticks[2].left_ticks == 20 and ticks[2].right_ticks == 22
    vel = tmp_path / "vel.csv"
    vel.write_text("t_s,v_mps,omega_rps\n0,0.5,0.1\n1,0.6,-0.1\n")
    out = list(read_odometry_csv(vel, "r1"))
    assert out[1].v_mps == 0.6 and out[1].omega_rps == -0.1 and out[1].left_ticks is None


def test_missing_column_names_file_and_columns(tmp_path: Path) -> None:
    path = tmp_path / "imu.csv"
    path.write_text("t_s,ax,gx,gy,gz\n0,0,0,0,0\n")
    with pytest.raises(InputError, match=r"imu.csv: IMU CSV lacks column\(s\) ay, az"):
        list(read_imu(path, "p"))


def test_nan_names_file_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "imu.csv"
    path.write_text("t_s,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n0.1,0,nan,9.8,0,0,0\n")
    with pytest.raises(NonFiniteValueError, match=r"imu.csv: line 3, column ay: .*not a finite"):
        list(read_imu(path, "p"))


def test_inf_and_text_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "odom.csv"
    path.write_text("t_s,v_mps,omega_rps\n0,inf,0\n")
    with pytest.raises(NonFiniteValueError, match="line 2, column v_mps"):
        list(read_odometry_csv(path, "r"))
    path.write_text("t_s,observer,eid,rssi_dbm\n0,ap,e,strong\n")
    with pytest.raises(NonFiniteValueError, match="line 2, column rssi_dbm: 'strong'"):
        list(read_rssi_csv(path))


def test_non_monotonic_time_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "imu.csv"
    path.write_text(
        "t_s,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n0.2,0,0,9.8,0,0,0\n0.1,0,0,9.8,0,0,0\n"
    )
    with pytest.raises(
        NonMonotonicTimeError,
        match=r"line 4, column t_s: 0.1 s is earlier than the previous row \(0.2 s\)",
    ):
        list(read_imu(path, "p"))


def test_empty_and_missing_files(tmp_path: Path) -> None:
    empty = tmp_path / "e.csv"
    empty.write_text("")
    with pytest.raises(InputError, match="empty file; a header row is required"):
        list(read_rssi_csv(empty))
    with pytest.raises(InputError, match="no such file"):
        list(read_rssi_csv(tmp_path / "nope.csv"))


def _sensor_logger_files(folder: Path, with_total: bool) -> None:
    t = 1_700_000_000_000_000_000 + np.arange(20) * 10_000_000
    xyz = "time,seconds_elapsed,z,y,x\n"
    if with_total:
        (folder / "TotalAcceleration.csv").write_text(
            xyz + "".join(f"{ti},{i * 0.01},9.8,0.1,0.2\n" for i, ti in enumerate(t))
        )
    else:
        (folder / "Accelerometer.csv").write_text(
            xyz + "".join(f"{ti},{i * 0.01},0.0,0.1,0.2\n" for i, ti in enumerate(t))
        )
        (folder / "Gravity.csv").write_text(
            xyz + "".join(f"{ti},{i * 0.01},9.8,0,0\n" for i, ti in enumerate(t))
        )
    (folder / "Gyroscope.csv").write_text(
        xyz + "".join(f"{ti + 5_000_000},{i * 0.01},0.3,0,0\n" for i, ti in enumerate(t))
    )
    (folder / "Orientation.csv").write_text(
        "time,seconds_elapsed,qz,qy,qx,qw,roll,pitch,yaw\n"
        + "".join(f"{ti},{i * 0.01},0,0,0,1,0,0,0\n" for i, ti in enumerate(t))
    )


@pytest.mark.parametrize("with_total", [True, False])
def test_sensor_logger_folder_and_zip(tmp_path: Path, with_total: bool) -> None:
    folder = tmp_path / "export"
    folder.mkdir()
    _sensor_logger_files(folder, with_total)
    zpath = tmp_path / "export.zip"
    with zipfile.ZipFile(zpath, "w") as zf:
        for f in folder.iterdir():
            zf.write(f, f"Recording/{f.name}")
    for source in (folder, zpath):
        samples = list(read_imu(source, "p1"))
        assert len(samples) == 20
        s = samples[3]
        assert s.t_ns == 1_700_000_000_030_000_000
        assert (s.accel_mps2.x, s.accel_mps2.y, s.accel_mps2.z) == pytest.approx((0.2, 0.1, 9.8))
        assert s.gyro_rps.z == pytest.approx(0.3)
        assert s.orientation == Quat(0.0, 0.0, 0.0, 1.0)


def test_sensor_logger_folder_without_gyro_is_accelerometer_only(tmp_path: Path) -> None:
    folder = tmp_path / "export"
    folder.mkdir()
    (folder / "TotalAcceleration.csv").write_text("time,seconds_elapsed,z,y,x\n1,0,9.8,0,0\n")
    (sample,) = list(read_imu(folder, "p1"))
    assert sample.gyro_rps is None and sample.accel_mps2.z == pytest.approx(9.8)


def test_sensor_logger_folder_without_accelerometer_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "export"
    folder.mkdir()
    (folder / "Gyroscope.csv").write_text("time,seconds_elapsed,z,y,x\n1,0,0,0,0\n")
    with pytest.raises(InputError, match="not a Sensor Logger export"):
        list(read_imu(folder, "p1"))


# -- strict parsing ----------------------------------------------------------------------------


def _csv(tmp_path: Path, text: str, name: str = "s.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_accelerometer_only_imu_csv_is_valid(tmp_path: Path) -> None:
    path = _csv(tmp_path, "t_s,ax,ay,az\n0,0,0,9.8\n0.01,0.1,0,9.7\n")
    samples = list(read_imu(path, "p"))
    assert [s.gyro_rps for s in samples] == [None, None]
    assert samples[1].accel_mps2.x == pytest.approx(0.1)


@pytest.mark.parametrize("value", ["true", "False", "abc", "1,5", "0x10"])
def test_boolean_or_text_in_a_number_column_names_line_and_column(
    tmp_path: Path, value: str
) -> None:
    cell = f'"{value}"' if "," in value else value
    path = _csv(tmp_path, f"t_s,ax,ay,az\n0,0,0,9.8\n{cell},0,0,9.8\n")
    with pytest.raises(InputError, match=r"s.csv: line 3, column t_s: .* is not a finite number"):
        list(read_imu(path, "p"))


def test_rssi_ids_are_kept_exactly_as_written(tmp_path: Path) -> None:
    path = _csv(tmp_path, "t_s,observer,eid,rssi_dbm\n0,01,007,-50\n0,01,1e3,-60\n1,02,0x1F,-70\n")
    scans = list(read_rssi_csv(path))
    assert [s.observer for s in scans] == ["01", "02"]
    assert [r.eid for s in scans for r in s.readings] == ["007", "1e3", "0x1F"]


def test_blank_rssi_id_is_an_error(tmp_path: Path) -> None:
    path = _csv(tmp_path, "t_s,observer,eid,rssi_dbm\n0,ap,aa,-50\n1,ap,,-60\n")
    with pytest.raises(InputError, match=r"s.csv: line 3, column eid: empty id"):
        list(read_rssi_csv(path))


@pytest.mark.parametrize(
    "rows, line",
    [("0,0,0,9.8\n1,0,0,9.8,5\n", 3), ("0,0,0,9.8,5\n1,0,0,9.8\n", 2)],
)
def test_row_with_more_fields_than_the_header_names_the_line(
    tmp_path: Path, rows: str, line: int
) -> None:
    path = _csv(tmp_path, "t_s,ax,ay,az\n" + rows)
    with pytest.raises(InputError, match=rf"s.csv: line {line}: .*fields.* header"):
        list(read_imu(path, "p"))


def test_millisecond_stamps_are_refused_with_a_hint(tmp_path: Path) -> None:
    path = _csv(tmp_path, "t_s,ax,ay,az\n0,0,0,9.8\n10,0,0,9.8\n20,0,0,9.8\n30,0,0,9.8\n")
    with pytest.raises(InputError, match=r"look like milliseconds.*--time-unit ms"):
        list(read_imu(path, "p"))
    samples = list(read_imu(path, "p", time_unit="ms"))
    assert [s.t_ns for s in samples] == [0, 10_000_000, 20_000_000, 30_000_000]


def test_epoch_millisecond_stamps_are_refused_and_converted_exactly(tmp_path: Path) -> None:
    path = _csv(
        tmp_path,
        "t_s,observer,eid,rssi_dbm\n1700000000123,ap,aa,-50\n1700000001123,ap,aa,-51\n",
    )
    with pytest.raises(InputError, match=r"line 2, column t_s: .* epoch milliseconds"):
        list(read_rssi_csv(path))
    scans = list(read_rssi_csv(path, time_unit="ms"))
    assert [s.t_ns for s in scans] == [1_700_000_000_123_000_000, 1_700_000_001_123_000_000]


def test_epoch_nanosecond_stamps_convert_without_float_rounding(tmp_path: Path) -> None:
    path = _csv(
        tmp_path, "t_s,v_mps,omega_rps\n1700000000123456789,0.5,0\n1700000000133456789,0.5,0\n"
    )
    with pytest.raises(InputError, match="epoch milliseconds or finer"):
        list(read_odometry_csv(path, "r"))
    out = list(read_odometry_csv(path, "r", time_unit="ns"))
    assert [o.t_ns for o in out] == [1_700_000_000_123_456_789, 1_700_000_000_133_456_789]


def test_epoch_seconds_are_valid_seconds(tmp_path: Path) -> None:
    path = _csv(tmp_path, "t_s,ax,ay,az\n1700000000.00,0,0,9.8\n1700000000.01,0,0,9.8\n")
    samples = list(read_imu(path, "p"))
    assert samples[1].t_ns - samples[0].t_ns == 10_000_000


# -- column maps, header-less files, time units (record --columns / --no-header) -------------


def test_header_less_file_is_read_by_index_map(tmp_path: Path) -> None:
    path = _csv(tmp_path, "9.8,0.1,0,0.00\n9.7,0.2,0,0.01\n")
    layout = CsvLayout(parse_columns("t=3,ax=1,ay=2,az=0"))
    samples = list(read_imu(path, "p", layout=layout))
    assert [s.t_ns for s in samples] == [0, 10_000_000]
    assert (samples[1].accel_mps2.x, samples[1].accel_mps2.z) == pytest.approx((0.2, 9.7))
    assert samples[0].gyro_rps is None


def test_header_names_map_and_unmapped_fields_go_by_contract_name(tmp_path: Path) -> None:
    path = _csv(
        tmp_path, "time,accX,accY,accZ,gx,gy,gz\n1000,1,2,3,0.1,0.2,0.3\n1010,1,2,3,0,0,0\n"
    )
    layout = CsvLayout(parse_columns("t=time,ax=accX,ay=accY,az=accZ"))
    samples = list(read_imu(path, "p", time_unit="ms", layout=layout))
    assert [s.t_ns for s in samples] == [1_000_000_000, 1_010_000_000]
    assert samples[0].accel_mps2 == Vec3(1.0, 2.0, 3.0)
    assert samples[0].gyro_rps == Vec3(0.1, 0.2, 0.3)


@pytest.mark.parametrize("unit, factor", [("s", 10**9), ("ms", 10**6), ("us", 10**3), ("ns", 1)])
def test_time_units_of_a_mapped_time_column(tmp_path: Path, unit: str, factor: int) -> None:
    path = _csv(tmp_path, "v,w,stamp\n0.5,0,7\n0.5,0,8\n0.5,0,9\n")
    layout = CsvLayout(parse_columns("t=stamp,v_mps=v,omega_rps=w"))
    if unit == "s":  # integer seconds a second apart look like milliseconds: refused, with a hint
        with pytest.raises(InputError, match=r"line 2, column stamp: .*--time-unit"):
            list(read_odometry_csv(path, "r", time_unit=unit, layout=layout))
        return
    out = list(read_odometry_csv(path, "r", time_unit=unit, layout=layout))
    assert [o.t_ns for o in out] == [7 * factor, 8 * factor, 9 * factor]


def test_forced_header_and_forced_no_header(tmp_path: Path) -> None:
    numeric_header = _csv(tmp_path, "0,1,2,3\n0.0,0,0,9.8\n0.1,0,0,9.8\n")
    layout = CsvLayout(parse_columns("t=0,ax=1,ay=2,az=3"), header=True)
    assert len(list(read_imu(numeric_header, "p", layout=layout))) == 2
    assert len(list(read_imu(numeric_header, "p", layout=CsvLayout(layout.columns)))) == 3
    text_first = _csv(tmp_path, "x,0,0,9.8\n0.1,0,0,9.8\n", "t.csv")
    with pytest.raises(NonFiniteValueError, match=r"t.csv: line 1, column 0 \(0-based\): 'x'"):
        list(read_imu(text_first, "p", layout=CsvLayout(layout.columns, header=False)))


def test_header_less_file_without_a_map_asks_for_columns(tmp_path: Path) -> None:
    path = _csv(tmp_path, "0,0,0,9.8\n0.1,0,0,9.8\n")
    with pytest.raises(
        InputError, match=r"s.csv: line 1 holds numbers.*--columns t=0,ax=1,ay=2,az=3"
    ):
        list(read_imu(path, "p"))
    with pytest.raises(InputError, match=r"(?s)--columns t=0,ax=1.*missing: ay, az"):
        list(read_imu(path, "p", layout=CsvLayout({"t_s": 0, "ax": 1})))


def test_errors_name_the_files_own_column_and_line_blank_lines_included(tmp_path: Path) -> None:
    by_name = _csv(tmp_path, "time,accX,accY,accZ\n0,0,0,9.8\n\n0.1,0,oops,9.8\n")
    layout = CsvLayout(parse_columns("t=time,ax=accX,ay=accY,az=accZ"))
    with pytest.raises(NonFiniteValueError, match=r"s.csv: line 4, column accY: 'oops'"):
        list(read_imu(by_name, "p", layout=layout))
    by_index = _csv(tmp_path, "0,0,0,9.8\n\n\n0.1,0,0,\n", "i.csv")
    with pytest.raises(
        NonFiniteValueError, match=r"i.csv: line 4, column 3 \(0-based\): empty, expected a"
    ):
        list(read_imu(by_index, "p", layout=CsvLayout(parse_columns("t=0,ax=1,ay=2,az=3"))))
    back = _csv(tmp_path, "stamp,observer,eid,rssi_dbm\n1,a,e,-50\n\n0.5,a,e,-50\n", "r.csv")
    with pytest.raises(NonMonotonicTimeError, match=r"r.csv: line 4, column stamp: 0.5 s"):
        list(read_rssi_csv(back, layout=CsvLayout({"t_s": "stamp"})))


def test_duplicate_header_names_are_never_renamed(tmp_path: Path) -> None:
    # pandas would call the second '0.0' column '0.0.1': that name is in no file
    path = _csv(tmp_path, "t_s,0.0,0.0,az\n0,1,2,9.8\n0.1,x,2,9.8\n")
    layout = CsvLayout({"ax": 1, "ay": 2})
    with pytest.raises(NonFiniteValueError) as err:
        list(read_imu(path, "p", layout=layout))
    assert "line 3, column 0.0: 'x'" in str(err.value) and "0.0.1" not in str(err.value)
    with pytest.raises(InputError, match=r"'0.0' heads columns 1 and 2 \(0-based\)") as dup:
        list(read_imu(path, "p", layout=CsvLayout({"ax": "0.0", "ay": 2})))
    assert "0.0.1" not in str(dup.value)
    twice = _csv(tmp_path, "t_s,ax,ay,az,az\n0,0,0,9.8,1\n", "d.csv")
    with pytest.raises(InputError, match=r"d.csv: line 1: header name 'az' heads columns 3 and 4"):
        list(read_imu(twice, "p"))
    assert len(list(read_imu(twice, "p", layout=CsvLayout({"az": 4})))) == 1


@pytest.mark.parametrize(
    "text, columns, header, message",
    [
        (
            "t,a\n0,1\n",
            {"t_s": 0, "ax": 9},
            None,
            r"--columns ax=9: the file has 2 columns \(0..1\)",
        ),
        ("0,1\n", {"t_s": 0, "ax": "accX"}, False, r"--columns ax=accX names a header column"),
        (
            "t,a\n0,1\n",
            {"t_s": 0, "ax": "accX"},
            None,
            r"no column 'accX' in the header \(line 1: t,a\)",
        ),
        ("t,a\n0,1\n", {"t_s": 0, "v_mps": 1}, None, r"v_mps is not a field of an IMU CSV"),
        ("t_s,ax,ay,az,g\n0,0,0,9,1\n", {"gx": 4}, None, r"--columns gives gx but not gy, gz"),
    ],
)
def test_bad_column_maps_name_the_file_and_the_column(
    tmp_path: Path,
    text: str,
    columns: dict[str, int | str],
    header: bool | None,
    message: str,
) -> None:
    path = _csv(tmp_path, text)
    with pytest.raises(InputError, match=r"s.csv: .*" + message):
        list(read_imu(path, "p", layout=CsvLayout(columns, header)))


def test_rssi_and_odometry_by_index(tmp_path: Path) -> None:
    rssi = _csv(tmp_path, "-50,ap1,007,0\n-60,ap1,008,0\n", "r.csv")
    layout = CsvLayout(parse_columns("t=3,observer=1,eid=2,rssi_dbm=0"))
    (scan,) = list(read_rssi_csv(rssi, layout=layout))
    assert [r.eid for r in scan.readings] == ["007", "008"] and scan.observer == "ap1"
    odom = _csv(tmp_path, "0,10,11\n0.1,20,22\n", "o.csv")
    ticks = list(
        read_odometry_csv(
            odom, "r", layout=CsvLayout(parse_columns("t=0,left_ticks=1,right_ticks=2"))
        )
    )
    assert ticks[1].right_ticks == 22
    with pytest.raises(InputError, match=r"o.csv: line 1 holds numbers.*--columns t=0,left_ticks"):
        list(read_odometry_csv(odom, "r"))


@pytest.mark.parametrize(
    "spec, message",
    [
        ("t=0,ax", r"'ax' is not KEY=COLUMN"),
        ("t=0,t_s=1", r"t_s given twice"),
        ("t=0,ax=0", r"column 0 given for two fields"),
        ("=1", r"'=1' is not KEY=COLUMN"),
    ],
)
def test_parse_columns_errors(spec: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_columns(spec)


def test_parse_column_options_targets() -> None:
    got = parse_column_options(["t=0,ax=1", "p1:t=time", "rssi:t=1"])
    assert got == {"": {"t_s": 0, "ax": 1}, "p1": {"t_s": "time"}, "rssi": {"t_s": 1}}
    with pytest.raises(InputError, match="a second --columns for p1"):
        parse_column_options(["p1:t=0", "p1:ax=1"])
    assert parse_column_options(["t=a:b"]) == {"": {"t_s": "a:b"}}  # ':' after '=' is a name


@settings(max_examples=examples(25), deadline=None)
@given(order=st.permutations(range(7)), header=st.booleans())
def test_any_column_order_reads_the_same_samples(order: list[int], header: bool) -> None:
    import tempfile

    fields = ("t_s", "ax", "ay", "az", "gx", "gy", "gz")
    rows = [[f"{0.01 * i:.2f}", str(i), "0.5", "9.8", "0", "0", f"{i / 10}"] for i in range(5)]
    lines = ([",".join(f"c{j}" for j in range(7))] if header else []) + [
        ",".join(r[order.index(j)] for j in range(7)) for r in rows
    ]
    columns = {f: (f"c{order[k]}" if header else order[k]) for k, f in enumerate(fields)}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "p.csv"
        path.write_text("\n".join(lines) + "\n")
        samples = list(read_imu(path, "p", layout=CsvLayout(columns)))
    assert [s.t_ns for s in samples] == [i * 10_000_000 for i in range(5)]
    assert [s.accel_mps2.x for s in samples] == [float(i) for i in range(5)]
    assert [s.gyro_rps.z for s in samples] == pytest.approx([i / 10 for i in range(5)])


def test_line_numbers_across_chunks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import trackctl.ingest.sensors_csv as sensors_csv

    monkeypatch.setattr(sensors_csv, "CHUNK_ROWS", 3)
    rows = [f"{0.01 * i:.2f},0,0,9.8" for i in range(8)]
    rows[6] = "0.06,0,0,bad"
    path = _csv(tmp_path, "t_s,ax,ay,az\n" + "\n".join(rows[:2]) + "\n\n" + "\n".join(rows[2:]))
    # line 1 header, lines 2-3 samples 0-1, line 4 blank, sample k >= 2 on line k + 3
    with pytest.raises(NonFiniteValueError, match=r"line 9, column az: 'bad'"):
        list(read_imu(path, "p"))
    rows[6] = "0.06,0,0,9.8"
    path.write_text("t_s,ax,ay,az\n" + "\n".join(rows[:2]) + "\n\n" + "\n".join(rows[2:]))
    assert len(list(read_imu(path, "p"))) == 8
