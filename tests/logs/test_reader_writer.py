"""LogWriter/LogReader: round trips, filters, atomicity, truncation, bad files."""

from __future__ import annotations

import os
import tracemalloc
import warnings
from pathlib import Path

import pytest
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from trackctl.errors import (
    MissingTopicError,
    NotAFileError,
    NotAnMcapError,
    OutputError,
    TruncatedLogWarning,
)
from trackctl.logs import Imu, LogReader, LogWriter, RssiReading, RssiScan, Vec3

S = 1_000_000_000


def _imu(i: int) -> Imu:
    return Imu(i * 10_000_000, "phone/p1", Vec3(0.0, 0.1 * i, 9.81), Vec3(0.0, 0.0, 0.01))


def _write(path: Path, n: int = 300, compression: str = "zstd", chunk_size: int = 4096) -> None:
    with LogWriter(path, compression=compression, chunk_size=chunk_size) as w:
        for i in range(n):
            w.write("/phone/p1/imu", _imu(i))
            if i % 10 == 0:
                w.write("/rssi", RssiScan(i * 10_000_000, "ap1", (RssiReading("aa", -50.0),)))
        img = CompressedImage(frame_id="cam0", data=b"\xff\xd8\x00\x01", format="jpeg")
        img.timestamp.FromNanoseconds(15_000_000)
        w.write("/cam0/image", img, 15_000_000)
        w.add_metadata("scenario", {"seed": 3})
        w.add_attachment("notes.txt", b"hello", "text/plain")


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_round_trip_every_compression(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "a.mcap"
    _write(path, compression=compression)
    reader = LogReader(path)
    topics = reader.topics()
    assert topics["/phone/p1/imu"].count == 300
    assert topics["/rssi"].count == 30
    assert topics["/cam0/image"].schema_name == "foxglove.CompressedImage"
    msgs = [m for m in reader.messages(["/phone/p1/imu"])]
    assert [m.message for m in msgs] == [_imu(i) for i in range(300)]
    assert reader.metadata() == {"scenario": {"seed": "3"}}
    assert reader.attachments() == {"notes.txt": ("text/plain", b"hello")}


def test_messages_come_in_log_time_order_and_respect_time_range(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write(path)
    reader = LogReader(path)
    times = [m.log_time_ns for m in reader.raw()]
    assert times == sorted(times)
    window = list(reader.raw(start_ns=1 * S, end_ns=2 * S))
    assert window and all(S <= m.log_time_ns < 2 * S for m in window)
    assert len([m for m in window if m.topic == "/phone/p1/imu"]) == 100


def test_topic_rates_and_span(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write(path)
    info = LogReader(path).topics()["/phone/p1/imu"]
    assert info.first_ns == 0 and info.last_ns == 299 * 10_000_000
    assert info.rate_hz == pytest.approx(100.0)


def test_every_channel_decodes_with_the_plain_mcap_readers(tmp_path: Path) -> None:
    import json

    path = tmp_path / "a.mcap"
    _write(path)
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        n = 0
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "protobuf":
                decoder = DecoderFactory().decoder_for(channel.message_encoding, schema)
                assert decoder is not None
                assert decoder(message.data).format == "jpeg"
            else:
                assert channel.message_encoding == "json"
                assert schema.encoding == "jsonschema"
                json.loads(message.data)
            n += 1
    assert n == 331


def test_writer_is_atomic_on_error(tmp_path: Path) -> None:
    path = tmp_path / "out.mcap"
    path.write_bytes(b"previous content")
    with pytest.raises(RuntimeError):
        with LogWriter(path) as w:
            w.write("/phone/p1/imu", _imu(0))
            raise RuntimeError("boom")
    assert path.read_bytes() == b"previous content"
    assert [p.name for p in tmp_path.iterdir()] == ["out.mcap"]


def test_output_equal_to_input_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write(path)
    before = path.read_bytes()
    with pytest.raises(OutputError, match="output path is the input log"):
        LogWriter(path, inputs=[tmp_path / "." / "a.mcap"])
    assert path.read_bytes() == before


def test_topic_schema_conflict_is_refused(tmp_path: Path) -> None:
    with LogWriter(tmp_path / "a.mcap") as w:
        w.write("/x", _imu(0))
        with pytest.raises(OutputError, match="already written with schema trackctl.Imu"):
            w.write("/x", RssiScan(0, "ap", ()))


def test_output_permissions_follow_umask(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write(path, n=5)
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


def test_not_a_file(tmp_path: Path) -> None:
    with pytest.raises(NotAFileError, match="no such file"):
        LogReader(tmp_path / "missing.mcap")
    with pytest.raises(NotAFileError, match="not a regular file"):
        LogReader(tmp_path)


def test_not_an_mcap(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    path.write_text("t_s,ax\n1,2\n")
    with pytest.raises(NotAnMcapError, match="x.mcap: not an MCAP file"):
        LogReader(path)


def test_truncated_log_is_read_as_far_as_it_goes(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write(path, n=2000)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        reader = LogReader(cut)
        msgs = list(reader.messages(["/phone/p1/imu"]))
    assert reader.truncated
    assert any(issubclass(w.category, TruncatedLogWarning) for w in caught)
    assert any("log is cut at byte" in w and "the rest is lost" in w for w in reader.warnings)
    # every message that survived is intact and in order
    assert 500 < len(msgs) < 2000
    assert [m.message for m in msgs] == [_imu(i) for i in range(len(msgs))]


def test_require_names_the_missing_topic_and_who_needs_it(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write(path, n=5)
    with pytest.raises(MissingTopicError, match=r"topic /cam9/image is missing; vm-track needs it"):
        LogReader(path).require(["/rssi", "/cam9/image"], "vm-track", "camera frames")


def test_reading_memory_does_not_grow_with_log_length(tmp_path: Path) -> None:
    peaks = []
    for n in (5_000, 50_000):
        path = tmp_path / f"{n}.mcap"
        with LogWriter(path) as w:
            for i in range(n):
                w.write("/phone/p1/imu", _imu(i))
        tracemalloc.start()
        count = sum(1 for _ in LogReader(path).messages())
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
        assert count == n
    assert peaks[1] < 2.0 * peaks[0] + 1_000_000, peaks
