"""Pedestrian motion models: independent random waypoints and a crowd that avoids itself."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from trackctl.errors import InputError
from trackctl.sim.walkers import (
    hidden_route,
    load_trajectories_csv,
    random_waypoint,
    random_waypoint_crowd,
    walk_route,
)

SIZE = (20.0, 15.0)


def _close_share(paths: np.ndarray, within_m: float) -> float:
    """Share of person-samples with someone else within ``within_m``: paths (steps, n, 2)."""
    hits = total = 0
    for xy in paths[::10]:
        d, _ = cKDTree(xy).query(xy, k=2)
        hits += int(np.sum(d[:, 1] < within_m))
        total += len(xy)
    return hits / total


def test_a_crowd_keeps_its_distance_where_independent_walkers_do_not() -> None:
    names = [f"p{i}" for i in range(40)]
    crowd = random_waypoint_crowd(names, np.random.default_rng(1), SIZE, 120.0)
    rng = np.random.default_rng(1)
    alone = [random_waypoint(n, rng, SIZE, 120.0) for n in names]
    c = _close_share(np.stack([t.xy for t in crowd], axis=1), 0.4)
    a = _close_share(np.stack([t.xy for t in alone], axis=1), 0.4)
    assert c < 0.03 < a
    assert c < a / 3


def test_crowd_walkers_walk_stay_inside_and_are_deterministic() -> None:
    names = ["a", "b", "c"]
    one = random_waypoint_crowd(names, np.random.default_rng(7), SIZE, 60.0)
    two = random_waypoint_crowd(names, np.random.default_rng(7), SIZE, 60.0)
    for t1, t2 in zip(one, two, strict=True):
        assert np.array_equal(t1.xy, t2.xy)
        assert (
            np.all(t1.xy >= 0) and np.all(t1.xy[:, 0] <= SIZE[0]) and np.all(t1.xy[:, 1] <= SIZE[1])
        )
        speed = np.linalg.norm(t1.velocity(), axis=1)
        assert 0.3 < np.median(speed) < 1.6  # walking pace, pauses included
        assert np.max(speed) < 1.3 * 1.5 + 1e-6


def _eth_ucy_rows(step: int, sep: str = "\t") -> str:
    """Two people annotated every 0.4 s: one walks 0.5 m per annotation along x, the other
    misses an annotation (a double step, which must not be read as the frame step)."""
    rows = [f"{k * step}{sep}1.0{sep}{0.5 * k}{sep}2.0" for k in range(20)]
    rows += [f"{k * step}{sep}2.0{sep}1.0{sep}{0.5 * k}" for k in range(0, 20) if k != 7]
    return "\n".join(rows) + "\n"


@pytest.mark.parametrize("step", [10, 6, 1])
def test_eth_ucy_frames_are_read_at_their_own_step_and_keep_true_speeds(
    tmp_path: Path, step: int
) -> None:
    path = tmp_path / "scene.txt"
    path.write_text(_eth_ucy_rows(step))
    walkers = {t.person: t for t in load_trajectories_csv(path, dt_s=0.1)}
    assert sorted(walkers) == ["1", "2"]
    for t in walkers.values():
        speed = np.linalg.norm(np.diff(t.xy, axis=0), axis=1) / t.dt_s
        np.testing.assert_allclose(speed, 0.5 / 0.4, rtol=1e-9)
        assert t.t0_s == 0.0
        assert len(t.xy) == 77  # 19 annotations of 0.4 s on a 0.1 s grid


def test_eth_ucy_text_separated_by_commas_or_spaces_reads_the_same(tmp_path: Path) -> None:
    tabs, commas = tmp_path / "tabs.txt", tmp_path / "commas.txt"
    tabs.write_text(_eth_ucy_rows(10))
    commas.write_text(_eth_ucy_rows(10, sep=","))
    a, b = load_trajectories_csv(tabs), load_trajectories_csv(commas)
    assert [t.person for t in a] == [t.person for t in b]
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.xy, y.xy)


def test_eth_obsmat_columns_are_frame_id_x_z_y(tmp_path: Path) -> None:
    path = tmp_path / "obsmat.txt"
    rows = [f"{6 * k:.7e} 1.0 {0.5 * k:.7e} 0.0 3.0 1.25 0.0 0.0" for k in range(10)]
    path.write_text("\n".join(rows) + "\n")
    (t,) = load_trajectories_csv(path, dt_s=0.4)
    np.testing.assert_allclose(t.xy[:, 0], 0.5 * np.arange(10))
    np.testing.assert_allclose(t.xy[:, 1], 3.0)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("0\t1\t0.5\t2.0\n10\t1\tabc\t2.0\n", "row 2: x_m 'abc' is not a finite number"),
        ("0\t1\t0.5\t2.0\n10\t1\tnan\t2.0\n", "row 2: x_m 'nan' is not a finite number"),
        ("0\t1\t0.5\n10\t1\t0.6\n", "3 columns"),
        ("t_s,id,x_m,y_m\n0,p,1,1\nabc,p,2,2\n", "row 2: t_s 'abc' is not a finite number"),
        ("t_s,id,x_m,y_m\n0,p,1,1\n1,p,,2\n", "row 2: x_m '' is not a finite number"),
    ],
)
def test_bad_eth_ucy_text_is_one_error_naming_file_and_row(
    tmp_path: Path, text: str, expected: str
) -> None:
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_trajectories_csv(path)
    assert str(path) in str(err.value)
    assert expected in str(err.value)


def test_a_csv_keeps_its_ids_and_counts_time_from_its_first_row(tmp_path: Path) -> None:
    path = tmp_path / "scene.csv"
    path.write_text("t_s,id,x_m,y_m\n1000,7,0,0\n1002,7,2,0\n1001,alice,1,1\n1003,alice,1,3\n")
    got = {t.person: t for t in load_trajectories_csv(path)}
    assert set(got) == {"7", "alice"}
    assert got["7"].t0_s == 0.0 and got["alice"].t0_s == 1.0
    assert np.allclose(got["7"].at(1.0), [1.0, 0.0]) and np.allclose(
        got["alice"].at(2.0), [1.0, 2.0]
    )


def _outside_disc(radius_m: float):
    return lambda xy: np.hypot(xy[:, 0], xy[:, 1]) > radius_m


def test_a_hidden_route_goes_round_the_seen_area_at_its_margin() -> None:
    """Out at one side of a seen disc (radius 5 m), back in at the other: the walk leaves
    along its way out, keeps 1 m (less a grid cell) from the disc, and is about as short as
    the way round (2 x 1 m straight + half a circle of radius 6 m)."""
    route = hidden_route(
        np.array([5.0, 0.0]),
        np.array([-5.0, 0.0]),
        _outside_disc(5.0),
        away=(np.array([1.0, 0.0]), np.array([1.0, 0.0])),
    )
    assert np.allclose(route[0], [5.0, 0.0]) and np.allclose(route[-1], [-5.0, 0.0])
    inner = route[1:-1]
    assert np.hypot(inner[:, 0], inner[:, 1]).min() >= 6.0 - 0.25
    assert route[1][0] > 5.0 and abs(route[1][1]) < 1e-9  # straight out along +x
    length = float(np.linalg.norm(np.diff(route, axis=0), axis=1).sum())
    assert 2 + math.pi * 6 - 1.5 <= length <= 2 + math.pi * 6 + 1.5


def test_a_hidden_route_that_cannot_exist_raises() -> None:
    with pytest.raises(ValueError):
        hidden_route(np.array([5.0, 0.0]), np.array([-5.0, 0.0]), _outside_disc(1e6), pad_m=5.0)


@given(
    duration=st.floats(5.0, 60.0),
    speed=st.floats(0.5, 2.0),
    far=st.floats(1.0, 40.0),
)
def test_a_walked_route_is_at_most_the_walking_speed_and_ends_at_both_ends(
    duration: float, speed: float, far: float
) -> None:
    """Along a route the walk keeps its speed, standing the spare time; a route too long for
    the time is walked faster, never skipped."""
    route = np.array([[0.0, 0.0], [far, 0.0], [far, far]])
    xy = walk_route(route, duration, speed, 0.05)
    assert np.allclose(xy[0], route[0]) and np.allclose(xy[-1], route[-1], atol=1e-6)
    v = np.linalg.norm(np.diff(xy, axis=0), axis=1) / (duration / (len(xy) - 1))
    assert v.max() <= max(speed, 2 * far / duration) * 1.001 + 1e-9
