"""MOTChallenge public detections (``record --detections``): the parser, the reader, and
vm-track on a simulated scene's boxes."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.cache import simulated
from tests.ingest.mot_scene import FALSE_SCORE, JUNK_LINES, MotScene, build_scene
from trackctl.errors import InputError
from trackctl.ingest.mot import MotLineError, parse_mot_line, read_mot_detections
from trackctl.ingest.record import IngestPlan, RecordConfig, ingest
from trackctl.logs import LogReader, topics
from trackctl.logs.messages import BBox, Detections, Tracks
from trackctl.metrics.tracking import MotAccumulator, MotSummary
from trackctl.processing import run_processors
from trackctl.sim.vm import VmScenario, simulate_vm
from trackctl.vmtrack import Mode, VmTrackConfig, VmTrackProcessor

SCENE = VmScenario(
    field="office", users=1, nonusers=2, duration_s=30, seed=11, fps=5.0, preset="paper"
)
"""Three people walking in the office (two cameras) for 30 s, truth at 5 Hz."""


def test_a_line_becomes_a_zero_based_box() -> None:
    box = parse_mot_line("12,-1,101.5,51,40,100,0.93,-1,-1,-1\n")
    assert box.frame == 12
    assert box.box == BBox(100.5, 50.0, 40.0, 100.0)
    assert box.conf == pytest.approx(0.93)
    assert parse_mot_line("3 -1 11 21 5 9 42.0").box == BBox(10.0, 20.0, 5.0, 9.0)


@pytest.mark.parametrize(
    ("line", "column"),
    [
        ("1,-1,100,100,30", 0),
        ("1,-1,100,100,30,80,0.9,-1,-1,-1,5", 0),
        ("2,-1,nan,100,30,80,0.9,-1,-1,-1", 3),
        ("2,-1,100,inf,30,80,0.9", 4),
        ("2,-1,100,100,abc,80,0.9", 5),
        ("3,-1,100,100,-30,80,0.9,-1,-1,-1", 5),
        ("3,-1,100,100,30,0,0.9,-1,-1,-1", 6),
        ("0,-1,100,100,30,80,0.9,-1,-1,-1", 1),
        ("1.5,-1,100,100,30,80,0.9,-1,-1,-1", 1),
        ("1,-1,100,100,30,80,,-1,-1,-1", 7),
    ],
)
def test_a_bad_line_names_its_column(line: str, column: int) -> None:
    with pytest.raises(MotLineError) as err:
        parse_mot_line(line)
    assert err.value.column == column


@given(st.text(max_size=80))
def test_no_garbage_line_raises_anything_but_a_line_error(line: str) -> None:
    try:
        box = parse_mot_line(line)
    except MotLineError:
        return
    assert box.frame >= 1 and box.box.w_px > 0 and box.box.h_px > 0


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=7, max_size=10))
def test_numeric_garbage_never_raises_anything_but_a_line_error(values: list[float]) -> None:
    try:
        parse_mot_line(",".join(repr(v) for v in values))
    except MotLineError:
        pass


def test_unsorted_frames_come_out_in_frame_order_with_gaps_filled(tmp_path: Path) -> None:
    det = tmp_path / "det.txt"
    det.write_text(
        "3,-1,10,10,5,9,0.8,-1,-1,-1\n1,-1,10,10,5,9,0.7,-1,-1,-1\n\n3,-1,30,10,5,9,0.9,-1,-1,-1\n"
    )
    read = read_mot_detections(det, "cam0", fps=10.0, start_ns=1_000)
    assert [m.t_ns for m in read.messages] == [1_000, 100_001_000, 200_001_000]
    assert [len(m.detections) for m in read.messages] == [1, 0, 2]
    assert read.boxes == 3 and read.skipped == 0
    assert all(isinstance(m, Detections) and m.camera == "cam0" for m in read.messages)


def test_scores_on_another_scale_are_rescaled_and_min_score_uses_the_raw_conf(
    tmp_path: Path,
) -> None:
    det = tmp_path / "det.txt"
    det.write_text("1,-1,1,1,5,9,-2,-1,-1,-1\n1,-1,1,1,5,9,8,-1,-1,-1\n2,-1,1,1,5,9,18\n")
    all_boxes = read_mot_detections(det, "c", fps=1.0)
    scores = [d.score for m in all_boxes.messages for d in m.detections]
    assert scores == pytest.approx([0.0, 0.5, 1.0])
    kept = read_mot_detections(det, "c", fps=1.0, min_score=0.0)
    assert kept.boxes == 2 and kept.below_score == 1


def test_bad_lines_are_skipped_counted_and_warned_once(tmp_path: Path) -> None:
    det = tmp_path / "det.txt"
    det.write_text("1,-1,10,10,5,9,0.8\n" + "\n".join(JUNK_LINES) + "\n2,-1,10,10,5,9,0.8\n")
    with pytest.warns(UserWarning) as caught:
        read = read_mot_detections(det, "cam0", fps=1.0)
    assert read.skipped == len(JUNK_LINES) and read.boxes == 2
    assert len(caught) == 1
    text = str(caught[0].message)
    assert f"{det}:2: column 1 (frame)" in text and f"skipped {len(JUNK_LINES)}" in text


def test_a_file_without_a_usable_line_is_one_error_naming_it(tmp_path: Path) -> None:
    det = tmp_path / "det.txt"
    det.write_text("\n".join(JUNK_LINES) + "\n")
    with pytest.raises(InputError, match=r"det\.txt: no usable line.*first problem"):
        read_mot_detections(det, "cam0", fps=30.0)
    det.write_text("1,-1,10,10,5,9,0.1\n")
    with pytest.raises(InputError, match="none at --min-score 0.5"):
        read_mot_detections(det, "cam0", fps=30.0, min_score=0.5)


def test_detections_need_a_calibration_and_a_frame_rate(tmp_path: Path) -> None:
    det = tmp_path / "det.txt"
    det.write_text("1,-1,10,10,5,9,0.8\n")
    plan = IngestPlan(RecordConfig(detections={"cam7": det}, fps=30.0))
    with pytest.raises(InputError, match="camera cam7 has no --calib cam7=FILE"):
        ingest(plan, tmp_path / "o.mcap")
    assert not (tmp_path / "o.mcap").exists()


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> MotScene:
    log = simulated("mot-office.mcap", simulate_vm, SCENE)
    return build_scene(log, tmp_path_factory.mktemp("mot"), fps=SCENE.fps)


def score(scene: MotScene, tracked: Path) -> tuple[MotSummary, int]:
    """CLEAR MOT on the ground plane (1 m gate, as vm-track's report) and the track count."""
    hyps: dict[int, dict[str, tuple[float, float]]] = {}
    for m in LogReader(tracked).messages(["/vmtrack/tracks"]):
        msg: Tracks = m.message
        hyps[round(msg.t_ns * scene.fps / 1e9)] = {
            t.track_id: (t.position_m.x, t.position_m.y) for t in msg.tracks
        }
    acc = MotAccumulator(1.0)
    for gt in scene.truth:
        truth = {e.entity_id: (e.position_m.x, e.position_m.y) for e in gt.entities}
        acc.update(truth, hyps.get(round(gt.t_ns * scene.fps / 1e9), {}))
    ids = {i for frame in hyps.values() for i in frame}
    return acc.summary(), len(ids)


def test_vm_track_follows_every_person_on_public_detections(
    scene: MotScene, tmp_path: Path
) -> None:
    out = tmp_path / "det.mcap"
    cfg = RecordConfig(detections=scene.det, calib=scene.calib, fps=scene.fps, min_score=0.5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        summary = ingest(IngestPlan(cfg), out)
    assert len([w for w in caught if "unusable line" in str(w.message)]) == 1
    assert summary.skipped == {str(scene.det["cam0"]): len(JUNK_LINES), str(scene.det["cam1"]): 0}
    reader = LogReader(out)
    dets = [m.message for m in reader.messages([topics.detections("cam0")])]
    assert dets and all(d.score > FALSE_SCORE for m in dets for d in m.detections)
    assert (
        sum(
            len(m.message.detections)
            for m in reader.messages()
            if isinstance(m.message, Detections)
        )
        == scene.boxes
    )
    tracked = tmp_path / "tracked.mcap"
    (rep,) = run_processors(out, tracked, [VmTrackProcessor(VmTrackConfig(mode=Mode.V_AF))])
    assert rep.metrics["source"] == "detections"
    mot, n_tracks = score(scene, tracked)
    people = len({e.entity_id for gt in scene.truth for e in gt.entities})
    # Exact boxes of 3 people in 2 cameras (measured: 3 tracks, MOTA 0.987, IDF1 0.993, no ID
    # switch). The bars leave room for a spare track (a person who leaves every view and comes
    # back) and for the frames a track needs to be confirmed, not for a lost person or a broken
    # track (a tenth of the frames missed fails MOTA; a switch in mid-scene fails IDF1).
    assert people <= n_tracks <= people + 1, n_tracks
    assert mot.mota > 0.9, mot
    assert mot.idf1 > 0.9, mot
