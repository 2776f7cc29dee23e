"""``trackctl simulate``: scenario generators. Each system adds its own subcommand."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from trackctl.cli.common import JsonOption, QuietOption, SeedOption, print_json, stderr

simulate_app = typer.Typer(help="Generate scenario logs with ground truth.", no_args_is_help=True)


@simulate_app.command("demo")
def demo(
    out: Annotated[Path, typer.Option(help="MCAP log to write.")],
    duration: Annotated[float, typer.Option(help="Seconds of scenario.")] = 20.0,
    seed: SeedOption = 0,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """A small office scene using every trackctl format (the shipped sample log).

    Example: trackctl simulate demo --out demo.mcap --seed 0 --duration 20
    """
    from trackctl.logs.output import check_output
    from trackctl.sim.demo import DemoConfig, simulate_demo

    check_output(out)
    counts = simulate_demo(str(out), DemoConfig(duration_s=duration, seed=seed))
    if json_out:
        print_json({"out": str(out), "topics": counts})
    elif not quiet:
        stderr.print(f"wrote {sum(counts.values())} messages on {len(counts)} topics to {out}")
