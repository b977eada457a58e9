"""The one car description: every number the Gazebo car model and the simulator use.

A car description is a TOML file with one table per section below. Every field has a unit
(in its name), a default and a source; ``docs/car.md`` is generated from this module
(``python -m vehicle.description --doc``) and ``vehicle/data/nxp_cup_car.toml`` is the default file
(``python -m vehicle.description --write PATH`` writes a fresh, commented one).

Car body frame: origin at the middle of the rear axle on the ground, x forward, y left,
z up. Steering angles are radians, positive = left (counter-clockwise seen from above);
the bicycle-equivalent angle ``steer_rad`` relates to the turn radius of the rear-axle
midpoint by R = wheelbase / tan(steer).

Default car: the real NXP Cup car (1:1, not the thesis's 130 % Gazebo model). Where the
thesis gives a Gazebo number for its 130 % model, the default is that number divided by
1.3 (the thesis's speed normalisation 0.774 = 1/1.29 confirms the scale).
"""
from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Mapping

import tomli_w

from vehicle.userfiles import write_atomic

SCALE = 1.3  # thesis section 3.1: its Gazebo model was ~130 % of the real car


class CarDescriptionError(ValueError):
    """A car description file is missing, malformed or out of range."""


def _f(default: Any, doc: str, source: str, lo: float | None = None, hi: float | None = None):
    return field(default=default, metadata={"doc": doc, "source": source, "lo": lo, "hi": hi})


def _choice(default: str, choices: tuple[str, ...], doc: str, source: str):
    return field(default=default, metadata={"doc": doc, "source": source, "lo": None, "hi": None,
                                            "choices": choices})


@dataclass(frozen=True)
class Chassis:
    mass_kg: float = _f(1.0, "Total mass of the car including wheels.",
                        "estimate for the NXP Cup car with battery; measure (thesis eq. 5.5)", 0.05, 50)
    wheelbase_m: float = _f(0.175, "Distance between front and rear axle (L in thesis eq. 5.1).",
                            "NXP Cup (Alamak-type) chassis, nominal", 0.05, 1.0)
    track_m: float = _f(0.154, "Distance between left and right wheel centres (wheel separation).",
                        "thesis Fig. 3.2 wheel_separation 0.2 m / 1.3", 0.05, 1.0)
    length_m: float = _f(0.28, "Chassis box length (collision and drawing only).", "estimate", 0.05, 2.0)
    width_m: float = _f(0.16, "Chassis box width.", "estimate", 0.02, 1.0)
    height_m: float = _f(0.05, "Chassis box height.", "estimate", 0.005, 1.0)
    rear_overhang_m: float = _f(0.05, "Chassis box extent behind the rear axle.", "estimate", 0.0, 1.0)
    cog_height_m: float = _f(0.045, "Height of the chassis box centre above the ground.",
                             "estimate", 0.01, 1.0)


@dataclass(frozen=True)
class Wheels:
    radius_m: float = _f(0.034, "Wheel radius.", "thesis Fig. 3.2 wheel_radius 0.044 m / 1.3", 0.005, 0.5)
    width_m: float = _f(0.025, "Tyre width.", "estimate", 0.002, 0.2)
    mass_kg: float = _f(0.04, "Mass of one wheel.", "estimate", 0.001, 5)
    friction_mu: float = _f(1.0, "Tyre-track friction coefficient (thesis eq. 5.4: mu = tan(slip angle)).",
                            "estimate; calibrate with the tilt test", 0.01, 3.0)
    tyre_model: str = _choice("rigid", ("rigid", "slip"),
                              "How the tyres hold the track: 'rigid' (no slip below friction_mu x load, then "
                              "sliding: the contact friction of the physics engine) or 'slip' (a tyre force "
                              "model: the force rises with the slip to a peak of friction_mu x load and falls "
                              "beyond it; longitudinal and lateral slip share it in a friction circle; the "
                              "car understeers, oversteers and drifts; docs/tyres.md).",
                              "Pacejka, Tire and Vehicle Dynamics (2012): magic formula (4.3), combined "
                              "slip (4.3.2), relaxation length (7.2)")
    cornering_stiffness_front_per_rad: float = _f(
        4.718, "slip: the front tyres' cornering stiffness per unit load: lateral force / (slip angle x load) "
        "at small slip angles (and the longitudinal slip stiffness: an isotropic tyre).",
        "F1TENTH 1:10 car, CommonRoad vehicle parameters: C_Sf = 4.718 1/rad", 0.5, 50.0)
    cornering_stiffness_rear_per_rad: float = _f(
        5.4562, "slip: the rear tyres' cornering stiffness per unit load (stiffer than the front: the car "
        "understeers).", "F1TENTH 1:10 car, CommonRoad vehicle parameters: C_Sr = 5.4562 1/rad", 0.5, 50.0)
    tyre_shape: float = _f(1.2, "slip: the magic formula's shape factor C: beyond the peak the force falls "
                           "to sin(C pi / 2) of it (1.2: 95 %; 1: no fall).",
                           "Liniger et al. 2015, 1:43 racing cars: C_f = 1.2, C_r = 1.2691", 1.0, 1.9)
    relaxation_length_m: float = _f(0.05, "slip: the distance a tyre rolls to build up its slip force "
                                    "(first-order lag; it also holds a standing car without creep).",
                                    "estimate: 1.5 tyre radii (car tyres: 1-2 radii, Pacejka 2012, 7.2)",
                                    0.005, 0.5)


@dataclass(frozen=True)
class Steering:
    limit_rad: float = _f(0.40, "Maximum bicycle-equivalent steering angle (thesis eq. 5.1).",
                          "estimate (~23 deg); calibrate from the measured turning radius", 0.01, 1.2)
    rate_radps: float = _f(6.0, "Servo slew rate of the steering angle.",
                           "hobby servo, ~0.17 s per 60 deg", 0.1, 100)


@dataclass(frozen=True)
class Drive:
    max_speed_mps: float = _f(3.1, "Maximum forward (and reverse) speed.",
                              "thesis Fig. 3.2 max_linear_velocity 4 m/s / 1.3", 0.1, 30)
    max_accel_mps2: float = _f(3.1, "Acceleration limit (motor torque limit).",
                               "thesis Fig. 3.2 max_linear_acceleration 4 m/s^2 / 1.3", 0.1, 50)
    max_brake_mps2: float = _f(3.1, "Braking deceleration limit.",
                               "thesis Fig. 3.2 min_linear_acceleration -4 m/s^2 / 1.3", 0.1, 50)
    front_share: float = _f(0.0, "Share of the drive and brake torque at the front wheels (0 = rear-wheel "
                            "drive; 0.5 = four-wheel drive with an even split). simrunner's car only: the "
                            "Gazebo model drives the rear wheels.",
                            "NXP Cup car: rear-wheel drive (thesis 5.2)", 0.0, 1.0)
    command: str = _choice("speed", ("speed", "duty"),
                           "What the car is commanded in: 'speed' (m/s; an ideal speed controller in the ESC "
                           "reaches it within the acceleration limits) or 'duty' (the two rear motors' PWM "
                           "duty -1..1 through the motor model below: set_speed carries the duty of both, "
                           "set_motors each one's).",
                           "NXP Cup kits: two brushed DC motors on an H-bridge (rules summary section 2)")
    motor_force_n: float = _f(0.0, "duty: the force one rear motor drives its wheel with at full duty from "
                              "standstill (c1); 0 = from max_accel_mps2: c1 = m_eff max_accel / 2.",
                              "derived from drive.max_accel_mps2 unless measured (0 -> 0 m/s in one step)", 0.0, 1000.0)
    motor_back_emf_nspm: float = _f(0.0, "duty: the force the motor's back-EMF takes away per m/s of the "
                                    "wheel's speed at full duty (c2); 0 = c1 / max_speed_mps (full duty's top "
                                    "speed is then max_speed_mps without rolling resistance and drag).",
                                    "derived from drive.max_speed_mps unless measured (top speed at a few duties)",
                                    0.0, 1000.0)
    hbridge: str = _choice("brake", ("coast", "brake"),
                           "duty: what the H-bridge does in the PWM's off time and at duty 0: 'brake' (the "
                           "motor is driven or shorted all the time: force c1 d - c2 v, the steady speed is "
                           "d x the top speed, at 0 the back-EMF brakes) or 'coast' (fast decay, the motor "
                           "floats in the off time: force (c1 - c2 v) d, at 0 the wheel rolls freely).",
                           "FRDM-TFC library TFC_SetMotorPWM: each motor's two half-bridges take complementary "
                           "PWM at (d + 1) / 2 (locked anti-phase): mean voltage d x V, always driven = brake")
    rolling_resistance_n: float = _f(0.0, "duty: the force rolling resistance takes away, the whole car "
                                     "(constant, against the motion).",
                                     "measure it: the constant deceleration of a coast-down x the mass", 0.0, 100.0)
    drag_nspm2: float = _f(0.0, "duty: air drag, force per (m/s)^2 of the car's speed.", "measure it: the speed-squared part of a coast-down", 0.0, 10.0)


CAMERA_MODELS = ("ideal", "linescan", "area")
TSL1401 = "TSL1401CL datasheet (ams, 2016)"


def _floats(doc: str, source: str, lo: float, hi: float):
    return field(default=(), metadata={"doc": doc, "source": source, "lo": lo, "hi": hi, "list": True})


@dataclass(frozen=True)
class Camera:
    """The camera: where it sits and what it sees (geometry, the first group), and how it turns
    light into numbers (``model`` and the sensor and lens fields after it; docs/camera.md).
    The default is a physical line camera; ``model = "ideal"`` is the exact render of earlier
    versions (fixed grey levels plus ``noise_std``), whose images do not depend on the sensor
    and lens fields."""

    forward_m: float = _f(0.20, "Camera position ahead of the rear axle.", "estimate", -1, 1)
    height_m: float = _f(0.30, "Camera height above the ground.", "NXP Cup camera mast, estimate", 0.02, 2)
    pitch_rad: float = _f(0.65, "Downward tilt of the optical axis from horizontal (positive = down).",
                          "chosen so row 60 looks 0.40 m ahead of the front bumper and sees 0.80 m "
                          "of ground across (both edge lines of a 0.55 m lane with margin)", 0.0, 1.57)
    hfov_rad: float = _f(1.30, "Horizontal field of view.", "estimate (~75 deg lens)", 0.1, 3.0)
    width_px: int = _f(128, "Image width; the real line camera has 128 pixels.", "thesis 5.1.2", 8, 4096)
    height_px: int = _f(128, "Image height (rows for the row-selection test, thesis Fig. 5.2).",
                        "thesis Fig. 5.2 loops over 128 rows", 1, 4096)
    default_row: int = _f(60, "The image row that plays the real line camera (Spinner.LINE_ROW, shown "
                          "stretched in the debug video).", "thesis 5.1.2: the team used row 60", 0, 4095)
    fps_hz: float = _f(50.0, "Frame rate of the ideal and area models; get_image() waits for the next "
                       "frame. (linescan: the frame period is exposure_s + readout_s.)", "estimate", 1, 1000)
    noise_std: float = _f(6.0, "Std-dev of additive Gaussian pixel noise (0-255 scale) of add_noise "
                          "(and of the ideal model's images).", "estimate", 0, 128)
    model: str = _choice("linescan", CAMERA_MODELS,
                         "How light becomes pixels: 'ideal' (exact render, fixed grey levels + noise_std); "
                         "'linescan' (one row integrated over exposure_s, frame period = exposure_s + "
                         "readout_s, as the TSL1401); 'area' (every row, frames at fps_hz, exposure_s <= "
                         "1 / fps_hz). linescan and area follow the EMVA 1288 linear camera model.",
                         "a TSL1401-type line camera as NXP Cup kits have (docs/camera.md); EMVA 1288 "
                         "release 4.0 (linear model)")
    exposure_s: float = _f(0.0195, "Integration (exposure) time at the start of a run; the controller sets it "
                           "with set_exposure(seconds). linescan: the time between two SI pulses minus "
                           "the read-out.", "estimate: teams use 1-20 ms (issue 47); 19.5 ms + 0.5 ms "
                           "read-out = 50 frames a second, the ideal model's fps_hz", 1e-5, 1.0)
    readout_s: float = _f(0.0005, "linescan: time to clock out and convert the 128 pixels after the "
                          "exposure (the frame period is exposure_s + readout_s).",
                          "estimate: 128 ADC conversions of ~4 us (FRDM-KL25Z); the sensor itself "
                          f"clocks up to 8 MHz ({TSL1401})", 0.0, 0.1)
    f_number: float = _f(2.8, "Lens f-number N: image-plane illuminance = reflectance x illuminance x "
                         "lens_transmission / (4 N^2) on the optical axis.", "estimate (small M12 lens; the white lane reads ~210 of 255 at the image centre under "
                         "500 lux with the default exposure)",
                         0.7, 32)
    lens_transmission: float = _f(0.9, "Fraction of light the lens passes.", "estimate (coated glass lens)",
                                  0.05, 1.0)
    vignetting_power: float = _f(4.0, "Fall-off of the image-plane illuminance with the ray's angle theta to "
                                 "the optical axis: cos(theta)^power (4 = the natural cos^4 law; 0 = none).",
                                 "cos^4 law of a thin lens (e.g. Smith, Modern Optical Engineering)", 0.0, 12.0)
    vignetting_profile: tuple = _floats("Optional measured relative response of each column (width_px "
                                        "numbers, 1 = on-axis; e.g. from a flat field), multiplied on top of "
                                        "the cos^power law. Empty = none.", "none (measure with a flat field)",
                                        0.0, 10.0)
    psf_sigma_px: float = _f(0.7, "Optical blur: standard deviation of the lens's Gaussian point-spread "
                             "function along the row, in pixels (0 = sharp).",
                             "estimate: a 2 cm line 0.4 m ahead spans ~3 px and never reaches black "
                             "(issue 47)", 0.0, 20.0)
    motion_blur_samples: int = _f(4, "Poses averaged over the exposure (the image is integrated while "
                                  "the car moves; 1 = no motion blur).", "estimate (4 is within 1 grey "
                                  "level of 32 at 3 m/s and 10 ms)", 1, 64)
    quantum_efficiency: float = _f(0.6, "EMVA 1288 eta: electrons per photon (white light).",
                                   "estimate for a silicon photodiode in the visible", 0.01, 1.0)
    pixel_area_um2: float = _f(3524.3, "Light-sensitive area of one pixel.", TSL1401, 1.0, 1e5)
    saturation_capacity_e: float = _f(6.0e6, "EMVA 1288 saturation capacity: electrons at which a pixel "
                                      "saturates (full well).", "estimate: ~1700 e- per um^2 of the "
                                      "3524 um^2 pixel", 100.0, 1e9)
    dark_noise_e: float = _f(1500.0, "EMVA 1288 dark (read) noise, temporal, electrons rms.",
                             f"{TSL1401}: dynamic range 4000:1 (72 dB) = saturation / dark noise",
                             0.0, 1e8)
    dark_current_eps: float = _f(4.0e4, "Dark current, electrons per second.", "estimate", 0.0, 1e9)
    dsnu_e: float = _f(3.0e4, "EMVA 1288 DSNU: pixel-to-pixel spread (std) of the dark signal, electrons "
                       "(fixed pattern offset, seeded).", "estimate (~0.5 % of saturation)", 0.0, 1e8)
    prnu: float = _f(0.03, "EMVA 1288 PRNU: pixel-to-pixel spread (std) of the response, as a fraction "
                     "(fixed pattern gain, seeded).", "estimate", 0.0, 1.0)
    analog_gain: float = _f(1.0, "Gain before the ADC: at 1 the saturation capacity reaches the ADC's "
                            "maximum.", "TFC kit: no programmable gain", 0.01, 1000.0)
    black_level_dn: float = _f(4.0, "ADC reading of a dark pixel (offset), in ADC counts.",
                               "estimate: dark output up to ~0.1 V on a 3.3 V ADC", 0.0, 65535.0)
    adc_bits: int = _f(8, "ADC resolution. Images are 8-bit: more bits are shifted down to the top 8, "
                       "fewer are shifted up.", "FRDM-KL25Z ADC: 8 to 16 bits; 8 as the thesis's images",
                       1, 16)
    dead_pixels: int = _f(0, "Pixels that give the black level whatever the light (seeded places).",
                          "none on a good sensor", 0, 4096)
    hot_pixels: int = _f(0, "Pixels that read the ADC maximum whatever the light (seeded places).",
                         "none on a good sensor", 0, 4096)
    startup_frames: int = _f(1, "Frames after power-up that read saturated (the pixels integrated since "
                             "power-up before the first SI pulse).", "estimate", 0, 100)
    fixed_pattern_seed: int = _f(1, "Seed of this camera's fixed pattern (DSNU, PRNU, dead and hot pixel "
                                 "places): one number per physical camera, not per run.", "arbitrary",
                                 0, 2**31 - 1)

    @staticmethod
    def exposure_range_s() -> tuple[float, float]:
        """The range of ``exposure_s`` (set_exposure checks against it too)."""
        m = next(f for f in fields(Camera) if f.name == "exposure_s").metadata
        return float(m["lo"]), float(m["hi"])

    def frame_period_s(self, exposure_s: float | None = None, free_running: bool = False) -> float:
        """Time between frames: ``exposure + readout_s`` for ``linescan`` (``exposure``:
        ``exposure_s`` when None; ``exposure`` alone when ``free_running``: SI pulses from a
        free-running timer, each read-out overlapping the next integration), else ``1 / fps_hz``."""
        if self.model == "linescan":
            e = float(self.exposure_s if exposure_s is None else exposure_s)
            return e if free_running else e + self.readout_s
        return 1.0 / self.fps_hz


PIXY2_LINE_API = "Pixy2 line tracking API and PixyMon line parameters (docs.pixycam.com, wiki v2)"


@dataclass(frozen=True)
class Pixy2:
    """The Pixy2's line tracking (the Pixy2 API of ``spinner.pixy2()``, ``Pixy2.h``,
    ``pixy2_line.h``; docs/pixy2.md): how the camera's frame becomes vectors and
    intersections. The camera section gives the frame (a Pixy2 car: examples/pixy2_car.toml);
    its width and height must be whole multiples of the grid."""

    grid_width_px: int = _f(79, "Width of the line-tracking grid (vector x is 0 .. width - 1); the frame "
                            "is averaged over blocks of camera.width_px / this.", PIXY2_LINE_API + ": x 0..78", 8, 1024)
    grid_height_px: int = _f(52, "Height of the line-tracking grid (vector y is 0 .. height - 1, 0 = top = "
                             "farthest).", PIXY2_LINE_API + ": y 0..51", 8, 1024)
    edge_threshold: float = _f(10.0, "Edge threshold: grey-level step (0-255) between two grid pixels "
                               "edge_distance_px apart that counts as an edge (lower: more lines).",
                               "estimate; PixyMon 'Edge threshold' (tune it as on the real camera)", 1.0, 255.0)
    edge_distance_px: int = _f(2, "Edge distance: pixels between the two samples of the edge detector "
                               "(larger: fuzzier edges found).", "estimate; PixyMon 'Edge distance'", 1, 8)
    min_line_width_px: float = _f(0.0, "Narrower dark runs are not lines.", "PixyMon 'Minimum line width'; "
                                  "estimate", 0.0, 100.0)
    max_line_width_px: float = _f(10.0, "Wider dark runs are not lines (the crossing's square, the floor).",
                                  "PixyMon 'Maximum line width'; estimate: a 2 cm line is ~5 grid px at "
                                  "the nearest row of examples/pixy2_car.toml", 1.0, 200.0)
    min_line_length_px: float = _f(4.0, "Shorter lines are dropped (end to end).",
                                   "PixyMon 'Minimum line length'; estimate", 0.0, 200.0)
    max_merge_distance_px: float = _f(5.0, "Line ends this close meet (an intersection when 3 or more do).",
                                      "PixyMon 'Maximum merge distance'; estimate", 0.0, 100.0)
    barcode_edge_threshold: float = _f(35.0, "Edge threshold of the barcode reader: grey-level step between "
                                       "two frame pixels barcode_edge_distance_px apart (single pixels, "
                                       "so higher than edge_threshold, which acts on grid block means).",
                                       "the firmware's default edge threshold (charmedlabs/pixy2 line.h "
                                       "LINE_EDGE_THRESH_DEFAULT)", 1.0, 255.0)
    barcode_edge_distance_px: int = _f(2, "Edge distance of the barcode reader along the camera frame's "
                                       "rows, in frame pixels: narrower bars and gaps are measured too "
                                       "wide (larger: fuzzier edges found, bigger barcodes needed).",
                                       "estimate; PixyMon 'Edge distance' (its docs: it sets the minimum "
                                       "barcode size)", 1, 16)
    max_line_compare_px: float = _f(10.0, "A line keeps its tracking index from the last frame when both "
                                    "its ends moved at most this far.", "PixyMon 'Maximum line compare'; "
                                    "estimate", 0.0, 200.0)


HC_SR04 = "HC-SR04 ultrasonic ranging module datasheet (Elecfreaks)"


@dataclass(frozen=True)
class RangeSensor:
    """One range sensor on the car (``[range_sensors.NAME]``; read with ``get_distance(NAME)``, a
    lidar's whole scan with ``get_scan(NAME)``, docs/events.md): where it sits and looks (car body
    frame), its cone, range, rate and noise. It measures the objects standing on the track (the
    rules' cube and block), not the floor. Defaults: an HC-SR04 ultrasonic module at the front
    bumper, looking ahead."""

    kind: str = _choice("ultrasonic", ("ultrasonic", "infrared", "tof", "lidar"),
                        "What the sensor is: a cone of rays read as its nearest hit, or a planar 'lidar' "
                        "whose every ray is a reading (get_scan; get_distance: the nearest).",
                        "the part on your car")
    x_m: float = _f(0.24, "Position of the sensor ahead of the rear axle.", "estimate: the default car's "
                    "front bumper", -2.0, 2.0)
    y_m: float = _f(0.0, "Position to the left of the car's centre line.", "estimate", -1.0, 1.0)
    z_m: float = _f(0.06, "Height of the sensor above the track.", "estimate", 0.0, 1.0)
    yaw_rad: float = _f(0.0, "Direction it looks, + = left of straight ahead.", "estimate", -3.1416, 3.1416)
    fov_rad: float = _f(0.26, "Full angle of its cone across the car (rays spread over it, from its "
                        "right edge to its left; 6.2832 = all round, no ray twice).",
                        HC_SR04 + ": measuring angle 15 deg", 0.0, 6.2832)
    rays: int = _f(7, "Rays across the cone; the reading is the nearest hit (a lidar: one reading each).",
                   "ours", 1, 4096)
    min_range_m: float = _f(0.02, "Nearer objects read this.", HC_SR04 + ": 2 cm", 0.0, 10.0)
    max_range_m: float = _f(4.0, "Nothing nearer than this: the reading is inf.", HC_SR04 + ": 400 cm",
                            0.01, 100.0)
    rate_hz: float = _f(16.0, "Readings per second; a reading is held until the next.",
                        HC_SR04 + ": a measurement cycle of at least 60 ms", 0.1, 1000.0)
    noise_std_m: float = _f(0.003, "Standard deviation of the reading's Gaussian noise (a lidar: each ray's).",
                            HC_SR04 + ": resolution 0.3 cm", 0.0, 1.0)


FXAS21002C = "FXAS21002C gyroscope datasheet (NXP, rev. 2.1)"
FXOS8700CQ = "FXOS8700CQ accelerometer datasheet (NXP, rev. 8)"


@dataclass(frozen=True)
class Encoders:
    """Wheel encoders (``[encoders]``; read with ``get_encoder(WHEEL)``, docs/drive.md): which wheels
    carry one, its lines per wheel revolution and how its pulses are counted. A car file
    without the section has none."""

    wheels: str = _choice("rear", ("rear", "front", "all"), "Which wheels carry an encoder.",
                          "the rules list encoders and one Hall sensor per wheel (rules summary section 2); "
                          "teams measure the driven rear wheels")
    lines_per_rev: int = _f(512, "Lines (pulses of one channel) per revolution of the wheel (an encoder on "
                            "the motor: its lines times the gear ratio).",
                            "estimate: a 512-line incremental encoder; count your wheel's pulses", 1, 100000)
    counting: str = _choice("x4", ("x4", "x2", "x1", "single"),
                            "How the counter counts: quadrature decoding of both channels' edges (x4), of "
                            "one channel's edges (x2) or of its rising edges (x1), signed; or one channel's "
                            "rising edges without direction (single: a Hall sensor on a magnet ring).",
                            "the quadrature decoder of the MCU's timer (FTM/TPM quadrature mode: x4)")


@dataclass(frozen=True)
class Imu:
    """An inertial measurement unit (``[imu]``; read with ``get_gyro()`` and ``get_accel()``,
    docs/drive.md): a 3-axis gyroscope and accelerometer in the car body frame (x ahead, y left,
    z up), sampled at ``rate_hz`` (a reading is held until the next sample), each axis with its
    white noise, a bias drawn once per device (``device_seed``) that then drifts as a random walk,
    its range and its resolution. Defaults: NXP's FXAS21002C gyroscope (+-500 deg/s) and
    FXOS8700CQ accelerometer (+-4 g). A car file without the section has none."""

    x_m: float = _f(0.10, "Position ahead of the rear axle (the accelerometer feels the turn there).",
                    "estimate: the main board between the axles", -1.0, 1.0)
    y_m: float = _f(0.0, "Position to the left of the car's centre line.", "estimate", -0.5, 0.5)
    z_m: float = _f(0.05, "Height above the ground.", "estimate", 0.0, 1.0)
    rate_hz: float = _f(200.0, "Samples per second (output data rate).",
                        FXAS21002C + ": ODR 12.5 to 800 Hz (ours: 200)", 1.0, 2000.0)
    gyro_range_radps: float = _f(8.7266, "Largest angular rate it reads (+-).",
                                 FXAS21002C + ": full scale +-250/500/1000/2000 deg/s (ours: 500)", 0.1, 100.0)
    gyro_lsb_radps: float = _f(2.7271e-4, "Resolution: one count of its 16-bit output.",
                               FXAS21002C + ": 0.015625 deg/s per LSB at +-500 deg/s", 0.0, 1.0)
    gyro_noise_density_radps_rthz: float = _f(4.3633e-4, "White noise density; a sample's noise is "
                                              "density x sqrt(rate_hz / 2).",
                                              FXAS21002C + ": 0.025 deg/s/sqrt(Hz)", 0.0, 1.0)
    gyro_bias_std_radps: float = _f(0.027, "Spread of the zero-rate offset between devices (each axis).",
                                    "FXAS21002C zero-rate offset: typically +-50 LSB at +-2000 deg/s (+-3.1 "
                                    "deg/s, NXP community answer on the FXAS21002C); ours: half of it as the "
                                    "spread", 0.0, 1.0)
    gyro_bias_walk_radps_rts: float = _f(1e-4, "Drift of the offset: a random walk growing by this x "
                                         "sqrt(seconds).", "estimate: MEMS gyroscope bias instability", 0.0, 1.0)
    accel_range_mps2: float = _f(39.227, "Largest acceleration it reads (+-).",
                                 FXOS8700CQ + ": +-2/4/8 g (ours: 4 g)", 0.1, 1000.0)
    accel_lsb_mps2: float = _f(4.7884e-3, "Resolution: one count of its 14-bit output.",
                               FXOS8700CQ + ": 0.488 mg per LSB at +-4 g", 0.0, 10.0)
    accel_noise_density_mps2_rthz: float = _f(1.2356e-3, "White noise density; a sample's noise is "
                                              "density x sqrt(rate_hz / 2).",
                                              FXOS8700CQ + ": 126 ug/sqrt(Hz)", 0.0, 10.0)
    accel_bias_std_mps2: float = _f(0.1, "Spread of the zero-g offset between devices (each axis).",
                                     "estimate: MEMS accelerometers of this class, tens of mg; measure it at rest",
                                     0.0, 10.0)
    accel_bias_walk_mps2_rts: float = _f(1e-3, "Drift of the offset: a random walk growing by this x "
                                         "sqrt(seconds).", "estimate", 0.0, 10.0)
    device_seed: int = _f(1, "This device: its offsets are drawn once from this seed (another device, "
                          "another seed).", "ours", 0, 2 ** 31 - 1)


@dataclass(frozen=True)
class Effects:
    """Catalogue of effects the nominal model leaves out (issue 4). Neutral values give back
    the nominal model exactly. ``simrunner.car.effects`` applies them; docs/effects.md explains
    what each means physically and which manoeuvre reveals it."""

    steering_offset_rad: float = _f(0.0, "steering_offset: constant added to the steering command "
                                    "(servo trim). Revealed by straight runs and left/right step steers.",
                                    "neutral", -0.5, 0.5)
    steering_gain: float = _f(1.0, "steering_gain: actual steer target = gain * command. Revealed by "
                              "constant-radius circles.", "neutral", 0.2, 3.0)
    steering_lag_s: float = _f(0.0, "steering_lag: first-order lag time constant of the steering "
                               "target. Revealed by step steers and the chirp.", "neutral", 0.0, 2.0)
    steering_rate_limit_radps: float = _f(math.inf, "steering_rate_limit: extra slew limit of the "
                                          "steering (effective rate = min(servo rate, this)). Revealed by "
                                          "large step steers.", "neutral (inf)", 0.01, math.inf)
    command_latency_s: float = _f(0.0, "command_latency: pure delay between a command and its effect. "
                                  "Revealed by step steers and speed steps.", "neutral", 0.0, 1.0)
    motor_lag_s: float = _f(0.0, "motor_lag: first-order lag time constant of the speed command. "
                            "Revealed by speed steps and ramps.", "neutral", 0.0, 5.0)
    throttle_deadband_mps: float = _f(0.0, "throttle_deadband: speed commands below this magnitude "
                                      "give no drive. Revealed by slow speed ramps.", "neutral", 0.0, 2.0)
    rolling_resistance_coeff: float = _f(0.0, "rolling_resistance: resisting force c_rr * m * g "
                                         "against motion. Revealed by coast-down at low speed.",
                                         "neutral", 0.0, 0.5)
    drag_coeff_kgpm: float = _f(0.0, "drag: resisting force k * v^2 (N with v in m/s). Revealed by "
                                "coast-down from high speed.", "neutral", 0.0, 5.0)
    tire_slip_understeer_radps2pm: float = _f(0.0, "tire_slip: understeer gradient K: effective steer "
                                              "= steer - K * lateral acceleration (rad per m/s^2). "
                                              "Revealed by circles at rising speed.", "neutral", 0.0, 0.5)
    friction_scale: float = _f(1.0, "friction: multiplies the tyre friction coefficient. Revealed at "
                               "the grip limit (circles at rising speed, tilt test).", "neutral", 0.05, 5.0)
    speed_scale: float = _f(1.0, "speed_scale: the car reaches speed_scale x the commanded speed (ESC "
                            "or encoder calibration; drive.max_speed_mps scales too). Revealed by "
                            "steady straight runs and speed steps.", "neutral", 0.1, 10.0)
    steering_asymmetry: float = _f(0.0, "steering_asymmetry: left steer targets get gain (1 + a), right ones "
                                   "(1 - a), after gain and offset. Revealed by left and right circles and "
                                   "step steers.", "neutral", -0.9, 0.9)
    steering_play_rad: float = _f(0.0, "steering_play: backlash b of the linkage: the wheels follow the servo "
                                  "only once the slack is taken up (hysteresis of width 2 b). Revealed by "
                                  "small steering reversals (chirp, random steps).", "neutral", 0.0, 0.3)
    esc_reverse_delay_s: float = _f(0.0, "esc_brake_reverse: a negative speed command while rolling forward "
                                    "brakes to rest, holds for this time, then reverses (0 = reverses at "
                                    "once). Revealed by forward-to-reverse commands.", "neutral", 0.0, 5.0)
    accel_scale: float = _f(1.0, "accel_scale: the real acceleration limit is accel_scale x "
                            "drive.max_accel_mps2. Revealed by speed steps up from rest.", "neutral", 0.05, 20.0)
    brake_scale: float = _f(1.0, "brake_scale: the real braking limit is brake_scale x "
                            "drive.max_brake_mps2. Revealed by braking to rest.", "neutral", 0.05, 20.0)
    servo_rate_scale: float = _f(1.0, "servo_rate_scale: the real servo slew rate is servo_rate_scale x "
                                 "steering.rate_radps. Revealed by large step steers.", "neutral", 0.01, 100.0)
    steer_limit_scale: float = _f(1.0, "steer_limit_scale: the real steering stop is steer_limit_scale x "
                                  "steering.limit_rad. Revealed by full-lock circles.", "neutral", 0.1, 3.0)
    mass_scale: float = _f(1.0, "mass_scale: every mass and inertia of the car times this, with the motor "
                           "and brake torques of the file's numbers (so accel and brake limits / mass_scale). "
                           "Revealed by speed steps and braking.", "neutral", 0.1, 10.0)
    top_speed_mps: float = _f(math.inf, "top_speed: the car does not go faster than this whatever the "
                              "command (ESC speed limit, gearing, battery); inf = the file's max_speed_mps "
                              "only. Revealed by straights at high commanded speed.", "neutral (inf)",
                              0.01, math.inf)
    lift_lag_s: float = _f(0.0, "lift_lag: slowing down to a lower forward speed command follows a first-order "
                           "lag of this time constant (an ESC that coasts or drag-brakes when the throttle is "
                           "lifted); a zero or negative command still brakes. Revealed by speed steps down.",
                           "neutral", 0.0, 10.0)
    front_share_shift: float = _f(0.0, "front_drive: the car drives and brakes its front wheels with a share "
                                  "drive.front_share + this of the torque (clamped to [0, 1]): a four-wheel-drive "
                                  "car whose file says rear drive. Revealed by hard braking and accelerating, "
                                  "most of all while turning.", "neutral", -1.0, 1.0)
    inertia_scale: float = _f(1.0, "inertia: the chassis body's moments of inertia (those of a uniform box "
                              "of the chassis size) times this: below 1 when the mass sits near the centre "
                              "(battery, motor, electronics). Revealed only where the tyres slide: circles, turns and "
                              "step steers at the grip limit.", "neutral", 0.05, 5.0)
    tyre_stiffness_scale: float = _f(1.0, "tyre_stiffness (slip tyres only): both axles' cornering stiffness "
                                     "(wheels.cornering_stiffness_front/rear_per_rad) times this: softer tyres "
                                     "need larger slip angles, the car turns less for its steering. Revealed by "
                                     "circles, turns and step steers at speed.", "neutral", 0.05, 20.0)
    tyre_balance: float = _f(0.0, "tyre_balance (slip tyres only): the front cornering stiffness times (1 + "
                             "this), the rear times (1 - this): > 0 moves the car towards oversteer, < 0 "
                             "towards understeer (the single-track understeer gradient (1/c_f - 1/c_r) / g). "
                             "Revealed by circles at several speeds.", "neutral", -0.9, 0.9)
    tyre_relaxation_scale: float = _f(1.0, "tyre_relaxation (slip tyres only): wheels.relaxation_length_m "
                                      "times this: the distance a tyre rolls to build up its force, a lag of "
                                      "the car's lateral response that shrinks with speed. Revealed by chirps "
                                      "and step steers at speed.", "neutral", 0.05, 20.0)


@dataclass(frozen=True)
class CarDescription:
    """Everything the Gazebo car model and the dartpy car are built from."""

    name: str = "nxp_cup_car"
    chassis: Chassis = field(default_factory=Chassis)
    wheels: Wheels = field(default_factory=Wheels)
    steering: Steering = field(default_factory=Steering)
    drive: Drive = field(default_factory=Drive)
    camera: Camera = field(default_factory=Camera)
    effects: Effects = field(default_factory=Effects)
    pixy2: Pixy2 = field(default_factory=Pixy2)
    range_sensors: tuple = ()  # (name, RangeSensor) pairs: [range_sensors.NAME] tables
    encoders: Encoders | None = None  # [encoders]: none without the section
    imu: Imu | None = None            # [imu]: none without the section

    def __post_init__(self) -> None:
        problem = relation_problem(self)
        if problem is not None:
            raise CarDescriptionError(problem[2])

    @property
    def min_turn_radius_m(self) -> float:
        """Smallest rear-axle turning radius, R = L / tan(limit) (thesis eq. 5.1)."""
        return self.chassis.wheelbase_m / math.tan(self.steering.limit_rad)

    def replace(self, **sections: Any) -> "CarDescription":
        return dataclasses.replace(self, **sections)

    # -- files ---------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def to_toml(self, sources: Mapping[str, str] | None = None) -> str:
        """TOML text with a comment above every field (meaning, range, source).

        ``sources``: ``"section.field"`` -> where that value comes from (a fit, a
        calibration). A field without one says its default's source when it holds the
        default, else that its value is not the default (and what the default is), so a
        written file never credits a changed number to the default's source."""
        sources = sources or {}
        lines = ["# NXP Cup car description (units in field names; see docs/car.md).",
                 "# Every field is optional: a missing field takes its default.",
                 "", tomli_w.dumps({"name": self.name}).rstrip("\n")]
        for section, cls in {**_SECTION_TYPES, **_OPTIONAL_SECTIONS}.items():
            if getattr(self, section) is None:
                continue
            lines += ["", f"[{section}]"]
            values = dataclasses.asdict(getattr(self, section))
            for f in fields(cls):
                m = f.metadata
                value = values[f.name]
                source = sources.get(f"{section}.{f.name}")
                if source is None:
                    source = m["source"] if value == f.default else (
                        f"this file, not the default ({_toml_value(f.default)}: {m['source']})")
                rng = (f"One of {', '.join(repr(c) for c in m['choices'])}" if m.get("choices")
                       else f"Range {m['lo']} .. {m['hi']}" + (" each" if m.get("list") else ""))
                lines.append(f"# {m['doc']} {rng}. Source: {source}.")
                lines.append(tomli_w.dumps({f.name: value}).rstrip("\n"))
        for name, sensor in self.range_sensors:
            lines += ["", f"[range_sensors.{name}]", tomli_w.dumps(dataclasses.asdict(sensor)).rstrip("\n")]
        return "\n".join(lines) + "\n"

    def save(self, path: str | Path, sources: Mapping[str, str] | None = None) -> None:
        """Write atomically (``sources``: see :meth:`to_toml`)."""
        write_atomic(Path(path), self.to_toml(sources))


def _toml_value(value: Any) -> str:
    """``value`` as TOML writes it (``inf``, ``1.0``, ``"text"``)."""
    return tomli_w.dumps({"v": value}).strip()[len("v = "):]


_SECTION_TYPES = {"chassis": Chassis, "wheels": Wheels, "steering": Steering, "drive": Drive,
                  "camera": Camera, "effects": Effects, "pixy2": Pixy2}
_OPTIONAL_SECTIONS = {"encoders": Encoders, "imu": Imu}  # the car has the part only with the section


def car_from_dict(data: dict[str, Any], source: str = "<car>", text: str | None = None) -> CarDescription:
    """Build and range-check a description; unknown keys and bad values raise. ``text``: the
    TOML text ``data`` was read from, so messages can say ``source:line:``."""
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key == "name":
            if not isinstance(value, str) or not value:
                raise _error(source, text, None, "name", "'name' must be a non-empty string")
            kwargs["name"] = value
            continue
        if key == "range_sensors":
            if isinstance(value, (list, tuple)):  # to_dict's form: (name, table) pairs
                try:
                    value = {name: table for name, table in value}
                except (TypeError, ValueError):
                    value = None
            if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
                raise _error(source, text, None, key, "[range_sensors.NAME] tables expected, one per sensor")
            for name in value:
                if not re.fullmatch(r"[A-Za-z0-9_-]{1,40}", str(name)):
                    raise _error(source, text, key, None, f"[range_sensors.{name}]: a sensor's name is 1 to 40 "
                                 "letters, digits, '_' or '-' (get_distance(NAME) reads it)")
            kwargs[key] = tuple((name, _section_from_dict(RangeSensor, f"range_sensors.{name}", table, source,
                                                          text)) for name, table in value.items())
            continue
        if key in _OPTIONAL_SECTIONS and value is None:  # to_dict's form of a part the car lacks
            continue
        cls = _SECTION_TYPES.get(key) or _OPTIONAL_SECTIONS.get(key)
        if cls is None:
            raise _error(source, text, key, None,
                         f"unknown section [{key}] (expected one of {', '.join(_SECTION_TYPES)}, "
                         f"{', '.join(_OPTIONAL_SECTIONS)}, range_sensors)")
        if not isinstance(value, dict):
            raise _error(source, text, None, key, f"[{key}] must be a table")
        kwargs[key] = _section_from_dict(cls, key, value, source, text)
    # the relations between fields, checked here too so the message can name the line
    parts = {name: kwargs.get(name) or cls() for name, cls in _SECTION_TYPES.items()}
    problem = relation_problem(SimpleNamespace(**parts))
    if problem is not None:
        section, key, message = problem
        raise _error(source, text, section, key, message)
    return CarDescription(**kwargs)


def relation_problem(car: CarDescription | SimpleNamespace) -> tuple[str, tuple[str, ...], str] | None:
    """The first field that is in its own range but does not fit another one, as
    ``(section, fields involved, message)``; None when the description is consistent."""
    cam = car.camera
    if cam.default_row >= cam.height_px:
        return ("camera", ("default_row", "height_px"), f"camera.default_row = {cam.default_row}: expected a row "
                f"in [0, {cam.height_px - 1}] (camera.height_px = {cam.height_px})")
    # the line camera's row must look down at the ground (pinhole model of simrunner's camera)
    f_px = (cam.width_px / 2.0) / math.tan(cam.hfov_rad / 2.0)
    b = -(cam.default_row + 0.5 - cam.height_px / 2.0) / f_px
    if -math.sin(cam.pitch_rad) + b * math.cos(cam.pitch_rad) >= 0.0:
        return ("camera", ("default_row", "pitch_rad", "hfov_rad", "height_px"),
                f"camera.default_row = {cam.default_row}: this row looks "
                f"at or above the horizon (camera.pitch_rad = {cam.pitch_rad:g}); expected a row "
                f"that sees the track")
    if cam.vignetting_profile and len(cam.vignetting_profile) != cam.width_px:
        return ("camera", ("vignetting_profile", "width_px"), f"camera.vignetting_profile has "
                f"{len(cam.vignetting_profile)} numbers: expected one per column (camera.width_px = "
                f"{cam.width_px}) or none")
    if cam.model == "area" and cam.exposure_s > 1.0 / cam.fps_hz:
        return ("camera", ("exposure_s", "fps_hz"), f"camera.exposure_s = {cam.exposure_s!r}: an area "
                f"camera exposes within its frame, expected at most 1 / fps_hz = {1.0 / cam.fps_hz:g} s")
    if cam.model != "ideal" and cam.dead_pixels + cam.hot_pixels > cam.width_px * cam.height_px:
        return ("camera", ("dead_pixels", "hot_pixels"), f"camera.dead_pixels + hot_pixels = "
                f"{cam.dead_pixels + cam.hot_pixels}: expected at most the {cam.width_px * cam.height_px} "
                f"pixels of the sensor")
    if car.drive.command == "duty" and car.drive.front_share > 0.0:
        return ("drive", ("command", "front_share"), f"drive.command = 'duty' drives the two rear motors: "
                f"expected drive.front_share = 0 (got {car.drive.front_share!r})")
    if car.wheels.width_m >= car.chassis.track_m:
        return ("wheels", ("width_m",), f"wheels.width_m = {car.wheels.width_m!r}: expected less "
                f"than chassis.track_m = {car.chassis.track_m!r} (the wheels would overlap)")
    return None


_HEADER = re.compile(r"^\s*\[\s*([A-Za-z0-9_\-\"' .]+?)\s*\]\s*(#.*)?$")


def _line_of(text: str | None, section: str | None, key: str | None) -> int | None:
    """1-based line of ``key`` in table ``[section]`` (or of the header ``[section]`` when
    ``key`` is None; a top-level key when ``section`` is None) in TOML ``text``; dotted keys
    (``section.key = ...``) count too. None when it cannot be told."""
    if text is None:
        return None
    current = None
    names = [] if key is None else [key, f'"{key}"']
    for number, line in enumerate(text.splitlines(), 1):
        m = _HEADER.match(line)
        if m:
            current = m.group(1).strip().strip("\"'")
            if key is None and current == section:
                return number
            continue
        if key is None:
            continue
        left = line.split("=", 1)[0].strip() if "=" in line else None
        if left is None:
            continue
        left = left.replace(" ", "")
        if current == section and left in names:
            return number
        if current is None and section is not None and left in (f"{section}.{key}",):
            return number
    return None


def _error(source: str, text: str | None, section: str | None, key: str | tuple[str, ...] | None,
           message: str) -> CarDescriptionError:
    """``source:line: message`` with the line of the first of ``key`` (one field or several)
    found in ``[section]``, else of the section's header."""
    keys = key if isinstance(key, tuple) else (key,)
    line = next((n for k in keys if (n := _line_of(text, section, k)) is not None), None)
    if line is None and section is not None and key is not None:
        line = _line_of(text, section, None)
    return CarDescriptionError(f"{source}:{line}: {message}" if line else f"{source}: {message}")


def _section_from_dict(cls: type, section: str, data: dict[str, Any], source: str,
                       text: str | None = None):
    known = {f.name: f for f in fields(cls)}
    out: dict[str, Any] = {}
    for key, value in data.items():
        f = known.get(key)
        if f is None:
            raise _error(source, text, section, key,
                         f"unknown field {section}.{key} (expected one of {', '.join(known)})")
        choices = f.metadata.get("choices")
        if choices is not None:
            if value not in choices:
                raise _error(source, text, section, key, f"{section}.{key} = {_short(value)}: expected "
                             f"one of {', '.join(repr(c) for c in choices)}")
            out[key] = value
            continue
        if f.metadata.get("list"):
            out[key] = _number_list(section, key, value, f.metadata, source, text)
            continue
        want_int = f.type in (int, "int")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (
                want_int and not isinstance(value, int)):
            raise _error(source, text, section, key, f"{section}.{key} = {_short(value)}: expected "
                         f"{'an integer' if want_int else 'a number'}")
        if math.isnan(value) or (math.isinf(value) and f.metadata.get("hi") != math.inf):
            raise _error(source, text, section, key,
                         f"{section}.{key} = {value!r}: expected a finite number")
        lo, hi = f.metadata.get("lo"), f.metadata.get("hi")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise _error(source, text, section, key,
                         f"{section}.{key} = {_short(value)}: expected a value in [{lo}, {hi}]")
        out[key] = int(value) if want_int else float(value)
    return cls(**out)


def _number_list(section: str, key: str, value: Any, meta: Mapping[str, Any], source: str,
                 text: str | None) -> tuple[float, ...]:
    """A TOML array of finite numbers, each in the field's range, as a tuple of floats."""
    if not isinstance(value, (list, tuple)):
        raise _error(source, text, section, key, f"{section}.{key} = {_short(value)}: expected a list "
                     f"of numbers")
    lo, hi = meta["lo"], meta["hi"]
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
            raise _error(source, text, section, key, f"{section}.{key}[{i}] = {_short(v)}: expected a "
                         f"number in [{lo}, {hi}]")
    return tuple(float(v) for v in value)


def _short(value: Any, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


_TOML_AT = re.compile(r"\(at line (\d+), column \d+\)")


def load_car(path: str | Path | None = None) -> CarDescription:
    """Load a car description TOML file; ``None`` gives the default car. Errors are one line,
    ``PATH:LINE: what was expected`` (``PATH:`` alone when no line can be told)."""
    if path is None:
        return CarDescription()
    from .userfiles import read_user_text

    text = read_user_text(path, "car description", CarDescriptionError, "TOML")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = _TOML_AT.search(str(exc))
        line = m.group(1) if m else (len(text.splitlines()) or 1) if "end of document" in str(exc) else None
        where = f"{path}:{line}" if line else f"{path}"
        raise CarDescriptionError(f"{where}: invalid TOML: {exc}") from None
    return car_from_dict(data, str(path), text)


def markdown_doc() -> str:
    """The field table of docs/car.md."""
    lines = ["# Car description fields", "",
             "Generated by `python -m vehicle.description --doc`. Units are in the field names.", ""]
    for section, cls in {**_SECTION_TYPES, **_OPTIONAL_SECTIONS}.items():
        lines += [f"## [{section}]", ""]
        if section in _OPTIONAL_SECTIONS:
            lines += [(cls.__doc__ or "").split("\n\n")[0].replace("\n    ", " "), ""]
        lines += ["| field | default | range | meaning | source |", "| --- | --- | --- | --- | --- |"]
        for f in fields(cls):
            m = f.metadata
            if m.get("choices"):
                rng = " / ".join(f"`{c}`" for c in m["choices"])
                default = f"`{f.default}`"
            else:
                rng = f"{m['lo']} .. {m['hi']}" + (" each" if m.get("list") else "")
                default = "[]" if m.get("list") else f.default
            lines.append(f"| `{f.name}` | {default} | {rng} | {m['doc']} | {m['source']} |")
        lines.append("")
    lines += ["## [range_sensors.NAME]", "", (RangeSensor.__doc__ or "").split("\n\n")[0].replace("\n    ", " "),
              "", "| field | default | range | meaning | source |", "| --- | --- | --- | --- | --- |"]
    for f in fields(RangeSensor):
        m = f.metadata
        rng = " / ".join(f"`{c}`" for c in m["choices"]) if m.get("choices") else f"{m['lo']} .. {m['hi']}"
        default = f"`{f.default}`" if m.get("choices") else f.default
        lines.append(f"| `{f.name}` | {default} | {rng} | {m['doc']} | {m['source']} |")
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover - developer helper
    import sys

    if sys.argv[1:2] == ["--doc"]:
        sys.stdout.write(markdown_doc() + "\n")
    elif sys.argv[1:2] == ["--write"]:
        CarDescription().save(sys.argv[2])
