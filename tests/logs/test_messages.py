"""Every message type round-trips through its codec and validates against its JSON schema."""

from __future__ import annotations

import json
import math

import jsonschema
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.conftest import ROOT
from trackctl.logs import codecs
from trackctl.logs import messages as m

finite = st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e9, max_value=1e9)
t_ns = st.integers(min_value=0, max_value=2**62)
text = st.text(min_size=1, max_size=12)
vec3 = st.builds(m.Vec3, finite, finite, finite)
quat = st.builds(m.Quat, finite, finite, finite, finite)
opt = st.none

imu = st.builds(m.Imu, t_ns, text, vec3, vec3, st.one_of(opt(), quat))
rssi = st.builds(
    m.RssiScan,
    t_ns,
    text,
    st.lists(st.builds(m.RssiReading, text, finite), max_size=4).map(tuple),
    st.one_of(opt(), vec3),
)
odom = st.one_of(
    st.builds(
        m.WheelOdometry, t_ns, text, st.integers(-(2**40), 2**40), st.integers(-(2**40), 2**40)
    ),
    st.builds(
        m.WheelOdometry,
        t_ns,
        text,
        st.none(),
        st.none(),
        finite,
        finite,
        st.one_of(opt(), st.builds(m.Pose2D, finite, finite, finite)),
    ),
)
box = st.builds(m.BBox, finite, finite, finite, finite)
detection = st.builds(
    m.Detection, box, st.floats(0, 1), text, st.one_of(opt(), vec3), st.one_of(opt(), text)
)
detections = st.builds(m.Detections, t_ns, text, st.lists(detection, max_size=3).map(tuple))
track = st.builds(
    m.Track,
    text,
    vec3,
    st.one_of(opt(), vec3),
    st.one_of(opt(), st.lists(finite, min_size=9, max_size=9).map(tuple)),
    st.sampled_from(list(m.TrackState)),
    st.one_of(opt(), text),
    st.one_of(opt(), st.floats(0, 1)),
)
tracks = st.builds(m.Tracks, t_ns, st.lists(track, max_size=3).map(tuple))
gt = st.builds(
    m.GroundTruth,
    t_ns,
    st.lists(
        st.builds(
            m.GroundTruthEntity,
            text,
            vec3,
            st.one_of(opt(), finite),
            st.one_of(opt(), text),
            st.one_of(opt(), text),
        ),
        max_size=3,
    ).map(tuple),
)
camera = st.builds(
    m.CameraModel,
    t_ns,
    text,
    st.integers(1, 8000),
    st.integers(1, 8000),
    st.floats(1, 1e4),
    st.floats(1, 1e4),
    finite,
    finite,
    st.sampled_from(["plumb_bob", "none"]),
    st.lists(finite, max_size=5).map(tuple),
    st.one_of(opt(), st.builds(m.Transform, vec3, quat)),
)
metric_value = st.one_of(st.none(), st.booleans(), st.integers(-(2**53), 2**53), finite, text)
report = st.builds(
    m.MetricReport,
    t_ns,
    text,
    st.dictionaries(text, metric_value, max_size=4),
    st.dictionaries(text, metric_value, max_size=3),
)

mirror_tx = st.builds(
    m.MirrorTransmission,
    t_ns,
    text,
    st.sampled_from(["image", "beacon"]),
    st.sampled_from(["unicast", "broadcast"]),
    st.integers(0, 1000),
    st.integers(0, 2**31),
    st.integers(0, 2**40),
    st.sampled_from([None, "new", "old"]),
    st.integers(0, 100),
    st.one_of(opt(), st.integers(0, 2**31)),
    st.one_of(opt(), st.floats(0, 1e4)),
)

ALL = st.one_of(imu, rssi, odom, detections, tracks, gt, camera, report, mirror_tx)

# EV-Matching (§3.2) messages: parallel arrays of equal length.
ev_e = st.integers(0, 4).flatmap(
    lambda n: st.builds(
        m.EObservations,
        t_ns,
        st.integers(0, 2**40),
        text,
        st.lists(text, min_size=n, max_size=n).map(tuple),
        st.lists(st.booleans(), min_size=n, max_size=n).map(tuple),
        st.integers(0, 100),
    )
)
ev_v = st.integers(0, 4).flatmap(
    lambda n: st.builds(
        m.VScenario,
        t_ns,
        st.integers(0, 2**40),
        text,
        st.lists(text, min_size=n, max_size=n).map(tuple),
        st.lists(finite, min_size=n, max_size=n).map(tuple),
        st.lists(finite, min_size=n, max_size=n).map(tuple),
        st.lists(st.integers(0, 1000), min_size=n, max_size=n).map(tuple),
    )
)
ev_matches = st.builds(
    m.EvMatches,
    t_ns,
    st.sampled_from(["ss", "edp"]),
    st.lists(
        st.builds(
            m.EvMatch,
            text,
            st.one_of(opt(), text),
            st.floats(0, 1),
            st.lists(text, max_size=3).map(tuple),
            st.text(max_size=12),
        ),
        max_size=3,
    ).map(tuple),
)
ALL = st.one_of(ALL, ev_e, ev_v, ev_matches)


def _schema(cls: type) -> dict:
    return json.loads((codecs.formats_dir() / f"{cls.SCHEMA}.json").read_text())


@given(ALL)
def test_codec_round_trip(msg: object) -> None:
    codec = codecs.codec_for_type(type(msg))
    data = codec.encode(msg)
    assert codec.decode(data) == msg


@given(ALL)
def test_encoded_message_validates_against_its_schema(msg: object) -> None:
    codec = codecs.codec_for_type(type(msg))
    jsonschema.validate(json.loads(codec.encode(msg)), _schema(type(msg)))


@given(ALL)
def test_jsonl_payload_round_trip(msg: object) -> None:
    codec = codecs.codec_for_type(type(msg))
    data = codec.encode(msg)
    assert codec.from_jsonable(codec.to_jsonable(data)) == data


@pytest.mark.parametrize("cls", m.MESSAGE_TYPES)
def test_every_message_type_has_a_valid_schema_file(cls: type) -> None:
    schema = _schema(cls)
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["title"] == cls.SCHEMA


@given(t_ns)
def test_time_json_round_trip(t: int) -> None:
    assert m.time_from_json(m.time_to_json(t)) == t


def test_nan_is_refused_by_the_encoder() -> None:
    codec = codecs.codec_for_type(m.Imu)
    msg = m.Imu(0, "p", m.Vec3(math.nan, 0, 0), m.Vec3(0, 0, 0))
    with pytest.raises(ValueError, match="Out of range float values"):
        codec.encode(msg)


def test_wheel_odometry_needs_ticks_or_velocities() -> None:
    with pytest.raises(ValueError, match="left_ticks and right_ticks, or v_mps and omega_rps"):
        m.WheelOdometry(0, "robot/r1")


def test_track_covariance_needs_nine_values() -> None:
    with pytest.raises(ValueError, match="covariance_m2 needs 9 values"):
        m.Track("a", m.Vec3(0, 0, 0), covariance_m2=(1.0, 0.0))


def test_camera_model_rejects_nonpositive_focal_length() -> None:
    with pytest.raises(ValueError, match="focal lengths must be positive"):
        m.CameraModel(0, "cam0", 640, 480, 0.0, 500.0, 320, 240)


@pytest.mark.parametrize("cls", m.MESSAGE_TYPES, ids=lambda c: c.SCHEMA)
def test_committed_schema_is_generated_from_the_class(cls: type) -> None:
    from trackctl.logs.jsonmap import schema_text

    committed = (ROOT / "formats" / f"{cls.SCHEMA}.json").read_text()  # type: ignore[attr-defined]
    assert committed == schema_text(cls), (
        f"formats/{cls.SCHEMA}.json is stale: regenerate with `make formats`"  # type: ignore[attr-defined]
    )


def test_a_message_type_is_one_class() -> None:
    # no hand-written JSON methods left: every message maps through trackctl.logs.jsonmap
    from trackctl.logs.jsonmap import JsonMessage

    for cls in m.MESSAGE_TYPES:
        assert issubclass(cls, JsonMessage)
        assert "to_json" not in vars(cls) and "from_json" not in vars(cls)
