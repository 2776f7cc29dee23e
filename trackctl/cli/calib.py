"""``trackctl calib``: place cameras on the floor, import and check calibrations."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from trackctl.cli.common import JsonOption, TrackctlGroup, console, print_json, stderr
from trackctl.errors import InputError
from trackctl.logs.output import check_output

calib_app = typer.Typer(
    cls=TrackctlGroup,
    help="Camera calibration on the floor: pose from floor points, Tsai/ROS import, checks.",
    no_args_is_help=True,
)

_UNITS_HELP = "Unit of the file's translation: m, cm or mm (Tsai XML: mm unless given)."


def _points(text: str, option: str, width: int) -> list[list[float]]:
    """``"x,y x,y ..."`` (or ``;``-separated) as a list of ``width``-number points."""
    out = []
    for item in text.replace(";", " ").split():
        try:
            values = [float(v) for v in item.split(",")]
        except ValueError:
            raise InputError(f"{option}: {item!r} is not a point of numbers") from None
        if len(values) != width:
            raise InputError(f"{option}: {item!r}: expected {width} comma-separated numbers")
        out.append(values)
    return out


def _units(units: str | None) -> float | None:
    from trackctl.geometry.calib import metres_per_unit

    return metres_per_unit(units, "--units")


def _show(summary: Mapping[str, object], problems: tuple[list[str], list[str]]) -> None:
    table = Table(show_header=False, show_edge=False)
    for key, value in summary.items():
        table.add_row(key, str(value))
    console().print(table)
    for w in problems[1]:
        stderr.print(f"[yellow]warning:[/] {w}", markup=True)


@calib_app.command("ground")
def ground(
    camera: Annotated[str, typer.Argument(help="Camera name (the NAME of /NAME/image).")],
    intrinsics: Annotated[
        Path,
        typer.Option(help="Calibration file with the intrinsics (OpenCV/ROS YAML, Tsai XML)."),
    ],
    out: Annotated[Path, typer.Option(help="OpenCV YAML to write (what record --calib reads).")],
    points: Annotated[
        Path | None,
        typer.Option(help="CSV of floor point pairs u_px,v_px,x_m,y_m[,z_m] (>= 4)."),
    ] = None,
    image_points: Annotated[
        str | None, typer.Option(help='Pixels "u,v u,v ..." (with --world-points).')
    ] = None,
    world_points: Annotated[
        str | None, typer.Option(help='Floor points "x,y x,y ..." in metres (z = 0), same order.')
    ] = None,
    json_out: JsonOption = False,
) -> None:
    """Pose of a camera on the floor from >= 4 floor point pairs (cv2.solvePnP).

    Example: trackctl calib ground cam0 --intrinsics intr.yaml --points floor.csv --out cam0.yaml
    """
    import numpy as np

    from trackctl.geometry.calib import camera_problems, geometry_summary
    from trackctl.ingest.calibration import calibrate_ground, read_point_pairs, write_calibration

    check_output(out, [intrinsics, points])
    if points is not None and (image_points or world_points):
        raise InputError("give --points or --image-points/--world-points, not both")
    if points is not None:
        img, world = read_point_pairs(points)
        name = str(points)
    elif image_points and world_points:
        img = np.array(_points(image_points, "--image-points", 2))
        world = np.array(_points(world_points, "--world-points", 2))
        name = "--image-points/--world-points"
    else:
        raise InputError("give --points CSV, or --image-points with --world-points")
    fit = calibrate_ground(intrinsics, camera, img, world, name)
    problems = camera_problems(fit.model)
    if problems[0]:
        raise InputError(f"{name}: the pose found is implausible: {problems[0][0]}")
    summary = geometry_summary(fit.model)
    summary.update(
        {
            "points": len(fit.residuals_px),
            "reprojection_rms_px": round(fit.rms_px, 3),
            "reprojection_max_px": round(fit.max_px, 3),
            "out": str(out),
        }
    )
    write_calibration(fit.model, out)  # last: nothing is written when anything before fails
    if json_out:
        print_json(summary)
        return
    _show(summary, problems)


@calib_app.command("import")
def import_cmd(
    source: Annotated[
        Path, typer.Argument(help="Tsai camera XML (PETS), ROS camera_info or OpenCV YAML.")
    ],
    out: Annotated[Path, typer.Option(help="OpenCV YAML to write.")],
    camera: Annotated[str, typer.Option(help="Camera name.")] = "cam0",
    units: Annotated[str | None, typer.Option(help=_UNITS_HELP)] = None,
    rvec: Annotated[
        str | None, typer.Option(help='Pose to add, OpenCV rvec "a,b,c" (camera <- world).')
    ] = None,
    tvec: Annotated[
        str | None, typer.Option(help='Pose to add, OpenCV tvec "x,y,z" (metres unless --units).')
    ] = None,
    json_out: JsonOption = False,
) -> None:
    """Convert a calibration to trackctl's OpenCV YAML (metres, z up), with checks.

    Example: trackctl calib import view001.xml --out cam0.yaml
    """
    import numpy as np

    from trackctl.geometry.calib import camera_problems, geometry_summary, with_pose
    from trackctl.ingest.calibration import (
        checked_model,
        read_calibration,
        write_calibration,
    )

    check_output(out, [source])
    scale = _units(units)
    model = read_calibration(source, camera, scale)
    if (rvec is None) != (tvec is None):
        raise InputError("--rvec and --tvec go together")
    if rvec is not None and tvec is not None:
        r = np.array(_points(rvec, "--rvec", 3)).reshape(-1)
        t = np.array(_points(tvec, "--tvec", 3)).reshape(-1)
        model = checked_model(source, with_pose(model, r, t * (scale or 1.0)))
    errors, warns = camera_problems(model)
    if errors:
        raise InputError(f"{source}: {errors[0]}")
    summary = geometry_summary(model)
    summary["out"] = str(out)
    write_calibration(model, out)  # last: nothing is written when anything before fails
    if json_out:
        print_json(summary)
        return
    _show(summary, (errors, warns))


@calib_app.command("check")
def check(
    source: Annotated[Path, typer.Argument(help="Calibration file.")],
    video: Annotated[
        Path | None, typer.Option(help="Video or image folder the calibration is for.")
    ] = None,
    units: Annotated[str | None, typer.Option(help=_UNITS_HELP)] = None,
    json_out: JsonOption = False,
) -> None:
    """Where the camera is and looks, and what is implausible (exit 2 on an error).

    Example: trackctl calib check cam0.yaml
    """
    from trackctl.geometry.calib import camera_problems, geometry_summary
    from trackctl.ingest.calibration import read_calibration
    from trackctl.ingest.video import frame_size

    model = read_calibration(source, source.stem, _units(units))
    size = frame_size(video, model.camera) if video is not None else None
    errors, warns = camera_problems(model, size)
    if errors:
        raise InputError(f"{source}: {errors[0]}")
    summary = geometry_summary(model)
    if json_out:
        summary["warnings"] = "; ".join(warns) or None
        print_json(summary)
        return
    _show(summary, (errors, warns))


__all__ = ["calib_app"]
