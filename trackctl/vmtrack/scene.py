"""A foxglove.SceneUpdate of the tracks, so a 3-D panel in Foxglove/Lichtblick shows them."""

from __future__ import annotations

import zlib
from collections.abc import Iterable

from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

from trackctl.logs.messages import Track, TrackState

__all__ = ["scene_update"]

_HEIGHT_M = 1.7


def _colour(key: str) -> tuple[float, float, float]:
    """A stable colour per identity."""
    h = zlib.crc32(key.encode())
    return (
        (h & 0xFF) / 255 * 0.8 + 0.2,
        ((h >> 8) & 0xFF) / 255 * 0.8 + 0.2,
        ((h >> 16) & 0xFF) / 255 * 0.8 + 0.2,
    )


def scene_update(t_ns: int, tracks: Iterable[Track], phones: set[str]) -> SceneUpdate:
    """One entity per track: a body-sized cylinder (solid when identified by a phone, faint when
    anonymous or only predicted) and a text label with its identity."""
    msg = SceneUpdate()
    for trk in tracks:
        ent = msg.entities.add()
        ent.timestamp.FromNanoseconds(int(t_ns))
        ent.frame_id = "world"
        ent.id = trk.track_id
        ent.lifetime.FromNanoseconds(1_000_000_000)
        cyl = ent.cylinders.add()
        cyl.pose.position.x = trk.position_m.x
        cyl.pose.position.y = trk.position_m.y
        cyl.pose.position.z = _HEIGHT_M / 2
        cyl.pose.orientation.w = 1.0
        cyl.size.x = cyl.size.y = 0.5
        cyl.size.z = _HEIGHT_M
        cyl.bottom_scale = cyl.top_scale = 1.0
        r, g, b = _colour(trk.track_id)
        cyl.color.r, cyl.color.g, cyl.color.b = r, g, b
        identified = trk.track_id in phones
        cyl.color.a = 0.85 if identified and trk.state is TrackState.TRACKED else 0.35
        text = ent.texts.add()
        text.pose.position.x = trk.position_m.x
        text.pose.position.y = trk.position_m.y
        text.pose.position.z = _HEIGHT_M + 0.3
        text.pose.orientation.w = 1.0
        text.billboard = True
        text.font_size = 14
        text.scale_invariant = True
        text.color.r = text.color.g = text.color.b = text.color.a = 1.0
        text.text = trk.track_id if not identified else f"{trk.track_id} ({trk.visual_id})"
    return msg
