"""Processed logs the export tests read (built once per code version, shared read-only)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.cache import processed
from tests.conftest import ROOT

SAMPLES = ROOT / "sample_logs"


@pytest.fixture(scope="session")
def vm_office_tracked() -> tuple[dict[str, Any], Path]:
    """``vm-track sample_logs/vm-office.mcap --no-retrack``: its report's metrics and output."""
    from trackctl.vmtrack import VmTrackConfig, VmTrackProcessor
    from trackctl.vmtrack.retrack import RetrackConfig

    proc = VmTrackProcessor(VmTrackConfig(refinement=RetrackConfig(enabled=False)))
    return processed(SAMPLES / "vm-office.mcap", proc, name="vm-office-tracked.mcap")


@pytest.fixture(scope="session")
def demo_reckoned() -> Path:
    """``process sample_logs/demo.mcap --with dead-reckoning``: the output log."""
    from trackctl.processing.builtin import DeadReckoningProcessor

    _, out = processed(SAMPLES / "demo.mcap", DeadReckoningProcessor(), name="demo-dr.mcap")
    return out
