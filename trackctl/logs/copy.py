"""Copying logs: every message, metadata record and attachment; finishing unfinished recordings."""

from __future__ import annotations

import fcntl
import fnmatch
import os
from collections.abc import Container
from dataclasses import dataclass
from pathlib import Path

from trackctl.errors import LogError, OutputError
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import PARTIAL_SUFFIX, LogWriter
from trackctl.progress import Progress

__all__ = ["copy_log", "filter_log", "FilterResult", "recover_log", "RecoverResult"]


def copy_log(
    reader: LogReader,
    writer: LogWriter,
    progress: Progress | None = None,
    *,
    skip_topics: Container[str] = (),
    skip_metadata: Container[str] = (),
    attachments: bool = True,
) -> int:
    """Copy the messages, metadata records and attachments of ``reader`` into ``writer``.

    Args:
        skip_topics: topics not copied.
        skip_metadata: metadata record names not copied.
        attachments: copy attachments too.

    Returns:
        The number of messages copied.
    """
    wanted = None
    if skip_topics:
        # read only the kept topics: chunks holding none of them are not even decompressed
        wanted = [t for t in reader.topics() if t not in skip_topics]
    total = reader.message_count
    n = 0
    for raw in reader.raw(wanted) if wanted is None or wanted else ():
        if raw.topic in skip_topics:
            continue
        writer.write_raw(raw)
        n += 1
        if progress is not None and n % 500 == 0:
            progress(n, total, "copying the input")
    for name, data in reader.metadata().items():
        if name not in skip_metadata:
            writer.add_metadata(name, data)
    if attachments:
        for name, (media_type, blob) in reader.attachments().items():
            writer.add_attachment(name, blob, media_type)
    return n


@dataclass(frozen=True, slots=True)
class FilterResult:
    """What :func:`filter_log` wrote."""

    out: Path
    messages: int
    kept_topics: tuple[str, ...]
    dropped_topics: tuple[str, ...]


def filter_log(
    src: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    include: tuple[str, ...] = (),
    exclude: tuple[str, ...] = (),
    progress: Progress | None = None,
) -> FilterResult:
    """Copy ``src`` to ``out`` without some topics; metadata and attachments are kept.

    Args:
        include: glob patterns (``fnmatch``) of the topics to keep; empty keeps every topic.
        exclude: glob patterns of topics to drop (applied after ``include``).

    Raises:
        InputError: a pattern matches no topic of the log (a typo would silently keep it).
        OutputError: ``out`` is the input.
    """
    from trackctl.errors import InputError

    reader = LogReader(src)
    if Path(out).resolve() == Path(src).resolve():
        raise OutputError(f"{out}: output path is the input log; choose another --out")
    topics = sorted(reader.topics())
    for flag, patterns in (("--include", include), ("--exclude", exclude)):
        for pat in patterns:
            if not fnmatch.filter(topics, pat):
                raise InputError(
                    f"{flag} {pat!r}: no topic of {src} matches; it has {', '.join(topics)}"
                )
    kept = [
        t
        for t in topics
        if (not include or any(fnmatch.fnmatchcase(t, p) for p in include))
        and not any(fnmatch.fnmatchcase(t, p) for p in exclude)
    ]
    dropped = sorted(set(topics) - set(kept))
    with LogWriter(out, inputs=[Path(src)]) as writer:
        n = copy_log(reader, writer, progress, skip_topics=set(dropped))
    return FilterResult(Path(out), n, tuple(kept), tuple(dropped))


@dataclass(frozen=True, slots=True)
class RecoverResult:
    """What :func:`recover_log` wrote."""

    out: Path
    messages: int
    warnings: tuple[str, ...]
    removed_input: bool = False
    """The input was a recorder's ``OUT.partial`` holding messages, now all in ``out``, and was
    removed (every other input is kept)."""


def recover_log(
    partial: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    *,
    keep: bool = False,
) -> RecoverResult:
    """Finish an unfinished log (``OUT.partial`` of a killed recording, a cut copy) into ``out``.

    Every message that can be read is copied, with the metadata and attachments, into a complete,
    indexed log. The input is removed afterwards only when it is a recorder's ``*.partial`` file,
    at least one message was recovered and ``keep`` is not set (the next recording of that output
    refuses to start while it exists); any other input, and a partial file from which nothing
    was recovered, is never deleted.

    Args:
        partial: the unfinished log.
        out: the finished log; by default ``partial`` without its ``.partial`` suffix.

    Raises:
        OutputError: a recorder still writes ``partial`` (it is locked), or no output name.
        LogError: ``partial`` is not an MCAP log.
    """
    partial = Path(partial)
    if out is None:
        if not partial.name.endswith(PARTIAL_SUFFIX) or partial.name == PARTIAL_SUFFIX:
            raise OutputError(f"{partial}: name does not end in {PARTIAL_SUFFIX}; give --out")
        out = partial.with_name(partial.name[: -len(PARTIAL_SUFFIX)])
    reader = LogReader(partial)
    try:
        fd = os.open(partial, os.O_RDONLY | os.O_CLOEXEC)
    except OSError as err:
        raise LogError(f"{partial}: cannot open ({err.strerror})") from err
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputError(
                f"{partial}: a recorder is still writing it; stop it (Ctrl-C finishes the log "
                "itself) before recovering"
            ) from None
        with LogWriter(out, inputs=[partial], partial_suffix=".recovering") as writer:
            n = copy_log(reader, writer)
        remove = not keep and n > 0 and partial.name.endswith(PARTIAL_SUFFIX)
        if remove:
            partial.unlink(missing_ok=True)
    finally:
        os.close(fd)
    return RecoverResult(Path(out), n, tuple(reader.warnings), remove)
