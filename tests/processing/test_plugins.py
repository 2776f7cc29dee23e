"""Processors are plug-ins: a third-party package's entry point shows in `process --list`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, trackctl_exe
from trackctl.processing import processors
from trackctl.processing.base import ENTRY_POINT_GROUP

PLUGIN = ROOT / "tests" / "data" / "trackctl-hello"
BUILTIN = {"bridgeloc", "check", "dead-reckoning", "ev-match", "pdr", "smirror", "vm-track"}


def test_builtins_are_registered_through_entry_points() -> None:
    from importlib.metadata import entry_points

    names = {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)}
    assert BUILTIN <= names
    assert BUILTIN <= {p.name for p in processors()}


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The plug-in package installed (pip, offline) into a folder of its own."""
    site = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "--target",
            str(site),
            str(PLUGIN),
        ],
        capture_output=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr.decode()
    assert list(site.glob("trackctl_hello-*.dist-info"))
    return site


def _run(site: Path, *args: str) -> subprocess.CompletedProcess[bytes]:
    env = dict(os.environ, PYTHONPATH=str(site))
    return subprocess.run(
        [*trackctl_exe(), *args], capture_output=True, env=env, timeout=120, check=False
    )


def test_installed_plugin_is_listed_and_runs(plugin_site: Path, sample_log: Path) -> None:
    listed = _run(plugin_site, "process", "--list", "--json")
    assert listed.returncode == 0, listed.stderr.decode()
    names = [p["name"] for p in json.loads(listed.stdout)["processors"]]
    assert names == sorted(BUILTIN | {"hello"})
    entry = next(p for p in json.loads(listed.stdout)["processors"] if p["name"] == "hello")
    assert entry["description"] == "Hello: messages and topics of the input"
    ran = _run(plugin_site, "process", str(sample_log), "--with", "hello,check", "--json")
    assert ran.returncode == 0, ran.stderr.decode()
    reports = json.loads(ran.stdout)["reports"]
    assert reports[0]["processor"] == "hello"
    assert reports[0]["metrics"]["hello_messages"] == 1242
    assert reports[0]["metrics"]["hello_topics"] == 8


def test_without_the_plugin_it_is_unknown(sample_log: Path) -> None:
    proc = subprocess.run(
        [*trackctl_exe(), "process", str(sample_log), "--with", "hello"],
        capture_output=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert b"unknown processor 'hello'" in proc.stderr


def test_a_broken_plugin_warns_and_the_rest_still_load(monkeypatch: pytest.MonkeyPatch) -> None:
    import trackctl.processing.base as base

    class BrokenEntryPoint:
        name, value = "broken", "nowhere:THING"

        def load(self) -> object:
            raise ImportError("No module named 'nowhere'")

    real = base.entry_points
    monkeypatch.setattr(base, "_loaded", False)
    monkeypatch.setattr(base, "_REGISTRY", {})
    monkeypatch.setattr(
        base, "entry_points", lambda group: [*real(group=group), BrokenEntryPoint()]
    )
    with pytest.warns(base.PluginWarning, match="processor plug-in broken .* failed to load"):
        names = {p.name for p in base.processors()}
    assert names == BUILTIN
