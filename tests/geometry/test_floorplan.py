"""Floor plans: JSON round trip and line of sight (property tests)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from trackctl.geometry.floorplan import FloorPlan, line_of_sight, three_rooms

coord = st.floats(min_value=-50, max_value=50, allow_nan=False)
point = st.tuples(coord, coord)


def test_json_round_trip() -> None:
    plan = three_rooms()
    assert FloorPlan.from_json(plan.to_json()) == plan


@given(point, point)
def test_no_walls_means_clear(a: tuple[float, float], b: tuple[float, float]) -> None:
    assert line_of_sight(np.array(a), np.array(b), ())


@given(point, point)
def test_line_of_sight_is_symmetric(a: tuple[float, float], b: tuple[float, float]) -> None:
    walls = three_rooms().walls
    assert line_of_sight(np.array(a), np.array(b), walls) == line_of_sight(
        np.array(b), np.array(a), walls
    )


@given(st.floats(0.5, 8.5), st.floats(0.5, 7.5), st.floats(18.5, 26.5), st.floats(0.5, 7.5))
def test_a_wall_between_rooms_blocks_unless_through_doorways(
    x0: float, y0: float, x1: float, y1: float
) -> None:
    # from room 1 to room 3 the segment crosses x = 9 and x = 18 at heights set by the endpoints
    walls = three_rooms().walls
    ya = y0 + (y1 - y0) * (9 - x0) / (x1 - x0)
    yb = y0 + (y1 - y0) * (18 - x0) / (x1 - x0)
    through_doors = 3.2 < ya < 4.8 and 3.2 < yb < 4.8
    clear = line_of_sight(np.array([x0, y0]), np.array([x1, y1]), walls)
    if (
        abs(ya - 3.2) > 1e-2
        and abs(ya - 4.8) > 1e-2
        and abs(yb - 3.2) > 1e-2
        and abs(yb - 4.8) > 1e-2
    ):
        assert clear == through_doors
