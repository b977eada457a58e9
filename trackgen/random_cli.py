"""``trackgen random``: a thin click layer over :func:`trackgen.random.random_layout`.

    trackgen random --seed N [-o FILE] [--car CAR.toml] [--length MIN:MAX]
                    [--crossings N|MIN:MAX] [--mix straight=3,turn=4,chicane=1]
                    [--angles 30,45,60,90] [--radii 0.6,0.8,1] [--walk MIN:MAX] [--check-meshes]
    trackgen random --kit nxp --seed N [-o FILE] [--car CAR.toml] [--length MIN:MAX]
                    [--crossings N|MIN:MAX] [--mix straight=3,chicane=1]

Writes the layout text to FILE (atomically) or to stdout. Exit 2 with one line for bad
options or an unwritable FILE.
"""
from __future__ import annotations

from pathlib import Path

import click

from vehicle.description import CarDescriptionError, load_car
from vehicle.userfiles import write_atomic

from .errors import TrackError


def _numbers(text: str, what: str, kind=float) -> tuple:
    try:
        return tuple(kind(v) for v in text.replace(",", " ").split())
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected {what}") from None


def _range(text: str | None, kind=float) -> tuple | None:
    if text is None:
        return None
    parts = text.split(":")
    try:
        values = tuple(kind(p) for p in parts)
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected MIN:MAX or one number") from None
    if len(values) == 1:
        return (values[0], values[0])
    if len(values) != 2:
        raise click.BadParameter(f"{text!r}: expected MIN:MAX or one number")
    return values


def _mix(text: str | None) -> dict | None:
    if text is None:
        return None
    out = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise click.BadParameter(f"{item!r}: expected KIND=WEIGHT, e.g. straight=3,turn=4,chicane=1")
    return out


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder + rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, text)


@click.command("random")
@click.option("--seed", required=True, type=click.IntRange(min=0), help="Seed (same seed, same file).")
@click.option("-o", "--out", "out_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the layout here (default: stdout).")
@click.option("--car", "car_path", type=click.Path(path_type=Path), default=None,
              help="Car description TOML (default: the built-in NXP Cup car).")
@click.option("--length", "length", default=None, metavar="MIN:MAX", help="Lap length range, m (10:30).")
@click.option("--crossings", default=None, metavar="N|MIN:MAX",
              help="Crossroads crossed twice (0:2; with --kit: intersections crossed straight on, 0).")
@click.option("--mix", default=None, metavar="KIND=W,...",
              help="Weights of walk pieces: straight, turn, chicane (straight=3,turn=4,chicane=1; "
                   "with --kit: straight, chicane for the WAVE on straight tiles, straight=1,chicane=0).")
@click.option("--angles", default=None, metavar="DEG,...", help="Turn angles, degrees (30,45,60,90).")
@click.option("--radii", default=None, metavar="M,...", help="Turn radii, m (0.6,0.8,1).")
@click.option("--walk", default=None, metavar="MIN:MAX", help="Pieces per random walk (2:6).")
@click.option("--check-meshes", is_flag=True, help="Also run the watertight-mesh check (~40 ms).")
@click.option("--kit", default=None, type=click.Choice(["nxp"]),
              help="Only the official kit's pieces: a loop on the kit's 0.89 m grid, crossing "
                   "itself straight on at intersections (with --length, --crossings, --mix).")
def random_cmd(seed, out_path, car_path, length, crossings, mix, angles, radii, walk,
               check_meshes, kit=None) -> None:
    """Write a random closed layout (valid for the car) drawn from SEED."""
    from .random import random_layout

    options: dict = {"meshes": check_meshes}
    for key, value in (("length_m", _range(length)), ("crossings", _range(crossings, int)),
                       ("mix", _mix(mix)), ("walk_pieces", _range(walk, int)),
                       ("angles_deg", angles and _numbers(angles, "angles in degrees")),
                       ("radii_m", radii and _numbers(radii, "radii in metres"))):
        if value is not None:
            options[key] = value
    if kit is not None:
        other = [f"--{k}" for k, v in (("angles", angles), ("radii", radii), ("walk", walk)) if v is not None]
        if other:
            click.echo(f"trackgen random: {', '.join(other)}: not with --kit (the kit's tracks are "
                       "loops of its own pieces; --length, --crossings and --mix set them)", err=True)
            raise click.exceptions.Exit(2)
    try:
        car = load_car(car_path)
        if kit is not None:
            from .random_kit import random_kit_layout

            text = random_kit_layout(seed, car=car, **{k: options[k] for k in ("length_m", "crossings", "mix")
                                                       if k in options})
        else:
            text = random_layout(seed, car=car, **options)
    except (TrackError, CarDescriptionError) as exc:
        click.echo(f"trackgen random: {str(exc).splitlines()[0]}", err=True)
        raise click.exceptions.Exit(2) from None
    if out_path is None:
        click.echo(text, nl=False)
        return
    try:
        write_text_atomic(out_path, text)
    except OSError as exc:
        click.echo(f"{out_path}: cannot write ({exc.strerror or exc})", err=True)
        raise click.exceptions.Exit(2) from None
    click.echo(f"wrote {out_path}", err=True)
