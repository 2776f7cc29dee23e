"""Atomic text outputs of an export: temporary files beside the targets, renamed when complete."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import IO

from trackctl.errors import OutputError
from trackctl.logs.output import check_output

__all__ = ["atomic_outputs", "check_not_input"]


def check_not_input(out: str | os.PathLike[str], log: str | os.PathLike[str]) -> Path:
    """The file ``out`` will be written to, after checking it is not the input ``log``.

    Raises:
        OutputError: ``out`` is the log itself (or a link to it), a directory, a device, or in
            a folder that does not exist.
    """
    return check_output(out, [log])  # the one output rule: trackctl/logs/output.py


@contextmanager
def atomic_outputs(targets: Sequence[Path]) -> Iterator[list[IO[str]]]:
    """Text files for ``targets``, written as ``.NAME.*.tmp`` beside each and renamed over the
    targets only when the block ends without an error; on an error every temporary file is
    removed and the targets are left as they were.

    Raises:
        OutputError: a file cannot be created or written (no permission, a full disk).
    """
    tmps: list[Path] = []
    try:
        with ExitStack() as stack:
            files: list[IO[str]] = []
            for target in targets:
                fd, name = tempfile.mkstemp(
                    prefix=f".{target.name}.", suffix=".tmp", dir=target.parent
                )
                tmps.append(Path(name))
                files.append(stack.enter_context(os.fdopen(fd, "w", encoding="utf-8", newline="")))
            yield files
        for done, final in zip(tmps, targets, strict=True):
            os.replace(done, final)
    except OSError as err:
        raise OutputError(
            f"{targets[0]}: cannot write ({err.strerror or err}); nothing was changed"
        ) from err
    finally:
        for left in tmps:
            left.unlink(missing_ok=True)
