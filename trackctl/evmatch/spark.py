"""EV-Matching on Apache Spark with the data work on the executors.

The driver opens only the log's summary (or, for a cut log, rebuilds its index once and ships it).
Everything that touches E-observations or V-scenarios runs in executor tasks that open the log
themselves and read only the chunks they need through the MCAP chunk index:

* **E shards**: the E chunks are cut into groups of consecutive windows; one task per group reads
  its chunks and builds an :class:`~trackctl.evmatch.eindex.EShard` (integer-coded with the codes
  the driver fixed from the EID, cell and window names the tasks reported). The shards stay
  persisted on the executors; set splitting, evidence and refining questions are Spark jobs over
  them (:class:`~trackctl.evmatch.eindex.EIndex`), and the driver receives only the answers.
* **V votes**: VID filtering ships the (EID, scenario) evidence pairs cut by EID to the
  executors; each task reads the V-scenarios its EIDs need (topic and time through the index,
  cached in the Python worker across rounds), counts its EIDs' VIDs with the local engine's
  vectorised vote and returns only each EID's best two VIDs. The driver gets those and which
  scenarios were read or missing, never the VIDs of a scenario; no (EID, VID) record goes
  through a shuffle (a city's evidence has tens of millions).

The log path must be readable at the same path on every executor (a local path on a one-machine
cluster, or a shared filesystem such as NFS).
"""

from __future__ import annotations

import os
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from mcap.records import Channel, ChunkIndex
from mcap.summary import Summary

from trackctl.errors import InputError, MissingTopicError
from trackctl.evmatch.eindex import ECatalog, EIndex, EShard
from trackctl.evmatch.engines import (
    TOP_VIDS,
    VOTE_COLUMNS,
    SparkEngine,
    _sorted_vote,
    collect_columns,
)
from trackctl.logs import topics
from trackctl.logs.reader import LogReader

__all__ = ["spark_index", "SparkVStore"]

_WINDOWS_PER_SHARD = 1


@dataclass(frozen=True)
class _ChunkTask:
    """What one executor task reads: a log's E chunks (file offsets) and how to decode them."""

    path: str
    offsets: tuple[int, ...]
    channel_id: int
    schema: tuple[str, str, str, bytes]  # name, message encoding, schema encoding, data


def _read_e(task: _ChunkTask) -> Iterator[Any]:
    """The E-observations in the task's chunks (executor side)."""
    import struct

    from mcap.records import Message

    from trackctl.logs.codecs import codec_for
    from trackctl.logs.recovery import ChunkError, decode_chunk

    codec = codec_for(*task.schema)
    with open(task.path, "rb") as f:
        for offset in task.offsets:
            f.seek(offset)
            head = f.read(9)
            (length,) = struct.unpack_from("<Q", head, 1)
            try:
                records = decode_chunk(f.read(length))
            except ChunkError:
                continue  # the driver's reader reports damaged chunks; a shard skips them too
            for record in records:
                if isinstance(record, Message) and record.channel_id == task.channel_id:
                    yield codec.decode(record.data)


def _names(task: _ChunkTask) -> Iterator[tuple[str, Any]]:
    """The EIDs, cells, window starts and window lengths of a task's E-observations, tagged
    (``distinct`` then removes the repeats on the executors)."""
    seen: set[tuple[str, Any]] = set()
    for obs in _read_e(task):
        for item in (("c", obs.cell), ("t", obs.t_ns), ("l", obs.window_ns)):
            if item not in seen:
                seen.add(item)
                yield item
        for e in obs.eids:
            item = ("e", e)
            if item not in seen:
                seen.add(item)
                yield item


def _build_shard(task: _ChunkTask, codes: Any, rank: np.ndarray) -> EShard:
    """An E shard of the task's chunks with the driver's codes (executor side)."""
    eid_names, cell_code, window_code = codes.value
    eid_code = {str(name): i for i, name in enumerate(eid_names.tolist())}
    w: list[int] = []
    c: list[int] = []
    e: list[int] = []
    v: list[bool] = []
    for obs in _read_e(task):
        n = len(obs.eids)
        w.extend([window_code[obs.t_ns]] * n)
        c.extend([cell_code[obs.cell]] * n)
        e.extend(eid_code[x] for x in obs.eids)
        v.extend(obs.vague)
    wa, ca, ea = (np.asarray(x, np.int64) for x in (w, c, e))
    va = np.asarray(v, bool)
    n_cells, n_eids = len(cell_code), len(eid_code)
    # sort by (window, cell, EID); an EID listed twice in one scenario keeps its inclusive flag
    key = (wa * max(n_cells, 1) + ca) * max(n_eids, 1) + ea
    order = np.lexsort((va, key))
    first = np.r_[True, key[order][1:] != key[order][:-1]] if len(key) else np.zeros(0, bool)
    sel = order[first]
    shard = EShard(
        w=wa[sel].astype(np.int32),
        cell=ca[sel].astype(np.int32),
        eid=ea[sel].astype(np.int32),
        vague=va[sel],
        n_cells=n_cells,
        n_eids=n_eids,
        rank=rank,
    )
    shard._inclusive()  # built once here and persisted with the shard
    return shard


def _e_channel(reader: LogReader) -> tuple[Summary, Channel]:
    """The log's summary and its E-scenario channel.

    Raises:
        MissingTopicError: the log has no summary or no E-scenarios.
    """
    summary = reader.summary
    channel = next(
        (ch for ch in (summary.channels.values() if summary else ()) if ch.topic == topics.EV_E),
        None,
    )
    if summary is None or channel is None:
        raise MissingTopicError(
            f"{reader.path}: topic {topics.EV_E} is missing; ev-match needs the E-scenarios"
        )
    return summary, channel


def _decode_spec(summary: Summary, channel: Channel) -> tuple[str, str, str, bytes]:
    """How the executors decode the channel: schema name, message encoding, schema encoding,
    schema data (empty without a schema)."""
    schema = summary.schemas.get(channel.schema_id)
    if schema is None:
        return "", channel.message_encoding, "", b""
    return schema.name, channel.message_encoding, schema.encoding, schema.data


def _chunk_groups(chunks: Sequence[ChunkIndex]) -> list[list[int]]:
    """Offsets of consecutive chunks (in time order) grouped to cover about
    ``_WINDOWS_PER_SHARD`` distinct start times each."""
    groups: list[list[int]] = []
    last_start: int | None = None
    starts_in_group = 0
    for ci in chunks:
        new_start = ci.message_start_time != last_start
        if not groups or (new_start and starts_in_group >= _WINDOWS_PER_SHARD):
            groups.append([])
            starts_in_group = 0
        if new_start:
            starts_in_group += 1
            last_start = ci.message_start_time
        groups[-1].append(ci.chunk_start_offset)
    return groups


def _e_tasks(reader: LogReader, path: str) -> list[_ChunkTask]:
    summary, channel = _e_channel(reader)
    spec = _decode_spec(summary, channel)
    chunks = sorted(
        (ci for ci in summary.chunk_indexes if channel.id in ci.message_index_offsets),
        key=lambda ci: (ci.message_start_time, ci.chunk_start_offset),
    )
    return [_ChunkTask(path, tuple(g), channel.id, spec) for g in _chunk_groups(chunks)]


def spark_index(
    reader: LogReader, engine: SparkEngine, order_seed: int
) -> tuple[EIndex, np.ndarray]:
    """Build the E index on the executors; returns it and the random window order.

    Raises:
        MissingTopicError: the log has no E-observations.
        InputError: windows of different lengths, or the log has no index to read it by.
    """
    from pyspark import StorageLevel

    from trackctl.evmatch.matcher import window_order

    if not reader.reindex() and reader.summary is None:
        raise InputError(f"{reader.path}: no chunk index; the Spark engine reads logs by chunk")
    path = os.path.abspath(reader.path)
    tasks = _e_tasks(reader, path)
    sc = engine.sc
    names = sc.parallelize(tasks, max(len(tasks), 1)).flatMap(_names).distinct().persist()
    # the EIDs come back as one array per partition, not a Python tuple each
    blocks = (
        names.filter(lambda kv: kv[0] == "e")
        .map(lambda kv: kv[1])
        .mapPartitions(lambda it: [np.array(list(it), dtype=object)])
        .collect()
    )
    found: dict[str, list[Any]] = {"c": [], "t": [], "l": []}
    for kind, value in names.filter(lambda kv: kv[0] != "e").collect():
        found[kind].append(value)
    names.unpersist()
    eids = np.unique(np.concatenate(blocks)) if blocks else np.zeros(0, object)
    del blocks
    cells = sorted(found["c"])
    starts = np.array(sorted(found["t"]), dtype=np.int64)
    lengths = sorted(found["l"])
    if len(lengths) > 1:
        raise InputError(
            f"{reader.path}: {topics.EV_E}: windows of {len(lengths)} lengths "
            f"({', '.join(str(x) for x in lengths[:3])} ns); EV-Matching needs one"
        )
    order = window_order(len(starts), order_seed)
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    # the sorted EID names go out as they are; each task makes its own name -> code map
    codes = sc.broadcast(
        (
            eids,
            {c: i for i, c in enumerate(cells)},
            {int(t): i for i, t in enumerate(starts.tolist())},
        )
    )
    shards = (
        sc.parallelize(tasks, max(len(tasks), 1))
        .map(lambda t: _build_shard(t, codes, rank))
        .persist(StorageLevel.MEMORY_AND_DISK)
    )
    info = shards.map(lambda sh: (sh.windows.tolist(), len(np.unique(sh.w * sh.n_cells + sh.cell))))
    per_shard = info.collect()
    codes.unpersist()
    holders: dict[int, list[int]] = {}
    for i, (windows, _) in enumerate(per_shard):
        for w in windows:
            holders.setdefault(int(w), []).append(i)
    catalog = ECatalog(
        eids=eids,
        cells=cells,
        windows_ns=starts,
        window_ns=int(lengths[0]) if lengths else 0,
        e_scenarios=sum(n for _, n in per_shard),
    )

    def run(name: str, args: tuple[Any, ...], window: int | None) -> list[Any]:
        shipped = sc.broadcast(args)

        def call(shard: EShard) -> Any:
            return getattr(shard, name)(*shipped.value)

        try:
            if window is None:
                return shards.map(call).collect()
            parts = holders.get(window, [])
            if not parts:
                return []
            return sc.runJob(shards, lambda it: [call(sh) for sh in it], partitions=parts)
        finally:
            shipped.unpersist()

    def run_pairs(
        name: str, args: tuple[Any, ...], merge: Any, finish: Any
    ) -> tuple[np.ndarray, np.ndarray]:
        shipped = sc.broadcast(args)

        def call(shard: EShard) -> Any:
            return list(getattr(shard, name)(*shipped.value).items())

        try:
            pairs = (
                shards.flatMap(call)
                .reduceByKey(merge, engine.partitions)
                .flatMap(lambda kv: [(kv[0], x) for x in finish(kv[1])])
            )
            got = collect_columns(pairs, ["key", "value"], (np.int64, np.int64))
        finally:
            shipped.unpersist()
        return got["key"].to_numpy(np.int64), got["value"].to_numpy(np.int64)

    def close() -> None:
        shards.unpersist()

    return EIndex(catalog, run, rank, close=close, run_pairs=run_pairs), order


# -- V-scenarios on the executors ---------------------------------------------------------------

_V_CACHE: dict[tuple[str, int], tuple[str, ...] | None] = {}
_V_CACHE_LIMIT = 500_000


def _vote_eid_block(
    path: str,
    summary: Any,
    cells: Sequence[str],
    windows_ns: np.ndarray,
    window_ns: int,
    n_cells: int,
    banned: Any,
    block: tuple[np.ndarray, np.ndarray],
) -> list[tuple[str, Any]]:
    """Executor side of one vote task: all evidence pairs of some EIDs. Reads the V-scenarios
    they need (cached in the Python worker across rounds and tasks), counts each EID's VIDs with
    the local engine's vectorised vote, and returns its top VIDs plus which scenarios it read
    (first read in this worker, with their bytes) or found missing. Only the top VIDs per EID
    leave the task: no (EID, VID) record goes through a shuffle."""
    from trackctl.evmatch.engines import LocalEngine
    from trackctl.logs.reader import IndexedWindowReader

    e_arr, s_arr = block
    window_reader: IndexedWindowReader | None = None
    reader: LogReader | None = None
    seen: list[tuple[str, int, int]] = []
    vids: dict[int, tuple[str, ...]] = {}
    try:
        for s in np.unique(s_arr).tolist():
            key = (path, s)
            if key not in _V_CACHE:
                if window_reader is None:
                    reader = LogReader(path)
                    window_reader = IndexedWindowReader(reader, summary=summary)
                got, size = _read_v(reader, window_reader, cells, windows_ns, window_ns, n_cells, s)
                if len(_V_CACHE) >= _V_CACHE_LIMIT:
                    _V_CACHE.clear()
                _V_CACHE[key] = got
                seen.append(("missing" if got is None else "read", s, size))
            cached = _V_CACHE[key]
            if cached is None:
                seen.append(("missing", s, 0))
            else:
                vids[s] = cached
    finally:
        if window_reader is not None:
            window_reader.close()
    counts = LocalEngine().vote(e_arr, s_arr, vids, banned.value, TOP_VIDS)
    return [
        ("seen", seen),
        (
            "top",
            (
                counts["eid"].to_numpy(np.int64),
                counts["vid"].to_numpy(object),
                counts["count"].to_numpy(np.int64),
            ),
        ),
    ]


def _read_v(
    reader: Any,
    window_reader: Any,
    cells: Sequence[str],
    windows_ns: np.ndarray,
    window_ns: int,
    n_cells: int,
    s: int,
) -> tuple[tuple[str, ...] | None, int]:
    w, c = divmod(s, n_cells)
    topic = topics.ev_v(cells[c])
    if not window_reader.has_topic(topic):
        return None, 0
    start = int(windows_ns[w])
    raws = window_reader.read(topic, start, start + max(window_ns, 1))
    vids: set[str] = set()
    size = 0
    ok = False
    for raw in raws:
        try:
            scen = reader.codec(raw).decode(raw.data)
        except Exception:  # noqa: BLE001 - the driver-side reader reports undecodable messages
            continue
        ok = True
        vids.update(scen.vids)
        size += len(raw.data)
    return (tuple(sorted(vids)) if ok else None), size


@dataclass
class SparkVStore:
    """V-scenarios read and voted on by the executors (the driver keeps ids and counts only).

    Same interface as :class:`~trackctl.evmatch.data.VStore` for SS: ``vote``, ``known``,
    ``missing``, ``reads``, ``bytes_read``, ``total``, ``missing_topics``.
    """

    reader: LogReader
    data: ECatalog
    engine: SparkEngine
    read_ids: set[int] = field(default_factory=set)
    missing: set[int] = field(default_factory=set)
    reads: int = 0
    bytes_read: int = 0

    @property
    def known(self) -> Collection[int]:
        return self.read_ids

    def total(self) -> int:
        return sum(
            info.count
            for name, info in self.reader.topics().items()
            if name.startswith(topics.EV_V_PREFIX)
        )

    def missing_topics(self) -> list[str]:
        present = self.reader.topics()
        return [n for n in (topics.ev_v(c) for c in self.data.cells) if n not in present]

    def close(self) -> None:
        pass

    def vote(
        self,
        engine: Any,
        eid: np.ndarray,
        scenario: np.ndarray,
        exclude: Collection[str] = (),
    ) -> pd.DataFrame:
        sc, p = self.engine.sc, self.engine.partitions
        if not len(eid):
            return _sorted_vote(pd.DataFrame(columns=VOTE_COLUMNS))
        cat = self.data
        path = os.path.abspath(self.reader.path)
        summary = None if not self.reader.truncated else self.reader.summary
        args = (path, summary, cat.cells, cat.windows_ns, cat.window_ns, cat.n_cells)
        # the evidence pairs cut by EID on the driver (numpy, no shuffle): each task holds all
        # the evidence of its EIDs and ranks their VIDs itself
        by_task = np.argsort(np.asarray(eid) % p, kind="stable")
        e_all, s_all = np.asarray(eid)[by_task], np.asarray(scenario)[by_task]
        del by_task
        bounds = np.r_[0, np.cumsum(np.bincount(e_all % p, minlength=p))]
        blocks = [
            (e_all[bounds[i] : bounds[i + 1]], s_all[bounds[i] : bounds[i + 1]]) for i in range(p)
        ]
        banned = sc.broadcast(frozenset(exclude))
        try:
            parts = (
                sc.parallelize(blocks, p)
                .flatMap(lambda block: _vote_eid_block(*args, banned, block))
                .collect()
            )
        finally:
            banned.unpersist()
        tops = []
        for kind, value in parts:
            if kind == "top":
                tops.append(value)
                continue
            for what, s, size in value:
                if what == "missing":
                    self.missing.add(int(s))
                elif int(s) not in self.read_ids:
                    self.read_ids.add(int(s))
                    self.reads += 1
                    self.bytes_read += size
        counts = pd.DataFrame(
            {
                "eid": np.concatenate([t[0] for t in tops]),
                "vid": np.concatenate([t[1] for t in tops]),
                "count": np.concatenate([t[2] for t in tops]),
            }
        )
        return _sorted_vote(counts)
