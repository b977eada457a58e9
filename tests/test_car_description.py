"""vehicle.description: the shipped default file and docs are generated from the description."""
from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vehicle.description import (_SECTION_TYPES, CarDescription, CarDescriptionError, Chassis, Effects,
                                 car_from_dict, load_car, markdown_doc)

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
        if f.metadata.get("choices"):
            strategies[f.name] = st.sampled_from(f.metadata["choices"])
        elif f.metadata.get("list"):  # empty, or one number per column of the default camera
            strategies[f.name] = st.one_of(st.just(()), st.lists(
                st.floats(lo, hi, allow_nan=False), min_size=128, max_size=128).map(tuple))
        elif f.type in (int, "int"):
            strategies[f.name] = st.integers(int(lo), int(hi))
        else:
            strategies[f.name] = st.floats(lo, hi if math.isfinite(hi) else 1e6, allow_nan=False)
    built = st.builds(cls, **strategies)
    if cls.__name__ == "Camera":  # most random cameras break a relation: keep the row and profile in range
        built = built.map(lambda cam: dataclasses.replace(
            cam, default_row=min(cam.default_row, cam.height_px - 1),
            vignetting_profile=cam.vignetting_profile if len(cam.vignetting_profile) == cam.width_px else ()))
    return built


def _car_or_none(**kwargs):
    """A CarDescription, or None when its fields do not fit together (relation_problem)."""
    try:
        return CarDescription(**kwargs)
    except CarDescriptionError:
        return None


@settings(max_examples=60, deadline=None)
@given(st.builds(_car_or_none, name=st.from_regex(r"[a-z][a-z0-9_]{0,15}", fullmatch=True),
                 **{name: _section_values(cls) for name, cls in _SECTION_TYPES.items()})
       .filter(lambda car: car is not None))
def test_toml_round_trip(car):
    assert car_from_dict(tomllib.loads(car.to_toml())) == car


def test_a_written_file_credits_no_changed_number_to_the_default_source():
    """A field that differs from its default does not carry the default's source comment
    (an F1/10's 3.74 kg is not "estimate for the NXP Cup car"); ``sources`` names a fit."""
    car = CarDescription(chassis=Chassis(mass_kg=3.74), effects=Effects(steering_lag_s=0.12))
    lines = car.to_toml({"effects.steering_lag_s": "fitted by a test"}).splitlines()

    def comment(key):
        return lines[lines.index(next(x for x in lines if x.startswith(f"{key} ="))) - 1]

    assert comment("mass_kg").endswith("Source: this file, not the default (1.0: estimate for the NXP Cup car "
                                       "with battery; measure (thesis eq. 5.5)).")
    assert comment("steering_lag_s").endswith("Source: fitted by a test.")
    assert comment("wheelbase_m").endswith("Source: NXP Cup (Alamak-type) chassis, nominal.")  # the default
    assert comment("steering_rate_limit_radps").endswith("Source: neutral (inf).")
    assert car_from_dict(tomllib.loads("\n".join(lines))) == car


# -- file:line errors and the relations between fields (issue 13 item 8) -------------------
@pytest.mark.parametrize("text, line, pattern", [
    ('name = "x"\n[camera]\nwidth_px = 128\n\ndefault_row = 200\n', 5,
     r"camera\.default_row = 200: expected a row in \[0, 127\] \(camera\.height_px = 128\)"),
    ("[camera]\nheight_px = 40\n", 2,  # the default row (60) does not fit: the line of height_px
     r"camera\.default_row = 60: expected a row in \[0, 39\]"),
    ("[camera]\npitch_rad = 0.0\ndefault_row = 10\n", 3, r"looks at or above the horizon"),
    ("[wheels]\nwidth_m = 0.2\n", 2, r"wheels\.width_m = 0\.2: expected less than chassis\.track_m"),
    ("# a comment\n[wheels]\nradius_m = 9.0\n", 3, r"wheels\.radius_m = 9\.0: expected a value in"),
    ("[wheels]\n  radius_m   =   'big'\n", 2, r"wheels\.radius_m = 'big': expected a number"),
    ("[chassis]\nmass_kg = 1\n[camera]\nfps_hz = 0\n", 4, r"camera\.fps_hz = 0: expected a value in \[1, 1000\]"),
    ("[drive]\nmax_speed_mps = 3\n\n[whels]\n", 4, r"unknown section \[whels\]"),
    ("[steering]\nlimit_rad = 0.3\nrate = 1\n", 3, r"unknown field steering\.rate"),
    ("camera.default_row = 500\n", 1, r"camera\.default_row = 500: expected a value in \[0, 4095\]|"
                                      r"camera\.default_row = 500: expected a row"),
    ("name = 3\n", 1, r"'name' must be a non-empty string"),
    ("[wheels]\nradius_m = \n", 2, r"invalid TOML"),
    ("[wheels]\nradius_m = 0.03\nradius_m = 0.04\n", 3, r"invalid TOML"),
])
def test_car_file_errors_name_file_and_line(tmp_path, text, line, pattern):
    path = tmp_path / "car.toml"
    path.write_text(text)
    with pytest.raises(CarDescriptionError, match=pattern) as info:
        load_car(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{line}: ") and "\n" not in message, message


def test_relations_hold_in_the_python_api_too():
    """CarDescription(...) refuses what load_car refuses (no line to name there)."""
    from vehicle.description import Camera

    with pytest.raises(CarDescriptionError, match=r"camera\.default_row = 200"):
        CarDescription(camera=Camera(default_row=200))
    assert CarDescription(camera=Camera(default_row=127)).camera.default_row == 127


def test_out_of_range_row_is_bad_input_for_drive(tmp_path):
    """default_row = 200 with 128 rows was accepted and failed later as a controller_error:
    now drive() refuses the car file before anything runs."""
    from simrunner.run.runner import drive

    path = tmp_path / "car.toml"
    path.write_text("[camera]\ndefault_row = 200\n")
    with pytest.raises(CarDescriptionError, match=rf"^{path}:2: camera\.default_row = 200"):
        drive(lambda spinner: None, car=path, csv=tmp_path / "run.csv")
    assert not (tmp_path / "run.csv").exists()


_RANGED = [(section, f) for section, cls in _SECTION_TYPES.items() for f in dataclasses.fields(cls)
           if f.metadata.get("lo") is not None and not f.metadata.get("list")]  # numbers with a range
# (camera.model, a choice, and camera.vignetting_profile, a list: tests/test_imaging.py)


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(_RANGED), st.booleans(), st.integers(0, 3), st.integers(0, 4))
def test_any_out_of_range_field_names_its_line(tmp_path_factory, pick, above, blank, comments):
    """Every field is range-checked at load, and the error names the line it is on."""
    section, f = pick
    lo, hi = f.metadata["lo"], f.metadata["hi"]
    if above and not math.isfinite(hi):
        above = False
    is_int = f.type in (int, "int")
    bad = (hi + 1 if above else lo - 1) if is_int else (hi * 2 + 1 if above else lo - 1.5)
    head = ["# my car"] * comments + [""] * blank
    lines = head + [f"[{section}]", "# the value below is wrong"] + [""] * blank + [
        f"{f.name} = {bad!r}"]
    path = tmp_path_factory.mktemp("car") / "car.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(CarDescriptionError) as info:
        load_car(path)
    assert str(info.value).startswith(f"{path}:{len(lines)}: {section}.{f.name} = "), str(info.value)
