"""What every processor reports, and what each figure needs to be measured.

One place declares, per processor, the metrics it can report (names or ``fnmatch`` patterns
such as ``steps/*``), which of them need something the log may not hold (the ground truth,
phones), and the few that make its headline. From it:

- a report's figures that could not be measured are ``null`` with the reason beside them
  (``unmeasured``), never a 0 that a CI gate would take as a pass (:meth:`MetricCatalog.settle`);
- ``--fail-if`` keys are checked before any work (:meth:`MetricCatalog.declares`);
- the human output shows the headline first (:attr:`MetricCatalog.headline`).

A plug-in processor without a catalog keeps its report as it is, and its gates are checked only
after the run (against the keys the report has).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from fnmatch import fnmatchcase

from trackctl.logs import topics
from trackctl.logs.messages import MetricValue

__all__ = [
    "Need",
    "Metric",
    "MetricCatalog",
    "TRUTH",
    "EV_TRUTH",
    "PHONES",
    "catalog",
    "register_catalog",
    "WALL_S",
]

WALL_S = "wall_s"
"""Processing time of a run, seconds (added to every report by the runner)."""


@dataclass(frozen=True, slots=True)
class Need:
    """Something in the input a figure cannot be measured without.

    Attributes:
        name: Short name (``truth``, ``phones``).
        topics: Topic patterns; the need is met when the log has a topic matching any of them.
        missing: Why the figure is null when it is not met (ends the gate's error message).
    """

    name: str
    topics: tuple[str, ...]
    missing: str

    def met_by(self, present: Collection[str]) -> bool:
        """True when a topic in ``present`` matches one of :attr:`topics`."""
        return any(fnmatchcase(t, pattern) for t in present for pattern in self.topics)


TRUTH = Need("truth", (topics.GROUND_TRUTH,), f"the log has no {topics.GROUND_TRUTH}")
EV_TRUTH = Need("truth", (topics.EV_GROUND_TRUTH,), f"the log has no {topics.EV_GROUND_TRUTH}")
PHONES = Need("phones", ("/phone/*/imu",), "the log has no phone IMU (/phone/*/imu)")


@dataclass(frozen=True, slots=True)
class Metric:
    """One declared figure (or a family of them, by pattern).

    Attributes:
        pattern: Metric name, or an ``fnmatch`` pattern (``error_m_mean/*``).
        needs: What the log must hold for it to be measured.
        empty: Why it can be null although every need is met (no event of the kind happened).
    """

    pattern: str
    needs: tuple[Need, ...] = ()
    empty: str = "nothing in the run to measure it on"

    def matches(self, key: str) -> bool:
        """True when ``key`` is this metric or one of its family."""
        return key == self.pattern or fnmatchcase(key, self.pattern)


@dataclass(frozen=True, slots=True)
class MetricCatalog:
    """Every figure one processor reports.

    Attributes:
        processor: Registry name of the processor.
        metrics: The declared figures, most specific pattern first.
        headline: The few figures a person reads first (human output without ``--verbose``).
    """

    processor: str
    metrics: tuple[Metric, ...]
    headline: tuple[str, ...] = ()

    def spec(self, key: str) -> Metric | None:
        """The declaration of ``key`` (the first that matches), or None."""
        if key == WALL_S:
            return Metric(WALL_S)
        return next((m for m in self.metrics if m.matches(key)), None)

    def declares(self, key: str) -> bool:
        """True when the processor may report ``key``."""
        return self.spec(key) is not None

    def settle(
        self,
        metrics: Mapping[str, MetricValue],
        present: Collection[str],
        reasons: Mapping[str, str] | None = None,
    ) -> tuple[dict[str, MetricValue], dict[str, str]]:
        """``metrics`` with every figure whose needs the log does not meet set to null, and
        the reason for each null figure.

        Args:
            present: The input log's topics.
            reasons: Reasons the processor gave itself (``key -> why``), kept as they are.
        """
        out = dict(metrics)
        why: dict[str, str] = dict(reasons or {})
        for key, value in metrics.items():
            spec = self.spec(key)
            if spec is None:
                continue
            unmet = next((n for n in spec.needs if not n.met_by(present)), None)
            if unmet is not None:
                out[key] = None
                why[key] = unmet.missing
            elif value is None:
                why.setdefault(key, spec.empty)
        for key in list(why):
            if out.get(key, None) is not None:
                del why[key]  # measured after all (a processor's reason for another mode)
        return out, why

    def names(self) -> list[str]:
        """The declared names and patterns, for error messages."""
        return [m.pattern for m in self.metrics] + [WALL_S]


def _m(patterns: Iterable[str], *needs: Need, empty: str | None = None) -> tuple[Metric, ...]:
    kw = {} if empty is None else {"empty": empty}
    return tuple(Metric(p, tuple(needs), **kw) for p in patterns)


_CATALOGS: dict[str, MetricCatalog] = {}


def register_catalog(cat: MetricCatalog) -> None:
    """Declare (or replace) the metrics of a processor (plug-ins may declare theirs)."""
    _CATALOGS[cat.processor] = cat


def catalog(processor: str) -> MetricCatalog | None:
    """The declared metrics of ``processor``, or None for a processor that declares none."""
    return _CATALOGS.get(processor)


NO_LOSS = "no carrier was lost"

register_catalog(
    MetricCatalog(
        "vm-track",
        _m(
            [
                "people",
                "error_m_mean",
                "error_m_median",
                "idf1",
                "mota",
                "idf1_all",
                "mota_all",
                "det_error_m_mean",
                "det_recall",
                "wrong_binding_s",
            ],
            TRUTH,
        )
        + _m(["id_switches"], TRUTH)
        + _m(["loss_events"], TRUTH, PHONES)
        + _m(["recovery_s_mean", "first_loss_s_mean"], TRUTH, PHONES, empty=NO_LOSS)
        + _m(
            [
                "bindings",
                "checkpoint_bindings",
                "offline_bindings",
                "ambiguous_frames",
                "unanchored_frames",
                "clock_offset_s/*",
                "yaw_offset_deg/*",
                "step_scale/*",
                "withheld_s/*",
                "ambiguous_s/*",
                "grouped_s/*",
                "clear_share/*",
                "searched/*",
                "searched_again",
                "visits",
                "edge_turnover",
                "occupancy_steadiness",
                "imu_bad_samples",
            ],
            PHONES,
        )
        + _m(
            [
                "rssi_at_1m_dbm/*",
                "path_loss_exponent/*",
                "rssi_sigma_db/*",
                "rssi_readings/*",
            ],
            PHONES,
        )
        + _m(
            [
                "system",
                "mode",
                "frames",
                "users",
                "source",
                "detections_per_frame_mean",
                "detections_per_frame_max",
                "tracks_started",
                "tracks_published",
                "tracks_stitched",
                "tracks_reidentified",
                "tracks_dropped_short",
                "track_frames_median",
                "track_frames_p10",
                "track_frames_p90",
                "coasting_share",
                "ms_per_frame",
                "ms_per_frame_*",
                "background_s",
                "full_searches",
                "region_searches",
                "bad_frames",
            ]
        ),
        headline=(
            "source",
            "frames",
            "users",
            "tracks_published",
            "idf1",
            "mota",
            "id_switches",
            "error_m_mean",
            "wrong_binding_s",
            "ambiguous_frames",
        ),
    )
)

register_catalog(
    MetricCatalog(
        "smirror",
        _m(
            [
                "error_m_*",
                "error_m_mean/*",
                "error_m_mean_out_coverage/*",
                "delay_ms_mean",
                "delay_ms_mean_*",
                "delay_ms_mean_in_coverage/*",
                "kbps_in_coverage",
                "kbps_out_coverage",
                "coverage_fraction",
                "samples",
                "unlocalized_samples",
            ],
            TRUTH,
        )
        + _m(
            [
                "system",
                "mode",
                "kbps_mean",
                "kbps_unicast_equivalent",
                "requesters",
                "cast_mode",
                "foreground_bytes",
                "full_frame_bytes",
                "full_to_foreground_ratio",
                "image_messages",
                "images_new",
                "images_old",
                "beacons",
                "node_ms_median",
                "robot_ms_median",
                "fix_attempts",
                "fixes",
                "fixes_used",
                "fixes_used/*",
                "broadcast_lost",
                "decode_failures",
                "duration_s",
                "localized_share",
                "localized_share/*",
                "first_fix_s",
                "first_fix_s/*",
                "fixes_per_min",
                "nis_mean",
                "nis_within_95",
                "queue_ms_mean",
                "queue_ms_max",
                "answers_dropped",
                "delivered_share",
                "delivered_share/*",
                "robots",
            ]
        ),
        headline=(
            "mode",
            "robots",
            "localized_share",
            "first_fix_s",
            "error_m_mean",
            "error_m_p95",
            "delay_ms_mean",
            "kbps_mean",
            "fixes_used",
        ),
    )
)

register_catalog(
    MetricCatalog(
        "bridgeloc",
        _m(
            [
                "positions",
                "localized",
                "success_rate",
                "success_rate_*",
                "error_m_*",
                "confident_rate",
                "confident_within_2sigma",
                "office_median_m_*",
            ],
            TRUTH,
        )
        + _m(
            [
                "system",
                "mode",
                "tags",
                "success_threshold_m",
                "bridge_fixes",
                "icam_fixes",
                "tag_observations",
                "robot_frames",
                "ambiguous_matches",
                "rejected_updates",
                "frames_with_pose",
                "frames_with_fix",
                "icam_fused",
                "restarts",
                "ambiguous_skipped",
                "pose_share",
                "fix_share",
                "nis_per_dof_mean",
                "nis_within_95",
                "icam_static_blobs_dropped",
                "tags_mapped",
                "tag*",
                "tag_map_error_m_mean",
                "detect_ms_median",
                "ms_per_frame",
            ]
        ),
        headline=(
            "mode",
            "tags_mapped",
            "robot_frames",
            "pose_share",
            "success_rate",
            "error_m_mean",
            "error_m_median",
            "bridge_fixes",
            "icam_fixes",
        ),
    )
)

register_catalog(
    MetricCatalog(
        "ev-match",
        _m(["correct", "accuracy", "precision"], EV_TRUTH)
        + _m(
            [
                "system",
                "algorithm",
                "engine",
                "requested",
                "matched",
                "unresolved",
                "ambiguous",
                "v_scenarios_read",
                "v_scenarios_total",
                "v_bytes_read",
                "v_scenarios_missing",
                "v_topics_missing",
                "v_scenarios_unique",
                "e_scenarios_total",
                "eids_in_log",
                "distinguished",
                "split_iterations",
                "refine_rounds",
                "wall_s_*",
            ]
        ),
        headline=("engine", "requested", "matched", "ambiguous", "accuracy", "precision"),
    )
)

register_catalog(
    MetricCatalog(
        "pdr",
        _m(
            [
                "phones",
                "steps_total",
                "duration_s",
                "steps/*",
                "duration_s/*",
                "imu_rate_hz/*",
                "bad_samples/*",
                "walking_s/*",
                "distance_m/*",
            ]
        )
        + _m(["cadence_hz/*"], empty="the phone was never seen walking"),
        headline=("phones", "steps_total", "duration_s"),
    )
)

register_catalog(
    MetricCatalog(
        "dead-reckoning",
        _m(["error_m_mean", "error_m_max", "error_m_final"], TRUTH)
        + _m(["robots", "sources", "poses", "path_m", "method/*"])
        + _m(
            [
                "reference",
                "ape_m_rmse",
                "rpe_m_rmse",
                "reference/*",
                "ape_m_rmse/*",
                "ape_m_mean/*",
                "ape_m_max/*",
                "rpe_m_rmse/*",
            ],
            empty="no reference to score against (ground truth or /robot/NAME/reference/*)",
        )
        + _m(
            ["own_pose_gap_m_final/*", "twist_pose_disagreement/*"],
            empty="the odometry carries no pose (or no twist) to compare",
        ),
        headline=(
            "robots",
            "sources",
            "poses",
            "path_m",
            "error_m_mean",
            "error_m_final",
            "reference",
            "ape_m_rmse",
            "rpe_m_rmse",
        ),
    )
)

register_catalog(
    MetricCatalog(
        "check",
        _m(
            [
                "messages",
                "topics",
                "nonmonotonic_stamps",
                "nonfinite_values",
                "stamp_mismatches",
                "decode_errors",
                "gaps",
                "max_gap_s",
                "truncated",
                "crc_errors",
                "lost_messages",
                "data_crc_ok",
            ]
        )
        + _m(["first_problem"], empty="no problem found"),
        headline=(
            "messages",
            "topics",
            "nonmonotonic_stamps",
            "nonfinite_values",
            "decode_errors",
            "gaps",
            "truncated",
            "crc_errors",
            "lost_messages",
            "first_problem",
        ),
    )
)
