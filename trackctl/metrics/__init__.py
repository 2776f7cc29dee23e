"""Metrics: report handling now; tracking and trajectory metrics join with the systems."""

from trackctl.metrics.report import (
    Condition,
    failed_conditions,
    jsonable_metrics,
    parse_fail_if,
    read_reports,
    report_topic,
)

__all__ = [
    "Condition",
    "failed_conditions",
    "jsonable_metrics",
    "parse_fail_if",
    "read_reports",
    "report_topic",
]
