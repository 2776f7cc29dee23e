"""EV data as the matcher sees it: the E-scenario table (read in full, it is light) and a V-scenario
store that reads one (cell topic, window) at a time and counts what it read."""

from __future__ import annotations

from array import array
from collections.abc import Collection, Iterable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import pandas as pd

from trackctl.errors import InputError, LogError, MissingTopicError
from trackctl.evmatch.eindex import ECatalog
from trackctl.evmatch.engines import Engine
from trackctl.logs import topics
from trackctl.logs.codecs import Codec
from trackctl.logs.messages import EObservations, GroundTruth, VScenario
from trackctl.logs.reader import IndexedWindowReader, LogReader, RawMessage

__all__ = ["ECatalog", "EData", "VSource", "VStore", "load_e", "load_ground_truth"]


@dataclass
class EData(ECatalog):
    """Every E-scenario of a log, as integer codes (the catalog plus the listings).

    Attributes:
        rows: one row per (window, cell, EID) listing: columns ``w``, ``cell``, ``eid`` (codes)
            and ``vague`` (bool), sorted by (w, cell, eid). A scenario's id is
            ``w * len(cells) + cell``.
    """

    rows: pd.DataFrame = field(default_factory=pd.DataFrame)


@dataclass
class _EListings:
    """E-scenarios as streamed: EIDs and cells as integer codes (in order of first sight) in
    flat typed buffers (5 bytes per listing), not millions of Python strings or small arrays."""

    eid_code: dict[str, int] = field(default_factory=dict)
    cell_code: dict[str, int] = field(default_factory=dict)
    t_list: array[int] = field(default_factory=lambda: array("q"))
    """Per scenario: window start, ns."""
    c_list: array[int] = field(default_factory=lambda: array("i"))
    """Per scenario: cell code."""
    lengths: array[int] = field(default_factory=lambda: array("q"))
    """Per scenario: listings."""
    flat_e: array[int] = field(default_factory=lambda: array("i"))
    """Per listing: EID code."""
    flat_v: array[int] = field(default_factory=lambda: array("b"))
    """Per listing: vague (1) or inclusive (0)."""
    window_ns: int | None = None

    def add(self, obs: EObservations) -> None:
        """Append one E-scenario."""
        self.t_list.append(obs.t_ns)
        self.c_list.append(self.cell_code.setdefault(obs.cell, len(self.cell_code)))
        self.lengths.append(len(obs.eids))
        self.flat_e.extend(self.eid_code.setdefault(e, len(self.eid_code)) for e in obs.eids)
        self.flat_v.extend(obs.vague)


def _stream_e(reader: LogReader, topic: str) -> _EListings:
    """Every E-scenario on ``topic`` into flat buffers.

    Raises:
        InputError: windows of different lengths.
    """
    buf = _EListings()
    for msg in reader.messages([topic]):
        obs = msg.message
        if buf.window_ns is None:
            buf.window_ns = obs.window_ns
        elif obs.window_ns != buf.window_ns:
            raise InputError(
                f"{reader.path}: {topic} at {msg.log_time_ns} ns: window_ns {obs.window_ns} "
                f"differs from the first message's {buf.window_ns}; EV-Matching needs one "
                "window length"
            )
        buf.add(obs)
    return buf


def _sorted_codes(code: dict[str, int]) -> tuple[list[str], np.ndarray]:
    """The names in sorted order and the map from a first-sight code to the sorted one (a
    name's code is its index in the sorted list)."""
    names = sorted(code)
    remap = np.empty(len(code), np.int32)
    remap[[code[n] for n in names]] = np.arange(len(names), dtype=np.int32)
    return names, remap


def _listing_columns(
    buf: _EListings,
    t_arr: np.ndarray,
    windows: np.ndarray,
    e_remap: np.ndarray,
    c_remap: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per listing: window, cell and EID codes (sorted-name order) and the vague flag."""
    n_rows = len(buf.flat_e)
    lens = np.frombuffer(buf.lengths, dtype=np.int64) if buf.lengths else np.zeros(0, np.int64)
    w = np.repeat(np.searchsorted(windows, t_arr).astype(np.int32), lens)
    cell_codes = (
        c_remap[np.frombuffer(buf.c_list, dtype=np.int32)] if buf.c_list else np.zeros(0, np.int32)
    )
    c = np.repeat(cell_codes, lens)
    e = e_remap[np.frombuffer(buf.flat_e, dtype=np.int32)] if n_rows else np.zeros(0, np.int32)
    v = np.frombuffer(buf.flat_v, dtype=np.int8).astype(bool) if n_rows else np.zeros(0, bool)
    return w, c, e, v


def _unique_listings(
    w: np.ndarray, c: np.ndarray, e: np.ndarray, v: np.ndarray, n_cells: int, n_eids: int
) -> tuple[np.ndarray | slice, int]:
    """The listings in (window, cell, EID) order, one per EID and scenario (an EID listed twice
    in one scenario keeps its inclusive flag), and the number of scenarios listing any."""
    n_rows = len(e)
    # the key is built in place: a city's E table has tens of millions of listings
    key = w.astype(np.int64)
    key *= max(n_cells, 1)
    key += c
    key *= max(n_eids, 1)
    key += e
    if n_rows and bool(np.all(key[1:] > key[:-1])):
        sel: np.ndarray | slice = slice(None)  # written in order, no repeats (the simulator)
    else:
        order = np.lexsort((v, key))
        key = key[order]
        first = np.r_[True, key[1:] != key[:-1]] if n_rows else np.zeros(0, bool)
        sel = order[first]
        del order, first
    key //= max(n_eids, 1)  # the scenario of each (sorted) listing
    n_scenarios = int(np.count_nonzero(key[1:] != key[:-1])) + 1 if n_rows else 0
    return sel, n_scenarios


def load_e(reader: LogReader, topic: str = topics.EV_E) -> EData:
    """Read every E-scenario on ``topic`` (streamed; memory grows with the listings only).

    Raises:
        MissingTopicError: the log has no E-observations.
        InputError: windows of different lengths.
    """
    if topic not in reader.topics():
        raise MissingTopicError(
            f"{reader.path}: topic {topic} is missing; ev-match needs the E-scenarios "
            "(trackctl.EObservations: EIDs heard per cell and window)"
        )
    buf = _stream_e(reader, topic)
    window_ns = buf.window_ns
    t_arr = np.frombuffer(buf.t_list, dtype=np.int64) if buf.t_list else np.zeros(0, np.int64)
    windows = np.unique(t_arr)
    # codes in sorted-name order: an EID's code is its index in the sorted EID list
    eid_names, e_remap = _sorted_codes(buf.eid_code)
    eids = np.array(eid_names, dtype=object)
    cells, c_remap = _sorted_codes(buf.cell_code)
    w, c, e, v = _listing_columns(buf, t_arr, windows, e_remap, c_remap)
    del buf, t_arr
    sel, n_scenarios = _unique_listings(w, c, e, v, len(cells), len(eids))
    rows = pd.DataFrame({"w": w[sel], "cell": c[sel], "eid": e[sel], "vague": v[sel]})
    del w, c, e, v
    return EData(
        eids=eids,
        cells=cells,
        windows_ns=windows,
        window_ns=int(window_ns or 0),
        e_scenarios=n_scenarios,
        rows=rows,
    )


def load_ground_truth(reader: LogReader, topic: str = topics.EV_GROUND_TRUTH) -> dict[str, str]:
    """EID -> true VID from the ground-truth topic (empty when the log has none)."""
    if topic not in reader.topics():
        return {}
    out: dict[str, str] = {}
    for msg in reader.messages([topic]):
        gt: GroundTruth = msg.message
        for ent in gt.entities:
            if ent.electronic_id is not None and ent.visual_id is not None:
                out[ent.electronic_id] = ent.visual_id
    return out


class VSource(Protocol):
    """Where VID filtering gets its votes: :class:`VStore` (this process) or the Spark engine's
    executors (:class:`~trackctl.evmatch.spark.SparkVStore`)."""

    missing: set[int]
    reads: int
    bytes_read: int

    @property
    def known(self) -> Collection[int]:
        """Scenario ids read so far (with video)."""
        ...

    def vote(
        self,
        engine: Engine,
        eid: np.ndarray,
        scenario: np.ndarray,
        exclude: Collection[str] = (),
    ) -> pd.DataFrame:
        """Each EID's top VIDs (outside ``exclude``) over the given (EID, scenario) pairs
        (``Engine.vote`` columns)."""
        ...


@dataclass
class VStore:
    """Reads V-scenarios on demand, one (cell topic, window) each, and keeps what it read.

    Each scenario is fetched through the MCAP index with a topic filter and the window's time
    range, so the messages decoded are exactly the V-scenarios asked for; ``reads`` and
    ``bytes_read`` count those messages and their encoded sizes.
    """

    reader: LogReader
    data: ECatalog
    cache: dict[int, tuple[str, ...]] = field(default_factory=dict)
    sizes: dict[int, int] = field(default_factory=dict)
    _indexed: IndexedWindowReader | None = None
    _codecs: dict[tuple[str, str, bytes], Codec] = field(default_factory=dict)
    missing: set[int] = field(default_factory=set)
    reads: int = 0
    bytes_read: int = 0

    def total(self) -> int:
        """V-scenarios in the log: messages on the cell V topics."""
        return sum(
            info.count
            for name, info in self.reader.topics().items()
            if name.startswith(topics.EV_V_PREFIX)
        )

    def _window_reader(self) -> IndexedWindowReader | None:
        if self._indexed is None and self.reader.reindex():
            try:
                self._indexed = IndexedWindowReader(self.reader)
            except LogError:
                self._indexed = None
        return self._indexed

    def close(self) -> None:
        """Close the indexed reader, if one was opened."""
        if self._indexed is not None:
            self._indexed.close()
            self._indexed = None

    def _read(self, topic: str, start: int, end: int) -> list[RawMessage]:
        indexed = self._window_reader()
        if indexed is not None:
            return indexed.read(topic, start, end)
        return list(self.reader.raw([topic], start, end))

    def fetch(self, scenarios: Iterable[int]) -> dict[int, tuple[str, ...]]:
        """VIDs of each scenario id that has a V-scenario (read the first time, cached after).

        A scenario whose cell has no V topic, or whose topic has nothing in the window (a camera
        down, a gap in the log, a cut log), is left out of the result and added to
        :attr:`missing`: to the matcher it is VID-missing evidence, as in the dissertation.
        """
        scenarios = [int(s) for s in scenarios]
        wanted = sorted(set(scenarios) - self.cache.keys() - self.missing)
        n_cells = self.data.n_cells
        present = self.reader.topics()
        for s in wanted:
            w, c = divmod(s, n_cells)
            name = topics.ev_v(self.data.cells[c])
            start = int(self.data.windows_ns[w])
            raws = (
                self._read(name, start, start + max(self.data.window_ns, 1))
                if name in present
                else []
            )
            if not raws:
                self.missing.add(s)
                continue
            vids: set[str] = set()
            for raw in raws:
                key = (raw.schema_name, raw.message_encoding, raw.schema_data)
                codec = self._codecs.get(key)
                if codec is None:
                    codec = self._codecs[key] = self.reader.codec(raw)
                try:
                    scen: VScenario = codec.decode(raw.data)
                except Exception as err:  # noqa: BLE001 - foreign bytes may break any decoder
                    self.reader.skip_undecodable(raw, err)
                    continue
                vids.update(scen.vids)
                self.reads += 1
                self.bytes_read += len(raw.data)
                self.sizes[s] = self.sizes.get(s, 0) + len(raw.data)
            if s in self.sizes:
                self.cache[s] = tuple(sorted(vids))
            else:
                self.missing.add(s)
        return {s: self.cache[s] for s in scenarios if s in self.cache}

    @property
    def known(self) -> Collection[int]:
        """Scenario ids read so far (with video)."""
        return self.cache.keys()

    def vote(
        self,
        engine: Engine,
        eid: np.ndarray,
        scenario: np.ndarray,
        exclude: Collection[str] = (),
    ) -> pd.DataFrame:
        """Read the scenarios' V-scenarios and count, per EID, the VIDs over its evidence
        (``engine.vote``: its top VIDs outside ``exclude``); scenarios without video do not
        vote."""
        vids = self.fetch(scenario.tolist())
        return engine.vote(eid, scenario, vids, exclude)

    def missing_topics(self) -> list[str]:
        """V topics of cells listed in the E-observations that the log does not have."""
        present = self.reader.topics()
        return [name for name in (topics.ev_v(c) for c in self.data.cells) if name not in present]
