"""vehicle.description: the shipped default file and docs are generated from the description."""
from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vehicle.description import (_SECTION_TYPES, CarDescription, CarDescriptionError, car_from_dict, load_car,
                        markdown_doc)

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "vehicle" / "data" / "nxp_cup_car.toml"
REGENERATE = "regenerate with `python -m vehicle.description --write vehicle/data/nxp_cup_car.toml` " \
             "and `python -m vehicle.description --doc > docs/car.md`"


def test_shipped_file_is_the_generated_default():
    assert SHIPPED.read_text() == CarDescription().to_toml(), REGENERATE
    assert load_car(SHIPPED) == CarDescription() == load_car(None)


def test_shipped_file_comments_every_field():
    lines = SHIPPED.read_text().splitlines()
    for section, cls in _SECTION_TYPES.items():
        start = lines.index(f"[{section}]")
        for f in dataclasses.fields(cls):
            i = next(i for i, ln in enumerate(lines) if i > start and ln.startswith(f"{f.name} = "))
            assert lines[i - 1].startswith("# ") and f.metadata["doc"] in lines[i - 1], (section, f.name)


def test_docs_are_up_to_date():
    assert (REPO / "docs" / "car.md").read_text() == markdown_doc() + "\n", REGENERATE


def test_partial_file_takes_defaults(tmp_path):
    path = tmp_path / "car.toml"
    path.write_text('name = "mine"\n[wheels]\nradius_m = 0.03\n')
    car = load_car(path)
    assert car.name == "mine" and car.wheels.radius_m == 0.03
    assert car.chassis == CarDescription().chassis


@pytest.mark.parametrize("text, pattern", [
    ("[wheel]\nradius_m = 0.03\n", r"unknown section \[wheel\]"),
    ("[wheels]\nradius = 0.03\n", r"unknown field wheels\.radius"),
    ("[wheels]\nradius_m = 9.0\n", r"wheels\.radius_m = 9\.0: expected a value in \[0\.005, 0\.5\]"),
    ("[camera]\nwidth_px = 12.5\n", r"camera\.width_px = 12\.5: expected an integer"),
    ("[wheels]\nradius_m = nan\n", r"expected a finite number"),
    ("[wheels\n", r"invalid TOML"),
])
def test_bad_files_raise_one_line(tmp_path, text, pattern):
    path = tmp_path / "car.toml"
    path.write_text(text)
    with pytest.raises(CarDescriptionError, match=pattern) as info:
        load_car(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def _section_values(cls):
    strategies = {}
    for f in dataclasses.fields(cls):
        lo, hi = f.metadata["lo"], f.metadata["hi"]
        if f.type in (int, "int"):
            strategies[f.name] = st.integers(int(lo), int(hi))
        else:
            strategies[f.name] = st.floats(lo, hi if math.isfinite(hi) else 1e6, allow_nan=False)
    return st.builds(cls, **strategies)


@settings(max_examples=60, deadline=None)
@given(st.builds(CarDescription, name=st.from_regex(r"[a-z][a-z0-9_]{0,15}", fullmatch=True),
                 **{name: _section_values(cls) for name, cls in _SECTION_TYPES.items()}))
def test_toml_round_trip(car):
    assert car_from_dict(tomllib.loads(car.to_toml())) == car
