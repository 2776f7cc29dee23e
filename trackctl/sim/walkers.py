"""Pedestrian motion: random-waypoint walkers and external trajectories, sampled on a fine grid."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import ndimage, sparse
from scipy.sparse import csgraph

from trackctl.errors import InputError

__all__ = [
    "Trajectory",
    "random_waypoint",
    "random_waypoint_crowd",
    "load_trajectories_csv",
    "longest_walkers",
    "hidden_route",
    "walk_route",
]


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


@dataclass(frozen=True, slots=True)
class SocialForce:
    """Collision avoidance of a walking crowd: Helbing and Molnar's social force model (Phys. Rev.
    E 51, 1995), with the parameters Helbing, Farkas and Vicsek fitted to pedestrian flows
    (Nature 407, 2000) and Moussaid et al. measured in controlled experiments (Proc. R. Soc. B
    276, 2009): a person relaxes to their desired velocity over ``relax_s`` and is pushed
    away from everyone else by ``strength`` exp((2 ``radius_m`` - d) / ``range_m``), weighted by
    ``anisotropy`` for people behind them (one reacts to what is ahead)."""

    strength_mps2: float = 2.1
    range_m: float = 0.3
    radius_m: float = 0.25
    relax_s: float = 0.5
    anisotropy: float = 0.3
    reach_m: float = 3.0
    """Others farther than this exert no force (exp(-8) of the contact force)."""


def random_waypoint_crowd(
    people: list[str],
    rng: np.random.Generator,
    size_m: tuple[float, float],
    duration_s: float,
    dt_s: float = 0.05,
    speed_range: tuple[float, float] = (0.5, 1.5),
    pause_s: tuple[float, float] = (0.0, 2.0),
    margin_m: float = 0.5,
    force: SocialForce | None = None,
) -> list[Trajectory]:
    """Random-waypoint walkers (:func:`random_waypoint`'s plan: a point, a speed, a pause) that
    avoid each other as people do (:class:`SocialForce`), simulated together. Independent
    random-waypoint walkers pass through each other: in a 20 x 15 m lobby with 40 of them, 15%
    of the time someone is within 0.5 m of another person, which real walkers keep for groups.

    Hand-written integration (explicit Euler at ``dt_s``, all pairs at once with numpy): no
    well-kept Python package simulates pedestrian crowds without a heavy framework."""
    f = force or SocialForce()
    n = len(people)
    steps = int(math.ceil(duration_s / dt_s)) + 1
    lo = np.array([margin_m, margin_m])
    hi = np.array(size_m) - margin_m
    pos = rng.uniform(lo, hi, (n, 2))
    target = rng.uniform(lo, hi, (n, 2))
    speed = rng.uniform(*speed_range, n)
    wait = np.zeros(n)  # seconds left of a pause
    vel = np.zeros((n, 2))
    out = np.empty((steps, n, 2))
    eye = np.eye(n, dtype=bool)
    for k in range(steps):
        out[k] = pos
        to = target - pos
        dist = np.linalg.norm(to, axis=1)
        arrived = (dist < 0.3) & (wait <= 0)
        for i in np.flatnonzero(arrived):
            # at the waypoint: pause, then the next point at a new speed
            wait[i] = rng.uniform(*pause_s) + 1e-9
            target[i] = rng.uniform(lo, hi)
            speed[i] = rng.uniform(*speed_range)
        pausing = wait > 0
        wait = np.maximum(wait - dt_s, 0.0)
        to = target - pos
        dist = np.maximum(np.linalg.norm(to, axis=1), 1e-9)
        # slow down over the last metre; stand while pausing
        want = to / dist[:, None] * np.minimum(speed, dist / f.relax_s)[:, None]
        want[pausing] = 0.0
        diff = pos[:, None, :] - pos[None, :, :]
        d = np.linalg.norm(diff, axis=2)
        d[eye] = np.inf
        near = d < f.reach_m
        unit = np.where(near[..., None], diff / np.maximum(d, 1e-9)[..., None], 0.0)
        push = np.where(near, f.strength_mps2 * np.exp((2 * f.radius_m - d) / f.range_m), 0.0)
        # anisotropy: full weight for someone ahead (against the walking direction), less behind
        heading = vel / np.maximum(np.linalg.norm(vel, axis=1), 1e-9)[:, None]
        cos = -np.einsum("ijk,ik->ij", unit, heading)
        weight = f.anisotropy + (1 - f.anisotropy) * (1 + cos) / 2
        acc = (want - vel) / f.relax_s + np.einsum("ij,ijk->ik", push * weight, unit)
        vel = vel + acc * dt_s
        cap = 1.3 * np.maximum(speed, 0.5)
        fast = np.linalg.norm(vel, axis=1)
        vel *= np.minimum(1.0, cap / np.maximum(fast, 1e-9))[:, None]
        pos = np.clip(pos + vel * dt_s, lo / 2, np.array(size_m) - lo / 2)
    return [Trajectory(p, 0.0, dt_s, out[:, i].copy()) for i, p in enumerate(people)]


ETH_UCY_PERIOD_S = 0.4
"""ETH/UCY scenes are annotated at 2.5 Hz whatever their video's frame rate: frame numbers step
by 10 in the UCY scenes and ``biwi_hotel`` (25 fps video), by 6 in ``biwi_eth`` (15 fps)."""


def load_trajectories_csv(path: str | Path, dt_s: float = 0.05) -> list[Trajectory]:
    """Trajectories from a ``t_s,id,x_m,y_m`` CSV, or ETH/UCY text resampled to ``dt_s`` by
    linear interpolation.

    ETH/UCY text is ``frame id x y`` (tabs, spaces or commas), or the ETH ``obsmat.txt`` layout
    ``frame id x z y vx vz vy``. Its annotations are 0.4 s apart, and the frame step between them
    is read from the file (the most common step between a person's consecutive frames), so a
    scene whose video ran at another rate keeps its true walking speeds. Times count from the
    first annotation (a CSV's first ``t_s``, ETH/UCY's first frame): a file whose frames start
    late (`biwi_eth` at frame 780, a split of a longer recording) is not an empty scene."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such trajectories file")
    text = path.read_text()
    first = text.lstrip().split("\n", 1)[0]
    if first.startswith("t_s"):
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
        missing = [c for c in ("t_s", "id", "x_m", "y_m") if c not in df.columns]
        if missing:
            raise InputError(f"{path}: trajectories CSV lacks column(s) {', '.join(missing)}")
        _typed(df, ("t_s", "x_m", "y_m"), path)
        df["t_s"] = df["t_s"] - df["t_s"].min()
    else:
        df = _read_eth_ucy(path, sep="," if "," in first else r"\s+")
        step = _annotation_step(df)
        # frame numbers are an index into a video: times count from the first annotation
        df["t_s"] = (df["frame"] - df["frame"].min()) / step * ETH_UCY_PERIOD_S
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


def _read_eth_ucy(path: Path, sep: str) -> pd.DataFrame:
    """``frame id x y`` rows (4 columns, or 8 of ETH's ``obsmat.txt``), every value a number."""
    raw = pd.read_csv(path, sep=sep, header=None, dtype=str, keep_default_na=False)
    columns = {4: (0, 1, 2, 3), 8: (0, 1, 2, 4)}.get(raw.shape[1])
    if columns is None:
        raise InputError(
            f"{path}: {raw.shape[1]} columns; ETH/UCY trajectories have 4 (frame id x y) "
            "or 8 (obsmat: frame id x z y vx vz vy)"
        )
    df = raw.iloc[:, list(columns)].copy()
    df.columns = ["frame", "id", "x_m", "y_m"]
    _typed(df, ("frame", "x_m", "y_m"), path)
    return df


def _typed(df: pd.DataFrame, names: tuple[str, ...], path: Path) -> None:
    """Text rows typed in place: columns ``names`` as floats (the first value that is not a
    finite number is an error naming the file, the data row from 1 and the column), and the ids
    as numbers when they all are (ETH/UCY's are; any other id is kept as written)."""
    for name in names:
        values = pd.to_numeric(df[name], errors="coerce")
        bad = values.isna() | ~np.isfinite(values.to_numpy(float, na_value=np.nan))
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise InputError(
                f"{path}: row {row + 1}: {name} {df[name].iloc[row]!r} is not a finite number"
            )
        df[name] = values.astype(float)
    ids = pd.to_numeric(df["id"], errors="coerce")
    if ids.notna().all():
        df["id"] = ids.astype(float)


def _annotation_step(df: pd.DataFrame) -> float:
    """Frames between consecutive annotations: the most common step between a person's
    consecutive frames (a person missing from an annotation makes a double step, which is
    rarer). 10 when no person has two frames."""
    steps = df.sort_values(["id", "frame"]).groupby("id")["frame"].diff().to_numpy(float)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    if steps.size == 0:
        return 10.0
    values, counts = np.unique(np.round(steps, 6), return_counts=True)
    return float(values[np.argmax(counts)])


def longest_walkers(
    trajs: list[Trajectory], until_s: float, k: int, rank: int = 0
) -> tuple[str, ...]:
    """The ``k`` people who walk farthest before ``until_s``, after the ``rank`` who walk
    farther still (equal distances keep the order of ``trajs``)."""
    length = {}
    for t in trajs:
        xy = t.xy[t.t_s <= until_s]
        length[t.person] = float(np.nansum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))
    return tuple(sorted(length, key=lambda p: -length[p])[rank : rank + k])


def _person_id(pid: object) -> str:
    """``3.0`` (ETH/UCY ids are floats) -> ``"3"``; other ids (``"alice"``) as they are."""
    if isinstance(pid, int | float) and float(pid).is_integer():
        return str(int(pid))
    return str(pid)


def hidden_route(
    a: np.ndarray,
    b: np.ndarray,
    hidden: Callable[[np.ndarray], np.ndarray],
    *,
    away: tuple[np.ndarray, np.ndarray] | None = None,
    margin_m: float = 1.0,
    cell_m: float = 0.25,
    pad_m: float = 20.0,
) -> np.ndarray:
    """The shortest walk (a polyline, (n, 2) metres, from ``a`` to ``b``) that stays where
    nobody sees it: ``hidden`` maps ground points (k, 2) to a mask of those no camera sees, and
    the walk keeps ``margin_m`` from every seen point, except where it leaves ``a`` and comes in
    at ``b`` (a person who walks out of view at ``a`` and back in at ``b``).

    ``away`` = unit directions (out at ``a``, in at ``b``): the walk goes straight out along
    the first until it is ``margin_m`` into hiding, and comes in along the second the same way;
    None: straight to the nearest hidden spot. Shortest on a ``cell_m`` grid over the box of
    both ends grown by ``pad_m`` (scipy's Dijkstra, 8 neighbours). Raises ``ValueError`` when no
    hidden walk joins them inside that box."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    lo = np.minimum(a, b) - pad_m
    nx, ny = (np.ceil((np.maximum(a, b) + pad_m - lo) / cell_m).astype(int) + 1).tolist()
    gx, gy = np.meshgrid(
        lo[0] + cell_m * np.arange(nx), lo[1] + cell_m * np.arange(ny), indexing="ij"
    )
    centres = np.column_stack([gx.ravel(), gy.ravel()])
    seen = ~np.asarray(hidden(centres), bool).reshape(nx, ny)
    free = ndimage.distance_transform_edt(~seen) * cell_m >= margin_m
    ends = []
    for p, u in ((a, None if away is None else away[0]), (b, None if away is None else -away[1])):
        ends.append(_into_hiding(p, u, free, lo, cell_m))
    if not free.any():
        raise ValueError("no hidden ground near the route's ends")
    idx = np.arange(nx * ny).reshape(nx, ny)
    rows, cols, wts = [], [], []
    for dx, dy in ((1, 0), (0, 1), (1, 1), (1, -1)):
        i0, i1, j0, j1 = max(0, -dx), nx - max(0, dx), max(0, -dy), ny - max(0, dy)
        src, dst = idx[i0:i1, j0:j1], idx[i0 + dx : i1 + dx, j0 + dy : j1 + dy]
        ok = free.ravel()[src.ravel()] & free.ravel()[dst.ravel()]
        rows.append(src.ravel()[ok])
        cols.append(dst.ravel()[ok])
        wts.append(np.full(int(ok.sum()), cell_m * math.hypot(dx, dy)))
    graph = sparse.coo_matrix(
        (np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(nx * ny,) * 2
    ).tocsr()
    start, goal = (int(idx[c]) for c, _ in ends)
    dist, pred = csgraph.dijkstra(graph, directed=False, indices=start, return_predecessors=True)
    if not np.isfinite(dist[goal]):
        raise ValueError("no hidden walk joins the route's ends")
    chain = [goal]
    while chain[-1] != start:
        chain.append(int(pred[chain[-1]]))
    mid = centres[chain[::-1]]
    return np.vstack([a, ends[0][1], mid, ends[1][1][::-1], b])


def _into_hiding(
    p: np.ndarray, u: np.ndarray | None, free: np.ndarray, lo: np.ndarray, cell_m: float
) -> tuple[tuple[int, int], np.ndarray]:
    """The first free cell (index) from ``p`` straight along ``u`` (or the nearest one) and
    the points walked to reach it ((k, 2), ``p`` excluded)."""
    nx, ny = free.shape
    if u is not None:
        u = u / max(float(np.linalg.norm(u)), 1e-12)
        for s in np.arange(cell_m, cell_m * (nx + ny), cell_m / 2):
            q = p + s * u
            i, j = np.round((q - lo) / cell_m).astype(int).tolist()
            if not (0 <= i < nx and 0 <= j < ny):
                break
            if free[i, j]:
                return (i, j), np.array([q])
    fi, fj = np.nonzero(free)
    if len(fi) == 0:
        raise ValueError("no hidden ground near the route's ends")
    c = np.column_stack([fi, fj]) * cell_m + lo
    k = int(np.argmin(np.linalg.norm(c - p, axis=1)))
    return (int(fi[k]), int(fj[k])), c[k : k + 1]


def walk_route(route: np.ndarray, duration_s: float, speed_mps: float, dt_s: float) -> np.ndarray:
    """Positions ((n, 2), every ``dt_s`` over ``duration_s``, both ends included) of a walk
    along the polyline ``route`` at ``speed_mps``, standing still half way for the time the
    walk does not need; faster when the route is too long for the time."""
    seg = np.linalg.norm(np.diff(route, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(arc[-1])
    n = max(2, int(round(duration_s / dt_s)) + 1)
    t = np.linspace(0.0, duration_s, n)
    walk_s = min(duration_s, total / max(speed_mps, 1e-9))
    v = total / walk_s if walk_s > 0 else 0.0
    rest = duration_s - walk_s
    half = walk_s / 2
    s = np.where(t <= half, v * t, np.where(t <= half + rest, v * half, v * (t - rest)))
    keep = np.concatenate([[True], seg > 0])
    return np.column_stack([np.interp(s, arc[keep], route[keep, j]) for j in (0, 1)])
