"""Results out in the field's formats: MOTChallenge text (py-motmetrics, TrackEval), TUM
trajectories (evo) and flat CSV (pandas), one topic at a time (``trackctl export``).

One module per format (:mod:`~trackctl.export.mot`, :mod:`~trackctl.export.tum`,
:mod:`~trackctl.export.csv`), each writing from a stream of a topic's messages; :func:`export`
checks the topic and the output and picks the format.
"""

from __future__ import annotations

from trackctl.export.config import PERSON_HEIGHT_M, ExportConfig, ExportFormat, ExportResult
from trackctl.export.dispatch import FORMAT_SCHEMAS, export, exportable_topics, ids_path

__all__ = [
    "PERSON_HEIGHT_M",
    "ExportConfig",
    "ExportFormat",
    "ExportResult",
    "FORMAT_SCHEMAS",
    "export",
    "exportable_topics",
    "ids_path",
]
