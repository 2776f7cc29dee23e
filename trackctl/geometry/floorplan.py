"""Floor plans: rooms, opaque walls and line of sight on the ground plane (metres, world z up).

Shared by the S-Mirror processor (which node cameras can see the robot) and the simulators that
render the same rooms; neither owns it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

__all__ = ["FloorPlan", "Wall", "line_of_sight", "three_rooms"]

Wall = tuple[tuple[float, float], tuple[float, float]]
"""An opaque wall: a segment between two ground points (x, y), metres."""

Room = tuple[float, float, float, float]


@dataclass(frozen=True)
class FloorPlan:
    """Rooms on a rectangle ``size_m``; ``walls`` are opaque segments (doorways are gaps)."""

    size_m: tuple[float, float]
    walls: tuple[Wall, ...]
    rooms: tuple[Room, ...]
    """Each room as (x0, y0, x1, y1), metres."""
    wall_height_m: float = 2.6

    @cached_property
    def wall_array(self) -> np.ndarray:
        """The walls as one (n, 2, 2) array (built once: line of sight is tested per frame)."""
        return np.asarray(self.walls, float).reshape(-1, 2, 2)

    def to_json(self) -> dict[str, object]:
        """The plan as a JSON object (metadata ``smirror/floorplan``)."""
        return {
            "size_m": list(self.size_m),
            "walls": [[list(a), list(b)] for a, b in self.walls],
            "rooms": [list(r) for r in self.rooms],
            "wall_height_m": self.wall_height_m,
        }

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> FloorPlan:
        """A plan from :meth:`to_json`'s object."""
        return cls(
            size_m=(float(obj["size_m"][0]), float(obj["size_m"][1])),
            walls=tuple(
                ((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))) for a, b in obj["walls"]
            ),
            rooms=tuple(_room(r) for r in obj["rooms"]),
            wall_height_m=float(obj.get("wall_height_m", 2.6)),
        )


def _room(values: Any) -> Room:
    x0, y0, x1, y1 = (float(v) for v in values)
    return (x0, y0, x1, y1)


def three_rooms() -> FloorPlan:
    """Three 9 x 8 m rooms in a row joined by 1.6 m doorways (the paper's three-room area)."""
    w, h, door = 9.0, 8.0, (3.2, 4.8)
    walls: list[Wall] = [
        ((0, 0), (3 * w, 0)),
        ((3 * w, 0), (3 * w, h)),
        ((3 * w, h), (0, h)),
        ((0, h), (0, 0)),
    ]
    for x in (w, 2 * w):
        walls.append(((x, 0), (x, door[0])))
        walls.append(((x, door[1]), (x, h)))
    rooms = tuple((i * w, 0.0, (i + 1) * w, h) for i in range(3))
    return FloorPlan((3 * w, h), tuple(walls), rooms)


def line_of_sight(a: np.ndarray, b: np.ndarray, walls: tuple[Wall, ...] | np.ndarray) -> bool:
    """True when the segment a-b (ground plane) crosses no wall (touching a wall end counts as
    clear, so a camera mounted in a corner sees past its own walls)."""
    if len(walls) == 0:
        return True
    w = np.asarray(walls, float)  # (n, 2, 2)
    p, r = np.asarray(a, float)[:2], np.asarray(b, float)[:2] - np.asarray(a, float)[:2]
    q, s = w[:, 0], w[:, 1] - w[:, 0]
    denom = r[0] * s[:, 1] - r[1] * s[:, 0]
    qp = q - p
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / denom
        u = (qp[:, 0] * r[1] - qp[:, 1] * r[0]) / denom
    eps = 1e-3
    hit = (np.abs(denom) > 1e-12) & (t > eps) & (t < 1 - eps) & (u > eps) & (u < 1 - eps)
    return not bool(hit.any())
