"""The processor interface and its registry.

A processor reads an input log and writes derived channels into an output log that already holds
a copy of the input; it returns a :class:`~trackctl.logs.messages.MetricReport`. The system
commands (``vm-track``, ``ev-match``, ``smirror``, ``bridgeloc eval``) are shortcuts onto this
registry with their own configuration options.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from trackctl.errors import UnknownProcessorError
from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter

__all__ = [
    "Processor",
    "ProcessorInfo",
    "register_processor",
    "get_processor",
    "processors",
    "Progress",
]

Progress = Callable[[int, int | None], None]
"""Progress callback: (done, total or None). Library code reports; the CLI draws."""


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


_REGISTRY: dict[str, ProcessorInfo] = {}


def register_processor(info: ProcessorInfo) -> None:
    """Add (or replace) a processor in the registry."""
    _REGISTRY[info.name] = info


def processors() -> list[ProcessorInfo]:
    """Every registered processor, by name."""
    _load_builtin()
    return [_REGISTRY[k] for k in sorted(_REGISTRY)]


def get_processor(name: str) -> ProcessorInfo:
    """The registry entry named ``name``.

    Raises:
        UnknownProcessorError: nothing is registered under that name.
    """
    _load_builtin()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownProcessorError(
            f"unknown processor {name!r}; available: {', '.join(sorted(_REGISTRY)) or 'none'}"
        ) from None


def _load_builtin() -> None:
    # Imported lazily: system packages import this module to register themselves.
    import trackctl.bridgeloc  # noqa: F401
    import trackctl.evmatch  # noqa: F401
    import trackctl.processing.builtin  # noqa: F401
    import trackctl.smirror  # noqa: F401
    import trackctl.vmtrack  # noqa: F401
