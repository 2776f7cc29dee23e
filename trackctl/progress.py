"""The progress callback library code reports through (the CLI draws it; library code never
prints)."""

from __future__ import annotations

from typing import Protocol

__all__ = ["Progress"]


class Progress(Protocol):
    """``progress(done, total, stage)``: ``done`` of ``total`` units (None: unknown) of the
    current stage (None: the processor's main pass; else a name such as ``"re-tracking"``)."""

    def __call__(self, done: int, total: int | None, stage: str | None = None, /) -> None: ...
