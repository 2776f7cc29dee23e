"""The one output rule of every command that writes a file (a log, a CSV, a calibration...).

:func:`check_output` is called before any work: it refuses an output path that is (or links to)
an input, or lies inside an input folder (a ROS 2 bag), and any path that is not a regular file
or a new path (a directory, a device node such as ``/dev/null``, a FIFO, a socket), or whose
folder does not exist. Writers then write to a temporary name beside the target and rename it
over the target when complete (:func:`atomic_file`, :class:`~trackctl.logs.writer.LogWriter`),
so a failure (a full disk, an interrupt) leaves the target and every input as they were.
"""

from __future__ import annotations

import os
import signal
import stat
import tempfile
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from trackctl.errors import OutputError

__all__ = [
    "check_output",
    "check_output_path",
    "atomic_file",
    "write_text_atomic",
    "signals_deferred",
    "track_unfinished",
    "forget_unfinished",
    "remove_unfinished",
]

PathLike = str | os.PathLike[str]


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_output_path(path: PathLike) -> Path:
    """The file an output for ``path`` will really be written to (a symlink's regular target).

    Raises:
        OutputError: ``path`` is (or links to) a directory, device, FIFO or socket, or its folder
            does not exist.
    """
    path = Path(path)
    try:
        st = os.stat(path)  # follows symlinks: a link to a device is a device
    except FileNotFoundError:
        st = None
    except OSError as err:
        raise OutputError(f"{path}: cannot use as output ({err.strerror})") from err
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise OutputError(
            f"{path}: is {_kind(st.st_mode)}; trackctl writes logs only to regular files or new "
            "paths (nothing was written)"
        )
    target = Path(os.path.realpath(path)) if path.is_symlink() else path
    parent = target.parent
    if not parent.is_dir():
        raise OutputError(f"{path}: folder {parent} does not exist (nothing was written)")
    return target


def _bag_folder(real: str) -> str | None:
    """The folder an input stands for: itself when a folder, a ROS 2 bag's folder for a file in
    one (a ``metadata.yaml`` beside it), else None."""
    if os.path.isdir(real):
        return real
    parent = os.path.dirname(real)
    if os.path.isfile(os.path.join(parent, "metadata.yaml")):
        return parent
    return None


def _same(out_real: str, out: Path, inp: Path, inp_real: str) -> bool:
    if out_real == inp_real:
        return True
    try:
        return out.exists() and inp.exists() and os.path.samefile(out, inp)
    except OSError:
        return False


def check_output(out: PathLike, inputs: Iterable[PathLike | None] = ()) -> Path:
    """Check ``out`` against the output rule before any work; the path to write.

    Raises:
        OutputError: ``out`` resolves (realpath, or the same inode) to one of ``inputs``, lies
            inside an input folder or ROS 2 bag, is not a regular file or new path, or its
            folder does not exist. Nothing has been written.
    """
    target = check_output_path(out)
    out_real = os.path.realpath(target)
    for inp in inputs:
        if inp is None:
            continue
        inp_path = Path(inp)
        inp_real = os.path.realpath(inp_path)
        what = "log" if inp_path.suffix == ".mcap" else "file"
        if _same(out_real, target, inp_path, inp_real):
            raise OutputError(
                f"{out}: output path is the input {what} {inp}; choose another output "
                "(trackctl never overwrites its input; nothing written)"
            )
        folder = _bag_folder(inp_real)
        if folder is not None and out_real.startswith(folder.rstrip(os.sep) + os.sep):
            raise OutputError(
                f"{out}: lies inside the input folder {folder} (of {inp}); write outside it "
                "(nothing written)"
            )
    return target


@contextmanager
def atomic_file(path: PathLike, inputs: Iterable[PathLike | None] = ()) -> Iterator[IO[str]]:
    """A text file for ``path`` (checked by :func:`check_output`), written as ``.NAME.*.tmp``
    beside it and renamed over it when the block ends without an error; on any error (an
    interrupt too) the temporary file is removed and ``path`` is left as it was.

    Raises:
        OutputError: the output rule refuses ``path``, or it cannot be written (a full disk, no
            permission); nothing is changed then.
    """
    target = check_output(path, inputs)
    try:
        with signals_deferred():
            fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
            track_unfinished(Path(tmp))
    except OSError as err:
        raise OutputError(f"{path}: cannot write ({err.strerror}); nothing was changed") from err
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except OSError as err:
        raise OutputError(f"{path}: cannot write ({err.strerror}); nothing was changed") from err
    finally:
        with signals_deferred():
            Path(tmp).unlink(missing_ok=True)
            forget_unfinished(Path(tmp))


_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
_UNFINISHED: dict[Path, None] = {}  # ordered set of temporary outputs not yet renamed or removed


@contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP back (they are delivered when the block ends), so that a
    temporary output is created and registered, or renamed or removed and forgotten, as one
    step: an interrupt then never leaves one behind unregistered. Main thread only."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def track_unfinished(path: Path) -> None:
    """Register a temporary output (``OUT.partial``, a stage file): :func:`remove_unfinished`
    removes it if the program is interrupted before it is finished."""
    _UNFINISHED[Path(path)] = None


def forget_unfinished(path: Path) -> None:
    """The temporary output was renamed into place or removed."""
    _UNFINISHED.pop(Path(path), None)


def remove_unfinished() -> list[Path]:
    """Remove every registered temporary output (after an interrupt: a rerun then finds the
    output path free); the paths removed."""
    removed = []
    with signals_deferred():
        for path in list(_UNFINISHED):
            try:
                path.unlink(missing_ok=True)
                removed.append(path)
            except OSError:
                pass
            _UNFINISHED.pop(path, None)
    return removed


def write_text_atomic(path: PathLike, text: str, inputs: Iterable[PathLike | None] = ()) -> None:
    """Write ``text`` to ``path`` by :func:`atomic_file`: a reader sees the old file or the whole
    new one, never a half; ``path`` follows :func:`check_output`.

    Raises:
        OutputError: as :func:`atomic_file`.
    """
    with atomic_file(path, inputs) as f:
        f.write(text)
