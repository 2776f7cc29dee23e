"""``trackctl smirror`` and ``trackctl simulate smirror``."""

from __future__ import annotations

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
    SiteOption,
    VerboseOption,
    fail_if_option,
    load_site_file,
    out_option,
    parse_choice,
    parse_pose,
    print_written,
    stderr,
)
from trackctl.cli.process import run_system
from trackctl.logs.output import check_output


def smirror(
    log: Annotated[Path, typer.Argument(help="MCAP log with node frames (+ robot odometry).")],
    out: Annotated[
        Path | None, out_option("input + /smirror/<robot>/pose, /smirror/<node>/sent, report")
    ] = None,
    outputs_only: OutputsOnlyOption = False,
    mode: Annotated[
        str,
        typer.Option(help="mirror+odom (S-Mirror + motion sensor) or centralized (vision only)."),
    ] = "mirror+odom",
    broadcast_threshold: Annotated[
        int, typer.Option(help="A node broadcasts an image from this many requests on.")
    ] = 15,
    requesters: Annotated[
        int | None,
        typer.Option(help="Robots requesting images (default: the log's smirror/requesters)."),
    ] = None,
    robot: Annotated[
        str | None,
        typer.Option(help="Localize only this robot (default: every robot of the log)."),
    ] = None,
    link_kbps: Annotated[
        float, typer.Option("--link-kbps", help="Unicast link throughput, kB/s.")
    ] = 1000.0,
    start: Annotated[
        str | None,
        typer.Option(
            help="The robot's known start pose X,Y,YAW (m, m, rad; world frame), e.g. a dock. "
            "Default: unknown; the robot asks every node until one sees its LEDs, and has no "
            "pose until then."
        ),
    ] = None,
    site: SiteOption = None,
    plot: PlotOption = None,
    json_out: JsonOption = False,
    fail_if: Annotated[str | None, fail_if_option("error_m_mean>0.33")] = None,
    allow_unmeasured: AllowUnmeasuredOption = False,
    verbose: VerboseOption = False,
    quiet: QuietOption = False,
) -> None:
    """S-Mirror: localize robots from their LEDs in node images, dead-reckoning in between.

    Example: trackctl smirror sample_logs/smirror.mcap --out localized.mcap
    """
    from trackctl.errors import InputError
    from trackctl.smirror import Mode, SmirrorConfig, SmirrorProcessor
    from trackctl.smirror.link import LinkConfig

    if out is not None:
        check_output(out, [log, site])  # before the site is read
    mode_value = parse_choice(Mode, mode, "--mode")
    try:
        cfg = SmirrorConfig(
            mode=mode_value,
            broadcast_threshold=broadcast_threshold,
            requesters=requesters,
            robot=robot,
            link=LinkConfig(unicast_kBps=link_kbps),
            start=None if start is None else parse_pose(start, "--start"),
            site=load_site_file(site),
        )
    except ValueError as err:
        raise InputError(str(err)) from None
    if plot is not None:
        from trackctl.plots.smirror import require_matplotlib

        require_matplotlib()
    proc = SmirrorProcessor(cfg)

    def draw() -> None:
        if proc.last_result is not None and plot is not None:
            from trackctl.plots.smirror import plot_result

            written = plot_result(proc.last_result, plot)
            if not json_out and not quiet:
                stderr.print(f"wrote {len(written)} figures to {plot}")

    run_system(
        "smirror",
        log,
        out,
        proc,
        json_out=json_out,
        fail_if=fail_if,
        quiet=quiet,
        allow_unmeasured=allow_unmeasured,
        verbose=verbose,
        plot=draw if plot is not None else None,
        outputs_only=outputs_only,
        inputs=[site],
    )


def simulate_smirror(
    out: Annotated[Path, typer.Option(help="MCAP log to write.")],
    paths: Annotated[int, typer.Option(help="Patrol loops of ~40 m the robot drives (1-4).")] = 4,
    people: Annotated[int, typer.Option(help="People walking in the rooms.")] = 6,
    requesters: Annotated[
        int, typer.Option(help="Robots requesting node images (the fleet + others).")
    ] = 1,
    robots: Annotated[
        int,
        typer.Option(
            help="Robots that patrol and log odometry (1-3; each with its own LED colours)."
        ),
    ] = 1,
    seed: SeedOption = 0,
    fps: Annotated[float, typer.Option(help="Node frame rate, Hz.")] = 5.0,
    size: Annotated[str, typer.Option(help="Node image size WxH.")] = "640x480",
    jpeg_quality: Annotated[int, typer.Option(help="JPEG quality of node frames.")] = 80,
    duration: Annotated[
        float | None, typer.Option(help="Cut the patrol after this many seconds.")
    ] = None,
    calib_error_deg: Annotated[
        float, typer.Option(help="Node calibration error: rotation sigma per axis, degrees.")
    ] = 0.15,
    distortion_k1: Annotated[
        float, typer.Option(help="Radial lens distortion k1 of the node cameras (e.g. -0.2).")
    ] = 0.0,
    wheel_scale_error: Annotated[
        float | None,
        typer.Option(
            help="Opposite encoder scale errors of the two wheels (0.02 = +-2 %; default "
            "+0.4 % / -0.3 %)."
        ),
    ] = None,
    slip: Annotated[
        float, typer.Option(help="Relative random slip of each wheel increment.")
    ] = 0.03,
    led_clothes: Annotated[
        float, typer.Option(help="Share of people in LED-coloured (green/magenta) shirts.")
    ] = 0.0,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Three rooms, three node cameras, a robot with LEDs and encoders patrolling (S-Mirror).

    Example: trackctl simulate smirror --out smirror.mcap --duration 36 --seed 0
    """
    from trackctl.errors import InputError
    from trackctl.sim.smirror import SmirrorScenario
    from trackctl.sim.smirror import simulate_smirror as simulate

    check_output(out)
    try:
        w, h = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {size!r}: expected WxH, e.g. 640x480") from None
    try:
        cfg = SmirrorScenario(
            paths=paths,
            people=people,
            requesters=requesters,
            robots=robots,
            seed=seed,
            fps=fps,
            width_px=w,
            height_px=h,
            jpeg_quality=jpeg_quality,
            duration_s=duration,
            calib_rot_deg=calib_error_deg,
            distortion_k1=distortion_k1,
            slip_sigma=slip,
            led_clothes=led_clothes,
            wheel_scale=SmirrorScenario().wheel_scale
            if wheel_scale_error is None
            else (1.0 + wheel_scale_error, 1.0 - wheel_scale_error),
        )
    except ValueError as err:
        raise InputError(f"simulate smirror: {err}") from None
    counts = simulate(str(out), cfg)
    print_written(out, counts, json_out=json_out, quiet=quiet)
