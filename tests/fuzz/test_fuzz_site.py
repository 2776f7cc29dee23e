"""Seeded mutations of a site YAML: read by ``record --site`` (the parse and every range) and,
when it parses, laid over the S-Mirror sample log's site (what smirror builds from it)."""

from __future__ import annotations

import random
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.conftest import ROOT
from tests.fuzz.common import Fuzz, mutate_text
from trackctl.errors import TrackctlError
from trackctl.ingest.site import read_site
from trackctl.logs import LogReader

CASES = 50
SITE = {
    "robots": {
        "r1": {
            "ticks_per_m": 2000,
            "wheel_base_m": 0.3,
            "led_height_m": 0.32,
            "led_front_m": 0.15,
            "led_back_m": -0.15,
            "front_hue": [45, 80],
        }
    },
    "smirror": {
        "requesters": 2,
        "floorplan": {
            "size_m": [27.0, 8.0],
            "wall_height_m": 2.6,
            "walls": [[[0, 0], [27, 0]], [[9, 0], [9, 3.2]]],
            "rooms": [[0, 0, 9, 8], [9, 0, 27, 8]],
        },
    },
    "bridgeloc": {"robot": "r1", "tag_n": 2, "tag_size_m": 0.3, "max_range_m": 4.5},
}


def _use(path: Path, reader: LogReader) -> None:
    """What smirror does with a site that parsed: its site, a coverage query, the robot."""
    from trackctl.smirror import SmirrorConfig
    from trackctl.smirror.site import load_site

    try:
        records = read_site(path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            site = load_site(reader, SmirrorConfig(site=records))
        site.cover.covering(np.array([5.0, 4.0]))
    except TrackctlError:
        pass


def test_fuzz_site_yaml(tmp_path: Path, record_property: pytest.RecordProperty) -> None:
    fuzz = Fuzz("site YAML", record_property)
    reader = LogReader(ROOT / "sample_logs" / "smirror.mcap")
    text = yaml.safe_dump(SITE, default_flow_style=None)
    worst: list[Path] = []
    for case in range(CASES):
        rng = random.Random(f"site/{case}")
        mutant = text
        for _ in range(rng.choice([1, 1, 2, 3])):
            mutant = mutate_text(mutant, rng)
        site = tmp_path / f"site{case}.yaml"
        site.write_bytes(mutant.encode("utf-8", "surrogateescape"))
        fuzz.cases += 1
        fuzz.invoke(["record", str(tmp_path / "o.mcap"), "--site", str(site), "-q"], [site])
        _use(site, reader)
        if len(mutant) > 2 * len(text):
            worst.append(site)
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(
        "a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
        + "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]\n" for i in range(1, 9))
        + "robots: *a8\n"
    )
    for site in [bomb, *worst[:1]][:1]:
        fuzz.cases += 1
        fuzz.measure(["record", str(tmp_path / "m.mcap"), "--site", str(site), "-q"], [site])
    fuzz.check()
