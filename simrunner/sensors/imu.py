"""Wheel encoders and an IMU, as the car file's ``[encoders]`` and ``[imu]`` describe them
(:class:`vehicle.description.Encoders`, :class:`vehicle.description.Imu`).

**Encoders.** A wheel's encoder counts its rotation (the wheel joint's angle since the start,
``CarSim.wheel_angles_rad``): ``floor(angle / 2 pi x lines x m)`` with ``m`` = 4, 2 or 1 for
quadrature decoding ``x4``, ``x2``, ``x1`` (signed: backwards counts down); ``single`` (one
channel, a Hall sensor) counts rising edges whichever way the wheel turns, from the angle it
turned between two reads (a direction change between reads is not seen). No noise: a counter
counts.

**IMU.** The gyroscope reads the chassis's angular velocity and the accelerometer the specific
force at the IMU's place (the point's acceleration minus gravity: at rest it reads +9.81 m/s^2
up), both in the car body frame (x ahead, y left, z up; docs/DESIGN.md). Each axis adds
- a bias: drawn once per device from ``device_seed`` (``*_bias_std``), plus a random walk in
  time (``*_bias_walk`` x sqrt(s)) from the run's seed;
- white noise: ``*_noise_density`` x sqrt(rate_hz / 2) per sample, from the run's seed and the
  sample's number (drawn in blocks of 1024 samples: a reading depends on when it is taken, not
  on how often);
then rounds to ``*_lsb`` and clips to +-``*_range``. It samples at ``rate_hz``: the first read in
a sample period takes the car's state then, later reads in the same period get the same values.
"""
from __future__ import annotations

import math

import numpy as np

from simrunner.errors import CommandError

WHEELS = ("FL", "FR", "RL", "RR")  # the order of CarSim's wheel read-outs
ON = {"rear": ("RL", "RR"), "front": ("FL", "FR"), "all": WHEELS}
PER_LINE = {"x4": 4, "x2": 2, "x1": 1, "single": 1}
GRAVITY_MPS2 = 9.81
_WALK_BLOCK = 1024  # random-walk increments are drawn in blocks of this many samples


def wheel_index(wheel, call: str) -> int:
    """``"FL"``..``"RR"`` (any case) or 0..3 -> the wheel's index; else a CommandError."""
    if isinstance(wheel, str) and wheel.upper() in WHEELS:
        return WHEELS.index(wheel.upper())
    if isinstance(wheel, (int, np.integer)) and not isinstance(wheel, bool) and 0 <= int(wheel) < 4:
        return int(wheel)
    raise CommandError(f"{call}({wheel!r}): expected a wheel, one of {', '.join(WHEELS)} (or 0..3)")


class Encoders:
    """The car's wheel encoders (``spec``: a ``vehicle.description.Encoders`` or None)."""

    def __init__(self, spec):
        self.spec = spec
        self._counts_per_rad = 0.0 if spec is None else spec.lines_per_rev * PER_LINE[spec.counting] / (2 * math.pi)
        self._turned = [0.0] * 4  # single: the angle turned so far (either way)
        self._last = None         # single: the angles at the last read
        # the wheels with an encoder as a controller names them most often -> their index
        self._fitted: dict = {}
        if spec is not None:
            for name in ON[spec.wheels]:
                i = WHEELS.index(name)
                self._fitted.update({name: i, name.lower(): i, i: i})
        self._quadrature = spec is not None and spec.counting != "single"

    def count(self, wheel, angles_rad) -> int:
        """The count of ``wheel``'s encoder, the wheels at ``angles_rad`` (FL, FR, RL, RR)."""
        i = self._fitted.get(wheel) if type(wheel) in (str, int) else None
        if i is None:  # another spelling, or an error to report
            i = self._check(wheel)
        if self._quadrature:
            return math.floor(angles_rad[i] * self._counts_per_rad)
        return self._single(i, angles_rad)

    def read(self, wheel, sim) -> int:
        """:meth:`count` of ``wheel`` with the wheels' angles read from ``sim`` (a ``CarModel``) now;
        a quadrature counter reads its own wheel's angle only."""
        i = self._fitted.get(wheel) if type(wheel) in (str, int) else None
        if i is None:
            i = self._check(wheel)
        if self._quadrature:
            return math.floor(sim.wheel_angle_rad(i) * self._counts_per_rad)
        return self._single(i, sim.wheel_angles_rad())

    def counter(self, wheels, sim):
        """A function of no arguments giving the counts of ``wheels`` (names) with the wheels'
        angles read from ``sim`` (a ``CarModel``) then, as :meth:`count` gives them (the run
        log's, at each frame)."""
        angles_of = sim.wheel_angles_rad
        if not self._quadrature:
            def counts() -> tuple[int, ...]:
                angles = angles_of()
                return tuple([self.count(w, angles) for w in wheels])
            return counts
        index, per_rad, floor = [self._check(w) for w in wheels], self._counts_per_rad, math.floor

        def quadrature() -> tuple[int, ...]:
            angles = angles_of()
            return tuple([floor(angles[i] * per_rad) for i in index])
        return quadrature

    def _single(self, i: int, angles_rad) -> int:
        """One channel: every wheel's angle turned (either way) since the last read, counted."""
        last = self._last if self._last is not None else [0.0] * 4
        self._turned = [t + abs(a - b) for t, a, b in zip(self._turned, angles_rad, last)]
        self._last = list(angles_rad)
        return math.floor(self._turned[i] * self._counts_per_rad)

    def _check(self, wheel) -> int:
        """``wheel``'s index, or the CommandError that says why it has no encoder."""
        i = wheel_index(wheel, "get_encoder")
        spec = self.spec
        if spec is None:
            raise CommandError(f"get_encoder({wheel!r}): the car has no encoders (add [encoders] to the car file)")
        if WHEELS[i] not in ON[spec.wheels]:
            raise CommandError(f"get_encoder({wheel!r}): the car's encoders are on its {spec.wheels} wheels "
                               f"({', '.join(ON[spec.wheels])})")
        return i


class ImuNoise:
    """What one IMU device adds to each sample in a run: its bias, the bias's random walk and the
    white noise (6 floats a sample, gyro x, y, z then accelerometer x, y, z), from the device's
    seed, the run's seed and the sample's number. Two :class:`Imu` of one device in one run (the
    controller's and the run log's copy) share one: a block is drawn and summed once."""

    def __init__(self, spec, seed: int):
        self.spec = spec
        self.seed = int(seed)
        dev = np.random.default_rng([int(spec.device_seed), 0x42494153])  # this device's offsets
        stds = np.array([spec.gyro_bias_std_radps] * 3 + [spec.accel_bias_std_mps2] * 3)
        self._bias = dev.standard_normal(6) * stds
        rate = float(spec.rate_hz)
        self._noise = np.array([spec.gyro_noise_density_radps_rthz] * 3
                               + [spec.accel_noise_density_mps2_rthz] * 3) * math.sqrt(rate / 2.0)
        self._step_walk = np.array([spec.gyro_bias_walk_radps_rts] * 3
                                   + [spec.accel_bias_walk_mps2_rts] * 3) / math.sqrt(rate)
        self._walk: list[np.ndarray] = []  # cumulative random walk at the end of each block
        self._blocks: dict[int, list[float]] = {}  # the last two blocks' offsets, row after row

    def at(self, k: int) -> list[float]:
        """Bias + its walk + the white noise of sample ``k`` (6 floats)."""
        block, within = divmod(max(k, 0), _WALK_BLOCK)
        return self.block(block)[6 * within:6 * within + 6]

    def block(self, block: int) -> list[float]:
        """The offsets of samples ``block B .. block B + B - 1`` (``B = _WALK_BLOCK``) as one flat
        list, 6 floats a sample. The normals come from the run's seed and the block's number (the
        same values whatever was read before); a block's offsets are summed once."""
        flat = self._blocks.get(block)
        if flat is None:
            normals = np.random.default_rng([self.seed, 0x494D55, block]).standard_normal((_WALK_BLOCK, 6))
            # one flat list of floats (a list per row: 1024 more objects to make, collect and free)
            flat = (self._bias + self._walk_rows(block) + normals * self._noise).ravel().tolist()
            if len(self._blocks) > 1:  # reads come in time order: the older block is done
                del self._blocks[min(self._blocks)]
            self._blocks[block] = flat
        return flat

    def _walk_rows(self, block: int) -> np.ndarray:
        """The bias random walk at samples ``block B .. block B + B - 1`` (``B = _WALK_BLOCK``): the
        sum of the increments of samples 1 .. k (sample ``b B + 1 + j`` has ``_increments(b)[j]``)."""
        if not self._step_walk.any():
            return np.zeros((_WALK_BLOCK, 6))
        while len(self._walk) < block:  # the walk at the end of each earlier block
            self._walk_end(len(self._walk), self._increments(len(self._walk)))
        base = self._walk[block - 1] if block else np.zeros(6)
        increments = self._increments(block)
        if len(self._walk) == block:  # this block's end, for the next (its increments drawn once)
            self._walk_end(block, increments)
        steps = np.cumsum(increments, axis=0)
        return base + np.vstack([np.zeros((1, 6)), steps[:-1]])

    def _walk_end(self, block: int, increments: np.ndarray) -> None:
        """Append the walk at the end of ``block`` (the one before it is known)."""
        self._walk.append((self._walk[-1] if self._walk else 0.0) + increments.sum(axis=0))

    def _increments(self, block: int) -> np.ndarray:
        steps = np.random.default_rng([self.seed, 0x57414C4B, block]).standard_normal((_WALK_BLOCK, 6))
        return steps * self._step_walk


class Imu:
    """The car's IMU (``spec``: a ``vehicle.description.Imu`` or None) in a run with ``seed``;
    ``noise``: the :class:`ImuNoise` of this device in this run, shared with another copy (None:
    its own)."""

    def __init__(self, spec, seed: int, noise: ImuNoise | None = None):
        self.spec = spec
        self.seed = int(seed)
        self._held_k: int | None = None  # the sample held (read in its period already) and its value
        self._held: tuple[float, ...] = ()
        if spec is None:
            return
        self._rate_hz = float(spec.rate_hz)
        self._noise = noise if noise is not None else ImuNoise(spec, seed)
        self._block_first, self._block = -_WALK_BLOCK, []  # the block of the last sample (none yet)
        self._gyro_lsb, self._accel_lsb = float(spec.gyro_lsb_radps), float(spec.accel_lsb_mps2)
        self._gyro_top, self._accel_top = float(spec.gyro_range_radps), float(spec.accel_range_mps2)

    def sample(self, call: str, t_s: float, truth) -> tuple[float, ...]:
        """``(6,)``: gyro x, y, z (rad/s), accelerometer x, y, z (m/s^2) of the sample at ``t_s``;
        ``truth()`` gives the car's ``(angular velocity (3,), specific force (3,))`` in the body
        frame, asked only at a new sample. (Written out axis by axis: this runs at every frame of
        a run log, and a loop over the six axes cost twice as much.)"""
        if self.spec is None:
            raise CommandError(f"{call}(): the car has no IMU (add [imu] to the car file)")
        k = math.floor(t_s * self._rate_hz + 1e-9)
        if k == self._held_k:
            return self._held
        (g0, g1, g2), (a0, a1, a2) = truth()
        i = k - self._block_first
        if not 0 <= i < _WALK_BLOCK:
            block = max(k, 0) // _WALK_BLOCK
            self._block_first, self._block = block * _WALK_BLOCK, self._noise.block(block)
            i = max(k, 0) - self._block_first
        o0, o1, o2, o3, o4, o5 = self._block[6 * i:6 * i + 6]
        g0, g1, g2, a0, a1, a2 = g0 + o0, g1 + o1, g2 + o2, a0 + o3, a1 + o4, a2 + o5
        lsb = self._gyro_lsb
        if lsb > 0.0:
            g0, g1, g2 = round(g0 / lsb) * lsb, round(g1 / lsb) * lsb, round(g2 / lsb) * lsb
        lsb = self._accel_lsb
        if lsb > 0.0:
            a0, a1, a2 = round(a0 / lsb) * lsb, round(a1 / lsb) * lsb, round(a2 / lsb) * lsb
        top = self._gyro_top
        low = -top
        g0 = top if g0 > top else (low if g0 < low else g0)
        g1 = top if g1 > top else (low if g1 < low else g1)
        g2 = top if g2 > top else (low if g2 < low else g2)
        top = self._accel_top
        low = -top
        a0 = top if a0 > top else (low if a0 < low else a0)
        a1 = top if a1 > top else (low if a1 < low else a1)
        a2 = top if a2 > top else (low if a2 < low else a2)
        value = self._held = (g0, g1, g2, a0, a1, a2)
        self._held_k = k
        return value
