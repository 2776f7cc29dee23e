"""VM-Tracking's identities do not depend on how the phones are carried."""

from __future__ import annotations

from dataclasses import replace

import pytest

from tests.vmtrack.test_realistic import LOBBY, _cached_run
from trackctl.sim.vm import VmScenario


def _same_identities_however_carried(base: VmScenario) -> None:
    figures = [
        _cached_run(replace(base, carry_yaw_deg=yaw), f"yaw{yaw:.0f}")[0]["idf1"]
        for yaw in (0.0, 90.0, 180.0)
    ]
    assert max(figures) - min(figures) <= 0.02  # type: ignore[operator]
    assert min(figures) >= 0.8  # type: ignore[type-var]


@pytest.mark.slow
def test_identity_does_not_depend_on_how_the_phone_is_carried() -> None:
    """The device-to-walk yaw is estimated, not assumed: turning every phone by 180 deg (or
    90) in its pocket gives the same identities (two carriers and two others for 30 s of the
    lobby: 0.971 each). Under ``-m slow``: by default the realistic lobby
    (test_realistic.py) gives each phone a random carry yaw of its own. Five carriers for
    300 s at each of 0/45/90/180 deg are the benchmark's rows (benchmarks/vm_realistic.py)."""
    _same_identities_however_carried(replace(LOBBY, users=2, nonusers=2, duration_s=30, seed=4))
