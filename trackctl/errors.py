"""Error hierarchy of trackctl.

Library code raises these; only :mod:`trackctl.cli` turns them into a one-line message and exit
code 2. Every message names the file, topic or field at fault and what was expected.
"""

from __future__ import annotations

__all__ = [
    "TrackctlError",
    "LogError",
    "NotAFileError",
    "NotAnMcapError",
    "TruncatedLogWarning",
    "IncompleteInputWarning",
    "SchemaError",
    "UnknownSchemaError",
    "InputError",
    "MissingTopicError",
    "NonMonotonicTimeError",
    "NonFiniteValueError",
    "OutputError",
    "ProcessorError",
    "UnknownProcessorError",
]


class TrackctlError(Exception):
    """Base class of every error trackctl raises on purpose."""


class LogError(TrackctlError):
    """A log file cannot be opened or read."""


class NotAFileError(LogError):
    """The path does not exist or is not a regular file."""


class NotAnMcapError(LogError):
    """The file exists but does not start with the MCAP magic bytes."""


class TruncatedLogWarning(UserWarning):
    """A log ends early (unfinished recording, cut copy); it is read as far as it goes."""


class IncompleteInputWarning(UserWarning):
    """The input lacks data a processor uses (a camera's topic, an empty log); it works with what
    exists and says what was missing."""


class SchemaError(TrackctlError):
    """A message does not match its schema, or a schema is malformed."""


class UnknownSchemaError(SchemaError):
    """No codec is registered for a schema name and encoding."""


class InputError(TrackctlError):
    """User-supplied input (CSV, video, calibration, JSON lines, options) is invalid."""


class MissingTopicError(InputError):
    """A processor needs a topic that the log does not hold."""


class NonMonotonicTimeError(InputError):
    """Timestamps go backwards where they must not."""


class NonFiniteValueError(InputError):
    """A sensor value is NaN or infinite."""


class OutputError(TrackctlError):
    """An output cannot be written (e.g. it would overwrite an input)."""


class ProcessorError(TrackctlError):
    """A processor failed on otherwise valid input."""


class UnknownProcessorError(ProcessorError):
    """No processor is registered under the requested name."""
