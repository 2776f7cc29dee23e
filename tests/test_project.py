"""Project contract: CI runs the README's test command; required top-level layout exists."""

from __future__ import annotations

from tests.conftest import ROOT


def test_ci_runs_the_readme_test_command() -> None:
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    command = (
        "python3 -m venv .venv && .venv/bin/pip install -c constraints.txt -e '.[dev]' "
        "&& .venv/bin/pytest -q"
    )
    assert command in readme
    assert command in ci
    # the venv's own pip and pytest: the command never installs into the system Python
    assert "\npip install" not in readme and " pytest -q" not in readme.replace(
        "/bin/pytest -q", ""
    )


def test_required_top_level_layout() -> None:
    for name in (
        "pyproject.toml",
        "trackctl",
        "formats",
        "sample_logs",
        "tests",
        "docs",
        "README.md",
        ".ci/run",
    ):
        assert (ROOT / name).exists(), name


def test_sample_logs_stay_small() -> None:
    # five logs, four of them with rendered camera frames, in a few MB
    total = sum(p.stat().st_size for p in (ROOT / "sample_logs").glob("*.mcap"))
    assert total < 6 * 1024 * 1024
