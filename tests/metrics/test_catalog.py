"""metrics/catalog.py: what each processor declares, nulls with reasons, gates that cannot pass
on nothing."""

from __future__ import annotations

import pytest

from trackctl.errors import InputError
from trackctl.metrics.catalog import TRUTH, Metric, MetricCatalog, catalog
from trackctl.metrics.report import (
    UnmeasuredGateError,
    check_gate_keys,
    failed_conditions,
    parse_fail_if,
)

CAT = MetricCatalog(
    "toy",
    (
        Metric("error_m_mean", (TRUTH,)),
        Metric("people", (TRUTH,)),
        Metric("steps/*"),
        Metric("recovery_s", empty="nobody was lost"),
    ),
    headline=("people",),
)


def test_figures_that_need_the_truth_are_null_without_it_with_the_reason() -> None:
    metrics = {"error_m_mean": None, "people": 0, "steps/p1": 3, "recovery_s": None}
    out, why = CAT.settle(metrics, present={"/phone/p1/imu"})
    # a count that needs the truth is null, not the 0 the run computed on nothing
    assert out == {"error_m_mean": None, "people": None, "steps/p1": 3, "recovery_s": None}
    assert why == {
        "error_m_mean": "the log has no /ground_truth",
        "people": "the log has no /ground_truth",
        "recovery_s": "nobody was lost",
    }


def test_with_the_truth_the_figures_stay_and_a_stale_reason_is_dropped() -> None:
    metrics = {"error_m_mean": 0.2, "people": 3, "steps/p1": 3, "recovery_s": 1.5}
    out, why = CAT.settle(metrics, {"/ground_truth"}, reasons={"recovery_s": "off"})
    assert out == metrics and why == {}


def test_unknown_gate_key_is_refused_before_any_work() -> None:
    with pytest.raises(InputError, match=r"vm-track reports no metric 'nosuchkey'.*idf1"):
        check_gate_keys(parse_fail_if("nosuchkey>1"), ["vm-track"])
    check_gate_keys(parse_fail_if("idf1<0.9, clock_offset_s/02:00:00:00:00:01>1"), ["vm-track"])
    # PROCESSOR.KEY names one processor of a chain
    check_gate_keys(parse_fail_if("check.nonfinite_values>0"), ["check", "pdr"])
    with pytest.raises(InputError, match="check reports no metric 'steps_total'"):
        check_gate_keys(parse_fail_if("check.steps_total>0"), ["check", "pdr"])
    # a plug-in that declares nothing is checked against its report after the run
    check_gate_keys(parse_fail_if("anything>0"), ["hello-plugin"])


def test_a_gate_on_a_null_metric_is_an_error_not_a_pass() -> None:
    conds = parse_fail_if("id_switches>0")
    why = {"id_switches": "the log has no /ground_truth"}
    with pytest.raises(UnmeasuredGateError, match="id_switches was not measured: the log has no"):
        failed_conditions({"id_switches": None}, conds, why)
    assert failed_conditions({"id_switches": None}, conds, why, allow_unmeasured=True) == []
    assert failed_conditions({"id_switches": 2}, conds, why) == ["id_switches=2 (id_switches>0)"]


@pytest.mark.parametrize(
    "processor", ["vm-track", "ev-match", "smirror", "bridgeloc", "pdr", "dead-reckoning", "check"]
)
def test_every_builtin_processor_declares_its_metrics_and_a_headline(processor: str) -> None:
    cat = catalog(processor)
    assert cat is not None and cat.headline
    assert all(cat.declares(k) for k in cat.headline)
    assert cat.declares("wall_s")
