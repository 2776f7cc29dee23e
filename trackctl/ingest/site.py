"""A site file: the physical setup that logs do not carry (robot geometry, tags, lights, walls).

One documented YAML (metres, radians, world frame z up) replaces the metadata records that only
the simulators wrote. ``record --site FILE`` stores it in a log (as those records plus the file
as an attachment); ``smirror --site FILE`` and ``bridgeloc eval --site FILE`` lay it over the
log's own records (the file wins). Every key is optional; a processor names what it defaulted.

.. code-block:: yaml

    robots:
      r1:                    # the robot's NAME (/robot/NAME/odom)
        ticks_per_m: 2000    # wheel encoder ticks per metre of travel
        wheel_base_m: 0.30   # distance between the wheels
        led_height_m: 0.32   # S-Mirror LEDs above the floor
        led_front_m: 0.15    # front LED ahead of the wheel axis centre
        led_back_m: -0.15    # back LED, negative = behind
        front_hue: [45, 80]  # front LED colour: OpenCV hue range 0..180 (default green)
        back_hue: [135, 170] # back LED colour (default magenta); robots of one fleet should
                             # carry different pairs (e.g. [20, 34] yellow / [100, 125] blue)
    smirror:
      requesters: 1          # robots requesting images (ours + others)
      floorplan:             # walls block a node's view (line of sight)
        size_m: [27.0, 8.0]
        wall_height_m: 2.6
        walls: [[[0, 0], [27, 0]], [[9, 0], [9, 3.2]]]
        rooms: [[0, 0, 9, 8], [9, 0, 27, 8]]
    bridgeloc:
      robot: r1
      robot_camera: r1cam    # the camera on the robot (/r1cam/image)
      tag_n: 2               # N x N code cells of the rotation-symmetric tags
      tag_size_m: 0.30       # printed tag side
      tag_family: plain      # plain, or parity (N >= 3: two check cells catch misreads)
      border_ratio: 5.0
      ir_height_m: 0.65      # height of the IR light on the robot
      max_range_m: 4.5       # tags the robot sees farther than this are not used
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trackctl.errors import IncompleteInputWarning, InputError
from trackctl.ingest.limits import bounded_number, short_repr

if TYPE_CHECKING:
    from trackctl.geometry.floorplan import FloorPlan

__all__ = [
    "read_site",
    "site_records",
    "warn_site_defaults",
    "ROBOT_KEYS",
    "BRIDGELOC_KEYS",
    "SITE_RANGES",
    "MAX_WALLS",
    "record_number",
    "floorplan_from_json",
]

ROBOT_KEYS = ("ticks_per_m", "wheel_base_m", "led_height_m", "led_front_m", "led_back_m")
HUE_KEYS = ("front_hue", "back_hue")
BRIDGELOC_KEYS = {
    "robot": str,
    "robot_camera": str,
    "tag_n": int,
    "tag_size_m": float,
    "tag_family": str,
    "border_ratio": float,
    "ir_height_m": float,
    "max_range_m": float,
}
MAX_SITE_BYTES = 1 << 20
"""Largest site file read (1 MiB: a floor plan of :data:`MAX_WALLS` walls fits; PyYAML parses
1 MiB in a few seconds)."""
MAX_WALLS = 5000
"""Walls a floor plan may hold (a real floor has hundreds; line of sight tests every wall for
every node camera and frame, vectorised over the walls)."""
MAX_ROOMS = 1000
MAX_COORD_M = 1e5
"""Largest floor plan coordinate or size, metres (100 km)."""
SITE_RANGES: dict[str, tuple[float, float, bool]] = {
    "ticks_per_m": (1.0, 1e8, False),
    "wheel_base_m": (0.01, 20.0, False),
    "led_height_m": (0.0, 20.0, False),
    "led_front_m": (-20.0, 20.0, False),
    "led_back_m": (-20.0, 20.0, False),
    "tag_n": (2, 6, True),
    "tag_size_m": (0.01, 20.0, False),
    "border_ratio": (0.1, 100.0, False),
    "ir_height_m": (0.0, 20.0, False),
    "max_range_m": (0.01, 1e5, False),
    "requesters": (1, 100_000, True),
    "wall_height_m": (0.01, 1000.0, False),
}
"""Accepted range of every numeric site value (low, high, integer); one table for a site file
and for the metadata records a log carries (a log recorded elsewhere is checked the same way)."""
_SMIRROR_KEYS = ("requesters", "floorplan")
_TOP = ("robots", "smirror", "bridgeloc")


def _range_text(key: str) -> str:
    lo, hi, integer = SITE_RANGES[key]
    return f"expected {'an integer' if integer else 'a number'} in [{lo:g}, {hi:g}]"


def _number(value: Any, where: str, kind: type = float, key: str | None = None) -> str:
    """``value`` as its record text, checked against ``SITE_RANGES[key]`` when given."""
    expected = f"; {_range_text(key)}" if key in SITE_RANGES else ""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: {short_repr(value)} is not a number{expected}")
    if isinstance(value, int) and abs(value) > 1 << 53:
        raise InputError(f"{where}: {short_repr(value)} is out of range{expected}")
    if not math.isfinite(float(value)):
        raise InputError(f"{where}: {value!r} is not finite{expected}")
    if kind is int and float(value) != int(value):
        raise InputError(f"{where}: {value!r} is not an integer{expected}")
    if key in SITE_RANGES:
        lo, hi, _ = SITE_RANGES[key]
        if not lo <= float(value) <= hi:
            raise InputError(f"{where}: {value!r} is out of range{expected}")
    return str(int(value)) if kind is int else str(float(value))


def record_number(values: Mapping[str, str], key: str, default: float, where: str) -> float:
    """A numeric value of a metadata record (site file or log), ``default`` when absent.

    Raises:
        InputError: not a number, not finite, or outside ``SITE_RANGES[key]`` (naming
            ``where``, the key and the expected range).
    """
    if key not in values:
        return default
    text = values[key]
    try:
        value: float = float(text)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{where}: {key}={short_repr(text)} is not a number") from None
    integer = key in SITE_RANGES and SITE_RANGES[key][2]
    _number(value, f"{where}: {key}", int if integer else float, key)
    return value


def _point(value: Any, where: str) -> tuple[float, float]:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
        raise InputError(f"{where}: {short_repr(value)} is not a point [X, Y] (metres)")
    x, y = (
        bounded_number(v, f"{where}[{i}]", -MAX_COORD_M, MAX_COORD_M) for i, v in enumerate(value)
    )
    return x, y


def _seq(value: Any, where: str, limit: int, what: str) -> Sequence[Any]:
    if not isinstance(value, Sequence) or isinstance(value, str):
        raise InputError(f"{where}: expected a list of {what}, got {type(value).__name__}")
    if len(value) > limit:
        raise InputError(
            f"{where}: {len(value):,} {what}; expected at most {limit:,} (the limit of a floor "
            "plan)"
        )
    return value


def floorplan_from_json(obj: Any, where: str) -> FloorPlan:
    """A floor plan from its JSON object (site file or ``smirror/floorplan`` record), every
    value checked: ``size_m`` two sizes in (0, 1e5] m, at most :data:`MAX_WALLS` walls of two
    points each and :data:`MAX_ROOMS` rooms ``[X0, Y0, X1, Y1]``, coordinates within 1e5 m.

    Raises:
        InputError: naming ``where``, the key (and index) and what was expected.
    """
    from trackctl.geometry.floorplan import FloorPlan

    plan = _mapping(obj, where)
    _known(plan, ("size_m", "walls", "rooms", "wall_height_m"), where)
    for key in ("size_m", "walls"):
        if key not in plan:
            raise InputError(f"{where}: {key} is missing")
    size = plan["size_m"]
    if not isinstance(size, Sequence) or isinstance(size, str) or len(size) != 2:
        raise InputError(
            f"{where}.size_m: {short_repr(size)} is not a size [X, Y]; expected two numbers in "
            f"(0, {MAX_COORD_M:g}] m"
        )
    sx, sy = (
        bounded_number(v, f"{where}.size_m[{i}]", 1e-3, MAX_COORD_M) for i, v in enumerate(size)
    )
    walls = tuple(
        (
            _point(_pair(w, f"{where}.walls[{i}]")[0], f"{where}.walls[{i}][0]"),
            _point(_pair(w, f"{where}.walls[{i}]")[1], f"{where}.walls[{i}][1]"),
        )
        for i, w in enumerate(_seq(plan["walls"], f"{where}.walls", MAX_WALLS, "walls"))
    )
    rooms = tuple(
        _room(r, f"{where}.rooms[{i}]")
        for i, r in enumerate(_seq(plan.get("rooms", []), f"{where}.rooms", MAX_ROOMS, "rooms"))
    )
    height = float(
        _number(plan.get("wall_height_m", 2.6), f"{where}.wall_height_m", float, "wall_height_m")
    )
    return FloorPlan((sx, sy), walls, rooms, height)


def _pair(value: Any, where: str) -> Sequence[Any]:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
        raise InputError(f"{where}: {short_repr(value)} is not a wall [[X0, Y0], [X1, Y1]]")
    return value


def _room(value: Any, where: str) -> tuple[float, float, float, float]:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 4:
        raise InputError(f"{where}: {short_repr(value)} is not a room [X0, Y0, X1, Y1]")
    x0, y0, x1, y1 = (
        bounded_number(v, f"{where}[{i}]", -MAX_COORD_M, MAX_COORD_M) for i, v in enumerate(value)
    )
    return x0, y0, x1, y1


def _hue_range(value: Any, where: str) -> str:
    """An OpenCV hue range [LO, HI] (0..180) as the record's ``LO-HI``."""
    if (
        not isinstance(value, Sequence)
        or isinstance(value, str)
        or len(value) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    ):
        raise InputError(
            f"{where}: {short_repr(value)} is not a hue range [LO, HI] (OpenCV hue, 0..180)"
        )
    lo, hi = value
    if not 0 <= lo <= hi <= 180:
        raise InputError(f"{where}: {value!r}: need 0 <= LO <= HI <= 180")
    return f"{lo}-{hi}"


def _mapping(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise InputError(f"{where}: expected a mapping, got {type(value).__name__}")
    return value


def _known(values: Mapping[str, Any], allowed: Any, where: str) -> None:
    unknown = sorted(set(values) - set(allowed))
    if unknown:
        raise InputError(
            f"{where}: unknown key {unknown[0]!r} (known: {', '.join(sorted(allowed))})"
        )


def _robot_records(robots: Any, path: str | Path) -> dict[str, dict[str, str]]:
    """``robot/NAME`` records of the ``robots`` section."""
    out: dict[str, dict[str, str]] = {}
    for name, robot in _mapping(robots, f"{path}: robots").items():
        where = f"{path}: robots.{name}"
        if not isinstance(name, str) or not name or "/" in name:
            raise InputError(f"{where}: a robot NAME must be a non-empty string without '/'")
        robot = _mapping(robot, where)
        _known(robot, ROBOT_KEYS + HUE_KEYS, where)
        out[f"robot/{name}"] = {
            k: _hue_range(v, f"{where}.{k}") if k in HUE_KEYS else _robot_value(robot, k, where)
            for k, v in robot.items()
        }
    return out


def _robot_value(robot: Mapping[str, Any], key: str, where: str) -> str:
    value = robot[key]
    if key in ("ticks_per_m", "wheel_base_m"):
        positive = isinstance(value, int | float) and not isinstance(value, bool) and value <= 0
        if positive:
            raise InputError(f"{where}.{key}: must be positive, got {value!r}; {_range_text(key)}")
    return _number(value, f"{where}.{key}", float, key)


def _smirror_records(section: Any, path: str | Path) -> dict[str, dict[str, str]]:
    """``smirror/requesters`` and ``smirror/floorplan`` records of the ``smirror`` section."""
    smirror = _mapping(section, f"{path}: smirror")
    _known(smirror, _SMIRROR_KEYS, f"{path}: smirror")
    out: dict[str, dict[str, str]] = {}
    if "requesters" in smirror:
        value = smirror["requesters"]
        if isinstance(value, int) and not isinstance(value, bool) and value < 1:
            raise InputError(f"{path}: smirror.requesters: must be >= 1, got {value}")
        count = _number(value, f"{path}: smirror.requesters", int, "requesters")
        out["smirror/requesters"] = {"count": count}
    if "floorplan" in smirror:
        plan = floorplan_from_json(smirror["floorplan"], f"{path}: smirror.floorplan")
        out["smirror/floorplan"] = {"plan": json.dumps(plan.to_json())}
    return out


def _bridgeloc_records(section: Any, path: str | Path) -> dict[str, dict[str, str]]:
    """The ``bridgeloc`` record (none when the section is empty or absent)."""
    bl = _mapping(section, f"{path}: bridgeloc")
    _known(bl, BRIDGELOC_KEYS, f"{path}: bridgeloc")
    if not bl:
        return {}
    rec = {}
    for k, v in bl.items():
        kind = BRIDGELOC_KEYS[k]
        where = f"{path}: bridgeloc.{k}"
        if kind is str:
            if not isinstance(v, str) or not v:
                raise InputError(f"{where}: expected a name, got {v!r}")
            rec[k] = v
        else:
            rec[k] = _number(v, where, kind, k)
    return {"bridgeloc": rec}


def site_records(data: Any, path: str | Path = "site") -> dict[str, dict[str, str]]:
    """A parsed site file as the metadata records processors read.

    Raises:
        InputError: an unknown key, a value of the wrong type (names the file and key path).
    """
    top = _mapping(data if data is not None else {}, str(path))
    _known(top, _TOP, str(path))
    return {
        **_robot_records(top.get("robots", {}), path),
        **_smirror_records(top.get("smirror", {}), path),
        **_bridgeloc_records(top.get("bridgeloc", {}), path),
    }


def read_site(path: str | Path) -> dict[str, dict[str, str]]:
    """The metadata records of a site file.

    Raises:
        InputError: the file is missing, is not YAML, or does not fit the layout above.
    """
    from trackctl.ingest.limits import load_yaml, read_bounded

    path = Path(path)
    # stat before open: a FIFO or device is refused, not waited on; size bounded before reading
    data = load_yaml(read_bounded(path, f"--site {path}", MAX_SITE_BYTES), f"--site {path}")
    return site_records(data, path)


def warn_site_defaults(log: str | Path, used: Sequence[str]) -> None:
    """One warning naming every site value a processor defaulted (``used``: ``key=value``
    groups); nothing when it defaulted none."""
    if used:
        warnings.warn(
            f"{log}: site defaults used: {'; '.join(used)} (give them with --site)",
            IncompleteInputWarning,
            stacklevel=3,
        )
