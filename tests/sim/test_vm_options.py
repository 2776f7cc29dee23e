"""simulate vm's light and stillness options: what they put in the log, and their checks."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from trackctl.cli.main import app
from trackctl.errors import InputError
from trackctl.logs.reader import LogReader
from trackctl.sim.vm import VmScenario, simulate_vm

runner = CliRunner()


def _brightness(path: Path, topic: str = "/cam0/image") -> list[float]:
    out = []
    for m in LogReader(path).messages([topic]):
        img = cv2.imdecode(np.frombuffer(m.message.data, np.uint8), cv2.IMREAD_GRAYSCALE)
        out.append(float(img.mean()))
    return out


def test_light_drop_and_flicker_change_only_the_pixels(tmp_path: Path) -> None:
    base = VmScenario(field="office", users=1, nonusers=0, duration_s=8, seed=2, frames=True)
    clean, dim, flick = tmp_path / "c.mcap", tmp_path / "d.mcap", tmp_path / "f.mcap"
    simulate_vm(str(clean), base)
    simulate_vm(str(dim), VmScenario(**{**_fields(base), "light_drop": 0.25, "light_drop_at_s": 4}))
    simulate_vm(str(flick), VmScenario(**{**_fields(base), "flicker": 0.2}))
    c, d, f = _brightness(clean), _brightness(dim), _brightness(flick)
    assert len(c) == len(d) == len(f) == 24
    assert np.allclose(d[:12], c[:12], atol=0.5)  # before 4 s (3 fps)
    assert np.allclose(np.array(d[12:]) / np.array(c[12:]), 0.75, atol=0.02)
    ratio = np.array(f) / np.array(c)
    assert ratio.std() > 0.05 and ratio.min() > 0.75 and ratio.max() < 1.25
    # every other topic is unchanged
    imu = [m.message for m in LogReader(clean).messages(["/phone/020000000001/imu"])]
    assert imu == [m.message for m in LogReader(flick).messages(["/phone/020000000001/imu"])]


def _fields(cfg: VmScenario) -> dict:
    return {k: getattr(cfg, k) for k in cfg.__dataclass_fields__}


def test_standing_person_stands_still_for_the_time_asked(tmp_path: Path) -> None:
    path = tmp_path / "s.mcap"
    simulate_vm(
        str(path),
        VmScenario(field="office", users=1, nonusers=0, duration_s=30, seed=1, standing_s=20),
    )
    track = []
    for m in LogReader(path).messages(["/ground_truth"]):
        for e in m.message.entities:
            if e.entity_id == "s0":
                track.append((m.log_time_ns / 1e9, e.position_m.x, e.position_m.y))
    arr = np.array(track)
    steps = np.linalg.norm(np.diff(arr[:, 1:], axis=0), axis=1)
    still = arr[1:][steps < 1e-6]
    assert still[-1, 0] - still[0, 0] == pytest.approx(20, abs=0.7)
    assert arr[-1, 0] - arr[0, 0] > 20  # it walks in and out too


def test_option_checks() -> None:
    with pytest.raises(InputError, match="--light-drop"):
        VmScenario(light_drop=1.5)
    with pytest.raises(InputError, match="--standing"):
        VmScenario(duration_s=10, standing_s=20)
    result = runner.invoke(app, ["simulate", "vm", "--out", "x.mcap", "--shadows"])
    assert result.exit_code == 2 and "--frames" in result.output


def test_preset_checks_through_the_cli(tmp_path: Path) -> None:
    out = str(tmp_path / "x.mcap")
    bad = runner.invoke(app, ["simulate", "vm", "--out", out, "--preset", "lab"])
    assert bad.exit_code == 2 and "--preset 'lab'" in bad.output and "realistic" in bad.output
    mixed = runner.invoke(
        app, ["simulate", "vm", "--out", out, "--preset", "paper", "--carry-yaw", "45"]
    )
    assert mixed.exit_code == 2 and "--preset realistic" in mixed.output
    assert not Path(out).exists()
    ok = runner.invoke(
        app,
        [
            "simulate",
            "vm",
            "--out",
            out,
            "--field",
            "office",
            "--users",
            "1",
            "--nonusers",
            "0",
            "--duration",
            "5",
            "--carry-yaw",
            "90",
            "--clock-offset",
            "0.5",
            "--json",
        ],
    )
    assert ok.exit_code == 0, ok.output
    truth = LogReader(out).metadata()["phone_truth"]
    offset = float(truth["02:00:00:00:00:01/clock_offset_s"])
    assert abs(offset) <= 0.5


def test_always_on_phones_are_heard_out_of_view_and_fainter(tmp_path: Path) -> None:
    # a person crosses a corridor from 20 s to 40 s of a 60 s log (somebody else stands there
    # all along); their phone is on all along
    rows = ["t_s,id,x_m,y_m"] + [f"{20 + k / 2},p,{k * 0.6},3.0" for k in range(41)]
    rows += [f"{k},q,12.0,1.0" for k in range(61)]
    csv = tmp_path / "walk.csv"
    csv.write_text("\n".join(rows) + "\n")
    log = tmp_path / "vm.mcap"
    simulate_vm(str(log), VmScenario(trajectories=str(csv), phones=("p",), duration_s=60, seed=1))
    heard: dict[str, list[tuple[float, float]]] = {"in": [], "out": []}
    for m in LogReader(log).messages(["/rssi"]):
        t = m.log_time_ns / 1e9
        for r in m.message.readings:
            heard["in" if 20 <= t <= 40 else "out"].append((t, r.rssi_dbm))
    assert heard["in"] and heard["out"]
    # heard before and after the visit, fainter (behind walls, walking away)
    assert min(t for t, _ in heard["out"]) < 15 and max(t for t, _ in heard["out"]) > 45
    assert np.median([v for _, v in heard["out"]]) < np.median([v for _, v in heard["in"]]) - 5
    # the paper's phones report only in view
    paper = tmp_path / "paper.mcap"
    sc = VmScenario(trajectories=str(csv), phones=("p",), duration_s=60, seed=1, preset="paper")
    simulate_vm(str(paper), sc)
    times = [
        m.log_time_ns / 1e9 for m in LogReader(paper).messages(["/rssi"]) if m.message.readings
    ]
    assert times and min(times) >= 19 and max(times) <= 41


def test_trajectories_without_phones_give_phones_to_the_users_who_walk_farthest(
    tmp_path: Path,
) -> None:
    scene = tmp_path / "scene.csv"
    rows = ["t_s,id,x_m,y_m"]
    for person, metres in (("a", 2.0), ("b", 8.0), ("c", 5.0), ("d", 1.0)):
        rows += [f"{t},{person},{metres * t / 10},{1 + ord(person) % 4}" for t in (0.0, 10.0)]
    scene.write_text("\n".join(rows) + "\n")

    def carriers(cfg: VmScenario) -> set[str]:
        out = tmp_path / "vm.mcap"
        simulate_vm(str(out), cfg)
        named = set()
        for m in LogReader(out).messages(["/ground_truth"]):
            named |= {(e.entity_id, e.electronic_id) for e in m.message.entities}
        return {person for person, mid in named if mid}

    base = VmScenario(trajectories=str(scene), users=2, duration_s=8.0, seed=1)
    assert carriers(base) == {"b", "c"}
    assert carriers(VmScenario(**{**_fields(base), "phones": ("d",)})) == {"d"}


def test_a_scene_whose_annotations_start_late_is_the_same_log(tmp_path: Path) -> None:
    # ETH/UCY frames numbered from 10000 (a split of a longer recording) make the log the frames
    # numbered from 0 make, message for message, not 400 s of nobody
    rows = [(f, p, 0.5 + 0.05 * f + p, 2.0 + 0.3 * p) for p in (1, 2, 3) for f in range(0, 300, 10)]
    logs = []
    for start in (0, 10000):
        scene = tmp_path / f"scene{start}.txt"
        scene.write_text("".join(f"{f + start}\t{p}\t{x}\t{y}\n" for f, p, x, y in rows))
        out = tmp_path / f"vm{start}.mcap"
        simulate_vm(str(out), VmScenario(trajectories=str(scene), users=1, duration_s=20, seed=3))
        with out.open("rb") as f:
            logs.append(
                [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]
            )
    assert logs[0] == logs[1]
    first = next(LogReader(tmp_path / "vm10000.mcap").messages(["/ground_truth"]))
    assert first.log_time_ns == 0 and len(first.message.entities) == 3


def test_a_csv_scene_starts_at_its_first_row(tmp_path: Path) -> None:
    # t_s from 1000 s (a clock of the recording): the log starts with the first person
    rows = ["t_s,id,x_m,y_m"] + [f"{1000 + k / 2},p,{k * 0.3},2.0" for k in range(41)]
    rows += [f"{1005 + k / 2},q,6.0,{k * 0.1}" for k in range(21)]
    csv = tmp_path / "late.csv"
    csv.write_text("\n".join(rows) + "\n")
    out = tmp_path / "vm.mcap"
    simulate_vm(str(out), VmScenario(trajectories=str(csv), phones=("p",), duration_s=60, seed=1))
    seen = {}
    for m in LogReader(out).messages(["/ground_truth"]):
        for e in m.message.entities:
            seen.setdefault(e.entity_id, m.log_time_ns / 1e9)
    assert seen["p"] == 0.0 and seen["q"] == pytest.approx(5.0, abs=0.34)
