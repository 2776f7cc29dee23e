"""Every log trackctl writes decodes with the plain `mcap` reader + mcap-protobuf-support (what
Foxglove, Lichtblick and other tools rely on), and JSON channels validate against their schema."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from tests.conftest import run_cli


def assert_plain_decodable(path: Path) -> dict[str, int]:
    """Decode every message of ``path`` without trackctl; return counts per schema."""
    factory = DecoderFactory()
    counts: dict[str, int] = {}
    validators: dict[int, jsonschema.Draft202012Validator] = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            assert schema is not None, f"{channel.topic}: schemaless channel"
            if channel.message_encoding == "protobuf":
                assert schema.encoding == "protobuf"
                decoder = factory.decoder_for("protobuf", schema)
                assert decoder is not None
                decoded = decoder(message.data)
                assert type(decoded).DESCRIPTOR.full_name == schema.name
            else:
                assert (channel.message_encoding, schema.encoding) == ("json", "jsonschema")
                validator = validators.get(schema.id)
                if validator is None:
                    validator = validators[schema.id] = jsonschema.Draft202012Validator(
                        json.loads(schema.data)
                    )
                validator.validate(json.loads(message.data))
            if channel.topic.endswith("/image"):
                assert schema.name == "foxglove.CompressedImage"
            counts[schema.name] = counts.get(schema.name, 0) + 1
    return counts


def test_sample_log(sample_log: Path) -> None:
    counts = assert_plain_decodable(sample_log)
    assert counts["foxglove.CompressedImage"] == 60


@pytest.mark.parametrize("processors", ["check", "dead-reckoning"])
def test_processor_outputs(sample_log: Path, tmp_path: Path, processors: str) -> None:
    out = tmp_path / "o.mcap"
    run_cli(
        "process", str(sample_log), "--with", processors, "--out", str(out), "--quiet", check=True
    )
    counts = assert_plain_decodable(out)
    assert counts["trackctl.MetricReport"] == 1
    if processors == "dead-reckoning":
        assert counts["foxglove.PoseInFrame"] == 500


def test_recorded_log(recorded: Path) -> None:
    counts = assert_plain_decodable(recorded)
    assert counts["foxglove.CameraCalibration"] == 1 and counts["trackctl.CameraModel"] == 1
