"""VM-Tracking's score against the ground truth (the only reader of the truth; metrics only)."""

from __future__ import annotations

import math

import numpy as np

from trackctl.logs.messages import (
    GroundTruth,
    Track,
)
from trackctl.metrics.tracking import InitialIdentity, MotAccumulator
from trackctl.vmtrack.config import Mode
from trackctl.vmtrack.online import OnlineTracker


class TruthScore:
    """The published tracks scored against the ground truth, frame by frame (the only reader
    of the truth): MOT over everybody and over the phone users, each carrier's position error,
    its losses and recoveries of identity (VM), and the raw detections' error and recall."""

    def __init__(
        self,
        truth: dict[int, GroundTruth],
        online: OnlineTracker,
        threshold_m: float,
        mode: Mode,
        mids: set[str],
    ) -> None:
        self.truth = truth
        self.raw_points = online.raw_points
        self.threshold = threshold_m
        self.mode = mode
        self.mids = mids
        frames = online.frames
        self.t_start = frames[0].t_ns if frames else 0
        self.frame_s = (
            (frames[-1].t_ns - frames[0].t_ns) / 1e9 / max(len(frames) - 1, 1) if frames else 0.0
        )
        self.users_acc = MotAccumulator(threshold_m)
        self.all_acc = MotAccumulator(threshold_m)
        self.followed = InitialIdentity(threshold_m)
        self.people: set[str] = set()
        self.users: set[str] = set()
        self.errors: list[float] = []
        self.det_err: list[float] = []
        self.det_hits = self.det_people = 0
        self.ok_since: dict[str, bool] = {}
        self.lost_at: dict[str, int] = {}
        self.first_loss: dict[str, float] = {}
        self.recovery: list[float] = []
        self.loss_events = 0
        self.wrong_s = 0.0

    def add_frame(self, t_ns: int, tracks: list[Track]) -> None:
        """Score the tracks published at ``t_ns`` (nothing when the truth has no such frame)."""
        gt = self.truth.get(t_ns)
        if gt is None:
            return
        hyp = {m.track_id: (m.position_m.x, m.position_m.y) for m in tracks}
        gtf = {e.entity_id: (e.position_m.x, e.position_m.y) for e in gt.entities}
        carriers = {e.entity_id: e.electronic_id for e in gt.entities if e.electronic_id}
        self.people.update(gtf)
        self.users.update(carriers)
        self._score_detections(self.raw_points.get(t_ns), gtf)
        self.all_acc.update(gtf, hyp)
        nonusers = [p for p in gtf if p not in carriers]
        if self.mode is Mode.VM:
            self._score_phones(t_ns, gtf, carriers, hyp, nonusers)
        else:
            self._score_visual(gtf, carriers, hyp, nonusers)

    def _score_detections(
        self, pts: np.ndarray | None, gtf: dict[str, tuple[float, float]]
    ) -> None:
        """The raw detections' distance to the nearest person (within 2 m) and the people with
        a detection within the evaluation threshold."""
        if pts is not None and len(pts) and gtf:
            g = np.array(list(gtf.values()))
            d = np.linalg.norm(pts[:, None, :] - g[None, :, :], axis=2).min(axis=1)
            self.det_err.extend(float(x) for x in d if x < 2.0)
            # recall: people with a raw detection within the evaluation threshold
            near = np.linalg.norm(g[:, None, :] - pts[None, :, :], axis=2).min(axis=1)
            self.det_hits += int(np.sum(near < self.threshold))
        self.det_people += len(gtf)

    def _score_phones(
        self,
        t_ns: int,
        gtf: dict[str, tuple[float, float]],
        carriers: dict[str, str],
        hyp: dict[str, tuple[float, float]],
        nonusers: list[str],
    ) -> None:
        """VM: the users' MOT over the tracks naming a phone, and each carrier followed by its
        phone's MID."""
        # identity is the phone: only tracks carrying a MID claim to be a user; anonymous
        # tracks (non-users, users not yet identified) make no identity claim
        user_hyp = {h: xy for h, xy in hyp.items() if h in self.mids}
        self.users_acc.update({p: gtf[p] for p in carriers}, user_hyp, ignore=nonusers)
        for person, mid in carriers.items():
            self._follow(t_ns, person, hyp.get(mid), gtf)

    def _follow(
        self,
        t_ns: int,
        person: str,
        xy: tuple[float, float] | None,
        gtf: dict[str, tuple[float, float]],
    ) -> None:
        """One carrier at one frame, its MID's track at ``xy`` (None: not published): the
        error, time bound to somebody else, a loss (its track no longer on it) or recovery."""
        good = xy is not None and math.dist(xy, gtf[person]) < self.threshold
        if xy is not None:
            self.errors.append(math.dist(xy, gtf[person]))
            if not good and self._near_another(xy, person, gtf):
                self.wrong_s += self.frame_s
        if self.ok_since.get(person) and not good:
            self.loss_events += 1
            self.lost_at[person] = t_ns
            self.first_loss.setdefault(person, (t_ns - self.t_start) / 1e9)
        if good and person in self.lost_at:
            self.recovery.append((t_ns - self.lost_at.pop(person)) / 1e9)
        self.ok_since[person] = good

    def _near_another(
        self, xy: tuple[float, float], person: str, gtf: dict[str, tuple[float, float]]
    ) -> bool:
        """Whether a person other than ``person`` is within the threshold of ``xy`` (the MID's
        track is bound to somebody else)."""
        return any(
            math.dist(xy, pos) < self.threshold for other, pos in gtf.items() if other != person
        )

    def _score_visual(
        self,
        gtf: dict[str, tuple[float, float]],
        carriers: dict[str, str],
        hyp: dict[str, tuple[float, float]],
        nonusers: list[str],
    ) -> None:
        """V-AF: the users' MOT over every track, and each carrier's error on the track first
        matched to it."""
        # visual-only tracks name nobody: tracks on non-users are don't-care, not false
        # positives (they must be in the truth given, to be matched and ignored)
        self.users_acc.update(gtf, hyp, ignore=nonusers)
        for person in carriers:
            err = self.followed.error(person, gtf[person], hyp)
            if err is not None:
                self.errors.append(err)

    def people_metrics(self, n_phones: int) -> dict[str, float | int | None]:
        """People and users seen, and the users' position error (m)."""
        return {
            "people": len(self.people),
            "users": len(self.users) if self.users else n_phones,
            "error_m_mean": rounded_mean(self.errors, 4),
            "error_m_median": round(float(np.median(self.errors)), 4) if self.errors else None,
        }

    def mot_metrics(self) -> dict[str, float | int | None]:
        """IDF1 and MOTA over the users (and their identity switches), then over everybody."""
        s_users = self.users_acc.summary()
        s_all = self.all_acc.summary()
        return {
            "idf1": round(s_users.idf1, 4) if s_users.gt else None,
            "mota": round(s_users.mota, 4) if s_users.gt else None,
            "id_switches": s_users.id_switches,
            "idf1_all": round(s_all.idf1, 4) if s_all.gt else None,
            "mota_all": round(s_all.mota, 4) if s_all.gt else None,
        }

    def recovery_metrics(self) -> dict[str, float | None]:
        """Mean time to recover a lost identity, and mean time to a carrier's first loss (s)."""
        return {
            "recovery_s_mean": rounded_mean(self.recovery, 3),
            "first_loss_s_mean": rounded_mean(list(self.first_loss.values()), 3),
        }

    def detection_metrics(self) -> dict[str, float | None]:
        """The raw detections' mean error (m) and recall, and (VM) the time a MID's track was
        on somebody else (s)."""
        return {
            "det_error_m_mean": rounded_mean(self.det_err, 4),
            "det_recall": round(self.det_hits / self.det_people, 4) if self.det_people else None,
            "wrong_binding_s": round(self.wrong_s, 3)
            if self.mode is Mode.VM and self.people
            else None,
        }


def rounded_mean(values: list[float], digits: int) -> float | None:
    """The mean of ``values`` rounded to ``digits`` (None without values)."""
    return round(float(np.mean(values)), digits) if values else None
