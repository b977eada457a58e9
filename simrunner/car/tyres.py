"""Tyres that slide (``wheels.tyre_model = "slip"``): the tyre forces of :class:`CarSim`.

The physics engine keeps the contacts (the tyres' normal forces); their friction is off, and
each tyre instead gets a force at its contact point from the slip of its contact patch
(docs/car-physics.md):

* **Slip.** In the wheel's frame (x along its heading, y to its left) the patch slides at
  ``s_x = v_x - omega r`` and ``s_y = v_y`` (``v``: the velocity of the chassis-fixed point on
  the ground below the wheel centre; ``omega``: the wheel's spin). A first-order lag with the
  relaxation length ``sigma`` (Pacejka 2012, 7.2) turns them into deflections
  ``du/dt = -s - |v_x| u / sigma`` (implicit in the decay), and the transient slips
  ``kappa = u_x / sigma``, ``tan(alpha) = u_y / sigma`` equal the steady ones
  ``(omega r - v_x) / |v_x|`` and ``-v_y / |v_x|`` once the tyre has rolled a few ``sigma``.
  Standing still, ``u`` is a spring (stiffness ``c N / sigma``): a parked car holds on a slope
  without creep.
* **Force.** Combined slip by the similarity method (Pacejka 2012, 4.3.2): with
  ``lambda = |(kappa, tan alpha)|`` the force ``F = mu N sin(C atan(B lambda))`` points along
  ``(kappa, tan alpha)``, ``B = c / (C mu)`` so that its slope at 0 is the cornering stiffness
  ``c N`` (``c`` per unit load: ``wheels.cornering_stiffness_front/rear_per_rad``, the same
  longitudinally: an isotropic tyre); the peak ``mu N`` is reached at ``B lambda = tan(pi / 2C)``
  and the force falls to ``sin(C pi / 2) mu N`` beyond (``wheels.tyre_shape`` C). ``lambda`` is
  capped a little past the fall (``LAMBDA_CAP_B / B``: the bristles slide; the deflection does
  not grow without end in a wheel spin at standstill).
* **Low speed.** Below ``LOW_SPEED_MPS`` a damper fades in (critical for the tyre spring and
  the tyre's share ``N / g`` of the mass; longitudinally at most ``DAMPER_MAX_GAIN`` of what
  stops the patch in one update, the wheel's spin inertia being small).
* **Loads.** While the four tyres are the car's only contacts, ``N`` per tyre is quasi-static
  (:meth:`SlipTyres.set_loads`): the weight along the car's z split by the centre of mass,
  with the load transfer of the last tyre forces (``h F_x / L`` front to rear, ``2 h F_y / t``
  across each axle); otherwise (a wheel in the air, the chassis on the ground) the engine's
  contact forces of the last step (reading them costs more than a step). A tyre in the air
  has no force.
* **Update.** Rolling, the forces are set every ``n`` physics steps (:meth:`SlipTyres.update_steps`:
  the most, up to 4, that keep the stiffest mode - the tyre spring against the wheel's spin
  inertia - at ``omega n dt <= 1.5``, three quarters of the explicit stability limit); while a tyre rolls
  slower than ``LOW_SPEED_MPS``, every step, and the relaxation length shrinks toward
  ``STAND_SIGMA_M`` (at least what keeps that mode stable at one step) so that a standing
  tyre is a stiff spring: a car on a slope holds within millimetres.

Steady state (no lag left), a car on these tyres is the single-track model with cornering
stiffness ``c N`` per tyre: understeer gradient ``K = (1/c_f - 1/c_r) / g`` rad per m/s^2 for
load-proportional stiffness at small steering angles, lateral grip a little under ``mu g``
(the rear tyres also drive against the front tyres' drag). :meth:`SlipTyres.single_track_turn`
solves that model's steady turn exactly (tests/test_tyres.py, bench/bench_tyres.py).
"""
from __future__ import annotations

import math

G_MPS2 = 9.81
LOW_SPEED_MPS = 0.15    # below it the low-speed damper fades in (ours)
DAMPER_MAX_GAIN = 0.5   # the longitudinal damper stops at most this share of the patch's slip per update
LAMBDA_CAP_B = 12.0     # the combined slip is capped at this / B (atan(12) = 85 deg: past the fall)
STAND_SIGMA_M = 0.005   # the relaxation length at standstill (a tyre's static deflection scale; ours)
STABLE_OMEGA_DT = 1.5   # update_steps: omega n dt of the stiffest tyre mode at most this (limit: 2)


class SlipTyres:
    """The four tyres' state (deflections, loads) and forces; one per :class:`CarSim`.

    Wheels in the order FL, FR, RL, RR at chassis-frame ground points ``(x_i, y_i, 0)``."""

    def __init__(self, *, mu: float, stiffness_front: float, stiffness_rear: float, shape: float,
                 relaxation_m: float, radius_m: float, wheel_spin_inertia_kgm2: float,
                 wheelbase_m: float, half_track_m: float, mass_kg: float,
                 com_m: tuple[float, float, float]):
        self.mu, self.shape, self.sigma_m, self.r_m = mu, shape, relaxation_m, radius_m
        self.c = (stiffness_front, stiffness_front, stiffness_rear, stiffness_rear)
        self.b = tuple(c / (shape * mu) for c in self.c)
        self.points = ((wheelbase_m, half_track_m), (wheelbase_m, -half_track_m), (0.0, half_track_m),
                       (0.0, -half_track_m))
        self.spin_mass_kg = wheel_spin_inertia_kgm2 / (radius_m * radius_m)  # I / r^2
        self.wheelbase_m, self.half_track_m, self.mass_kg = wheelbase_m, half_track_m, mass_kg
        self.com_x_m, self.com_h_m = com_m[0], com_m[2]  # ahead of the rear axle, above the ground
        self.last = [(0.0, 0.0)] * 4  # the last forces, chassis frame
        self.sigma_lo_m = min(relaxation_m, STAND_SIGMA_M)  # set by update_steps
        self.slow = True  # a tyre rolled slower than LOW_SPEED_MPS at the last update
        self.loads_n = [0.0] * 4
        self.set_loads(mass_kg * G_MPS2)
        self.u = [0.0] * 8  # deflections (x, y) per tyre, m

    def update_steps(self, dt_s: float, most: int) -> int:
        """How many physics steps one force update may last (module docstring, "Update")."""
        m_i = self.mass_kg / 4.0  # the lightest a loaded tyre's share gets, as the stiffness grows with load
        c_n = max(self.c) * self.mass_kg * G_MPS2 / 2.0  # one tyre carrying half the car
        m_red = 1.0 / (1.0 / m_i + 1.0 / self.spin_mass_kg)
        # standing (every step): the shortest relaxation length that keeps a free wheel stable
        self.sigma_lo_m = min(self.sigma_m, max(STAND_SIGMA_M, c_n * dt_s * dt_s / (STABLE_OMEGA_DT ** 2 * m_red)))
        omega = math.sqrt(c_n / self.sigma_m / m_red)  # rolling: a free wheel's spin against its tyre
        return max(1, min(most, int(STABLE_OMEGA_DT / (omega * dt_s))))

    def set_loads(self, weight_n: float) -> None:
        """Quasi-static loads: ``weight_n`` (the weight along the car's z) split by the centre of
        mass, shifted by the last forces' pitch and roll moments (module docstring)."""
        fx = sum(f[0] for f in self.last)
        h, L, t = self.com_h_m, self.wheelbase_m, 2.0 * self.half_track_m
        front = 0.5 * (self.com_x_m * weight_n - h * fx) / L
        rear = 0.5 * ((L - self.com_x_m) * weight_n + h * fx) / L
        fy_f, fy_r = self.last[0][1] + self.last[1][1], self.last[2][1] + self.last[3][1]
        d_f, d_r = h * fy_f / t, h * fy_r / t  # left minus right, halved: -2 h F_y / t / 2
        self.loads_n = [max(0.0, front - d_f), max(0.0, front + d_f), max(0.0, rear - d_r), max(0.0, rear + d_r)]

    # -- state (saved with the car's) ----------------------------------------------------------
    def state(self) -> tuple:
        return tuple(self.u), tuple(self.loads_n), tuple(self.last), self.slow

    def restore(self, state: tuple) -> None:
        u, loads, last, self.slow = state
        self.u, self.loads_n, self.last = list(u), list(loads), list(last)

    def reset_slip(self) -> None:
        """A car placed anew rolls without slip: no deflection, no force remembered (the load
        transfer and the update rate start as on a new car; what a placed car does must not
        depend on where it was before)."""
        self.u = [0.0] * 8
        self.last = [(0.0, 0.0)] * 4
        self.slow = True
        self.set_loads(self.mass_kg * G_MPS2)

    # -- the closed form of a steady turn -----------------------------------------------------
    def single_track_turn(self, speed_mps: float, steer_rad: float) -> tuple[float, float]:
        """The single-track model's steady turn on these tyres at the rear axle's forward speed
        ``speed_mps`` and the steering ``steer_rad``: ``(radius of the rear axle's path m, its
        lateral acceleration m/s^2)``, or ``(nan, nan)`` where none is found. The same tyre law
        (the front rolling free, the rear driving against the front's drag in the friction
        ellipse, the longitudinal load transfer) with exact trigonometry; its small-angle limit
        is ``delta = L / R + (1/c_f - 1/c_r) a_y / g``. Started from the turn without slip (the
        branch a car reaches by speeding up slowly, below :meth:`single_track_limit`)."""
        state = self._steady(speed_mps, steer_rad, [0.0, speed_mps * math.tan(steer_rad) / self.wheelbase_m, 0.0])
        if state is None:
            return math.nan, math.nan
        radius = speed_mps / state[1]
        return radius, speed_mps * speed_mps / radius

    def single_track_limit(self, steer_rad: float, step_mps: float = 0.002) -> tuple[float, float]:
        """Where the steady turns of :meth:`single_track_turn` end at ``steer_rad``: ``(speed
        m/s, lateral acceleration m/s^2)`` at the peak of the lateral acceleration over the
        speed (followed from 0.2 m/s up, each turn solved from the last); faster, no steady
        turn holds and the car slides out."""
        v = 0.2
        state = [0.0, v * math.tan(steer_rad) / self.wheelbase_m, 0.0]
        best = (0.0, 0.0)
        while v < 100.0:
            state = self._steady(v, steer_rad, state)
            if state is None:
                break
            a_y = v * state[1]
            if a_y < best[1]:
                break
            best = (v, a_y)
            v += step_mps
        return best

    def _steady(self, speed_mps: float, steer_rad: float, guess) -> list[float] | None:
        """``[v_y, yaw rate, rear slip kappa]`` of the steady single-track turn near ``guess``."""
        from scipy.optimize import fsolve

        mu, shape, L, x_cg, h = self.mu, self.shape, self.wheelbase_m, self.com_x_m, self.com_h_m
        m, c_f, c_r = self.mass_kg, self.c[0], self.c[2]
        weight, v_x, cd, sd = m * G_MPS2, float(speed_mps), math.cos(steer_rad), math.sin(steer_rad)

        def force(c: float, n: float, kappa: float, tan_a: float) -> tuple[float, float]:
            lam = math.hypot(kappa, tan_a)
            if lam < 1e-15:
                return 0.0, 0.0
            f = mu * n * math.sin(shape * math.atan(c / (shape * mu) * lam)) / lam
            return f * kappa, f * tan_a

        def residual(u):
            v_y, w, kappa = u
            v_long = v_x * cd + (v_y + w * L) * sd  # the front wheel's velocity in its own frame
            v_lat = (v_y + w * L) * cd - v_x * sd
            fx_total = 0.0
            for _ in range(3):  # the loads with the longitudinal transfer of the total force
                n_f = (x_cg * weight - h * fx_total) / L
                _, fy_f = force(c_f, n_f, 0.0, -v_lat / abs(v_long))
                fx_r, fy_r = force(c_r, weight - n_f, kappa, -v_y / v_x)
                fx_total = fx_r - fy_f * sd
            return [fx_total + m * w * (v_y + w * x_cg), fy_r + fy_f * cd - m * w * v_x,
                    fy_f * cd * (L - x_cg) - fy_r * x_cg]

        u, _, ok, _ = fsolve(residual, list(guess), xtol=1e-12, full_output=True)
        if ok != 1 or u[1] * steer_rad <= 0.0:
            return None
        return [float(x) for x in u]

    # -- the forces -----------------------------------------------------------------------------
    def forces(self, v_c, w_c, steer_rad, spin_radps, locked: bool, dt_s: float) -> list[tuple[float, float]]:
        """Each tyre's force (x along its heading, y) in its WHEEL's frame after ``dt_s`` more of
        slip history (``last``: the same in the chassis frame).

        ``v_c``, ``w_c``: the chassis origin's velocity and the angular velocity in the chassis
        frame; ``steer_rad``: (left, right) knuckle angles; ``spin_radps``: the four wheels' spin;
        ``locked``: the wheels are locked (their spin is the chassis's)."""
        out, last = [], []
        mu, C, sigma, r = self.mu, self.shape, self.sigma_m, self.r_m
        sigma_lo = self.sigma_lo_m
        slow = False
        u = self.u
        vx0, vy0, wz = v_c[0], v_c[1], w_c[2]
        for i in range(4):
            n = self.loads_n[i]
            x_i, y_i = self.points[i]
            vx, vy = vx0 - wz * y_i, vy0 + wz * x_i
            if i < 2:
                d = steer_rad[i]
                cd, sd = math.cos(d), math.sin(d)
                v_long, v_lat = vx * cd + vy * sd, vy * cd - vx * sd
            else:
                cd, sd = 1.0, 0.0
                v_long, v_lat = vx, vy
            speed = abs(v_long)
            s_x = v_long - spin_radps[i] * r
            if speed >= LOW_SPEED_MPS:
                sig_x = sig_y = sigma
            else:
                sig_x = sig_y = sigma_lo + (sigma - sigma_lo) * speed / LOW_SPEED_MPS
                slow = True
            ux = (u[2 * i] - dt_s * s_x) / (1.0 + dt_s * speed / sig_x)
            uy = (u[2 * i + 1] - dt_s * v_lat) / (1.0 + dt_s * speed / sig_y)
            b = self.b[i]
            kappa, tan_a = ux / sig_x, uy / sig_y
            lam = math.hypot(kappa, tan_a)
            cap = LAMBDA_CAP_B / b
            if lam > cap:
                ux, uy, kappa, tan_a, lam = ux * cap / lam, uy * cap / lam, kappa * cap / lam, tan_a * cap / lam, cap
            u[2 * i], u[2 * i + 1] = ux, uy
            if n <= 0.0:
                out.append((0.0, 0.0))
                last.append((0.0, 0.0))
                continue
            if lam > 1e-12:
                f = mu * n * math.sin(C * math.atan(b * lam)) / lam  # force per unit of slip
                fx, fy = f * kappa, f * tan_a
            else:
                fx = fy = 0.0
            if speed < LOW_SPEED_MPS:  # the low-speed damper
                w = 1.0 - speed / LOW_SPEED_MPS
                m_i = n / G_MPS2
                c_n = self.c[i] * n
                c_y = 2.0 * math.sqrt(c_n / sig_y * m_i)
                m_x = m_i if locked else 1.0 / (1.0 / m_i + 1.0 / self.spin_mass_kg)
                c_x = min(2.0 * math.sqrt(c_n / sig_x * m_x), DAMPER_MAX_GAIN * m_x / dt_s)
                fx -= w * c_x * s_x
                fy -= w * c_y * v_lat
                total, most = math.hypot(fx, fy), mu * n  # the damper is friction too
                if total > most:
                    fx, fy = fx * most / total, fy * most / total
            out.append((fx, fy))
            last.append((fx * cd - fy * sd, fx * sd + fy * cd))
        self.last = last
        self.slow = slow
        return out
