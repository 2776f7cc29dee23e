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
from typing import Any

from trackctl.errors import IncompleteInputWarning, InputError

__all__ = [
    "read_site",
    "site_records",
    "warn_site_defaults",
    "ROBOT_KEYS",
    "BRIDGELOC_KEYS",
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
MAX_SITE_BYTES = 4 << 20
"""Largest site file read (4 MiB)."""
_SMIRROR_KEYS = ("requesters", "floorplan")
_TOP = ("robots", "smirror", "bridgeloc")


def _number(value: Any, where: str, kind: type = float) -> str:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: {value!r} is not a number")
    if not math.isfinite(float(value)):
        raise InputError(f"{where}: {value!r} is not finite")
    if kind is int and float(value) != int(value):
        raise InputError(f"{where}: {value!r} is not an integer")
    return str(int(value)) if kind is int else str(float(value))


def _hue_range(value: Any, where: str) -> str:
    """An OpenCV hue range [LO, HI] (0..180) as the record's ``LO-HI``."""
    if (
        not isinstance(value, Sequence)
        or isinstance(value, str)
        or len(value) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    ):
        raise InputError(f"{where}: {value!r} is not a hue range [LO, HI] (OpenCV hue, 0..180)")
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
            k: _hue_range(v, f"{where}.{k}") if k in HUE_KEYS else _number(v, f"{where}.{k}")
            for k, v in robot.items()
        }
        for k in ("ticks_per_m", "wheel_base_m"):
            if k in robot and float(robot[k]) <= 0:
                raise InputError(f"{where}.{k}: must be positive, got {robot[k]!r}")
    return out


def _smirror_records(section: Any, path: str | Path) -> dict[str, dict[str, str]]:
    """``smirror/requesters`` and ``smirror/floorplan`` records of the ``smirror`` section."""
    smirror = _mapping(section, f"{path}: smirror")
    _known(smirror, _SMIRROR_KEYS, f"{path}: smirror")
    out: dict[str, dict[str, str]] = {}
    if "requesters" in smirror:
        count = _number(smirror["requesters"], f"{path}: smirror.requesters", int)
        if int(count) < 1:
            raise InputError(f"{path}: smirror.requesters: must be >= 1, got {count}")
        out["smirror/requesters"] = {"count": count}
    if "floorplan" in smirror:
        from trackctl.geometry.floorplan import FloorPlan

        plan = _mapping(smirror["floorplan"], f"{path}: smirror.floorplan")
        try:
            FloorPlan.from_json(dict(plan))
        except (ValueError, KeyError, TypeError) as err:
            raise InputError(f"{path}: smirror.floorplan: {err}") from err
        out["smirror/floorplan"] = {"plan": json.dumps(dict(plan))}
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
            rec[k] = _number(v, where, kind)
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
