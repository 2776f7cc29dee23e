"""Bounds on what a small input file (calibration, site; YAML or XML) may make trackctl do
before it is parsed.

A hostile or damaged file must fail fast, in little memory and with one line naming the file and
the key, instead of hanging on a FIFO, expanding an alias bomb to gigabytes, recursing through
10,000 brackets or crashing OpenCV's ``FileStorage`` (which segfaults on deep nesting). The
rules, in the order they apply:

1. :func:`read_bounded`: the path is stat'ed first; a FIFO, device, socket or folder is refused
   without opening it, and a file over the size limit is refused without reading it. The file is
   then opened non-blocking and read up to the limit (what was checked is what is parsed).
2. :func:`load_yaml`: PyYAML's safe loader, composing with a depth limit, an alias count limit
   and a bound on the document's size once aliases are expanded (each node's expanded size is
   counted once, as it is composed, so an alias bomb is refused after a few hundred events);
   dates, binary, sets and other tags are refused, as are integers with more digits than any
   real value has (Python refuses over 4300 digits with a ValueError deep inside the loader).
3. :func:`parse_xml`: ``defusedxml`` (no entity expansion, no DTD, no external fetch) through
   an incremental parse that stops at the first element nested too deep.
4. :func:`check_text_nesting`: for the files only OpenCV parses (its ``%YAML:1.0`` dialect is not
   YAML PyYAML reads), a linear scan bounds the bracket and indentation depth before
   ``FileStorage`` sees the text.
"""

from __future__ import annotations

import io
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, ParseError

import numpy as np
import yaml

from trackctl.errors import InputError

__all__ = [
    "MAX_DEPTH",
    "MAX_INT_DIGITS",
    "YamlLimits",
    "read_bounded",
    "load_yaml",
    "parse_xml",
    "check_text_nesting",
    "short_repr",
    "bounded_number",
]

MAX_DEPTH = 32
"""Nesting levels a calibration or site file may use (the deepest real one, a floor plan's wall
coordinate, is 6 deep)."""

MAX_INT_DIGITS = 20
"""Digits an integer may have (int64 has 19); checked on the text, before ``int()``."""

_YAML_TAGS = {
    "tag:yaml.org,2002:" + t for t in ("null", "bool", "int", "float", "str", "seq", "map", "merge")
}
_TAG_NAMES = {
    "tag:yaml.org,2002:timestamp": "a date",
    "tag:yaml.org,2002:binary": "binary data",
    "tag:yaml.org,2002:set": "a set",
    "tag:yaml.org,2002:omap": "an ordered map",
    "tag:yaml.org,2002:pairs": "a list of pairs",
}


@dataclass(frozen=True, slots=True)
class YamlLimits:
    """What one YAML document may hold."""

    max_depth: int = MAX_DEPTH
    max_aliases: int = 1000
    """Alias uses (``*name``) in the whole document."""
    max_nodes: int = 1_000_000
    """Values in the document with every alias expanded (what a consumer walking it meets)."""
    max_int_digits: int = MAX_INT_DIGITS


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (a hostile value's repr may be huge)."""
    text = reprlib_repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def reprlib_repr(value: Any) -> str:
    """A bounded repr: containers show their first items only (never walks a whole graph)."""
    import reprlib

    r = reprlib.Repr()
    r.maxlevel, r.maxlist, r.maxdict, r.maxstring, r.maxother = 2, 4, 4, 40, 40
    return r.repr(value)


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISDIR, "a folder"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def read_bounded(path: str | os.PathLike[str], where: str, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them.

    ``where`` starts every message (the file, or the option and the file).

    Raises:
        InputError: missing, not a regular file (FIFO, device, socket, folder: refused before
            it is opened), larger than ``max_bytes``, or unreadable.
    """
    path = Path(path)
    try:
        st = os.stat(path)  # follows symlinks: a link to a FIFO is a FIFO
    except FileNotFoundError:
        raise InputError(f"{where}: no such file") from None
    except OSError as err:
        raise InputError(f"{where}: cannot read ({err.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{where}: is {_kind(st.st_mode)}; expected a regular file")
    _check_size(st.st_size, where, max_bytes)
    try:
        # non-blocking: if the path was swapped for a FIFO since the stat, open does not hang
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    except OSError as err:
        raise InputError(f"{where}: cannot read ({err.strerror})") from None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{where}: is {_kind(st.st_mode)}; expected a regular file")
        try:
            data = f.read(max_bytes + 1)
        except OSError as err:
            raise InputError(f"{where}: cannot read ({err.strerror})") from None
    _check_size(len(data), where, max_bytes)
    return data


def _check_size(size: int, where: str, max_bytes: int) -> None:
    if size > max_bytes:
        raise InputError(
            f"{where}: {size:,} bytes or more; expected at most {max_bytes:,} for this kind of file"
        )


class _YamlLimitError(Exception):
    """A limit hit while composing: carries the message, turned into InputError outside."""


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader composing under :class:`YamlLimits` (PyYAML's composer is recursive and
    expands nothing itself, so counting as it composes is exact and cheap)."""

    def __init__(self, stream: str, limits: YamlLimits) -> None:
        super().__init__(stream)
        self.limits = limits
        self.depth = 0
        self.aliases = 0
        self.key_path: list[str] = []
        self.weight: dict[int, int] = {}
        """Expanded size of every finished node (by id; the nodes live in the tree)."""

    def where(self) -> str:
        path = self.key_path
        if len(path) > 8:
            path = [*path[:4], "...", *path[-2:]]
        return ".".join(path).replace(".[", "[") or "(top level)"

    def compose_node(self, parent: Any, index: Any) -> Any:
        step = _path_step(index)
        if step is not None:
            self.key_path.append(step)
        try:
            if self.check_event(yaml.AliasEvent):
                return self._alias(parent, index)
            self.depth += 1
            if self.depth > self.limits.max_depth:
                raise _YamlLimitError(
                    f"{self.where()}: nested deeper than {self.limits.max_depth} levels"
                )
            node = super().compose_node(parent, index)
            self.depth -= 1
            self._account(node)
            return node
        finally:
            if step is not None:
                self.key_path.pop()

    def _alias(self, parent: Any, index: Any) -> Any:
        self.aliases += 1
        if self.aliases > self.limits.max_aliases:
            raise _YamlLimitError(
                f"{self.where()}: more than {self.limits.max_aliases} aliases (*name)"
            )
        anchor = self.peek_event().anchor
        target = self.anchors.get(anchor)
        if target is not None and id(target) not in self.weight:
            raise _YamlLimitError(f"{self.where()}: alias *{anchor} refers to itself")
        return super().compose_node(parent, index)

    def _account(self, node: Any) -> None:
        if isinstance(node, yaml.ScalarNode):
            self._check_scalar(node)
            self.weight[id(node)] = 1
            return
        if isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        else:
            children = list(node.value)
        total = 1 + sum(self.weight[id(c)] for c in children)
        if total > self.limits.max_nodes:
            raise _YamlLimitError(
                f"{self.where()}: expands to more than {self.limits.max_nodes:,} values "
                "(YAML aliases)"
            )
        self.weight[id(node)] = total

    def _check_scalar(self, node: yaml.ScalarNode) -> None:
        tag = node.tag
        if tag not in _YAML_TAGS:
            what = _TAG_NAMES.get(tag, f"a value tagged {tag}")
            raise _YamlLimitError(
                f"{self.where()}: {what} ({short_repr(node.value)}) is not allowed; expected a "
                "number, a string, true/false or null"
            )
        if tag == "tag:yaml.org,2002:int":
            digits = sum(ch.isalnum() for ch in node.value)
            if digits > self.limits.max_int_digits:
                raise _YamlLimitError(
                    f"{self.where()}: an integer of {digits} digits; expected at most "
                    f"{self.limits.max_int_digits}"
                )


def _path_step(index: Any) -> str | None:
    """The key path element of a node composed at ``index`` (a mapping key's node, a sequence
    index, or None for a mapping key itself)."""
    if isinstance(index, yaml.ScalarNode):
        return str(index.value)[:40]
    if isinstance(index, int) and not isinstance(index, bool):
        return f"[{index}]"
    if isinstance(index, yaml.Node):
        return "?"
    return None


def load_yaml(data: bytes | str, where: str, limits: YamlLimits | None = None) -> Any:
    """The one YAML document in ``data``, parsed under ``limits``.

    Raises:
        InputError: not UTF-8, not valid YAML (with the line), or over a limit or holding a
            value that is not plain data (naming the key path and what was expected).
    """
    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8-sig")
        except UnicodeDecodeError as err:
            raise InputError(f"{where}: not UTF-8 text (byte {err.start})") from None
    limits = limits or YamlLimits()
    # PyYAML's scanner looks ahead over a whole run of opening brackets (quadratic in it):
    # bound the bracket depth first, by a linear scan that errs on the safe side
    _check_flow_depth(
        _COMMENT.sub(rb"\1", _QUOTED.sub(b'""', data.encode())), where, limits.max_depth
    )
    try:
        # the reader refuses control characters as it is built: inside the try
        loader = _BoundedLoader(data, limits)
    except yaml.reader.ReaderError as err:
        raise InputError(
            f"{where}: not valid YAML (character #x{err.character:04x} at position "
            f"{err.position}: special characters are not allowed)"
        ) from None
    try:
        node = loader.get_single_node()
        return None if node is None else loader.construct_document(node)
    except _YamlLimitError as err:
        raise InputError(f"{where}: {err}") from None
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        at = f" at line {mark.line + 1}" if mark is not None else ""
        reason = " ".join(str(err.problem or err.context or "").split())[:100]
        raise InputError(f"{where}: not valid YAML{at} ({reason})") from None
    except yaml.YAMLError as err:
        raise InputError(f"{where}: not valid YAML ({' '.join(str(err).split())[:100]})") from None
    except (ValueError, RecursionError) as err:  # a constructor's own conversion failed
        raise InputError(f"{where}: not valid YAML ({' '.join(str(err).split())[:100]})") from None
    finally:
        loader.dispose()


def parse_xml(data: bytes, where: str, max_depth: int = MAX_DEPTH) -> Element:
    """The root element of the XML document ``data``, parsed by ``defusedxml`` (no entities, no
    DTD, no external references) and refused at the first element nested deeper than
    ``max_depth``.

    Raises:
        InputError: not well-formed XML, an entity or DTD, or too deep (naming the element).
    """
    from defusedxml import DefusedXmlException  # type: ignore[import-untyped]
    from defusedxml.ElementTree import iterparse  # type: ignore[import-untyped]

    depth = 0
    events = iterparse(io.BytesIO(data), events=("start", "end"), forbid_dtd=True)
    try:
        for event, elem in events:
            depth += 1 if event == "start" else -1
            if depth > max_depth:
                raise InputError(
                    f"{where}: element <{str(elem.tag)[:40]}> is nested deeper than {max_depth} "
                    "levels"
                )
    except ParseError as err:
        raise InputError(f"{where}: not well-formed XML ({err})") from None
    except DefusedXmlException as err:
        raise InputError(f"{where}: XML with {type(err).__name__} is refused ({err})") from None
    root: Element = events.root
    return root


_QUOTED = re.compile(rb'"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'')
_COMMENT = re.compile(rb"(?m)(^|\s)#.*$")
_DASHES = re.compile(rb"(?:-[ \t]+)*")


def check_text_nesting(data: bytes, where: str, max_depth: int = MAX_DEPTH) -> None:
    """Refuse a YAML-like or XML text nested deeper than ``max_depth`` (brackets ``[ {``,
    indentation and ``- `` sequence markers, or XML elements), by a scan linear in its size
    that allocates nothing per level. Quoted strings and comments are skipped; the count errs
    on the safe side (a text it passes parses to at most ``max_depth`` levels).

    Raises:
        InputError: naming the line where the limit was passed.
    """
    if data.lstrip()[:1] == b"<":
        parse_xml(data, where, max_depth)
        return
    text = _COMMENT.sub(rb"\1", _QUOTED.sub(b'""', data))
    _check_flow_depth(text, where, max_depth)
    _check_indentation(text, where, max_depth)


def _check_flow_depth(text: bytes, where: str, max_depth: int) -> None:
    """Bracket depth (``[`` and ``{``), counted over the whole text at once."""
    arr = np.frombuffer(text, dtype=np.uint8)
    step = np.isin(arr, np.frombuffer(b"[{", np.uint8)).astype(np.int32) - np.isin(
        arr, np.frombuffer(b"]}", np.uint8)
    ).astype(np.int32)
    flow = np.cumsum(step)
    if flow.size and int(flow.max()) > max_depth:
        line = text[: int(np.argmax(flow > max_depth))].count(b"\n") + 1
        raise InputError(f"{where}: line {line}: brackets nested deeper than {max_depth} levels")


def _check_indentation(text: bytes, where: str, max_depth: int) -> None:
    """Block nesting: the stack of indentation levels plus leading ``- `` markers per line."""
    indents: list[int] = []
    for lineno, raw in enumerate(text.split(b"\n"), 1):
        line = raw.rstrip()
        body = line.lstrip(b" \t")
        if not body or body.startswith((b"%", b"---", b"...")):
            continue
        indent = len(line) - len(body)
        while indents and indents[-1] > indent:
            indents.pop()
        if not indents or indents[-1] < indent:
            indents.append(indent)
        dashes = _DASHES.match(body).group(0).count(b"-")  # type: ignore[union-attr]
        if len(indents) + dashes > max_depth:
            raise InputError(f"{where}: line {lineno}: nested deeper than {max_depth} levels")


def bounded_number(value: Any, where: str, lo: float, hi: float, integer: bool = False) -> float:
    """``value`` as a finite float within [lo, hi] (an integral one when ``integer``).

    Raises:
        InputError: not a number (true/false are not), not finite, not integral, out of range;
            the message names ``where`` and the expected range.
    """
    kind = "an integer" if integer else "a number"
    expected = f"expected {kind} in [{lo:g}, {hi:g}]"
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(f"{where}: {short_repr(value)} is not a number; {expected}")
    try:
        number = float(value)
    except OverflowError:  # an int beyond float's range
        number = float("inf")
    if not np.isfinite(number):
        raise InputError(f"{where}: {short_repr(value)} is not finite; {expected}")
    if integer and number != int(number):
        raise InputError(f"{where}: {short_repr(value)} is not an integer; {expected}")
    if not lo <= number <= hi:
        raise InputError(f"{where}: {short_repr(value)} is out of range; {expected}")
    return number
