"""``simrunner calibrate-camera --scene straight``: the camera gap, from lines recorded on the car.

The car stood on a straight piece of track and its line camera recorded frames. The camera
model of the car file is compared with them, on the same scene:

* **The scene** (nuisance, fitted, not reported as effects): the lateral offset of the lane's
  centre from the camera's axis, a scale across the lane (field of view and camera height as
  one factor; a heading of the car shows on one row as offset and width, which these two
  absorb) and the floor's reflectance beside the track. The lane is the rules' (section 1.1:
  510 mm of white between two 20 mm black lines), reflectances 0.922 / 0.059 as the default
  track's.
* **The mean line** is modelled as ``clip(black + gain x V(col) x blur(reflectance), 0, 255)``
  with ``V = cos(theta)^power`` (times the car's measured profile, if any) and a Gaussian blur
  of ``sigma`` pixels; the car file's camera gives ``gain``, ``black``, ``power`` and ``sigma``
  (``before``). Each of them is an effect of the catalogue (``gain``, ``black_level``,
  ``vignetting``, ``blur``); one is named only if freeing it lowers the error on held-out
  pixels (two folds: even and odd columns; the effect fitted on one, the scene refitted on the
  other) by more than 5 % and 0.3 grey levels; all 16 subsets are scored (effects that trade
  for each other are judged together), and an effect the others make unnecessary is dropped.
* **From the frames**: ``startup_frames`` (leading frames far from the others),
  ``saturation`` (pixels at 255 in the mean line), ``dead_pixels`` (the black level where the
  fitted line is lit), ``hot_pixels`` (255 where it is not), ``noise`` (the temporal spread of
  each pixel against the car's prediction) and ``fixed_pattern`` (a pixel-to-pixel gain pattern
  that one half of the frames finds and the other half confirms). Each is named when it differs
  from what the car file's camera would record.

A gain pattern that both halves of the frames show is measured pixel by pixel on the lane
(``response``) and written into the fitted car as ``camera.vignetting_profile`` (with
``camera.prnu = 0``): the fitted camera then gives those pixels the recorded line; its error
``rmse_after`` is measured with the pattern of the first half of the frames on the second.
What no effect explains is reported against the error noise and fixed pattern explain, with
the columns where it is largest.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from vehicle.description import CarDescription
from worlds.lighting import DEFAULT_AMBIENT_LUX, LANE_REFLECTANCE, LINE_REFLECTANCE

from simrunner.workflows.calibration.camera_lines import Recording
from simrunner.workflows.calibration.measured import CalibrationError

LANE_HALF_M = 0.255  # rules 1.1: 550 mm over the lines, 20 mm lines: 510 mm of white lane
LINE_M = 0.02
RASTER_M = 0.005  # the simulator's raster (simrunner.track.raster.DEFAULT_M_PER_PX)
MODEL_DN = 2.0  # the line model's own error at the black lines' edges against the simulator's
# raster (edges placed to its 5 mm pixels): measured 1.2-2.0 grey levels on the ideal camera
MARGIN_PX = 12  # pixels modelled beyond each end of the row (blur up to 4 px)
SHAPE_EFFECTS = ("gain", "black_level", "vignetting", "blur")
CATALOGUE = SHAPE_EFFECTS + ("saturation", "dead_pixels", "hot_pixels", "fixed_pattern", "noise",
                             "startup_frames")
MIN_GAIN = 0.05  # an effect must lower the held-out error by this fraction ...
MIN_GAIN_DN = 0.3  # ... and by this many grey levels
BOUNDS = {"offset": (-0.35, 0.35), "scale": (0.6, 1.6), "floor": (0.0, 1.0),
          "gain": (1.0, 5000.0), "black_level": (-30.0, 120.0), "vignetting": (0.0, 12.0),
          "blur": (0.0, 4.0)}


@dataclass
class CameraFit:
    """What ``calibrate-camera`` found: the effects named, their values and hints, the errors
    before and after, the nuisance fit, and the car with the fitted camera."""

    effects: list[str]
    parameters: dict[str, float]
    hints: dict[str, str]
    rmse_before: float
    rmse_after: float
    noise_floor: float
    nuisance: dict[str, float]
    frames_used: int
    car_after: CarDescription
    unexplained: str
    response_measured: bool = False  # the per-pixel response went into camera.vignetting_profile
    scene: str = "straight"
    lines: dict[str, np.ndarray] = field(repr=False, default_factory=dict)

    def report_json(self) -> dict:
        return {"scene": self.scene, "effects": list(self.effects), "parameters": self.parameters,
                "hints": self.hints, "rmse_before": self.rmse_before, "rmse_after": self.rmse_after,
                "noise_floor": self.noise_floor, "nuisance": self.nuisance,
                "frames_used": self.frames_used, "unexplained": self.unexplained,
                "response_measured": self.response_measured}

    def text(self) -> str:
        left = "the noise alone" if self.response_measured else "the noise and the pixels' own gains"
        out = [f"camera gap, {self.scene} scene: {self.frames_used} frames; mean-line error "
               f"{self.rmse_before:.2f} grey levels with the car file's camera, {self.rmse_after:.2f} "
               f"fitted ({left}: {self.noise_floor:.2f})"]
        if not self.effects:
            out.append("effects: none (the car file's camera records these lines)")
        for name in self.effects:
            out.append(f"  {name}: {self.hints[name]}")
        if self.response_measured:
            out.append("measured: each pixel's response on the lane (written as camera.vignetting_profile; "
                       "camera.prnu set to 0)")
        if self.unexplained:
            out.append(f"not explained: {self.unexplained}")
        return "\n".join(out) + "\n"


# -- the scene ---------------------------------------------------------------------------------
class StraightView:
    """The line camera's row looking at a straight lane: the ground y of each pixel's centre
    and the ray's angle to the optical axis (the pinhole geometry of
    :class:`simrunner.sensors.camera.Camera`). A pixel sees the lane's reflectance at its
    centre, averaged by the simulator's raster sampling (bilinear on a ``RASTER_M`` grid: a
    triangle of that half-width), integrated exactly, so the model is smooth in the offset
    and the scale."""

    def __init__(self, cam) -> None:
        w, h, row = cam.width_px, cam.height_px, cam.default_row
        f = (w / 2.0) / math.tan(cam.hfov_rad / 2.0)
        p = cam.pitch_rad
        v = row + 0.5 - h / 2.0
        b = -v / f
        dz = -math.sin(p) + b * math.cos(p)
        if dz >= 0:
            raise CalibrationError(f"camera.default_row = {row} looks above the horizon: no ground to fit")
        t = cam.height_m / -dz
        centres = np.arange(-MARGIN_PX, w + MARGIN_PX) + 0.5 - w / 2.0
        self.gy = t * (-centres / f)  # (W + 2 margin,) metres, + = left
        self.cos_theta = row_cos_theta(cam)
        self.profile = (np.asarray(cam.vignetting_profile, np.float64) if cam.vignetting_profile
                        else np.ones(w))
        self.width = w

    @staticmethod
    def _double_integral(d: np.ndarray, floor: float) -> np.ndarray:
        """``G(d)``: the lane's reflectance profile integrated twice from 0 (metres across)."""
        def part(lo, hi):
            """The integral from 0 to d of clip(x, lo, hi) - clip(0, lo, hi): Q(d) - Q(0) - d
            clip(0, lo, hi), Q the antiderivative of clip(x, lo, hi)."""
            def q(x):
                return np.where(x < lo, lo * x, np.where(x <= hi, (x * x + lo * lo) / 2.0,
                                                         hi * x - (hi * hi - lo * lo) / 2.0))
            return q(d) - q(np.float64(0.0)) - d * min(max(0.0, lo), hi)

        inner, outer = LANE_HALF_M, LANE_HALF_M + LINE_M
        return (floor * d * d / 2.0 + (LANE_REFLECTANCE - floor) * part(-inner, inner)
                + (LINE_REFLECTANCE - floor) * (part(-outer, -inner) + part(inner, outer)))

    def reflectance(self, offset_m: float, scale: float, floor: float) -> np.ndarray:
        """Reflectance at each of the ``W + 2 margin`` pixel centres, triangle-averaged."""
        d = scale * self.gy - offset_m
        h = RASTER_M
        g = self._double_integral
        return (g(d + h, floor) - 2.0 * g(d, floor) + g(d - h, floor)) / (h * h)

    def mean_line(self, p: dict[str, float]) -> np.ndarray:
        """The modelled mean line (8-bit) for parameters ``p`` (offset, scale, floor, gain,
        black_level, vignetting, blur)."""
        rho = self.reflectance(p["offset"], p["scale"], p["floor"])
        sigma = p["blur"]
        if sigma > 1e-3:
            x = np.arange(-MARGIN_PX, MARGIN_PX + 1, dtype=np.float64)
            k = np.exp(-0.5 * (x / sigma) ** 2)
            rho = np.convolve(rho, k / k.sum(), mode="valid")
        else:
            rho = rho[MARGIN_PX:-MARGIN_PX]
        v = self.cos_theta ** p["vignetting"] * self.profile
        return np.clip(p["black_level"] + p["gain"] * v * rho, 0.0, 255.0)


def predicted(car: CarDescription, lux: float = DEFAULT_AMBIENT_LUX) -> dict[str, float]:
    """The car file's camera as the mean-line model's parameters (8-bit counts; the scene lit
    at ``lux``), with its temporal noise at the lane's centre (``noise_dn``) and the number
    of start-up frames."""
    cam = car.camera
    if cam.model == "ideal":
        return {"gain": 255.0, "black_level": 0.0, "vignetting": 0.0, "blur": 0.0,
                "noise_dn": float(cam.noise_std), "startup_frames": 0.0, "prnu": 0.0}
    from simrunner.sensors.imaging import PHOTONS_PER_LM_S

    lens = cam.lens_transmission / (4.0 * cam.f_number ** 2)
    e_per_lux_s = cam.quantum_efficiency * cam.pixel_area_um2 * 1e-12 * PHOTONS_PER_LM_S
    k8 = cam.analog_gain * (2 ** cam.adc_bits - 1) / cam.saturation_capacity_e / 2 ** (cam.adc_bits - 8)
    e_lane = lens * e_per_lux_s * lux * LANE_REFLECTANCE * cam.exposure_s
    return {"gain": lens * e_per_lux_s * lux * cam.exposure_s * k8,
            "black_level": cam.black_level_dn / 2 ** (cam.adc_bits - 8) + k8 * cam.dark_current_eps * cam.exposure_s,
            "vignetting": float(cam.vignetting_power), "blur": float(cam.psf_sigma_px),
            "noise_dn": k8 * math.sqrt(e_lane + cam.dark_noise_e ** 2),
            "startup_frames": float(cam.startup_frames), "prnu": float(cam.prnu),
            "k8": k8}


# -- fitting -----------------------------------------------------------------------------------
def _fit(view: StraightView, target: np.ndarray, use: np.ndarray, fixed: dict[str, float],
         free: tuple[str, ...]) -> tuple[dict[str, float], float]:
    """Least squares over the nuisance and ``free`` parameters on the pixels ``use``; returns
    the parameters and the rms error on them."""
    from scipy.optimize import least_squares

    nuisance = getattr(view, "nuisance", ("offset", "scale", "floor"))
    names = tuple(nuisance) + free
    lo = np.array([BOUNDS[n][0] for n in names])
    hi = np.array([BOUNDS[n][1] for n in names])

    def params(x) -> dict[str, float]:
        p = dict(fixed)
        p.update(zip(names, (float(v) for v in x)))
        return p

    def resid(x):
        return (view.mean_line(params(x)) - target)[use]

    if not names:
        r = resid(np.zeros(0))
        return dict(fixed), float(np.sqrt(np.mean(r ** 2)))
    start = [fixed[n] for n in free]
    if "offset" in nuisance:  # the lane's edges make local minima: start on a grid of offsets
        best = None
        for offset in np.linspace(-0.3, 0.3, 25):
            x0 = np.clip(np.array([offset, 1.0, fixed["floor"]] + start), lo, hi)
            cost = float(np.sum(resid(x0) ** 2))
            if best is None or cost < best[0]:
                best = (cost, x0)
        x0 = best[1]
    else:
        x0 = np.clip(np.array([fixed[n] for n in nuisance] + start), lo, hi)
    steps = np.array([{"offset": 1e-3, "scale": 1e-3, "floor": 1e-2}[n] for n in nuisance]
                     + [max(1e-3, 1e-3 * abs(fixed[n])) for n in free])
    sol = least_squares(resid, x0, bounds=(lo, hi), x_scale=steps, diff_step=1e-4, method="trf")
    p = params(sol.x)
    return p, float(np.sqrt(np.mean(resid(sol.x) ** 2)))


def _held_out_rmse(view, target, valid, fixed, free) -> float:
    """RMS error on held-out pixels: the effects ``free`` are fitted on the even columns and
    tested on the odd ones, and back. The scene (offset, scale, floor) is refitted on the test
    columns with the effects frozen: an effect must carry over, the car's place need not (a
    black line 3 pixels wide is found again in either half)."""
    blocks = np.arange(len(target)) % 2 == 0  # the columns' parity (frames flattened row after row)
    err = []
    for train in (blocks, ~blocks):
        p, _ = _fit(view, target, valid & train, fixed, free)
        frozen = {**fixed, **{name: p[name] for name in free}}
        _, rmse = _fit(view, target, valid & ~train, frozen, ())
        err.append(rmse)
    return float(np.sqrt(np.mean(np.square(err))))


def _better(value: float, than: float) -> bool:
    """``value`` beats ``than`` by the margins an effect must earn (MIN_GAIN, MIN_GAIN_DN)."""
    return value < (1.0 - MIN_GAIN) * than and than - value > MIN_GAIN_DN


def _choose_effects(view, mean, valid, fixed) -> list[str]:
    """The mean line's effects the recording shows: every subset of the four is scored on
    held-out pixels (16 fits: effects that trade for each other, as black level and fall-off,
    are judged together, not one after the other); the best is kept if it beats the car
    file's camera by the margins, then each of its effects is dropped again if the others
    do as well without it."""
    import itertools

    scores = {subset: _held_out_rmse(view, mean, valid, fixed, subset)
              for k in range(len(SHAPE_EFFECTS) + 1) for subset in itertools.combinations(SHAPE_EFFECTS, k)}
    best = min(scores, key=lambda sub: (scores[sub], len(sub)))
    if not _better(scores[best], scores[()]):
        return []
    chosen = list(best)
    for name in list(best):  # an effect the others make unnecessary goes again
        rest = tuple(c for c in chosen if c != name)
        if not _better(scores[tuple(c for c in SHAPE_EFFECTS if c in chosen)], scores[rest]):
            chosen = list(rest)
    return chosen


def _startup(frames: np.ndarray, starts: tuple[int, ...]) -> tuple[int, np.ndarray]:
    """Leading frames of each file far from the file's median frame: ``(count in the first
    file, mask of frames kept)``."""
    keep = np.ones(len(frames), bool)
    bounds = list(starts) + [len(frames)]
    first = 0
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        part = frames[a:b]
        med = np.median(part, axis=0)
        dev = np.mean(np.abs(part - med), axis=1)
        typical = np.median(dev)
        n = 0
        while n < len(part) - 1 and dev[n] > max(10.0 * typical, 3.0):
            n += 1
        keep[a:a + n] = False
        if i == 0:
            first = n
    return first, keep


def calibrate_straight(rec: Recording, car: CarDescription) -> CameraFit:
    """Fit the camera of ``car`` to lines recorded on a straight (module docstring)."""
    cam = car.camera
    if rec.frames.shape[1] != cam.width_px:
        raise CalibrationError(f"{rec.where[0]}: {rec.frames.shape[1]} pixels a line, expected "
                               f"camera.width_px = {cam.width_px}")
    pred = predicted(car)
    n_start, keep = _startup(rec.frames, rec.file_starts)
    frames = rec.frames[keep]
    if len(frames) < 2:
        raise CalibrationError(f"{rec.where[0]}: {len(frames)} usable frame(s) after the start-up frames: "
                               f"expected at least 2 (record 50 or more)")
    mean = frames.mean(axis=0)
    spread = frames.std(axis=0, ddof=1)
    view = StraightView(cam)
    # the car file's camera on the same scene (nuisance fitted): "before"
    fixed = {"floor": 0.157, **{k: pred[k] for k in SHAPE_EFFECTS}}
    dead, hot = _defects(frames, mean)
    p_before, _ = _fit(view, mean, ~(dead | hot), fixed, ())
    # a defect reads against the scene, beyond what the car's pixel-to-pixel spread explains (4 sigma)
    line_before = view.mean_line(p_before)
    signal = line_before - p_before["black_level"]
    margin = 4.0 * pred["prnu"] * signal + 10.0
    dead &= signal > 40.0
    hot &= (255.0 - line_before) > margin
    valid = ~(dead | hot)  # kept out of the fit
    p_before, _ = _fit(view, mean, valid, fixed, ())
    chosen = _choose_effects(view, mean, valid, fixed)
    p_after, _ = _fit(view, mean, valid, fixed, tuple(chosen))
    line_after = view.mean_line(p_after)
    rmse_before = float(np.sqrt(np.mean((view.mean_line(p_before) - mean)[valid] ** 2)))
    rmse_after = float(np.sqrt(np.mean((line_after - mean)[valid] ** 2)))
    params, hints = shape_effects(chosen, p_after, pred, f"{DEFAULT_AMBIENT_LUX:g} lux",
                                  blur_advice=": focus the lens or expect shallower black lines")
    # effects seen in the frames
    top = p_after["black_level"] + 0.5 * (line_after.max() - p_after["black_level"])
    lit = valid & (line_after > top)
    lit &= np.convolve(lit.astype(float), np.ones(7), mode="same") >= 7  # 3 px inside the lane's edges
    frame_effects(params, hints, car, pred, clipped=float(np.mean(mean[valid] >= 254.5)), clipped_what="line is",
                  dead=dead, hot=hot, against="light", n_start=n_start)
    noise = float(np.median(spread[lit & ~clipped_mask(mean)])) if (lit & ~clipped_mask(mean)).any() else 0.0
    noise_pred = math.sqrt(pred["noise_dn"] ** 2 + (1 / 12 if pred["noise_dn"] > 0.3 else 0.0))
    n = len(frames)
    if n >= 10 and (noise > max(1.5 * noise_pred, 0.6) or (noise_pred > 1.0 and noise < 0.6 * noise_pred)):
        params["noise"] = noise
        hints["noise"] = (f"each pixel varies by {noise:.2f} grey levels from frame to frame (the car file's "
                          f"camera: {noise_pred:.2f}): supply or ADC noise, or a flickering light")
    prnu = _fixed_pattern(frames, line_after, p_after["black_level"], lit & ~clipped_mask(mean), valid)
    pattern_effect(params, hints, prnu, pred)
    effects = [name for name in CATALOGUE if name in params]
    # the error no smooth model can remove: temporal noise over n frames and the pixels' own gains
    pattern = prnu if prnu is not None else pred["prnu"]
    signal = float(np.median((line_after - p_after["black_level"])[lit])) if lit.any() else 0.0
    floor = float(np.sqrt(np.median(spread[valid]) ** 2 / n + 1 / (12 * n) + (pattern * signal) ** 2))
    resid = np.abs(line_after - mean)
    rmse_smooth = rmse_after
    response = None
    if prnu is not None:  # a gain pattern both halves show: measure it pixel by pixel
        black = p_after["black_level"]

        def gains(line_mean: np.ndarray) -> np.ndarray:
            """Each lane pixel's gain over the model; a clipped one at least what reaches 255."""
            g = np.ones(len(line_mean))
            ratio = (line_mean - black) / np.maximum(line_after - black, 1.0)
            g[lit] = ratio[lit]
            clipped_lit = lit & (line_mean >= 254.5)
            g[clipped_lit] = np.maximum(ratio[clipped_lit], 1.0)
            return g

        half = n // 2  # measured on the first half of the frames, tested on the second
        held_out = np.clip(black + (line_after - black) * gains(frames[:half].mean(axis=0)), 0.0, 255.0)
        rmse_after = float(np.sqrt(np.mean((held_out - frames[half:].mean(axis=0))[valid] ** 2)))
        response = gains(mean)
        line_after = np.clip(black + (line_after - black) * response, 0.0, 255.0)
    unexplained = ""
    floor_smooth = floor
    if response is not None:  # the fitted model carries the pattern: only the noise is left
        floor = float(np.sqrt(np.median(spread[valid]) ** 2 / n + 1 / (12 * n)))
    if rmse_smooth > 1.5 * max(floor_smooth, 0.3) + MODEL_DN:
        worst = np.argsort(-(resid * valid))[:5]
        unexplained = (f"{rmse_smooth:.2f} grey levels remain (noise and fixed pattern explain {floor_smooth:.2f}), "
                       f"largest at columns "
                       f"{', '.join(str(int(c)) for c in sorted(worst))}")
    return CameraFit(
        effects=effects, parameters=params, hints=hints, rmse_before=rmse_before, rmse_after=rmse_after,
        noise_floor=floor, nuisance={"offset_m": p_after["offset"], "scale": p_after["scale"],
                                     "floor_reflectance": p_after["floor"]},
        frames_used=n, car_after=_car_after(car, pred, params, response),
        unexplained=unexplained, response_measured=response is not None,
        lines={"recorded": mean, "before": view.mean_line(p_before), "after": line_after})


def shape_effects(chosen, p: dict, pred: dict, light: str, blur_advice: str = "") -> tuple[dict, dict]:
    """``(parameters, hints)`` of the mean-line effects ``chosen``, fitted as ``p``, against the
    car file's camera ``pred`` (``light``: the scene's light, for the gain's hint)."""
    params, hints = {}, {}
    for name in chosen:
        v = p[name]
        params[name] = v
        hints[name] = {
            "gain": f"the line is {v / pred['gain']:.2f} x as bright as the car file's camera predicts under "
                    f"{light} (exposure, light or gain)",
            "black_level": f"a dark pixel reads {v:.1f} (the car file: {pred['black_level']:.1f})",
            "vignetting": f"the ends of the line fall off as cos^{v:.2f} (the car file: cos^{pred['vignetting']:g})",
            "blur": f"lines are blurred by {v:.2f} px (the car file: {pred['blur']:g} px){blur_advice}",
        }[name]
    return params, hints


def frame_effects(params: dict, hints: dict, car: CarDescription, pred: dict, *, clipped: float,
                  clipped_what: str, dead: np.ndarray, hot: np.ndarray, against: str, n_start: int) -> None:
    """Add the effects the frames show to ``params`` and ``hints``: ``saturation`` (``clipped``:
    the fraction at 255), dead and hot pixels (masks) where their count differs from the car
    file's, ``startup_frames`` where ``n_start`` does."""
    if clipped >= 0.01:
        params["saturation"] = clipped
        hints["saturation"] = (f"{clipped * 100:.0f} % of the {clipped_what} clipped at 255: shorten the "
                               f"exposure or lower the gain")
    for name, mask, what in (("dead_pixels", dead, f"read the black level whatever the {against}"),
                             ("hot_pixels", hot, f"read 255 whatever the {against}")):
        count = int(mask.sum())
        expected = _expected_defects(car, name)
        if count != expected:
            params[name] = float(count)
            cols = ", ".join(str(c) for c in np.flatnonzero(mask)[:8])
            hints[name] = f"{count} pixel(s) {what} (columns {cols}; the car file: {expected})"
    if n_start != int(pred["startup_frames"]):
        params["startup_frames"] = float(n_start)
        hints["startup_frames"] = (f"the first {n_start} frame(s) after power-up are not camera lines: skip "
                                   f"them in your code (the car file: {int(pred['startup_frames'])})")


def pattern_effect(params: dict, hints: dict, prnu: float | None, pred: dict) -> None:
    """Add ``fixed_pattern`` when a measured gain pattern ``prnu`` differs from the car file's."""
    if prnu is not None and abs(prnu - pred["prnu"]) > max(0.015, 0.4 * pred["prnu"]):
        params["fixed_pattern"] = prnu
        hints["fixed_pattern"] = (f"pixel-to-pixel gain differs by {prnu * 100:.1f} % (the car file: "
                                  f"{pred['prnu'] * 100:.1f} %)")


def row_cos_theta(cam) -> np.ndarray:
    """``(W,)`` cosine of the angle between each pixel's ray in the line row (``default_row``)
    and the optical axis (the pinhole of :class:`simrunner.sensors.camera.Camera`)."""
    w = cam.width_px
    f = (w / 2.0) / math.tan(cam.hfov_rad / 2.0)
    u = np.arange(w) + 0.5 - w / 2.0
    v = cam.default_row + 0.5 - cam.height_px / 2.0
    return f / np.sqrt(f * f + u * u + v * v)


def clipped_mask(mean: np.ndarray) -> np.ndarray:
    return mean >= 254.5


def _expected_defects(car: CarDescription, name: str) -> int:
    """Dead or hot pixels the car file's camera has in its line row (its seeded places)."""
    cam = car.camera
    if cam.model == "ideal" or getattr(cam, name) == 0:
        return 0
    fp = np.random.default_rng(int(cam.fixed_pattern_seed))
    h, w = cam.height_px, cam.width_px
    fp.standard_normal((h, w))
    fp.standard_normal((h, w))
    places = fp.choice(h * w, cam.dead_pixels + cam.hot_pixels, replace=False)
    chosen = places[:cam.dead_pixels] if name == "dead_pixels" else places[cam.dead_pixels:]
    return int(np.count_nonzero(chosen // w == cam.default_row))


def _defects(frames: np.ndarray, mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dead and hot pixels: constant in every frame, alone at the black level (dead) or at 255
    (hot) while both neighbours are at least 25 grey levels away (a black line or a clipped lane
    is wider than one pixel)."""
    constant = np.ptp(frames, axis=0) == 0
    left = np.concatenate(([mean[1]], mean[:-1]))
    right = np.concatenate((mean[1:], [mean[-2]]))
    low = mean.min()
    dead = constant & (mean <= low + 3.0) & (left > mean + 25.0) & (right > mean + 25.0)
    hot = constant & (mean >= 255.0) & (left < 230.0) & (right < 230.0)
    return dead, hot


def _fixed_pattern(frames, line, black, use, valid) -> float | None:
    """The spread of a per-pixel gain pattern that both halves of the frames show, or None.

    On the lane's inside (``use``: lit, away from its edges) the mean line's residual from the
    fit, relative to the signal, is high-passed (minus its 9-pixel running mean: the smooth
    part is the model's, the pixel-to-pixel part a gain pattern's or noise's); the two halves'
    patterns are compared: noise does not correlate, a fixed pattern does (correlation > 0.5).
    The spread is the shared part, ``sqrt(mean(a * b))``, corrected for the high-pass."""
    if use.sum() < 24 or len(frames) < 4:
        return None
    half = len(frames) // 2
    idx = np.flatnonzero(use)
    k = np.ones(9) / 9.0
    pats = []
    for part in (frames[:half], frames[half:]):
        r = (part.mean(axis=0) - line) / np.maximum(line - black, 1.0)
        r[~valid] = np.median(r[valid])  # dead and hot pixels are not a gain pattern
        hp = np.full(len(r), np.nan)
        hp[4:-4] = r[4:-4] - np.convolve(r, k, mode="valid")
        pats.append(hp[idx])
    ok = np.isfinite(pats[0]) & np.isfinite(pats[1])
    a, b = pats[0][ok], pats[1][ok]
    if len(a) < 16 or np.std(a) == 0 or np.std(b) == 0:
        return None
    if float(np.corrcoef(a, b)[0, 1]) < 0.5:
        return None
    return float(math.sqrt(max(np.mean(a * b), 0.0) / (1.0 - 1.0 / 9.0)))


def _car_after(car: CarDescription, pred: dict, params: dict, response=None) -> CarDescription:
    """``car`` with the fitted camera: an ideal camera becomes the default line camera first
    (it cannot show these effects), then each named effect sets its field; a measured
    per-pixel ``response`` multiplies the camera's profile and replaces its seeded gain
    pattern (``prnu = 0``)."""
    cam = car.camera
    if cam.model == "ideal" and (params or response is not None):
        cam = dataclasses.replace(CarDescription().camera, **{f.name: getattr(cam, f.name) for f in
                                                               dataclasses.fields(cam)
                                                               if f.name in GEOMETRY_FIELDS})
        pred = predicted(car.replace(camera=cam))
    scale = 2 ** (cam.adc_bits - 8)
    updates: dict = {}
    if "gain" in params:
        updates["analog_gain"] = min(max(cam.analog_gain * params["gain"] / pred["gain"], 0.01), 1000.0)
    if "black_level" in params:
        updates["black_level_dn"] = min(max(params["black_level"] * scale, 0.0), 65535.0)
    if "vignetting" in params:
        updates["vignetting_power"] = params["vignetting"]
    if "blur" in params:
        updates["psf_sigma_px"] = params["blur"]
    if "fixed_pattern" in params:
        updates["prnu"] = min(params["fixed_pattern"], 1.0)
    if "startup_frames" in params:
        updates["startup_frames"] = int(params["startup_frames"])
    for name in ("dead_pixels", "hot_pixels"):
        if name in params:  # as many in the line row on average: the sensor has H rows
            updates[name] = int(round(params[name] * cam.height_px))
    if "noise" in params:
        k8 = pred.get("k8")
        if k8:
            e_lane = (pred["gain"] * LANE_REFLECTANCE) / k8
            updates["dark_noise_e"] = min(math.sqrt(max((params["noise"] / k8) ** 2 - e_lane, 0.0)), 1e8)
    if response is not None:
        base = np.asarray(cam.vignetting_profile, np.float64) if cam.vignetting_profile else np.ones(cam.width_px)
        updates["vignetting_profile"] = tuple(float(v) for v in np.clip(base * response, 0.0, 10.0))
        updates["prnu"] = 0.0
    cam = dataclasses.replace(cam, **updates)
    if cam.dead_pixels + cam.hot_pixels > cam.width_px * cam.height_px:
        cam = dataclasses.replace(cam, dead_pixels=0, hot_pixels=0)
    return car.replace(camera=cam)


GEOMETRY_FIELDS = ("forward_m", "height_m", "pitch_rad", "hfov_rad", "width_px", "height_px", "default_row",
                   "fps_hz", "noise_std")


def record_straight(car: CarDescription, n_frames: int, *, offset_m: float = 0.0, seed: int = 0,
                    lux: float = DEFAULT_AMBIENT_LUX) -> np.ndarray:
    """``n_frames`` lines the car's own camera records standing on a straight (its lane centre
    ``offset_m`` to the left of the camera's axis, lit at ``lux``), from power-up:
    ``(n_frames, W)`` float, as a file of recorded lines would give them. For checking the
    fit on lines whose camera is known (bench/bench_camera_gap.py, tests)."""
    import shapely

    from pieces.pose import Pose2
    from simrunner.sensors.camera import Camera
    from simrunner.sensors.imaging import Imager
    from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, build_raster, layer_from_polygon
    from worlds.lighting import TrackLighting

    white = shapely.box(-3.0, -LANE_HALF_M, 6.0, LANE_HALF_M)
    lines = shapely.box(-3.0, -LANE_HALF_M - LINE_M, 6.0, LANE_HALF_M + LINE_M).difference(white)
    raster = build_raster([layer_from_polygon("edges", lines, BLACK_GRAY),
                           layer_from_polygon("lane", white, WHITE_GRAY)])
    cam = car.camera
    camera = Camera(cam, raster)
    pose = Pose2(0.0, -offset_m, 0.0)
    rng = np.random.default_rng(seed)
    if cam.model == "ideal":
        return np.array([camera.line_image(pose, cam.default_row, rng)[0] for _ in range(n_frames)], float)
    imager = Imager(camera, TrackLighting(ambient_lux=lux))
    return np.array([imager.line(pose, cam.default_row, exposure_s=cam.exposure_s, normals=rng,
                                 frame_index=k + 1)[0] for k in range(n_frames)], float)


def write_outputs(fit: CameraFit, out_dir, sources: list[str]) -> None:
    """``OUT/report.json``, ``OUT/car.toml`` (the input car with the fitted camera) and
    ``OUT/lines.png`` (recorded, before and after), written into a fresh folder beside ``OUT``
    and swapped in whole (trackgen.outdir): ``OUT`` holds a complete result or the old one."""
    import json
    from pathlib import Path

    from trackgen.outdir import clean_stale, swapped_in

    out = Path(out_dir)
    if not out.parent.is_dir():
        raise CalibrationError(f"{out}: cannot write the result (no folder {out.parent})")
    if out.exists() and not out.is_dir():
        raise CalibrationError(f"{out}: exists and is not a folder")
    clean_stale(out)
    with swapped_in(out) as tmp:
        report = fit.report_json()
        report["recordings"] = list(sources)
        (tmp / "report.json").write_text(json.dumps(report, indent=2, allow_nan=False) + "\n")
        names = {"gain": "camera.analog_gain", "black_level": "camera.black_level_dn",
                 "vignetting": "camera.vignetting_power", "blur": "camera.psf_sigma_px",
                 "fixed_pattern": "camera.prnu", "startup_frames": "camera.startup_frames",
                 "dead_pixels": "camera.dead_pixels", "hot_pixels": "camera.hot_pixels",
                 "noise": "camera.dark_noise_e"}
        fitted = {names[e]: "simrunner calibrate-camera (report.json)" for e in fit.effects if e in names}
        if fit.response_measured:
            fitted["camera.vignetting_profile"] = "simrunner calibrate-camera: each pixel's measured response"
            fitted["camera.prnu"] = "simrunner calibrate-camera: the measured response replaces the seeded pattern"
        fit.car_after.save(tmp / "car.toml", fitted)
        _plot(fit, tmp / "lines.png")


def _plot(fit: CameraFit, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4), dpi=100)
    cols = np.arange(len(fit.lines["recorded"]))
    ax.plot(cols, fit.lines["recorded"], color="black", lw=1.5, label=f"recorded (mean of {fit.frames_used} frames)")
    ax.plot(cols, fit.lines["before"], color="tab:red", lw=1, ls="--",
            label=f"car file's camera, rmse {fit.rmse_before:.1f}")
    ax.plot(cols, fit.lines["after"], color="tab:blue", lw=1,
            label=f"fitted: {', '.join(fit.effects) or 'no effect'}; rmse {fit.rmse_after:.1f}")
    ax.set_xlabel("pixel (0 = the car's left)")
    ax.set_ylabel("grey level")
    ax.set_ylim(0, 260)
    ax.legend(loc="lower center", fontsize=8)
    ax.set_title("calibrate-camera: the line on a straight" if fit.scene == "straight"
                 else "calibrate-camera: the mean of the lines recorded on the track")
    fig.tight_layout()
    fig.savefig(str(path))
    plt.close(fig)


def record_uniform(car: CarDescription, n_frames: int, *, lux: float, exposure_s: float | None = None,
                   seed: int = 0, skip_startup: bool = True) -> np.ndarray:
    """``n_frames`` lines the car's own (physical) camera records looking at an evenly lit
    white card (``lux``; 0: the lens covered, a dark frame) at ``exposure_s`` (default the
    car file's): ``(n_frames, W)`` float, for checking the camera procedures
    (tests, docs/calibration.md)."""
    import shapely

    from pieces.pose import Pose2
    from simrunner.sensors.camera import Camera
    from simrunner.sensors.imaging import Imager
    from simrunner.track.raster import WHITE_GRAY, build_raster, layer_from_polygon
    from worlds.lighting import TrackLighting

    raster = build_raster([layer_from_polygon("lane", shapely.box(-5.0, -5.0, 5.0, 5.0), WHITE_GRAY)])
    cam = car.camera
    imager = Imager(Camera(cam, raster), TrackLighting(ambient_lux=lux))
    rng = np.random.default_rng(seed)
    first = cam.startup_frames + 1 if skip_startup else 1
    t = cam.exposure_s if exposure_s is None else exposure_s
    return np.array([imager.line(Pose2(), cam.default_row, exposure_s=t, normals=rng, frame_index=first + k)[0]
                     for k in range(n_frames)], float)
