"""No function in trackctl/ over cyclomatic complexity 15, as radon counts it.

radon counts boolean operators and conditional expressions, where the metric dicts and option
checks hide their branches (ruff's C901, in pyproject.toml, does not), so this test is the rule
CI applies (issue 47); ``radon cc -s -n C trackctl`` lists the counts from 11 up.
"""

from __future__ import annotations

from radon.complexity import cc_visit
from radon.visitors import Function

from tests.conftest import ROOT

LIMIT = 15


def _complexities() -> dict[str, int]:
    out: dict[str, int] = {}
    for path in sorted((ROOT / "trackctl").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for block in cc_visit(path.read_text()):
            if not isinstance(block, Function):
                continue  # a class's figure is its methods'
            name = getattr(block, "fullname", block.name)
            out[f"{rel}::{name}"] = block.complexity
            for closure in getattr(block, "closures", []):
                out[f"{rel}::{name}.{closure.name}"] = closure.complexity
    return out


def test_no_function_over_the_limit() -> None:
    over = {k: v for k, v in _complexities().items() if v > LIMIT}
    assert over == {}, f"over cyclomatic complexity {LIMIT} (radon): {over}"


def test_the_count_sees_the_package() -> None:
    """The rule is not met by finding nothing to count."""
    files = {k.split("::")[0] for k in _complexities()}
    assert "trackctl/vmtrack/pipeline.py" in files and len(files) > 100
