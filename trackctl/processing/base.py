"""The processor interface and its registry.

A processor reads an input log and writes derived channels into an output log that already holds
a copy of the input; it returns a :class:`~trackctl.logs.messages.MetricReport`. The system
commands (``vm-track``, ``ev-match``, ``smirror``, ``bridgeloc eval``) are shortcuts onto this
registry with their own configuration options.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Protocol

from trackctl.errors import UnknownProcessorError
from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.progress import Progress

__all__ = [
    "Processor",
    "ProcessorInfo",
    "register_processor",
    "get_processor",
    "processors",
    "Progress",
    "ENTRY_POINT_GROUP",
    "PluginWarning",
]


class Processor(Protocol):
    """Something that turns a log into derived channels and a metric report."""

    name: str

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        """Process ``reader``; write derived messages to ``writer``; return the report."""
        ...


@dataclass(frozen=True, slots=True)
class ProcessorInfo:
    """A registry entry: name, one-line description, and a factory with default configuration."""

    name: str
    description: str
    factory: Callable[[], Processor]
    requires: tuple[str, ...] = ()


class PluginWarning(UserWarning):
    """A processor plug-in could not be loaded."""


_REGISTRY: dict[str, ProcessorInfo] = {}


def register_processor(info: ProcessorInfo) -> None:
    """Add (or replace) a processor in the registry (programmatic registration; packages use
    the entry point group instead)."""
    _REGISTRY[info.name] = info


ENTRY_POINT_GROUP = "trackctl.processors"
"""Packages register processors as entry points of this group, each naming a ProcessorInfo::

    [project.entry-points."trackctl.processors"]
    hello = "trackctl_hello:PROCESSOR"

trackctl's own processors are registered the same way (see its pyproject.toml)."""

_loaded = False


def _load_entry_points() -> None:
    """Register every processor published under :data:`ENTRY_POINT_GROUP` (once)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        try:
            info = ep.load()
        except Exception as err:  # noqa: BLE001 - a broken plug-in must not break the CLI
            warnings.warn(
                f"processor plug-in {ep.name} ({ep.value}) failed to load: {err}",
                PluginWarning,
                stacklevel=2,
            )
            continue
        if not isinstance(info, ProcessorInfo):
            warnings.warn(
                f"processor plug-in {ep.name} ({ep.value}) is not a ProcessorInfo; ignored",
                PluginWarning,
                stacklevel=2,
            )
            continue
        _REGISTRY.setdefault(info.name, info)


def processors() -> list[ProcessorInfo]:
    """Every registered processor, by name."""
    _load_entry_points()
    return [_REGISTRY[k] for k in sorted(_REGISTRY)]


def get_processor(name: str) -> ProcessorInfo:
    """The registry entry named ``name``.

    Raises:
        UnknownProcessorError: nothing is registered under that name.
    """
    _load_entry_points()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownProcessorError(
            f"unknown processor {name!r}; available: {', '.join(sorted(_REGISTRY)) or 'none'}"
        ) from None
