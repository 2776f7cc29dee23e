"""Expensive test inputs built once per code version and shared by every pytest-xdist worker.

A simulated log or a processor's output is built by the first worker that asks for it, under a
file lock, into ``.pytest_cache/trackctl-inputs/<code digest>/`` (or ``$TRACKCTL_TEST_CACHE``);
every later request, from any worker or a later session on the same code, reads the same file.
The key is the builder's name and its arguments' ``repr`` (frozen dataclasses print every field),
under a digest of trackctl's version and source, so a change to the simulator or a processor
builds afresh rather than testing a stale file. Cached files are read-only: a test that wants to
change one copies it first.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import pickle
import shutil
import stat
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any, TypeVar

import trackctl

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = Path(trackctl.__file__).resolve().parent

__all__ = ["cache_root", "cached_file", "cached_value", "processed", "simulated"]

T = TypeVar("T")


@cache
def code_digest() -> str:
    """trackctl's version and the bytes of its source and schemas (16 hex digits)."""
    h = hashlib.sha256(trackctl.__version__.encode())
    for path in sorted(PACKAGE.rglob("*")):
        if path.suffix in (".py", ".json") and "__pycache__" not in path.parts:
            h.update(str(path.relative_to(PACKAGE)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


@cache
def cache_root() -> Path:
    """This code version's cache folder (older versions' folders are removed, best effort)."""
    base = Path(os.environ.get("TRACKCTL_TEST_CACHE", ROOT / ".pytest_cache" / "trackctl-inputs"))
    base.mkdir(parents=True, exist_ok=True)
    here = base / code_digest()
    here.mkdir(exist_ok=True)
    for old in base.iterdir():
        if old.is_dir() and old != here:
            shutil.rmtree(old, ignore_errors=True)
    return here


def cached_file(name: str, build: Callable[[Path], object], *key: object) -> Path:
    """The file ``build(path)`` writes, built once for ``(name, *key)`` and then shared.

    ``name`` is a readable prefix (it also keeps the file's suffix); ``key`` is everything the
    result depends on besides trackctl's code. Concurrent callers wait on a lock for the first
    one's build instead of repeating it.
    """
    digest = hashlib.sha256(repr((name, key)).encode()).hexdigest()[:16]
    stem, dot, suffix = name.rpartition(".")
    target = cache_root() / (f"{stem}-{digest}{dot}{suffix}" if dot else f"{name}-{digest}")
    if target.exists():
        return target
    with open(target.with_name(target.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not target.exists():
            partial = target.with_name(f"building-{target.name}")
            if partial.exists():
                shutil.rmtree(partial) if partial.is_dir() else partial.unlink()
            build(partial)
            _read_only(partial)
            os.replace(partial, target)
    return target


def _read_only(path: Path) -> None:
    paths = [path, *path.rglob("*")] if path.is_dir() else [path]
    for p in paths:
        if p.is_file():
            p.chmod(p.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


def simulated(name: str, simulate: Callable[[str, Any], object], scenario: object) -> Path:
    """The log ``simulate(path, scenario)`` writes (a ``trackctl.sim`` function and its frozen
    scenario), built once per code version."""
    return cached_file(
        name,
        lambda path: simulate(str(path), scenario),
        f"{simulate.__module__}.{simulate.__qualname__}",
        scenario,
    )


def processed(log: Path, *chain: Any, name: str = "out.mcap") -> tuple[dict[str, Any], Path]:
    """``run_processors(log, OUT, chain)`` once per log, chain and code version: the last
    processor's metrics (as read back from OUT, the way ``trackctl report`` does) and OUT.

    The chain's key is each processor's name and ``repr`` of its config, so only processors
    whose config is a dataclass (all of trackctl's) are cached truthfully.
    """
    from trackctl.logs import LogReader
    from trackctl.metrics.report import read_reports
    from trackctl.processing import run_processors

    key = [(p.name, repr(getattr(p, "config", None))) for p in chain]
    out = cached_file(name, lambda path: run_processors(log, path, list(chain)), str(log), key)
    reports = read_reports(LogReader(out))
    return dict(reports[-1].metrics), out


def cached_value(name: str, compute: Callable[[], T], *key: object) -> T:
    """``compute()``, computed once for ``(name, *key)`` per code version and pickled."""
    path = cached_file(
        f"{name}.pickle", lambda p: p.write_bytes(pickle.dumps(compute(), protocol=5)), *key
    )
    value: T = pickle.loads(path.read_bytes())
    return value
