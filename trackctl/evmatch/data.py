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
from trackctl.logs.messages import GroundTruth, VScenario
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
    # EIDs and cells become integer codes while streaming, into flat typed buffers (5 bytes per
    # listing), not millions of Python strings or small arrays
    eid_code: dict[str, int] = {}
    cell_code: dict[str, int] = {}
    t_list = array("q")
    c_list = array("i")
    lengths = array("q")
    flat_e = array("i")
    flat_v = array("b")
    window_ns = None
    for msg in reader.messages([topic]):
        obs = msg.message
        if window_ns is None:
            window_ns = obs.window_ns
        elif obs.window_ns != window_ns:
            raise InputError(
                f"{reader.path}: {topic} at {msg.log_time_ns} ns: window_ns {obs.window_ns} "
                f"differs from the first message's {window_ns}; EV-Matching needs one window length"
            )
        t_list.append(obs.t_ns)
        c_list.append(cell_code.setdefault(obs.cell, len(cell_code)))
        lengths.append(len(obs.eids))
        flat_e.extend(eid_code.setdefault(e, len(eid_code)) for e in obs.eids)
        flat_v.extend(obs.vague)
    t_arr = np.frombuffer(t_list, dtype=np.int64) if t_list else np.zeros(0, np.int64)
    windows = np.unique(t_arr)
    # codes in sorted-name order: an EID's code is its index in the sorted EID list
    eids = np.array(sorted(eid_code), dtype=object)
    e_remap = np.empty(len(eid_code), np.int32)
    e_remap[[eid_code[e] for e in eids]] = np.arange(len(eids), dtype=np.int32)
    cells = sorted(cell_code)
    c_remap = np.empty(len(cell_code), np.int32)
    c_remap[[cell_code[c] for c in cells]] = np.arange(len(cells), dtype=np.int32)
    n_rows = len(flat_e)
    lens = np.frombuffer(lengths, dtype=np.int64) if lengths else np.zeros(0, np.int64)
    w = np.repeat(np.searchsorted(windows, t_arr).astype(np.int32), lens)
    c = np.repeat(
        c_remap[np.frombuffer(c_list, dtype=np.int32)] if c_list else np.zeros(0, np.int32), lens
    )
    e = e_remap[np.frombuffer(flat_e, dtype=np.int32)] if n_rows else np.zeros(0, np.int32)
    v = np.frombuffer(flat_v, dtype=np.int8).astype(bool) if n_rows else np.zeros(0, bool)
    del flat_e, flat_v
    # sort by (window, cell, EID); an EID listed twice in one scenario keeps its inclusive flag.
    # The key is built in place: a city's E table has tens of millions of listings.
    key = w.astype(np.int64)
    key *= max(len(cells), 1)
    key += c
    key *= max(len(eids), 1)
    key += e
    if n_rows and bool(np.all(key[1:] > key[:-1])):
        sel: np.ndarray | slice = slice(None)  # written in order, no repeats (the simulator)
    else:
        order = np.lexsort((v, key))
        key = key[order]
        first = np.r_[True, key[1:] != key[:-1]] if n_rows else np.zeros(0, bool)
        sel = order[first]
        del order, first
    key //= max(len(eids), 1)  # the scenario of each (sorted) listing
    n_scenarios = int(np.count_nonzero(key[1:] != key[:-1])) + 1 if n_rows else 0
    del key
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
