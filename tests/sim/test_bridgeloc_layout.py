"""The lobby's tag deployment (``trackctl.sim.bridgeloc.lobby_layout``)."""

from __future__ import annotations

from collections import Counter

import pytest

from trackctl.errors import InputError
from trackctl.sim.bridgeloc import BridgeLocScenario, lobby_layout


def _symbols(cfg: BridgeLocScenario) -> Counter[tuple[object, ...]]:
    return Counter((t.code, t.placement, t.mount) for t in lobby_layout(cfg).tags)


@pytest.mark.parametrize("tags", [2, 4, 6, 8, 10])
@pytest.mark.parametrize("seed", [0, 100, 101])
def test_every_tag_has_its_own_pattern_by_default(tags: int, seed: int) -> None:
    assert _symbols(BridgeLocScenario(tags=tags, seed=seed)).most_common(1)[0][1] == 1


def test_a_pool_of_patterns_makes_tags_far_apart_share_one() -> None:
    cfg = BridgeLocScenario(tags=10, seed=100, patterns=4)
    layout = lobby_layout(cfg)
    groups: dict[tuple[object, ...], list[tuple[float, float, float]]] = {}
    for t in layout.tags:
        groups.setdefault((t.code, t.placement, t.mount), []).append(t.center)
    shared = [g for g in groups.values() if len(g) > 1]
    assert len(groups) == 4 and shared
    # the same wall spots as with distinct patterns: only the symbols differ
    assert [t.center for t in layout.tags] == [
        t.center for t in lobby_layout(BridgeLocScenario(tags=10, seed=100)).tags
    ]


def test_a_negative_pool_is_refused() -> None:
    with pytest.raises(InputError, match="--patterns"):
        BridgeLocScenario(patterns=-1)
