"""``trackgen`` command line: a thin layer over :mod:`trackgen.build`.

    trackgen validate LAYOUT_OR_DIR [--car CAR.toml]
    trackgen build LAYOUT -o DIR [--force] [--car CAR.toml]
    trackgen random --seed N [-o FILE] [--car CAR.toml] [options]   (trackgen.random_cli)

Exit codes: 0 success (warnings allowed), 1 the track has problems (one line each),
2 unreadable input or an output folder that cannot be written (one line on stderr).
"""
from __future__ import annotations

import sys
from pathlib import Path

import click

from pieces.spec import PieceError
from vehicle.description import CarDescriptionError, load_car
from worlds.sdf_xml import WorldError

from .build import ValidationFailed, build as build_track, validate_path
from .errors import TrackError
from .validate import count_errors, errors

EXIT_OK, EXIT_PROBLEMS, EXIT_BAD_INPUT = 0, 1, 2
_HELP = {"help_option_names": ["-h", "--help"]}  # -h on every command, also invoked on its own
_INPUT_ERRORS = (TrackError, PieceError, WorldError, CarDescriptionError)


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> click.exceptions.Exit:
    """Print one line to stderr; return the exit to raise."""
    click.echo(message.splitlines()[0] if message else "trackgen: failed", err=True)
    return click.exceptions.Exit(code)


@click.group(context_settings=_HELP)
@click.version_option(package_name="nxpcup-sim", prog_name="trackgen")
def main() -> None:
    """Generate NXP Cup tracks (Gazebo worlds, meshes, track.json) from layout files."""


@main.command(context_settings=_HELP)
@click.argument("path", type=click.Path(path_type=Path))
@click.option("--car", "car_path", type=click.Path(path_type=Path), default=None,
              help="Car description TOML (default: the built-in NXP Cup car).")
@click.option("--no-sdf-check", is_flag=True, help="Do not run 'ign sdf -k' on a build folder.")
def validate(path: Path, car_path: Path | None, no_sdf_check: bool) -> None:
    """Check a LAYOUT file or a build output folder; one line per problem."""
    try:
        car = load_car(car_path)
        problems = validate_path(path, car, sdf_checker=not no_sdf_check)
    except _INPUT_ERRORS as exc:
        raise _fail(str(exc)) from None
    except OSError as exc:
        raise _fail(f"{path}: {exc.strerror or exc}") from None
    for p in problems:  # on stderr, as build's and the INVALID line
        click.echo(str(p), err=True)
    bad = errors(problems)
    if bad:
        click.echo(f"{path}: INVALID, {count_errors(problems)} problem(s)", err=True)
        raise click.exceptions.Exit(EXIT_PROBLEMS)
    click.echo(f"{path}: OK")


@main.command(context_settings=_HELP)
@click.argument("layout", type=click.Path(path_type=Path))
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(path_type=Path),
              help="Output folder (created; must not exist unless --force).")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option("--car", "car_path", type=click.Path(path_type=Path), default=None,
              help="Car description TOML (default: the built-in NXP Cup car).")
def build(layout: Path, out_dir: Path, force: bool, car_path: Path | None) -> None:
    """Validate LAYOUT and write the track world folder to DIR."""
    try:
        car = load_car(car_path)
        result = build_track(layout, out_dir, force=force, car=car)
    except ValidationFailed as exc:
        for p in exc.problems:
            click.echo(str(p), err=True)
        click.echo(f"{layout}: not built, {count_errors(exc.problems)} problem(s)", err=True)
        raise click.exceptions.Exit(EXIT_PROBLEMS) from None
    except _INPUT_ERRORS as exc:
        raise _fail(str(exc)) from None
    except OSError as exc:
        raise _fail(f"{out_dir}: cannot write output folder ({exc.strerror or exc})") from None
    for w in result.warnings:
        click.echo(str(w), err=True)
    click.echo(f"wrote {result.out_dir} (world.sdf, track.json, preview.png, models/)")


from .random_cli import random_cmd  # noqa: E402  (registers ``trackgen random``)

main.add_command(random_cmd)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
