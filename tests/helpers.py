"""Helpers several test modules share (test modules import from here, not from each other)."""
from __future__ import annotations

import math

import numpy as np

from pieces.pose import Pose2


class KinematicSim:
    """Kinematic bicycle with first-order speed tracking; honours steering_offset,
    steering_gain and motor_lag of ``car.effects`` (a CarSim stand-in for fast tests)."""

    def __init__(self, car, dt_s):
        self.car, self.dt = car, dt_s
        self.x = self.y = self.yaw = self.v = self.steer = 0.0
        self.v_cmd = self.s_cmd = self.v_tgt = 0.0

    def set_state(self, pose, speed_mps, steer_rad=0.0, yaw_rate_radps=0.0):
        self.x, self.y, self.yaw = pose.x_m, pose.y_m, pose.yaw_rad
        self.v, self.steer = speed_mps, steer_rad
        self.v_cmd = self.v_tgt = speed_mps
        self.s_cmd = (steer_rad / self.car.effects.steering_gain) - self.car.effects.steering_offset_rad

    def place(self, pose, speed_mps, steer_rad=0.0, yaw_rate_radps=0.0):
        self.x, self.y, self.yaw = pose.x_m, pose.y_m, pose.yaw_rad
        self.v, self.steer = speed_mps, steer_rad

    def set_command(self, speed_mps, steer_rad, yaw_rate_radps=None):
        self.v_cmd, self.s_cmd = speed_mps, steer_rad

    def set_coast(self, coast):
        pass

    def step(self, n=1):
        e, L = self.car.effects, self.car.chassis.wheelbase_m
        a = self.car.drive.max_accel_mps2 * self.dt
        for _ in range(n):
            lag = e.motor_lag_s
            self.v_tgt += (self.v_cmd - self.v_tgt) * (1.0 if lag == 0 else min(1.0, self.dt / lag))
            self.v += float(np.clip(self.v_tgt - self.v, -a, a))
            tgt = np.clip(e.steering_gain * (self.s_cmd + e.steering_offset_rad), -0.4, 0.4)
            r = self.car.steering.rate_radps * self.dt
            self.steer += float(np.clip(tgt - self.steer, -r, r))
            self.yaw += self.v * math.tan(self.steer) / L * self.dt
            self.x += self.v * math.cos(self.yaw) * self.dt
            self.y += self.v * math.sin(self.yaw) * self.dt

    @property
    def pose(self):
        return Pose2(self.x, self.y, self.yaw)

    @property
    def speed_mps(self):
        return self.v

    @property
    def yaw_rate_radps(self):
        return self.v * math.tan(self.steer) / self.car.chassis.wheelbase_m


def kin_factory(car, dt_s):
    return KinematicSim(car, dt_s)


# a batch controller that fails as ``--param mode`` says
FAULTY = """
import os, signal, time

def main(spinner):
    mode = spinner.param("mode", "drive")
    if mode == "crash":
        raise RuntimeError("boom")
    if mode == "die":                # the worker process itself dies (os._exit is a controller error now)
        os.kill(os.getpid(), signal.SIGKILL)
    if mode == "slow":               # lets simulated time pass, far slower than the timeout
        while True:
            spinner.sleep(0.002)
            t = time.perf_counter()  # busy wait: time.sleep waits in simulated time
            while time.perf_counter() - t < 0.05:
                pass
    while True:
        spinner.get_image(spinner.line_row)
        spinner.set_speed_and_servo(1.0, 0.0)
"""

# a controller whose run "stuck" sits in one C-level call (the batch tests of both backends)
STUCK = """
def main(s):
    for _ in range(5):
        s.set_speed_and_servo(0.3, 0.0)
        s.get_image()
    if s.param("mode", "drive") == "stuck":
        sum(range(10 ** 13))   # one C-level call that never lets Python code run
"""


# a C controller whose constructor faults (line 5, in boom()) as its library is loaded
C_CTOR_FAULT = r"""
#include "spinner.h"
static int *p;
__attribute__((constructor)) static void boom(void) {
    *p = 3;                                      /* line 5 */
}
int main(void) { while (1) { spinner_set_speed(0.5f); spinner_sleep(0.01f); } }
"""


# a C controller one of whose threads (not main()'s: started at its 21st frame) dereferences NULL
# (line 5, in worker()) while main() drives
C_THREAD_FAULT = r"""#include <pthread.h>
#include "spinner.h"
static int *volatile nowhere;
static void *worker(void *arg) {
    *nowhere = 1;                                /* line 5 */
    return arg;
}
int main(void) {
    static uint8_t row[4096];
    pthread_t t;
    for (int frame = 0;; frame++) {
        spinner_get_image(spinner_line_row(), 0, row, sizeof row);
        spinner_set_speed(0.5);
        if (frame == 20) pthread_create(&t, NULL, worker, NULL);
    }
}
"""


# A thread the program started recurses without end: its stack overflows (the recursing
# function's line: 5 as the fault is named, its first line 4 for the frames' own)
C_THREAD_OVERFLOW = r"""#include <pthread.h>
#include "spinner.h"
static volatile int depth;
static int recurse(int n) {
    volatile char pad[256]; pad[0] = (char)n; depth++;  /* line 5 */
    return recurse(n + 1) + pad[0];
}
static void *worker(void *arg) { return (void *)(long)recurse(0); }
int main(void) {
    static uint8_t row[4096];
    pthread_t t;
    for (int frame = 0;; frame++) {
        spinner_get_image(spinner_line_row(), 0, row, sizeof row);
        spinner_set_speed(0.5);
        if (frame == 20) pthread_create(&t, NULL, worker, NULL);
    }
}
"""

# The same from a std::thread (line 5 too)
CXX_THREAD_OVERFLOW = r"""#include <thread>
#include "spinner.h"
static volatile int depth;
static int recurse(int n) {
    volatile char pad[256]; pad[0] = (char)n; depth++;  /* line 5 */
    return recurse(n + 1) + pad[0];
}
int main() {
    static uint8_t row[4096];
    for (int frame = 0;; frame++) {
        spinner_get_image(spinner_line_row(), 0, row, sizeof row);
        spinner_set_speed(0.5);
        if (frame == 20) std::thread([] { recurse(0); }).detach();
    }
}
"""

# C/C++ programs that end in a constructor (line 4) as their library is loaded, before the run:
# name -> (source, the run's outcome, its message up to the ", in a constructor ..." drive adds
# in process; isolated an exit's message adds ", in a constructor as the program loaded", a fault's
# is just that)
C_CTOR_ENDS = {
    "exit3.c": ("""\
#include <stdlib.h>
#include "spinner.h"
__attribute__((constructor)) static void early(void) {
    exit(3);                                     /* line 4 */
}
int main(void) { spinner_sleep(0.1); return 0; }
""", "controller_error", "the controller called exit(3) at exit3.c:4"),
    "exit0.c": ("""\
#include <stdlib.h>
#include "spinner.h"
__attribute__((constructor)) static void early(void) {
    exit(0);                                     /* line 4 */
}
int main(void) { spinner_sleep(0.1); return 0; }
""", "controller_returned", "the controller called exit(0) at exit0.c:4"),
    "exit_minus1.c": ("""\
#include <stdlib.h>
#include "spinner.h"
__attribute__((constructor)) static void early(void) {
    exit(-1);                                    /* line 4 */
}
int main(void) { spinner_sleep(0.1); return 0; }
""", "controller_error", "the controller called exit(-1) at exit_minus1.c:4"),
    "fail.c": ("""\
#include "spinner.h"
static void check(void) { spinner_fail("no calibration table"); }
__attribute__((constructor)) static void early(void) {
    check();                                     /* line 4 */
}
int main(void) { spinner_sleep(0.1); return 0; }
""", "controller_error", "fail.c:2: no calibration table (in check())"),
    "misuse.c": ("""\
#include "spinner.h"
static void tick(void) {}
__attribute__((constructor)) static void early(void) {
    spinner_every(-1.0, tick);                   /* line 4 */
}
int main(void) { spinner_sleep(0.1); return 0; }
""", "controller_error", "misuse.c:4: spinner_every(period_s=-1): expected at least 1e-05 s (a 100 kHz timer) "
                         "(in early())"),
    "quick.cpp": ("""\
#include <cstdlib>
#include "spinner.h"
struct Car {
    Car() { std::quick_exit(4); }                // line 4
};
Car car;
int main() { spinner_sleep(0.1); return 0; }
""", "controller_error", "the controller called quick_exit(4) at quick.cpp:4"),
}


def session_processes(sid: int) -> list[int]:
    """The pids of the living (not zombie) processes of session ``sid`` (Linux /proc)."""
    from pathlib import Path

    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue  # ended meanwhile
        if int(fields[3]) == sid and fields[0] != "Z":
            pids.append(int(stat.parent.name))
    return pids


def kill_alone_and_wait_for_its_session(proc, timeout_s: float = 10.0) -> list[int]:
    """SIGKILL ``proc`` (started with ``start_new_session=True``) alone, not its group, and wait
    up to ``timeout_s`` for the rest of its session to end; returns the pids left."""
    import time

    proc.kill()
    proc.wait(timeout=30)
    end = time.monotonic() + timeout_s
    while session_processes(proc.pid) and time.monotonic() < end:
        time.sleep(0.05)
    return session_processes(proc.pid)


def kill_session(proc) -> None:
    """SIGKILL what is left of ``proc``'s session (a test's clean-up)."""
    import os
    import signal

    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def legends_off_the_panels(fig) -> None:
    """Every legend lies inside the figure and over no panel (it hid curves and bars)."""
    renderer = fig.canvas.get_renderer()
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert legends
    for legend in legends:
        box = legend.get_window_extent(renderer)
        assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1 and fig.bbox.y0 <= box.y0 and box.y1 <= fig.bbox.y1
        for ax in fig.axes:
            assert not box.overlaps(ax.get_window_extent(renderer)), ax.get_title() or ax.get_ylabel()
