"""The fuzz tests' one-line summaries, shown at the end of every run (``pytest -q`` included,
and under xdist: each line travels with its test's report)."""

from __future__ import annotations

import pytest

FUZZ_PROPERTY = "fuzz summary"


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    lines = [
        str(value)
        for reports in terminalreporter.stats.values()
        for report in reports
        if getattr(report, "when", None) == "call"
        for name, value in getattr(report, "user_properties", ())
        if name == FUZZ_PROPERTY
    ]
    if lines:
        terminalreporter.section("fuzz summaries")
        for line in sorted(lines):
            terminalreporter.write_line(line)
