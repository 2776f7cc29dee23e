"""Metric reports: building them, storing them in logs, and gating CI on them (``--fail-if``)."""

from __future__ import annotations

import json
import math
import operator
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

from trackctl.errors import InputError
from trackctl.logs import topics
from trackctl.logs.messages import MetricReport, MetricValue
from trackctl.logs.reader import LogReader
from trackctl.metrics.catalog import catalog


class UnmeasuredGateError(InputError):
    """A ``--fail-if`` condition names a metric the run could not measure (it came out null)."""


__all__ = [
    "Condition",
    "parse_fail_if",
    "failed_conditions",
    "read_reports",
    "report_topic",
    "METADATA_PREFIX",
    "jsonable_metrics",
    "check_gate_keys",
    "UnmeasuredGateError",
]

METADATA_PREFIX = "metrics/"

_OPS: dict[str, Callable[[float, float], bool]] = {
    ">=": operator.ge,
    "<=": operator.le,
    "==": operator.eq,
    "!=": operator.ne,
    ">": operator.gt,
    "<": operator.lt,
}
_COND = re.compile(
    r"^\s*([A-Za-z_][\w.\-/:]*)\s*(>=|<=|==|!=|>|<)\s*(-?[\d.]+(?:[eE][-+]?\d+)?)\s*$"
)


@dataclass(frozen=True, slots=True)
class Condition:
    """One ``KEY OP NUMBER`` threshold of ``--fail-if``."""

    key: str
    op: str
    threshold: float

    def holds(self, value: float) -> bool:
        """True when ``value`` crosses the threshold (the run should fail)."""
        return _OPS[self.op](value, self.threshold)

    def __str__(self) -> str:
        return f"{self.key}{self.op}{self.threshold:g}"


def parse_fail_if(expr: str) -> list[Condition]:
    """Parse ``"error_m_mean>0.5, idf1<0.9"``: comma-separated conditions, any one fails the run.

    Raises:
        InputError: a condition is not of the form KEY OP NUMBER.
    """
    conditions = []
    for part in re.split(r",|\bor\b", expr):
        if not part.strip():
            continue
        match = _COND.match(part)
        if match is None:
            raise InputError(
                f"--fail-if: cannot parse {part.strip()!r}; expected KEY OP NUMBER with OP one of "
                '> >= < <= == != (e.g. "error_m_mean>0.5")'
            )
        conditions.append(Condition(match[1], match[2], float(match[3])))
    if not conditions:
        raise InputError("--fail-if: empty expression")
    return conditions


def check_gate_keys(conditions: Iterable[Condition], processors: Sequence[str]) -> None:
    """Raise InputError, before any work, when a condition names a metric none of
    ``processors`` declares (``KEY`` or ``PROCESSOR.KEY``; see :mod:`trackctl.metrics.catalog`).

    A processor that declares no metrics (a plug-in without a catalog) accepts any plain key:
    its gates are checked against the report after the run.
    """
    cats = {p: catalog(p) for p in processors}
    for cond in conditions:
        head, dot, tail = cond.key.partition(".")
        owners, key = ([head], tail) if dot and head in cats else (list(cats), cond.key)
        declared = [c for c in (cats[p] for p in owners) if c is not None]
        if len(declared) < len(owners) or any(c.declares(key) for c in declared):
            continue
        names = sorted({n for c in declared for n in c.names()})
        raise InputError(
            f"--fail-if: {' or '.join(owners)} reports no metric {key!r}; it reports: "
            + ", ".join(names)
        )


def failed_conditions(
    metrics: Mapping[str, MetricValue],
    conditions: Iterable[Condition],
    unmeasured: Mapping[str, str] | None = None,
    *,
    allow_unmeasured: bool = False,
) -> list[str]:
    """The conditions that hold on ``metrics``, as ``key=value (cond)`` strings.

    A condition on a metric that is null (unmeasured) is an error, not a pass: a gate must not
    pass on nothing. With ``allow_unmeasured`` it is skipped instead.

    Raises:
        InputError: a condition names a metric the report does not have, or a non-numeric one.
        UnmeasuredGateError: a condition names a null metric (and ``allow_unmeasured`` is off).
    """
    failed = []
    for cond in conditions:
        if cond.key not in metrics:
            raise InputError(
                f"--fail-if: the report has no metric {cond.key!r}; it has: "
                + ", ".join(sorted(metrics))
            )
        value = metrics[cond.key]
        if value is None:
            if allow_unmeasured:
                continue
            why = (unmeasured or {}).get(cond.key, "it came out null")
            raise UnmeasuredGateError(
                f"--fail-if {cond}: {cond.key} was not measured: {why} "
                "(--allow-unmeasured skips such a condition)"
            )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"--fail-if: metric {cond.key!r} is {value!r}, not a number")
        if math.isnan(value) or cond.holds(float(value)):
            failed.append(f"{cond.key}={value:g} ({cond})")
    return failed


def report_topic(processor: str) -> str:
    """Topic a processor's report is published on."""
    return topics.metrics(processor)


def jsonable_metrics(metrics: Mapping[str, MetricValue]) -> dict[str, MetricValue]:
    """Metrics with NaN/inf replaced by None (JSON has no NaN)."""
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in metrics.items()
    }


def read_reports(reader: LogReader) -> list[MetricReport]:
    """Every metric report in a log: ``/metrics/*`` messages, else ``metrics/*`` metadata."""
    topics = [
        t
        for t, info in reader.topics().items()
        if t.startswith("/metrics/") and info.schema_name == MetricReport.SCHEMA
    ]
    reports = [m.message for m in reader.messages(topics)] if topics else []
    if reports:
        return reports
    for name, data in reader.metadata().items():
        if name.startswith(METADATA_PREFIX) and "report" in data:
            reports.append(MetricReport.from_json(json.loads(data["report"])))
    return reports
