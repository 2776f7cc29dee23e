"""A short S-Mirror log shared by the tests (rendered once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cache import cached_value, simulated
from trackctl.logs import LogReader
from trackctl.sim.smirror import SmirrorScenario, simulate_smirror
from trackctl.smirror import Mode, SmirrorConfig, SmirrorResult, run_detailed

SHORT = SmirrorScenario(
    paths=1, people=4, fps=2.5, width_px=480, height_px=360, duration_s=34.0, seed=3
)
"""34 s of the first patrol: in coverage, then out of it (the first doorway), with people."""


@pytest.fixture(scope="session")
def smirror_log() -> Path:
    return simulated("smirror-short.mcap", simulate_smirror, SHORT)


def _run(log: Path, cfg: SmirrorConfig) -> tuple[dict, SmirrorResult]:
    def compute() -> tuple[dict, SmirrorResult]:
        report, res = run_detailed(LogReader(log), None, cfg)
        return dict(report.metrics), res

    return cached_value("smirror-run", compute, str(log), cfg)


@pytest.fixture(scope="session")
def mirror_run(smirror_log: Path) -> tuple[dict, SmirrorResult]:
    return _run(smirror_log, SmirrorConfig())


@pytest.fixture(scope="session")
def centralized_run(smirror_log: Path) -> tuple[dict, SmirrorResult]:
    return _run(smirror_log, SmirrorConfig(mode=Mode.CENTRALIZED))
