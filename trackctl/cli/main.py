"""The ``trackctl`` command: a thin Typer layer over the library."""

from __future__ import annotations

import typer

from trackctl import __version__
from trackctl.cli.bridgeloc import bridgeloc_app, simulate_bridgeloc
from trackctl.cli.calib import calib_app
from trackctl.cli.common import TrackctlGroup
from trackctl.cli.evmatch import ev_match, simulate_ev
from trackctl.cli.export import export_cmd
from trackctl.cli.info import info
from trackctl.cli.process import process, report
from trackctl.cli.record import filter_cmd, record, recover
from trackctl.cli.replay import replay
from trackctl.cli.simulate import simulate_app
from trackctl.cli.smirror import simulate_smirror, smirror
from trackctl.cli.vmtrack import simulate_vm, vm_track

app = typer.Typer(
    cls=TrackctlGroup,
    name="trackctl",
    help="Offline indoor tracking and robot localization over MCAP sensor logs.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"trackctl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Offline indoor tracking and robot localization over MCAP sensor logs."""


app.command()(info)
app.command()(record)
app.command()(recover)
app.command("filter")(filter_cmd)
app.command()(replay)
app.command()(process)
app.command()(report)
app.command("export")(export_cmd)
app.command("vm-track")(vm_track)
simulate_app.command("vm")(simulate_vm)
app.command("ev-match")(ev_match)
simulate_app.command("ev")(simulate_ev)
app.command("smirror")(smirror)
simulate_app.command("smirror")(simulate_smirror)
simulate_app.command("bridgeloc")(simulate_bridgeloc)
app.add_typer(simulate_app, name="simulate")
app.add_typer(bridgeloc_app, name="bridgeloc")
app.add_typer(calib_app, name="calib")


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":
    main()
