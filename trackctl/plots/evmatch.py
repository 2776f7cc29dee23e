"""EV-Matching figures: accuracy vs number of matched EIDs (dissertation Figures 3.14, 3.15).

matplotlib is the optional ``plot`` extra: imported lazily, Agg backend.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from trackctl.errors import InputError

__all__ = ["require_matplotlib", "plot_run", "plot_paper"]


def require_matplotlib() -> Any:
    """The pyplot module (Agg backend), or InputError naming the extra to install."""
    from trackctl.plots import pyplot

    return pyplot()


def _outdir(folder: str | os.PathLike[str]) -> Path:
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise InputError(f"--plot {out}: not a folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def plot_run(log: str | os.PathLike[str], folder: str | os.PathLike[str]) -> list[Path]:
    """From an ev-match output log: accuracy over the first k requested EIDs, and the V-scenario
    burden (read vs total). Returns the files written."""
    from trackctl.evmatch.data import load_ground_truth
    from trackctl.logs import topics
    from trackctl.logs.reader import LogReader
    from trackctl.metrics.report import read_reports

    plt = require_matplotlib()
    out = _outdir(folder)
    reader = LogReader(log)
    truth = load_ground_truth(reader)
    matches = []
    for msg in reader.messages([topics.EV_MATCHES]):
        matches = list(msg.message.matches)
    reports = [r for r in read_reports(reader) if r.processor == "ev-match"]
    metrics = reports[-1].metrics if reports else {}
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.5))
    n = len(matches)
    if n and truth:
        ks = sorted({max(1, round(n * f / 10)) for f in range(1, 11)})
        acc = [
            100.0 * sum(m.vid is not None and truth.get(m.eid) == m.vid for m in matches[:k]) / k
            for k in ks
        ]
        ax1.plot(ks, acc, "o-", label=str(metrics.get("algorithm", "")))
        ax1.legend()
    ax1.set_xlabel("Number of matched EIDs")
    ax1.set_ylabel("Accuracy (%)")
    ax1.set_ylim(0, 101)
    ax1.grid(alpha=0.3)
    read = metrics.get("v_scenarios_read") or 0
    total = metrics.get("v_scenarios_total") or 0
    ax2.bar(["read", "total"], [read, total], color=["tab:blue", "tab:gray"])
    ax2.set_ylabel("V-scenarios")
    ax2.set_title("visual processing burden")
    fig.tight_layout()
    path = out / "ev_match.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return [path]


def plot_paper(
    rows: Sequence[Mapping[str, Any]], folder: str | os.PathLike[str], stem: str = "ev"
) -> list[Path]:
    """Figures 3.14 / 3.15 from benchmark rows (keys: sweep ``eid``/``vid``, miss, algorithm,
    requested, accuracy). Returns the files written."""
    plt = require_matplotlib()
    out = _outdir(folder)
    files = []
    for sweep, label, fig_no in (("eid", "E miss rate", "3.14"), ("vid", "V miss rate", "3.15")):
        sel = [r for r in rows if r["sweep"] == sweep]
        if not sel:
            continue
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), sharey=True)
        for ax, algo in zip(axes, ("ss", "edp"), strict=True):
            for miss in sorted({r["miss"] for r in sel}):
                pts = sorted(
                    (r["k"], 100 * r["accuracy"])
                    for r in sel
                    if r["miss"] == miss and r["algorithm"] == algo
                )
                if pts:
                    ax.plot(*zip(*pts, strict=True), "o-", label=f"{label} = {miss:.0%}")
            ax.set_title(f"({'ab'[algo == 'edp']}) {algo.upper()}")
            ax.set_xlabel("Number of matched EIDs")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        axes[0].set_ylabel("Accuracy (%)")
        fig.suptitle(f"like Figure {fig_no}: accuracy vs {label.split()[0]}ID missing")
        fig.tight_layout()
        path = out / f"{stem}_fig{fig_no.replace('.', '_')}.png"
        fig.savefig(path, dpi=80)
        plt.close(fig)
        files.append(path)
    return files
