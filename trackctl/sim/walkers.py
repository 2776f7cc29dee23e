"""Pedestrian motion: random-waypoint walkers and external trajectories, sampled on a fine grid."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from trackctl.errors import InputError

__all__ = ["Trajectory", "random_waypoint", "load_trajectories_csv"]


@dataclass(frozen=True)
class Trajectory:
    """Positions of one person sampled at ``dt_s`` from ``t0_s``; NaN rows = not in the scene."""

    person: str
    t0_s: float
    dt_s: float
    xy: np.ndarray  # (n, 2) metres

    @property
    def t_s(self) -> np.ndarray:
        return self.t0_s + self.dt_s * np.arange(len(self.xy))

    def at(self, t_s: float | np.ndarray) -> np.ndarray:
        """Linearly interpolated position(s); NaN outside the trajectory."""
        t = np.atleast_1d(np.asarray(t_s, float))
        f = (t - self.t0_s) / self.dt_s
        i = np.clip(np.floor(f).astype(int), 0, len(self.xy) - 2)
        a = (f - i)[:, None]
        out = (1 - a) * self.xy[i] + a * self.xy[i + 1]
        out[(f < 0) | (f > len(self.xy) - 1)] = np.nan
        return out

    def velocity(self) -> np.ndarray:
        """Finite-difference velocity (n, 2), m/s."""
        return np.gradient(self.xy, self.dt_s, axis=0)


def random_waypoint(
    person: str,
    rng: np.random.Generator,
    size_m: tuple[float, float],
    duration_s: float,
    dt_s: float = 0.05,
    speed_range: tuple[float, float] = (0.5, 1.5),
    pause_s: tuple[float, float] = (0.0, 2.0),
    margin_m: float = 0.5,
) -> Trajectory:
    """Random-waypoint walk (Camp et al.): pick a point, walk to it at a random speed, pause."""
    n = int(math.ceil(duration_s / dt_s)) + 1
    lo = np.array([margin_m, margin_m])
    hi = np.array(size_m) - margin_m
    pos = rng.uniform(lo, hi)
    xy = np.empty((n, 2))
    k = 0
    # smooth the corners a little: people do not turn on the spot
    while k < n:
        target = rng.uniform(lo, hi)
        speed = rng.uniform(*speed_range)
        dist = float(np.linalg.norm(target - pos))
        steps = max(1, int(dist / (speed * dt_s)))
        for s in range(1, steps + 1):
            if k >= n:
                break
            xy[k] = pos + (target - pos) * s / steps
            k += 1
        pos = target
        for _ in range(int(rng.uniform(*pause_s) / dt_s)):
            if k >= n:
                break
            xy[k] = pos
            k += 1
    kernel = np.ones(9) / 9.0
    padded = np.pad(xy, ((4, 4), (0, 0)), mode="edge")
    smooth = np.column_stack([np.convolve(padded[:, j], kernel, mode="valid") for j in range(2)])
    return Trajectory(person, 0.0, dt_s, smooth)


def load_trajectories_csv(path: str | Path, dt_s: float = 0.05) -> list[Trajectory]:
    """Trajectories from a ``t_s,id,x_m,y_m`` CSV (or ETH/UCY ``frame id x y`` text, frames of
    0.04 s), resampled to ``dt_s`` by linear interpolation."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such trajectories file")
    text = path.read_text()
    first = text.lstrip().split("\n", 1)[0]
    if first.startswith("t_s"):
        df = pd.read_csv(path)
        missing = [c for c in ("t_s", "id", "x_m", "y_m") if c not in df.columns]
        if missing:
            raise InputError(f"{path}: trajectories CSV lacks column(s) {', '.join(missing)}")
    else:
        df = pd.read_csv(path, sep=r"\s+", header=None, names=["frame", "id", "x_m", "y_m"])
        df["t_s"] = df["frame"] / 10.0 * 0.4
    out = []
    for pid, g in df.groupby("id", sort=True):
        g = g.sort_values("t_s")
        t = g["t_s"].to_numpy(float)
        if len(t) < 2:
            continue
        grid = np.arange(t[0], t[-1] + 1e-9, dt_s)
        xy = np.column_stack([np.interp(grid, t, g["x_m"]), np.interp(grid, t, g["y_m"])])
        out.append(Trajectory(_person_id(pid), float(t[0]), dt_s, xy))
    if not out:
        raise InputError(f"{path}: no trajectory with two or more points")
    return out


def _person_id(pid: object) -> str:
    """``3.0`` (ETH/UCY ids are floats) -> ``"3"``; other ids (``"alice"``) as they are."""
    if isinstance(pid, int | float) and float(pid).is_integer():
        return str(int(pid))
    return str(pid)
