"""Multi-object tracking metrics on the ground plane: error, CLEAR MOT (MOTA, ID switches), IDF1.

Frames are dicts ``id -> (x, y)`` of ground truth and hypotheses at the same instants. A pair
matches when closer than ``threshold_m``. Ground-truth ids in ``ignore`` are don't-care: a
hypothesis near one of them (and matched to nothing else) is neither a true nor a false positive,
which lets an evaluation focus on phone carriers without penalising tracks on other people.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = ["MotAccumulator", "MotSummary", "InitialIdentity"]

Frame = Mapping[str, tuple[float, float]]


@dataclass(frozen=True, slots=True)
class MotSummary:
    """CLEAR MOT and identity metrics."""

    frames: int
    gt: int
    matches: int
    misses: int
    false_positives: int
    id_switches: int
    mota: float
    motp_m: float
    idf1: float
    idp: float
    idr: float


class MotAccumulator:
    """Accumulates frame-by-frame matches (CLEAR MOT procedure: previous matches are kept while
    they stay within the threshold, the rest is solved by the Hungarian method)."""

    def __init__(self, threshold_m: float = 1.0) -> None:
        self.threshold = threshold_m
        self.frames = 0
        self.gt = self.matches = self.misses = self.fp = self.switches = 0
        self.dist_sum = 0.0
        self._last: dict[str, str] = {}
        self._co: dict[tuple[str, str], int] = defaultdict(int)
        self._gt_count: dict[str, int] = defaultdict(int)
        self._hyp_count: dict[str, int] = defaultdict(int)

    def update(self, gt: Frame, hyp: Frame, ignore: Iterable[str] = ()) -> dict[str, str]:
        """Add one frame; returns the gt -> hypothesis matches of this frame."""
        ignore = set(ignore)
        self.frames += 1
        g_ids = [g for g in gt if g not in ignore]
        h_ids = list(hyp)
        g_xy = np.array([gt[g] for g in g_ids]).reshape(-1, 2)
        h_xy = np.array([hyp[h] for h in h_ids]).reshape(-1, 2)
        d = (
            np.linalg.norm(g_xy[:, None, :] - h_xy[None, :, :], axis=2)
            if len(g_ids) and len(h_ids)
            else np.zeros((len(g_ids), len(h_ids)))
        )
        matches = self._match(g_ids, h_ids, hyp, d)
        for g, h in matches.items():
            if g in self._last and self._last[g] != h:
                self.switches += 1
            self._last[g] = h
            self.dist_sum += float(d[g_ids.index(g), h_ids.index(h)])
        ignored_h = self._ignored(gt, hyp, h_ids, set(matches.values()), ignore)
        self.gt += len(g_ids)
        self.matches += len(matches)
        self.misses += len(g_ids) - len(matches)
        self.fp += len(h_ids) - len(matches) - len(ignored_h)
        # identity counts: any pair within the threshold counts towards IDTP candidates
        for gi, g in enumerate(g_ids):
            self._gt_count[g] += 1
            for hi, h in enumerate(h_ids):
                if d[gi, hi] < self.threshold:
                    self._co[(g, h)] += 1
        for h in h_ids:
            if h not in ignored_h:
                self._hyp_count[h] += 1
        return matches

    def _match(
        self, g_ids: list[str], h_ids: list[str], hyp: Frame, d: np.ndarray
    ) -> dict[str, str]:
        """CLEAR-MOT matching: last frame's still-valid correspondences first, then a global
        assignment (scipy's linear_sum_assignment) of the rest within the threshold."""
        matches: dict[str, str] = {}
        for gi, g in enumerate(g_ids):
            h = self._last.get(g)
            if h is not None and h in hyp and h not in matches.values():
                hi = h_ids.index(h)
                if d[gi, hi] < self.threshold:
                    matches[g] = h
        free_g = [gi for gi, g in enumerate(g_ids) if g not in matches]
        used = set(matches.values())
        free_h = [hi for hi, h in enumerate(h_ids) if h not in used]
        if free_g and free_h:
            sub = d[np.ix_(free_g, free_h)]
            cost = np.where(sub < self.threshold, sub, 1e6)
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols, strict=True):
                if cost[r, c] < 1e6:
                    matches[g_ids[free_g[r]]] = h_ids[free_h[c]]
        return matches

    def _ignored(
        self, gt: Frame, hyp: Frame, h_ids: list[str], matched_h: set[str], ignore: set[str]
    ) -> set[str]:
        """Unmatched hypotheses on a don't-care person (not false positives)."""
        ignored_h: set[str] = set()
        if not ignore:
            return ignored_h
        for h in h_ids:
            if h in matched_h:
                continue
            hx = np.array(hyp[h])
            if any(
                np.linalg.norm(hx - np.array(gt[g])) < self.threshold for g in ignore if g in gt
            ):
                ignored_h.add(h)
        return ignored_h

    def summary(self) -> MotSummary:
        """The metrics over every frame so far."""
        gts = sorted(self._gt_count)
        hyps = sorted(self._hyp_count)
        idtp = 0
        if gts and hyps:
            m = np.zeros((len(gts), len(hyps)))
            gi = {g: i for i, g in enumerate(gts)}
            hi = {h: i for i, h in enumerate(hyps)}
            for (g, h), n in self._co.items():
                if h in hi:
                    m[gi[g], hi[h]] = n
            rows, cols = linear_sum_assignment(-m)
            idtp = int(m[rows, cols].sum())
        n_gt = sum(self._gt_count.values())
        n_hyp = sum(self._hyp_count.values())
        idfn, idfp = n_gt - idtp, n_hyp - idtp
        idf1 = 2 * idtp / (2 * idtp + idfp + idfn) if (idtp + idfp + idfn) else 1.0
        mota = 1.0 - (self.misses + self.fp + self.switches) / self.gt if self.gt else 1.0
        return MotSummary(
            frames=self.frames,
            gt=self.gt,
            matches=self.matches,
            misses=self.misses,
            false_positives=self.fp,
            id_switches=self.switches,
            mota=mota,
            motp_m=self.dist_sum / self.matches if self.matches else 0.0,
            idf1=idf1,
            idp=idtp / n_hyp if n_hyp else 1.0,
            idr=idtp / n_gt if n_gt else 1.0,
        )


class InitialIdentity:
    """Who a person is, for a tracker that never names people (visual-only baselines).

    Each person is given the hypothesis nearest to them (within ``threshold_m``) when they are
    first seen, as an entry check-point would, and that hypothesis is followed from then on: a
    swap makes the error jump, a lost track leaves the person unfollowed. This is how the
    dissertation scores V-AF and V-IVT (Table 3.7, Fig. 3.7).
    """

    def __init__(self, threshold_m: float = 1.0) -> None:
        self.threshold_m = threshold_m
        self.assigned: dict[str, str] = {}

    def error(self, person: str, xy: tuple[float, float], hyp: Frame) -> float | None:
        """Distance from ``person`` at ``xy`` to the hypothesis they follow, or None."""
        h = self.assigned.get(person)
        if h is None:
            taken = set(self.assigned.values())
            free = [
                (float(np.hypot(p[0] - xy[0], p[1] - xy[1])), k)
                for k, p in hyp.items()
                if k not in taken
            ]
            if not free:
                return None
            d, k = min(free)
            if d >= self.threshold_m:
                return None
            self.assigned[person] = h = k
        p = hyp.get(h)
        return None if p is None else float(np.hypot(p[0] - xy[0], p[1] - xy[1]))
