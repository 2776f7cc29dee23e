"""Pacing, rate meter and the JSON lines format (unit level, fake clocks)."""

from __future__ import annotations

import json

import pytest

from trackctl.errors import InputError, SchemaError, UnknownSchemaError
from trackctl.logs.jsonl import parse_jsonl, to_jsonl
from trackctl.logs.reader import RawMessage
from trackctl.logs.replay import RateMeter, paced, parse_host_port


def _raw(t_ns: int, topic: str = "/a") -> RawMessage:
    return RawMessage(
        topic,
        "trackctl.MetricReport",
        "jsonschema",
        b"",
        "json",
        t_ns,
        t_ns,
        b'{"timestamp":{"sec":0,"nsec":0},"processor":"p","metrics":{},"params":{},"unmeasured":{}}',
    )


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now

    def sleep(self, dt: float) -> None:
        self.sleeps.append(dt)
        self.now += dt


@pytest.mark.parametrize("speed", [1.0, 2.0, 0.5])
def test_paced_waits_log_time_over_speed(speed: float) -> None:
    clock = FakeClock()
    msgs = [_raw(t) for t in (0, 500_000_000, 1_500_000_000)]
    out = list(paced(msgs, speed, clock=clock, sleep=clock.sleep))
    assert out == msgs
    assert clock.sleeps == pytest.approx([0.5 / speed, 1.0 / speed])


def test_speed_zero_never_sleeps_and_negative_is_refused() -> None:
    clock = FakeClock()
    assert len(list(paced([_raw(0), _raw(10**9)], 0, clock=clock, sleep=clock.sleep))) == 2
    assert clock.sleeps == []
    with pytest.raises(InputError, match="--speed must be >= 0"):
        list(paced([_raw(0)], -1))


def test_rate_meter_counts_over_its_window() -> None:
    clock = FakeClock()
    meter = RateMeter(window_s=1.0, clock=clock)
    for i in range(10):
        meter.add(_raw(i, "/a"))
        clock.now += 0.25
    rows = {r[0]: r for r in meter.rows()}
    assert rows["/a"][2] == 10
    assert rows["/a"][3] == pytest.approx(4.0)  # 4 messages in the last second


def test_jsonl_passthrough_and_parse_round_trip() -> None:
    from trackctl.logs.codecs import codec_for

    raw = _raw(42)
    line = to_jsonl(raw, codec_for(raw.schema_name, "json"))
    obj = json.loads(line)
    assert obj["log_time_ns"] == 42 and obj["message"]["processor"] == "p"
    rec = parse_jsonl(line)
    assert (rec.topic, rec.log_time_ns) == ("/a", 42)
    assert json.loads(rec.data) == obj["message"]


@pytest.mark.parametrize(
    "line, error, match",
    [
        ("not json", InputError, r"<stdin>:3: not valid JSON"),
        ("[1, 2]", InputError, "expected a JSON object"),
        ('{"topic": "/a", "schema": "trackctl.Imu"}', InputError, "field 'message' is missing"),
        (
            '{"topic": "/a", "schema": "acme.X", "message": {}}',
            UnknownSchemaError,
            "unknown schema",
        ),
        (
            '{"topic": "/a", "schema": "trackctl.Imu", "message": {"frame_id": "x"}}',
            SchemaError,
            r"topic /a: trackctl.Imu: missing field 'timestamp'",
        ),
        (
            '{"topic": "/a", "schema": "trackctl.Imu", "log_time_ns": -5, "message": {}}',
            InputError,
            r"log_time_ns' must be an integer in 0..2\^64-1 \(got -5\)",
        ),
    ],
)
def test_bad_lines_name_line_topic_and_field(line: str, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        parse_jsonl(line, "<stdin>", 3)


def test_missing_log_time_uses_arrival_time() -> None:
    line = json.dumps(
        {
            "topic": "/a",
            "schema": "trackctl.MetricReport",
            "message": {"timestamp": {"sec": 1, "nsec": 0}, "processor": "p", "metrics": {}},
        }
    )
    assert parse_jsonl(line, now_ns=123).log_time_ns == 123


def test_host_port() -> None:
    assert parse_host_port("127.0.0.1:9870") == ("127.0.0.1", 9870)
    with pytest.raises(InputError, match="expected HOST:PORT"):
        parse_host_port("9870")
