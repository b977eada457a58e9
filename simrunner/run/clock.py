"""Lockstep clock: simulated time advances only inside Spinner calls, in whole physics steps.

Everything runs on one thread. The controller runs; when it calls a waiting Spinner method
(``get_image``, ``get_time``, ``sleep``, ...) the clock steps the physics. Commands set by
``set_*`` are stored and handed to the sim once, before the next step (``CarSim.set_command``
is not called per step). Steps are issued in chunks as large as possible: up to the next
camera-frame boundary or the end of the wait, whichever is first (``CarSim.step(n)``).

Frame schedule: frame ``k`` (k = 0, 1, 2, ...) is at physics step ``round(k * period / dt)``
(an exact multiple when the period is a whole number of steps). :meth:`LockstepClock.set_frame_period`
changes the period (a line camera whose exposure the controller sets): the frame in progress then
ends one new period after the last boundary (or after the current step, if that has passed) and
later frames follow at the new period. A period that is to load at the next boundary instead, as a
timer's period register written while it runs (``boundary_hook``, set by the owner: the Spinner's
``set_exposure(..., next_frame=True)``), is loaded there: the hook runs right after that boundary's
``on_frame``, before anything else at its step (a handler due then), and may call
:meth:`set_frame_period`, which then anchors the new period at that boundary. At every frame boundary the
clock calls ``on_frame(k, t_s, pose, command, row_command)`` once, whether or not the
controller asked for an image; frame 0 is the initial state, called by :meth:`start`.
``command`` is the command in force at the boundary; ``row_command`` is the command the first
physics step after the *previous* boundary applied (the controller's answer to frame k - 1,
which telemetry row k - 1 records), or None when no step followed it. ``on_frame`` returns
None, or ``(outcome, message)`` to end the run. The clock holds no reference back to its
caller beyond this function.

Interrupts (:meth:`LockstepClock.add_interrupt`, a timer interrupt of the controller's own): a
handler registered at step ``s0`` with a period of ``p`` steps (not necessarily whole) runs at
step ``ceil(s0 + k p)`` for k = 1, 2, ... - the first step boundary at or after its time, after
that boundary's frame work; handlers due at one step run in the order they were registered, one
due twice at a step (a period shorter than ``dt``) twice. :meth:`LockstepClock.remove_interrupt`
stops one (from a handler too: one due later at the same step is then not run). They run inside the controller's
waiting call that is stepping the clock then (the controller's code between calls takes no time,
so an interrupt due meanwhile is taken at its next call, as one the code had masked). Inside a
handler (``in_interrupt``) no time passes: :meth:`step_one` returns at once and waits are refused.

Masking (:meth:`LockstepClock.mask`, :meth:`LockstepClock.unmask`: the program's
``__disable_irq()`` / ``__enable_irq()``, the Cortex-M's PRIMASK bit): while masked, a handler
falling due does not run but is marked pending, one flag per handler (as an NVIC pending bit:
expiries while it is set give one call; ARMv6-M Architecture Reference Manual, ARM DDI 0419, the
exception model: pending is a state, not a count; PRIMASK one bit that keeps every exception of
configurable priority from being taken). Its schedule goes on (its next time is a whole period later, as a
timer's). :meth:`unmask` runs the pending handlers at once, at the time of the unmask (no time
passes), in the order they were registered; a pending handler stopped meanwhile does not run,
unless it was stopped as an NVIC source is (``remove_interrupt(latch=True)``: the pending bit
outlives the timer's own interrupt enable; ``unpend_interrupt`` clears it). :meth:`pend_interrupt`
sets a handler's pending bit without a timer (an NVIC's set-pending register): it runs at once
when unmasked and outside handlers, else when a pending one would. :meth:`is_pending` tells
whether a handler's call fell due and has not run (its NVIC pending bit, as a kit reads it).
Masking is a bit, not a count: a second mask is a no-op, one unmask clears it. Handlers do not
change it: one that masks leaves it masked on return (later handlers are held), and an unmask
inside a handler lets the pending ones run after it returns (handlers do not nest). A handler
held pending for :data:`HELD_WARN_S` of simulated time gives the run a warning (``warn``).
"""
from __future__ import annotations

import math
import time
from typing import Callable, Protocol

from simrunner.errors import CommandError, RunFinished

_monotonic = time.monotonic
_NEVER = 1 << 62  # the next interrupt's step when there is none
#: A handler held pending this long by masked interrupts (s of simulated time) gives the run a
#: warning: a critical section lasts microseconds on the board; one this long forgot its unmask.
HELD_WARN_S = 0.1


class InterruptWait(CommandError):
    """A wait (a frame, a sleep) asked for inside an interrupt handler, where no time passes."""


class _Interrupt:
    """A periodic handler: registered at step ``first_step``, every ``period_steps``."""

    __slots__ = ("handler", "first_step", "period_steps", "count", "next_step", "pending")

    def __init__(self, handler: Callable[[], None], first_step: int, period_steps: float):
        self.handler, self.first_step, self.period_steps = handler, first_step, period_steps
        self.count = 1
        self.next_step = self._step(1)
        self.pending = False  # fell due while masked: runs at the unmask

    def _step(self, k: int) -> int:  # the first step boundary at or after its k-th time
        return self.first_step + max(1, math.ceil(k * self.period_steps - 1e-9))

    def advance(self) -> None:
        self.count += 1
        self.next_step = self._step(self.count)


class SteppableSim(Protocol):
    """The part of a car model (``simrunner.car.CarModel``) the clock uses."""

    def set_command(self, speed_mps: float, steer_rad: float, yaw_rate_radps: float) -> None: ...

    def step(self, n: int = 1) -> None: ...

    @property
    def pose(self): ...


Command = tuple[float, float, float]  # speed_mps, steer_rad, yaw_rate_radps
# on_frame(k, t_s, pose, command in force, command of row k - 1 or None) -> None | (outcome, message)
FrameCallback = Callable[[int, float, object, Command, "Command | None"], "tuple[str, str] | None"]


class LockstepClock:
    """Steps ``sim`` in lockstep with the controller.

    ``dt_s``: physics step (s) and ``frame_period_s``: camera frame period (s), both
    validated by ``RunSettings`` / the car description; ``on_frame``: see the module
    docstring.
    Attributes: ``step_index`` (int, steps done), ``frame_index`` (last frame boundary
    reached), ``last_progress_wall_s`` (``time.monotonic()`` at the last progress, for the
    watchdog), ``finished`` (None or the :class:`RunFinished` that ends the run).
    """

    def __init__(self, sim: SteppableSim, *, dt_s: float, frame_period_s: float,
                 on_frame: FrameCallback | None = None):
        self.sim = sim
        self.dt_s = float(dt_s)
        ratio = frame_period_s / dt_s
        self._steps_per_frame = int(round(ratio)) if abs(ratio - round(ratio)) < 1e-9 else None
        self._ratio = max(ratio, 1.0)
        self.on_frame: FrameCallback = on_frame or (lambda *args: None)
        self._row_pending = True  # no step yet since the last boundary
        self._row_command: Command | None = None  # what the first step after it applied
        self.step_index = 0
        self.frame_index = 0
        self._anchor_step = 0   # frame _anchor_frame is at step _anchor_step; later ones follow
        self._anchor_frame = 0  # at the period (set_frame_period moves the anchor)
        self._boundary_step = 0  # step of the last frame boundary
        self.boundary_pose = None  # the car's pose at it (a camera's latest frame is taken there)
        # set by the owner when a camera blurs by the car's motion: () -> the twist to keep at
        # each boundary with the pose (boundary_twist), the latest frame's blur
        self.twist_fn: Callable[[], tuple[float, float, float]] | None = None
        self.boundary_twist: tuple[float, float, float] | None = None
        self._next_frame_step = self._frame_step(1)
        # run once at the next frame boundary, after its on_frame (module docstring), then cleared
        self.boundary_hook: Callable[[], None] | None = None
        self._command: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._command_dirty = True
        self._motors: tuple[float, float] | None = None  # set_motors' duties, until a speed is set
        self.finished: RunFinished | None = None
        self.last_progress_wall_s = time.monotonic()
        self.stall_limit_s: float | None = None  # the watchdog's limit, once armed
        self._pose = None
        self._pose_step = -1
        self._interrupts: list[_Interrupt] = []  # add_interrupt, in the order registered
        self._next_irq_step = _NEVER
        self.in_interrupt = False  # a handler runs (no time passes)
        self.masked = False  # interrupts masked (PRIMASK): handlers due are held pending
        self._any_pending = False  # a handler may be pending (cleared when none is)
        self._masked_at_step = 0  # the step of the mask
        self.mask_where: Callable[[], str | None] | None = None  # () -> the mask's file:line, or None
        self._held_at_step: int | None = None  # the step a handler was first held pending since the mask
        self._held_warned = False  # the warning of held handlers given for this mask
        self.warn: Callable[[str, str], None] | None = None  # (key, text): a warning of the run
        # set by the owner: run_handler(handler) runs a handler in place of handler() (--mcu-time
        # measures a Python handler's CPU time: simrunner.run.mcu.McuTime.run_handler)
        self.run_handler: Callable[[Callable[[], None]], None] | None = None

    # -- schedule ------------------------------------------------------------------
    def _frame_step(self, k: int) -> int:
        j = k - self._anchor_frame
        if self._steps_per_frame is not None:
            return self._anchor_step + j * max(self._steps_per_frame, 1)
        return self._anchor_step + int(math.floor(j * self._ratio + 0.5))

    def set_frame_period(self, period_s: float) -> None:
        """Frames from now on are ``period_s`` apart: the frame in progress ends one period
        after the last boundary (if that step has passed, one period from now) and every later
        frame one period after the one before (``period_s`` validated by the caller)."""
        ratio = period_s / self.dt_s
        self._steps_per_frame = int(round(ratio)) if abs(ratio - round(ratio)) < 1e-9 else None
        self._ratio = max(ratio, 1.0)
        self._anchor_step, self._anchor_frame = self._boundary_step, self.frame_index
        nxt = self._frame_step(self.frame_index + 1)
        if nxt <= self.step_index:  # the new period has passed already: it starts now
            self._anchor_step = self.step_index
            nxt = self._frame_step(self.frame_index + 1)
        self._next_frame_step = nxt

    @property
    def time_s(self) -> float:
        """Simulated time (s) = steps done x dt (exact; no float accumulation)."""
        return self.step_index * self.dt_s

    @property
    def frame_period_steps(self) -> float:
        return self._ratio

    def steps_to_next_frame(self) -> int:
        return self._next_frame_step - self.step_index

    def pose(self):
        """``sim.pose`` (a ``Pose2``; on a track with hills ``sim.pose3``, a ``Pose3``), read at
        most once per step index (cached)."""
        if self._pose_step != self.step_index:
            sim = self.sim
            self._pose = sim.pose3 if getattr(sim, "terrain", None) else sim.pose
            self._pose_step = self.step_index
        return self._pose

    # -- commands and end ----------------------------------------------------------
    def command(self, speed_mps: float, steer_rad: float, yaw_rate_radps: float,
                keep_motors: bool = False) -> None:
        """Store the targets; they reach the sim before the next step. A command that sets
        the speed ends the motors' own duties (``keep_motors`` False); a steering-only one keeps them."""
        self._command = (speed_mps, steer_rad, yaw_rate_radps)
        self._command_dirty = True
        if not keep_motors:
            self._motors = None

    def motors(self, left: float, right: float) -> None:
        """The rear motors' duties (``sim.set_motors``), before the next step and after any
        later steering command."""
        self._motors = (left, right)
        self._command_dirty = True

    @property
    def current_command(self) -> tuple[float, float, float]:
        """(speed_mps, steer_rad, yaw_rate_radps) last commanded."""
        return self._command

    def finish(self, outcome: str, message: str = "") -> None:
        """End the run (first call wins): the current and every later wait raises."""
        if self.finished is None:
            self.finished = RunFinished(outcome, message)

    def check(self) -> None:
        """Raise :class:`RunFinished` if the run is over."""
        if self.finished is not None:
            raise RunFinished(self.finished.outcome, self.finished.message)

    # -- interrupts ----------------------------------------------------------------
    def add_interrupt(self, period_s: float, handler: Callable[[], None]) -> None:
        """Run ``handler()`` every ``period_s`` of simulated time from now (module docstring;
        ``period_s`` validated by the caller)."""
        irq = _Interrupt(handler, self.step_index, period_s / self.dt_s)
        self._interrupts.append(irq)
        self._next_irq_step = min(self._next_irq_step, irq.next_step)

    def remove_interrupt(self, handler: Callable[[], None], *, latch: bool = False) -> int:
        """Stop every interrupt running ``handler`` (the same object): none of them runs again,
        one due at this step neither (also when called from a handler). Returns how many.

        ``latch``: an NVIC's pending bit, which outlives its source (a kit's timer whose own
        interrupt enable is cleared): one that fell due and has not run - held by the mask, or
        due at this step after the running handler - still runs once, when it would have."""
        gone = [irq for irq in self._interrupts if irq.handler is handler]
        for irq in gone:
            if latch and (irq.pending or irq.next_step <= self.step_index):
                irq.pending = self._any_pending = True  # (run by _interrupt or unmask, then pruned)
            else:
                irq.pending = False
            irq.next_step = _NEVER  # (a handler running now: its loop ends)
        if gone and not self.in_interrupt:  # (inside a handler: _interrupt prunes the list)
            self._prune()
        return len(gone)

    def unpend_interrupt(self, handler: Callable[[], None]) -> int:
        """Clear the pending call a stopped ``handler`` kept (``remove_interrupt(latch=True)``;
        the NVIC's clear-pending register): it does not run. Returns how many were cleared."""
        cleared = [irq for irq in self._interrupts
                   if irq.handler is handler and irq.pending and irq.next_step == _NEVER]
        for irq in cleared:
            irq.pending = False
        if cleared and not self.in_interrupt:
            self._prune()
        return len(cleared)

    def is_pending(self, handler: Callable[[], None]) -> bool:
        """Whether a call of ``handler`` fell due and has not run (no time passes): held pending by
        the mask, kept by ``remove_interrupt(latch=True)``, set by :meth:`pend_interrupt`, or due at
        this step after the running handler - the NVIC's pending bit of a kit's timer (ARMv6-M, ARM
        DDI 0419, B3.4: a source asserted while PRIMASK is set, or while another handler runs, is
        pending)."""
        i = self.step_index
        return any(irq.handler is handler and (irq.pending or irq.next_step <= i) for irq in self._interrupts)

    def hold_pending(self, handler: Callable[[], None]) -> None:
        """Mark ``handler``'s interrupts pending (a kit's timer started again while the call its
        stop kept is still pending: the NVIC has one bit for both); they run when a pending one
        would (the unmask, after the running handler)."""
        for irq in self._interrupts:
            if irq.handler is handler:
                irq.pending = self._any_pending = True

    def pend_interrupt(self, handler: Callable[[], None]) -> None:
        """Set ``handler``'s pending bit (an NVIC's set-pending register: a kit's interrupt pended
        in software, or one whose source fired while its IRQ was disabled): it runs once, as a
        handler, at the first point interrupts are unmasked and no handler runs - now (at this
        time: the caller answers the program's waiting call with it), at the unmask, or after the
        running handler. One bit: pending already, nothing changes (ARMv6-M, ARM DDI 0419, B3.4).
        ``handler`` without an interrupt is added as one with no schedule, pending (after the
        others in the order they run); ``unpend_interrupt`` clears it."""
        ours = [irq for irq in self._interrupts if irq.handler is handler]
        if not ours:
            irq = _Interrupt(handler, self.step_index, 1.0)
            irq.next_step = _NEVER
            self._interrupts.append(irq)
            ours = [irq]
        for irq in ours:
            irq.pending = True
        self._any_pending = True
        if self.masked or self.in_interrupt:
            return  # (the unmask, or _interrupt / unmask after the running handler, runs it)
        self._take_pending()

    def _take_pending(self) -> None:
        """Run the pending handlers now; then drop the stopped interrupts whose calls have run
        (also after a handler that raised) and see whether the run ended."""
        try:
            self._run_pending()
        finally:
            self._prune()
        if self.finished is not None:
            self.check()

    def _prune(self) -> None:  # (a stopped interrupt whose pending call is kept stays until it runs)
        self._interrupts = [irq for irq in self._interrupts if irq.next_step != _NEVER or irq.pending]
        self._next_irq_step = min((irq.next_step for irq in self._interrupts), default=_NEVER)

    def _run(self, irq: _Interrupt) -> None:
        self.in_interrupt = True
        try:
            if self.run_handler is None:
                irq.handler()
            else:
                self.run_handler(irq.handler)
        finally:
            self.in_interrupt = False

    def _interrupt(self) -> None:
        """The step index has reached an interrupt's step: run the handlers due (module docstring),
        or hold them pending while masked."""
        i = self.step_index
        try:
            for irq in self._interrupts:  # (a handler may add one: it is due later; or remove one)
                while irq.next_step <= i:
                    irq.advance()
                    if self.masked:  # (also after a handler masked): one pending bit
                        irq.pending = self._any_pending = True
                        self._held(i)
                    else:
                        self._run(irq)
            if self._any_pending and not self.masked:  # a handler unmasked with others pending
                self._run_pending()
        finally:  # a handler that raised: the schedule stays the one of the handlers run
            self._prune()
        if self.finished is not None:
            self.check()

    def _held(self, step: int) -> None:
        """A handler is held pending at ``step``: the first since the mask starts the count to
        the warning (HELD_WARN_S)."""
        if self._held_at_step is None:
            self._held_at_step = step
        elif (self.warn is not None and not self._held_warned
              and (step - self._held_at_step) * self.dt_s >= HELD_WARN_S - 1e-9):
            self._held_warned = True
            masked_s = self._masked_at_step * self.dt_s
            where = self.mask_where() if self.mask_where is not None else None
            self.warn("interrupts_masked", (
                f"{where + ': ' if where else ''}interrupts disabled at {masked_s:.3f} s (__disable_irq, "
                f"DisableInterrupts, OsIf_SuspendAllInterrupts, spinner_disable_interrupts) held a timer interrupt's "
                f"handler for {HELD_WARN_S:g} s and more: on the board no interrupt runs while they are "
                f"disabled; enable them again right after the critical section (__enable_irq, "
                f"EnableInterrupts, OsIf_ResumeAllInterrupts, spinner_enable_interrupts)"))

    def _run_pending(self) -> None:
        """Run the pending handlers, in the order registered, while unmasked (one that masks
        holds the rest)."""
        while not self.masked:
            irq = next((q for q in self._interrupts if q.pending), None)
            if irq is None:
                self._any_pending = False
                return
            irq.pending = False
            self._run(irq)

    def mask(self, where: Callable[[], str | None] | None = None) -> None:
        """Mask interrupts (module docstring): handlers falling due are held pending. ``where()``
        names the mask's file:line for the warning (called only then)."""
        if not self.masked:
            self.masked = True
            self._masked_at_step = self.step_index
            self._held_at_step = None
            self._held_warned = False
            self.mask_where = where

    def unmask(self) -> None:
        """Unmask interrupts: the pending handlers run now (after the running handler, inside one)."""
        if not self.masked:
            return
        self.masked = False
        if self.in_interrupt or not self._any_pending:
            return  # (in a handler: _interrupt or the unmask running it runs them after it)
        self._take_pending()

    def _refuse_wait(self) -> None:
        raise InterruptWait("inside an interrupt handler no simulated time passes: a handler cannot "
                            "wait (for a camera frame, a sleep); leave the waiting to the main loop")

    # -- stepping ------------------------------------------------------------------
    def start(self) -> None:
        """Run the frame-0 callback (the initial state)."""
        pose = self.boundary_pose = self.pose()
        if self.twist_fn is not None:
            self.boundary_twist = self.twist_fn()
        end = self.on_frame(0, 0.0, pose, self._command, None)
        if end is not None:
            self.finish(*end)
        self.last_progress_wall_s = time.monotonic()
        self.check()

    def _before_chunk(self) -> None:
        """Send a changed command to the sim; remember the open row's command."""
        if self._command_dirty:
            self.sim.set_command(*self._command)
            if self._motors is not None:
                self.sim.set_motors(*self._motors)
            self._command_dirty = False
        if self._row_pending:
            self._row_pending = False
            self._row_command = self._command

    def _frame_boundary(self) -> None:
        """The step index has reached the next frame: run ``on_frame`` for it; raises
        :class:`RunFinished` if the run is over."""
        k = self.frame_index = self.frame_index + 1
        self._boundary_step = self.step_index
        self._next_frame_step = self._frame_step(k + 1)
        row_command = None if self._row_pending else self._row_command
        pose = self.boundary_pose = self.pose()
        if self.twist_fn is not None:
            self.boundary_twist = self.twist_fn()
        if self._held_at_step is not None and self.masked:  # (a slow timer's next expiry is late)
            self._held(self.step_index)
        end = self.on_frame(k, self.step_index * self.dt_s, pose, self._command, row_command)
        self._row_pending = True
        self.last_progress_wall_s = _monotonic()
        if end is not None:
            self.finish(*end)
        hook = self.boundary_hook
        if hook is not None:  # (a period register loaded at this expiry: set_frame_period anchors here)
            self.boundary_hook = None
            hook()
        if self.finished is not None:
            self.check()

    def advance(self, n_steps: int) -> None:
        """Step ``n_steps`` physics steps, running ``on_frame`` at each boundary crossed.

        Raises :class:`RunFinished` (and stops stepping) as soon as the run is over.
        """
        if self.finished is not None:
            self.check()
        if self.in_interrupt:
            self._refuse_wait()
        while n_steps > 0:
            stop = min(self._next_frame_step, self._next_irq_step)
            chunk = min(stop - self.step_index, n_steps)
            self._before_chunk()
            self.sim.step(chunk)
            self.step_index += chunk
            n_steps -= chunk
            if self.step_index == self._next_frame_step:
                self._frame_boundary()
            if self.step_index == self._next_irq_step:
                self._interrupt()
        self.last_progress_wall_s = _monotonic()

    def step_one(self) -> None:
        """``advance(1)`` (a frame boundary is never behind the step index): the path of every
        Spinner call that lets one physics step pass (sensors, ``get_time``), kept short."""
        if self.finished is not None:
            self.check()
        if self.in_interrupt:
            return  # no time passes inside a handler (a sensor read gives the state now)
        if self._command_dirty or self._row_pending:
            self._before_chunk()
        self.sim.step(1)
        i = self.step_index = self.step_index + 1
        if i == self._next_frame_step:
            self._frame_boundary()
        if i == self._next_irq_step:
            self._interrupt()
        self.last_progress_wall_s = _monotonic()

    def advance_to_next_frame(self) -> None:
        """Step to the next frame boundary (at least one step): ``advance`` of one chunk,
        the path of every ``get_image``."""
        if self.finished is not None:
            self.check()
        if self._next_irq_step <= self._next_frame_step or self.in_interrupt:  # interrupts on the way
            k = self.frame_index  # (one may move the frame: set_frame_period)
            while self.frame_index == k:
                self.advance(min(self._next_frame_step, self._next_irq_step) - self.step_index)
            return
        self._before_chunk()
        self.sim.step(self._next_frame_step - self.step_index)
        self.step_index = self._next_frame_step
        self._frame_boundary()
