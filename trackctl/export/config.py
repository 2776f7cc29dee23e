"""What an export is asked to do and what it did."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["ExportFormat", "ExportConfig", "ExportResult", "PERSON_HEIGHT_M"]

PERSON_HEIGHT_M = 1.7
"""Height of the box drawn for a person in a MOT export with a camera (metres)."""


class ExportFormat(enum.StrEnum):
    """The file formats ``trackctl export`` writes."""

    MOT = "mot"
    """MOTChallenge text (py-motmetrics, TrackEval)."""
    TUM = "tum"
    """TUM trajectory text (evo)."""
    CSV = "csv"
    """Flat CSV of any topic's typed messages (pandas, spreadsheets)."""


@dataclass(frozen=True, slots=True)
class ExportConfig:
    """One export of one topic.

    Attributes:
        topic: The topic to export.
        format: The file format.
        camera: MOT only: the camera whose ``/<CAM>/camera_model`` projects the boxes; None
            writes -1 in the four box columns.
        person_height_m: MOT only: height of a person's box (its width is 0.41 of it).
        robot: TUM only: which entity of a topic holding several robots' poses.
    """

    topic: str
    format: ExportFormat
    camera: str | None = None
    person_height_m: float = PERSON_HEIGHT_M
    robot: str | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.person_height_m) and self.person_height_m > 0):
            raise ValueError(
                f"ExportConfig.person_height_m must be a positive number of metres, "
                f"got {self.person_height_m}"
            )


@dataclass(frozen=True, slots=True)
class ExportResult:
    """What an export wrote.

    Attributes:
        out: The file written.
        messages: Messages read from the topic.
        rows: Lines (rows) written, header excluded.
        extra: Other files written beside ``out`` (the MOT id mapping).
    """

    out: Path
    messages: int
    rows: int
    extra: tuple[Path, ...] = field(default_factory=tuple)
