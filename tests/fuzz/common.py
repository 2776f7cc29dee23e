"""What every fuzz test shares: seeded mutation of text, running the CLI in-process, and the
checks (no traceback, exit 0 or 2, inputs byte-identical, bounded memory)."""

from __future__ import annotations

import hashlib
import random
import resource
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from typer.testing import CliRunner

from tests.fuzz.conftest import FUZZ_PROPERTY
from tests.fuzz.hostile import Run, run_measured
from trackctl.cli.main import app

RSS_BOUND_MB = 500.0
"""Peak resident memory one trackctl run may reach on any fuzzed input."""

HOSTILE_TOKENS = (
    "0",
    "-1",
    "-0.0",
    "1e-300",
    "1.0e-300",
    "1e308",
    "1e999",
    ".nan",
    "nan",
    "NaN",
    ".inf",
    "-.inf",
    "Infinity",
    "9" * 30,
    "9" * 5000,
    "2026-12-04",
    "!!binary aGVsbG8=",
    "!!python/object:os.system x",
    "[]",
    "{}",
    "[1]",
    '""',
    "null",
    "~",
    "true",
    "&a [1, 2]",
    "*a",
    "\x00",
    "\xff",
    "é",
)
"""Values no real input holds (YAML spellings included: a YAML-free format reads them as junk)."""


def digest(path: Path) -> str:
    """sha256 of a file, or of every file under a folder (names included)."""
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for p in files:
        h.update(str(p.relative_to(path) if path.is_dir() else p.name).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def mutate_text(text: str, rng: random.Random, tokens: Sequence[str] = HOSTILE_TOKENS) -> str:
    """One seeded mutation of a text input: a value replaced by a hostile token, a line dropped,
    duplicated, swapped or cut, brackets or indentation piled up, bytes flipped."""
    lines = text.splitlines() or [""]
    kind = rng.choice(
        ["token", "token", "token", "drop", "dup", "swap", "cut", "nest", "indent", "flip", "many"]
    )
    i = rng.randrange(len(lines))
    if kind == "token":
        line = lines[i]
        cut = max(line.find(":"), line.find(","), line.find("="))
        head = line[: cut + 1] if cut >= 0 else line[: rng.randrange(len(line) + 1)]
        lines[i] = f"{head} {rng.choice(tokens)}" if ":" in head else head + rng.choice(tokens)
    elif kind == "drop":
        del lines[i]
    elif kind == "dup":
        lines[i:i] = [lines[i]] * rng.choice([2, 50])
    elif kind == "swap":
        j = rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    elif kind == "cut":
        return text[: rng.randrange(len(text) + 1)]
    elif kind == "nest":
        depth = rng.choice([40, 2000])
        lines[i] += " " + "[" * depth + "1" + "]" * depth
    elif kind == "indent":
        lines[i:i] = [" " * (2 * k) + f"k{k}:" for k in range(rng.choice([40, 300]))]
    elif kind == "flip":
        chars = list(text)
        for _ in range(rng.randint(1, 8)):
            if chars:
                chars[rng.randrange(len(chars))] = chr(rng.randrange(1, 256))
        return "".join(chars)
    else:  # the same hostile token everywhere
        token = rng.choice(tokens)
        lines = [(ln.split(":")[0] + ": " + token) if ":" in ln else ln for ln in lines]
    return "\n".join(lines) + "\n"


@dataclass
class Fuzz:
    """Counts of one fuzz test and its checks; :meth:`summary` is its one line."""

    kind: str
    record: Callable[[str, object], None]
    cases: int = 0
    tracebacks: list[str] = field(default_factory=list)
    changed: list[str] = field(default_factory=list)
    peak_rss_mb: float = 0.0
    exits: dict[int, int] = field(default_factory=dict)
    runner: CliRunner = field(default_factory=CliRunner)

    def invoke(self, args: list[str], inputs: Iterable[Path], stdin: bytes | None = None) -> int:
        """Run ``trackctl ARGS`` in-process; record a traceback, an exit code outside {0, 2}
        or a changed input. Returns the exit code."""
        inputs = [p for p in inputs if p.exists()]
        before = {p: digest(p) for p in inputs}
        res = self.runner.invoke(app, args, input=stdin)
        where = f"case {self.cases}: trackctl {' '.join(args)[:300]}"
        if res.exception is not None and not isinstance(res.exception, SystemExit):
            self.tracebacks.append(f"{where}: {type(res.exception).__name__}: {res.exception}")
        elif res.exit_code not in (0, 2) or "Traceback" in res.output:
            self.tracebacks.append(f"{where}: exit {res.exit_code}: {res.output[-500:]}")
        self.changed += [f"{where}: {p}" for p in inputs if digest(p) != before[p]]
        self.exits[res.exit_code] = self.exits.get(res.exit_code, 0) + 1
        return res.exit_code

    def measure(self, args: list[str], inputs: Iterable[Path], stdin: Path | None = None) -> Run:
        """Run ``trackctl ARGS`` in a child process (``stdin``: a file it reads) and keep its
        peak RSS (and the checks)."""
        inputs = [p for p in inputs if p.exists()]
        before = {p: digest(p) for p in inputs}
        run = run_measured(args, stdin=stdin)
        where = f"measured case: trackctl {' '.join(args)[:300]}"
        if run.code not in (0, 2) or "Traceback" in run.stderr + run.stdout:
            self.tracebacks.append(f"{where}: exit {run.code}: {run.stderr[-500:]}")
        self.changed += [f"{where}: {p}" for p in inputs if digest(p) != before[p]]
        self.peak_rss_mb = max(self.peak_rss_mb, run.peak_rss_mb)
        return run

    def summary(self) -> str:
        if not self.peak_rss_mb:  # in-process only: this process's own peak
            self.peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        return (
            f"fuzz {self.kind}: cases {self.cases}, tracebacks {len(self.tracebacks)}, "
            f"inputs changed {len(self.changed)}, peak RSS {self.peak_rss_mb:.0f} MB"
        )

    def check(self, rss_bound_mb: float = RSS_BOUND_MB) -> None:
        """Record the summary line and assert the fuzz test's promises."""
        line = self.summary()
        self.record(FUZZ_PROPERTY, line)
        assert not self.tracebacks, "\n".join(self.tracebacks[:5])
        assert not self.changed, "\n".join(self.changed[:5])
        assert self.peak_rss_mb < rss_bound_mb, line
