"""``trackctl vm-track`` and ``trackctl simulate vm``."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from trackctl.cli.common import (
    AllowUnmeasuredOption,
    JsonOption,
    OutputsOnlyOption,
    PlotOption,
    QuietOption,
    SeedOption,
    VerboseOption,
    fail_if_option,
    out_option,
    parse_choice,
    print_json,
    stderr,
)
from trackctl.cli.process import figures_from_output, run_system
from trackctl.logs.output import check_output


def vm_track(
    log: Annotated[Path, typer.Argument(help="MCAP log with detections (+ phone IMU, RSSI).")],
    out: Annotated[Path | None, out_option("input + /vmtrack/tracks + report")] = None,
    outputs_only: OutputsOnlyOption = False,
    mode: Annotated[str, typer.Option(help="vm (visual + motion) or v-af (visual only).")] = "vm",
    smooth: Annotated[
        bool, typer.Option("--smooth/--no-smooth", help="RTS-smooth every track (offline).")
    ] = True,
    source: Annotated[
        str,
        typer.Option(help="auto (frames when the log has them), frames, or detections."),
    ] = "auto",
    search: Annotated[
        str,
        typer.Option(
            help="In frames: predicted (motion-predicted regions, full search to initialize and "
            "recover) or full (every frame searched whole)."
        ),
    ] = "predicted",
    plot: PlotOption = None,
    phones_aligned: Annotated[
        bool,
        typer.Option(
            "--phones-aligned",
            help="The paper's assumption: phone heading = walking direction in the site frame "
            "and phone clocks = camera clocks (only if your phone app guarantees it; by "
            "default both are estimated per phone).",
        ),
    ] = False,
    retrack: Annotated[
        bool,
        typer.Option(
            "--retrack/--no-retrack",
            help="Follow each phone's carrier through the raw detections by the phone's walk "
            "(offline; ~1-3 s per phone and 5 min of log where its identity is clear, ~50 s "
            "where its alignment must be searched, as in crowds). Off: phones name the visual "
            "tracks.",
        ),
    ] = True,
    refine: Annotated[
        str,
        typer.Option(
            help="Re-tracking: auto (a phone whose identity is clear starts from its alignment, "
            "the others' are searched; the report's searched/<MID> says which) or full (every "
            "phone's alignment searched: ~20x the time where identities are clear; on the "
            "simulated lobby IDF1 moved by < 0.001).",
        ),
    ] = "auto",
    rssi: Annotated[
        bool,
        typer.Option(
            "--rssi/--no-rssi",
            help="Re-tracking weighs the phones' RSSI at the APs (the scans' AP positions): a "
            "phone no AP hears is out of view, its level says roughly how far from the AP.",
        ),
    ] = True,
    json_out: JsonOption = False,
    fail_if: Annotated[str | None, fail_if_option("error_m_mean>0.3")] = None,
    allow_unmeasured: AllowUnmeasuredOption = False,
    verbose: VerboseOption = False,
    quiet: QuietOption = False,
) -> None:
    """VM-Tracking: identify and track people by fusing detections with phone motion sensors.

    Example: trackctl vm-track sample_logs/vm-office.mcap --out tracked.mcap --fail-if "idf1<0.9"
    """
    from trackctl.errors import InputError
    from trackctl.vmtrack import FrameConfig, Mode, Source, VmTrackConfig, VmTrackProcessor
    from trackctl.vmtrack.radio import RadioConfig
    from trackctl.vmtrack.retrack import RetrackConfig

    mode_value = parse_choice(Mode, mode, "--mode")
    source_value = parse_choice(Source, source, "--source")
    if search not in ("predicted", "full"):
        raise InputError(f"--search {search!r}: expected predicted or full")
    if refine not in ("auto", "full"):
        raise InputError(f"--refine {refine!r}: expected auto or full")
    retrack_cfg = RetrackConfig(enabled=retrack, radio=RadioConfig(enabled=rssi))
    if refine == "full":
        retrack_cfg = replace(retrack_cfg, trust_clear_share=None)
    proc = VmTrackProcessor(
        VmTrackConfig(
            mode=mode_value,
            smooth=smooth,
            source=source_value,
            frames=FrameConfig(predicted=search == "predicted"),
            phones_aligned=phones_aligned,
            refinement=retrack_cfg,
        )
    )
    draw = figures_from_output(out, plot, "vmtrack")
    run_system(
        "vm-track",
        log,
        out,
        proc,
        json_out=json_out,
        fail_if=fail_if,
        quiet=quiet,
        allow_unmeasured=allow_unmeasured,
        verbose=verbose,
        plot=draw,
        outputs_only=outputs_only,
    )


def simulate_vm(
    out: Annotated[Path, typer.Option(help="MCAP log to write.")],
    field: Annotated[
        str, typer.Option(help="lobby (20x15 m, 6 cameras) or office (6x5 m, 2).")
    ] = "lobby",
    users: Annotated[int, typer.Option(help="People carrying a phone.")] = 5,
    nonusers: Annotated[int, typer.Option(help="People without a phone.")] = 2,
    duration: Annotated[float, typer.Option(help="Seconds.")] = 60.0,
    speed: Annotated[
        str, typer.Option(help="Walking speed m/s: MIN,MAX or one value.")
    ] = "0.5,1.5",
    seed: SeedOption = 0,
    det_noise: Annotated[float, typer.Option(help="Mean ground error of detections, m.")] = 0.35,
    trajectories: Annotated[
        Path | None,
        typer.Option(
            help="Drive people by a t_s,id,x_m,y_m CSV (or ETH/UCY text) instead; the log "
            "starts at its first annotation."
        ),
    ] = None,
    phones: Annotated[
        str | None,
        typer.Option(
            help="With --trajectories: ids of the people who carry a phone, comma-separated "
            "(default: the --users who walk farthest in the log)."
        ),
    ] = None,
    frames: Annotated[
        bool,
        typer.Option(
            "--frames/--no-frames",
            help="Render JPEG camera frames (the detector finds people in them) instead of "
            "writing simulated ground-plane detections.",
        ),
    ] = False,
    jpeg_quality: Annotated[
        int, typer.Option(help="JPEG quality of rendered frames (1-100).", min=1, max=100)
    ] = 60,
    light_drop: Annotated[
        str | None,
        typer.Option(
            metavar="FRACTION[@SECONDS]",
            help="With --frames: the scene gets darker by FRACTION from SECONDS (default 60), "
            "e.g. 0.25@60.",
        ),
    ] = None,
    flicker: Annotated[
        float, typer.Option(help="With --frames: exposure gain per frame uniform in 1 +- this.")
    ] = 0.0,
    shadows: Annotated[
        bool, typer.Option("--shadows", help="With --frames: people cast shadows on the floor.")
    ] = False,
    standing: Annotated[
        float,
        typer.Option(help="An extra person walks in, stands still this many seconds, walks out."),
    ] = 0.0,
    preset: Annotated[
        str,
        typer.Option(
            help="realistic: phones in pockets and bags, always on, own clocks; detections with "
            "calibration bias, merged boxes, missed episodes, static false positives (docs/"
            "vmtrack.md). paper: the dissertation's idealised setting."
        ),
    ] = "realistic",
    carry_yaw: Annotated[
        float | None,
        typer.Option(
            help="Realistic: every phone's device-to-walk yaw, degrees (default: per carry)."
        ),
    ] = None,
    clock_offset: Annotated[
        float | None,
        typer.Option(help="Realistic: phone clock offsets uniform in +- this many seconds (2)."),
    ] = None,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """People walking under calibrated cameras, some with phones (VM-Tracking scenarios).

    Example: trackctl simulate vm --out lobby.mcap --field lobby --users 5 --duration 60
    """
    from trackctl.errors import InputError
    from trackctl.sim.vm import VmScenario
    from trackctl.sim.vm import simulate_vm as simulate

    check_output(out, [trajectories])
    try:
        parts = [float(x) for x in speed.split(",")]
    except ValueError:
        raise InputError(f"--speed {speed!r}: expected MIN,MAX or one number") from None
    rng = (parts[0], parts[-1])
    drop, drop_at = 0.0, 60.0
    if light_drop is not None:
        value, _, at = light_drop.partition("@")
        try:
            drop = float(value)
            drop_at = float(at) if at else 60.0
        except ValueError:
            raise InputError(f"--light-drop {light_drop!r}: expected FRACTION[@SECONDS]") from None
    cfg = VmScenario(
        field=field,
        users=users,
        nonusers=nonusers,
        duration_s=duration,
        speed_mps=rng,
        seed=seed,
        det_noise_m=det_noise,
        trajectories=str(trajectories) if trajectories else None,
        phones=tuple(p.strip() for p in (phones or "").split(",") if p.strip()),
        frames=frames,
        jpeg_quality=jpeg_quality,
        light_drop=drop,
        light_drop_at_s=drop_at,
        flicker=flicker,
        shadows=shadows,
        standing_s=standing,
        preset=preset,
        carry_yaw_deg=carry_yaw,
        clock_offset_s=clock_offset,
    )
    if not frames and any((drop, flicker, shadows)):
        raise InputError(
            "--light-drop, --flicker and --shadows act on rendered frames: add --frames"
        )
    counts = simulate(str(out), cfg)
    if json_out:
        print_json({"out": str(out), "topics": counts})
    elif not quiet:
        stderr.print(f"wrote {sum(counts.values())} messages on {len(counts)} topics to {out}")
