"""VM-Tracking's identities do not depend on how the phones are carried (a file of its own:
its three runs take as long as the rest of ``test_realistic.py``, and pytest-xdist spreads
the suite over the cores a file at a time)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from tests.vmtrack.test_realistic import LOBBY, _run


def test_identity_does_not_depend_on_how_the_phone_is_carried(tmp_path: Path) -> None:
    """The device-to-walk yaw is estimated, not assumed: turning every phone by 180 deg (or
    90) in its pocket gives the same identities."""
    base = replace(LOBBY, duration_s=90, seed=4)
    figures = [
        _run(tmp_path, replace(base, carry_yaw_deg=yaw), f"yaw{yaw}")[0]["idf1"]
        for yaw in (0.0, 90.0, 180.0)
    ]
    assert max(figures) - min(figures) <= 0.02  # type: ignore[operator]
    assert min(figures) >= 0.8  # type: ignore[type-var]
