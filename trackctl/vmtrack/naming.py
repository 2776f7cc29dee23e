"""Stage 5 of VM-Tracking, naming: who each published track is, frame by frame.

The rule, in order: a re-tracked carrier's MID is published where its re-tracking put it (on
the nearest track within the gate, or on its own); else a track carries the offline identity's
MID (:mod:`~trackctl.vmtrack.identify`) for the frames it assigns; else the online binding's
(:mod:`~trackctl.vmtrack.binder`); else its chain's visual id (:mod:`~trackctl.vmtrack.stitch`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from trackctl.logs.messages import (
    Track,
    TrackState,
    Vec3,
)
from trackctl.vmtrack.identify import Identities
from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.retrack import PhoneTrack
from trackctl.vmtrack.stitch import Publication
from trackctl.vmtrack.tracker import GroundTrack


def _track_message(
    out_id: str, trk: GroundTrack, state: TrackState, est: tuple[np.ndarray, np.ndarray] | None
) -> Track:
    """A trackctl.Track from an estimated state (x, y, vx, vy) and its covariance."""
    if est is None:
        x, p = trk.kf.x[:, 0], trk.kf.P
    else:
        x, p = est
    cov = np.zeros((3, 3))
    cov[:2, :2] = p[:2, :2]
    return Track(
        out_id,
        Vec3(float(x[0]), float(x[1]), 0.0),
        Vec3(float(x[2]), float(x[3]), 0.0),
        tuple(float(c) for c in cov.ravel()),
        state=state,
        visual_id=trk.vid,
    )


def frame_tracks(
    fr: FrameOut,
    plan: Publication,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    ids: Identities | None = None,
    carriers: tuple[dict[str, PhoneTrack], int, float] | None = None,
) -> list[Track]:
    """The tracks published at one frame: the online rows the clean-up keeps, under their
    published ids (the offline identity's MID, else the online binding's, else the visual
    id), plus interpolated positions across stitched gaps. ``carriers``: the re-tracked
    carriers, this frame's index and the gate (m); a re-tracked phone's MID is published only
    where its re-tracking put it, on the nearest track within the gate (or on its own)."""
    retracked = carriers[0] if carriers is not None else {}
    tracks: list[Track] = []
    names: set[str] = set()
    _add_rows(tracks, names, fr, plan, positions, ids, retracked)
    _add_fills(tracks, names, fr.t_ns, plan, ids, retracked)
    if carriers is not None:
        _place_carriers(tracks, names, *carriers)
    if ids is not None:
        _add_unseen(tracks, names, ids.unseen.get(fr.t_ns, ()), retracked)
    return tracks


def _add_rows(
    tracks: list[Track],
    names: set[str],
    fr: FrameOut,
    plan: Publication,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    ids: Identities | None,
    retracked: dict[str, PhoneTrack],
) -> None:
    """Append (in place) the frame's online rows the clean-up keeps, each under an id no other
    track of the frame has taken."""
    # tracks bound now name first: one phone (MID) is never on two tracks in one frame, so a
    # back-dated identity gives way to the binding of the moment
    rows = sorted(fr.rows, key=lambda r: r[1] is None)
    for trk, mid_now, state, k in rows:
        if (trk.key, fr.t_ns) in plan.hidden:
            continue
        out_id = _row_id(trk, mid_now, fr.t_ns, plan, ids, retracked)
        out_id = _unclaimed_id(out_id, trk, plan, names)
        # entry k of a track's history is its state at this frame (snapshotted before the
        # next frame's prediction, or when the log ends)
        tracks.append(_track_message(out_id, trk, state, positions.get((trk.key, k))))
        names.add(out_id)


def _row_id(
    trk: GroundTrack,
    mid_now: str | None,
    t_ns: int,
    plan: Publication,
    ids: Identities | None,
    retracked: dict[str, PhoneTrack],
) -> str:
    """The id an online row would be published under at ``t_ns``: the offline identity's MID,
    else the online binding's (or its back-dated identity), else the track's published name."""
    name = plan.name.get(trk.key, trk.vid)
    if ids is not None:
        return _chain_mid(ids, plan.head.get(trk.key, trk.key), t_ns, retracked, name)
    if mid_now is not None:
        return mid_now
    if trk.first_mid is not None and trk.identity_from_ns <= t_ns < (trk.first_bound_ns or 0):
        # online identity, offline back-dated: the identity found later holds back to
        # where the track's motion stops agreeing with the phone
        return trk.first_mid
    return name


def _unclaimed_id(out_id: str, trk: GroundTrack, plan: Publication, names: set[str]) -> str:
    """``out_id`` unless another track of the frame has it; then the track's published name,
    or its visual id if that is taken too."""
    if out_id not in names:
        return out_id
    out_id = plan.name.get(trk.key, trk.vid)
    return trk.vid if out_id in names else out_id


def _add_fills(
    tracks: list[Track],
    names: set[str],
    t_ns: int,
    plan: Publication,
    ids: Identities | None,
    retracked: dict[str, PhoneTrack],
) -> None:
    """Append (in place) the positions interpolated across stitched gaps at ``t_ns`` (under
    their chain's MID when the offline identity gives one), where the id is still free."""
    for name, xy, v in plan.fills.get(t_ns, ()):
        out_id = name
        if ids is not None:
            out_id = _chain_mid(ids, plan.head_of_name.get(name, -1), t_ns, retracked, name)
        if out_id not in names:
            names.add(out_id)
            tracks.append(_coasting_track(out_id, xy, v))


def _add_unseen(
    tracks: list[Track],
    names: set[str],
    unseen: Iterable[tuple[str, tuple[float, float], tuple[float, float]]],
    retracked: dict[str, PhoneTrack],
) -> None:
    """Append (in place) the carriers no camera showed, walked on their phone between two
    stretches of their chains (not a MID already published, nor a re-tracked one)."""
    for mid, xy, v in unseen:
        if mid not in names and mid not in retracked:
            names.add(mid)
            tracks.append(_coasting_track(mid, xy, v))


def _coasting_track(
    out_id: str, xy: np.ndarray | tuple[float, float], v: np.ndarray | tuple[float, float]
) -> Track:
    """A ``predicted`` trackctl.Track at ground position ``xy`` with velocity ``v`` (no
    covariance)."""
    return Track(
        out_id,
        Vec3(float(xy[0]), float(xy[1]), 0.0),
        Vec3(float(v[0]), float(v[1]), 0.0),
        state=TrackState.PREDICTED,
    )


def _chain_mid(
    ids: Identities, head: int, t_ns: int, retracked: dict[str, PhoneTrack], default: str
) -> str:
    """The MID the offline identity gives chain ``head`` at ``t_ns`` (``default`` if none, or
    if that phone was re-tracked: then its re-tracking alone places it)."""
    mid = ids.mid_at.get((head, t_ns))
    return default if mid is None or mid in retracked else mid


def _place_carriers(
    tracks: list[Track], names: set[str], retracked: dict[str, PhoneTrack], k: int, gate: float
) -> None:
    """Name the re-tracked carriers at frame ``k`` (in place): each MID takes the nearest
    anonymous track within ``gate`` of where its phone put the carrier, at that position; a
    carrier no track is near is published on its own (``predicted`` where no detection was on
    its path)."""
    for mid in sorted(retracked):
        pt = retracked[mid]
        xy = pt.xy.get(k)
        if xy is None or mid in names:
            continue
        v = pt.velocity[k]
        vel = Vec3(0.0, 0.0, 0.0) if np.isnan(v).any() else Vec3(float(v[0]), float(v[1]), 0.0)
        state = TrackState.TRACKED if k in pt.seen else TrackState.PREDICTED
        best, best_d = -1, gate
        for i, trk in enumerate(tracks):
            if trk.track_id in retracked:
                continue
            d = math.hypot(trk.position_m.x - xy[0], trk.position_m.y - xy[1])
            if d < best_d:
                best, best_d = i, d
        pos = Vec3(float(xy[0]), float(xy[1]), 0.0)
        if best >= 0:
            old = tracks[best]
            names.discard(old.track_id)
            tracks[best] = Track(
                mid, pos, vel, old.covariance_m2, state=old.state, visual_id=old.visual_id
            )
        else:
            tracks.append(Track(mid, pos, vel, state=state))
        names.add(mid)
