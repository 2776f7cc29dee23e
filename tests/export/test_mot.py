"""MOT export: read back by py-motmetrics, scored as the vm-track report scores."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import motmetrics as mm
import numpy as np
import pandas as pd
import pytest

from trackctl.errors import InputError, SchemaError
from trackctl.export import ExportConfig, ExportFormat, export, ids_path
from trackctl.export.mot import BOX_WIDTH_SHARE, PersonBoxes, load_camera
from trackctl.logs.messages import GroundTruth, Tracks
from trackctl.logs.reader import LogReader

THRESHOLD_M = 1.0  # VmTrackConfig.eval_threshold_m


def _mot(log: Path, topic: str, out: Path, **kw: Any) -> pd.DataFrame:
    export(log, out, ExportConfig(topic, ExportFormat.MOT, **kw))
    return mm.io.loadtxt(str(out), fmt="mot15-2D")


def _mota(gt: pd.DataFrame, hyp: pd.DataFrame, keep_gt: set[int], keep_hyp: set[int]) -> float:
    """MOTA on the ground plane: world x, y are columns 8-9, which loadtxt names ClassId and
    Visibility (mot15-2D reads columns 3-6 as the box)."""
    acc = mm.MOTAccumulator(auto_id=False)
    frames = gt.index.get_level_values(0)
    hyp_frames = hyp.index.get_level_values(0)
    for f in sorted(set(frames)):
        g = gt[frames == f].droplevel(0)
        h = hyp[hyp_frames == f].droplevel(0)
        g = g[g.index.isin(keep_gt)]
        h = h[h.index.isin(keep_hyp)]
        xy = ["ClassId", "Visibility"]
        d = mm.distances.norm2squared_matrix(
            g[xy].to_numpy(), h[xy].to_numpy(), max_d2=THRESHOLD_M**2
        )
        acc.update(g.index.to_numpy(), h.index.to_numpy(), d, frameid=f)
    summary = mm.metrics.create().compute(acc, metrics=["mota"], name="export")
    return float(summary["mota"].iloc[0])


def _ids(out: Path) -> dict[str, int]:
    table = pd.read_csv(ids_path(out), dtype={"track_id": str})
    return dict(zip(table.track_id, table.mot_id, strict=True))


@pytest.fixture(scope="module")
def exported(
    vm_office_tracked: tuple[dict[str, Any], Path], tmp_path_factory: pytest.TempPathFactory
) -> tuple[dict[str, Any], Path, Path, Path]:
    metrics, log = vm_office_tracked
    folder = tmp_path_factory.mktemp("mot")
    return metrics, log, folder / "tracks.txt", folder / "gt.txt"


def test_mota_from_motmetrics_equals_the_report(
    exported: tuple[dict[str, Any], Path, Path, Path],
) -> None:
    metrics, log, tracks_txt, gt_txt = exported
    hyp = _mot(log, "/vmtrack/tracks", tracks_txt)
    gt = _mot(log, "/ground_truth", gt_txt)
    # every track against every person: the report's mota_all
    all_gt, all_hyp = set(_ids(gt_txt).values()), set(_ids(tracks_txt).values())
    assert _mota(gt, hyp, all_gt, all_hyp) == pytest.approx(metrics["mota_all"], abs=0.01)
    # the headline mota (VM mode): phone carriers against the tracks named by their phone
    carriers: dict[str, str] = {}
    for msg in LogReader(log).messages(["/ground_truth"]):
        assert isinstance(msg.message, GroundTruth)
        carriers.update(
            {e.entity_id: e.electronic_id for e in msg.message.entities if e.electronic_id}
        )
    gt_ids, hyp_ids = _ids(gt_txt), _ids(tracks_txt)
    users = {gt_ids[p] for p in carriers}
    named = {hyp_ids[m] for m in carriers.values() if m in hyp_ids}
    assert named, "no track carries a phone's MID"
    assert _mota(gt, hyp, users, named) == pytest.approx(metrics["mota"], abs=0.01)


def test_frames_ids_and_positions_follow_the_messages(
    exported: tuple[dict[str, Any], Path, Path, Path],
) -> None:
    _, log, tracks_txt, _ = exported
    export(log, tracks_txt, ExportConfig("/vmtrack/tracks", ExportFormat.MOT))
    rows = pd.read_csv(tracks_txt, header=None)
    ids = _ids(tracks_txt)
    assert list(ids.values()) == list(range(1, len(ids) + 1))
    expected = []
    for frame, msg in enumerate(LogReader(log).messages(["/vmtrack/tracks"]), start=1):
        assert isinstance(msg.message, Tracks)
        for t in msg.message.tracks:
            expected.append((frame, ids[t.track_id], t.position_m.x, t.position_m.y))
    assert len(rows) == len(expected)
    assert rows[[0, 1]].to_numpy().tolist() == [[f, i] for f, i, _, _ in expected]
    np.testing.assert_allclose(
        rows[[7, 8]].to_numpy(), [[x, y] for *_, x, y in expected], atol=1e-6
    )
    assert (rows[[2, 3, 4, 5]] == -1).all().all()  # no camera: no box
    assert (rows[6] == 1).all()


def test_boxes_through_a_camera_stand_on_the_ground_point(
    exported: tuple[dict[str, Any], Path, Path, Path], tmp_path: Path
) -> None:
    _, log, _, _ = exported
    out = tmp_path / "gt.txt"
    export(log, out, ExportConfig("/ground_truth", ExportFormat.MOT, camera="cam0"))
    rows = pd.read_csv(out, header=None)
    cam = load_camera(LogReader(log), "cam0")
    feet = rows[[7, 8]].to_numpy()
    px, front = cam.project(np.column_stack([feet, np.zeros(len(feet))]))
    boxed = rows[2].to_numpy() != -1
    assert boxed.any()
    left, top, w, h = (rows[c].to_numpy()[boxed] for c in (2, 3, 4, 5))
    np.testing.assert_allclose(left + w / 2 - 1, px[boxed, 0], atol=1e-4)  # MOT is 1-based
    np.testing.assert_allclose(top + h - 1, px[boxed, 1], atol=1e-4)  # the foot is the bottom
    np.testing.assert_allclose(w, BOX_WIDTH_SHARE * h, rtol=1e-4)
    point = np.array([[*feet[boxed][0], 0.0]])
    short, tall = (PersonBoxes(cam, m).boxes(point)[0] for m in (1.7, 3.4))
    assert short[3] == pytest.approx(h[0], abs=1e-4) and tall[3] > 1.5 * short[3]


def test_unknown_camera_and_wrong_schema(
    exported: tuple[dict[str, Any], Path, Path, Path], tmp_path: Path
) -> None:
    _, log, _, _ = exported
    out = tmp_path / "x.txt"
    with pytest.raises(InputError, match=r"--camera cam9: no /cam9/camera_model; cameras .*cam0"):
        export(log, out, ExportConfig("/ground_truth", ExportFormat.MOT, camera="cam9"))
    with pytest.raises(SchemaError, match=r"/rssi holds trackctl.RssiScan; mot export takes"):
        export(log, out, ExportConfig("/rssi", ExportFormat.MOT))
    assert list(tmp_path.iterdir()) == []
