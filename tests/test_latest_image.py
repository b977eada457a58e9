"""The camera's latest frame without waiting (``Spinner.latest_image``, C
``spinner_latest_image``), and the kits' camera read-outs built on it: on the board the TFC
library reads the camera in its interrupts, beside the main loop, which runs on between two
images (docs/firmware.md)."""
from __future__ import annotations

import dataclasses
import re
import textwrap

import pytest

from simrunner.run.native import build_program
from simrunner.run.runner import drive


def test_latest_image_gives_each_frame_once_and_lets_no_time_pass():
    """Polled every physics step: every frame once, in order, each the frame get_image would have
    returned then; a call lets no time pass and returns (index, None) until the next frame."""
    seen, times = [], []

    def main(s):
        k, _ = s.latest_image(60, False)
        while s.get_time() < 0.5:
            t0 = s.get_time()
            frame, img = s.latest_image(60, False, k)
            times.append(s.get_time() - t0)  # (get_time itself is one step)
            if img is not None:
                assert img.shape == (1, s.image_shape[1])
                seen.append(frame)
                k = frame

    r = drive(main, track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    assert seen == list(range(seen[0], seen[0] + len(seen))) and len(seen) >= 20  # 50 frames/s
    assert set(round(t, 6) for t in times) == {0.002}  # one step: get_time's own


LOOP = """\
#include "derivative.h"
#include "spinner.h"
#include "TFC\\\\TFC.h"
int main(void) {
    TFC_Init();
    unsigned passes = 0, ticks = 0, frames = 0;
    while (spinner_get_time() < 1.0) {
        TFC_Task();
        passes++;
        if (TFC_Ticker[0] >= 1) { TFC_Ticker[0] = 0; ticks++; }
        if (LineScanImageReady) { LineScanImageReady = 0; frames++; }
    }
    printf("passes %u ticks %u frames %u\\n", passes, ticks, frames);
    return 0;
}
"""


@pytest.mark.parametrize("isolate", [False, True])
def test_a_tfc_main_loop_runs_on_between_two_images(tmp_path, capfd, isolate):
    """A super-loop of TFC_Task() and a 1-ms ticker check: each pass is two physics steps (TFC_Task
    and the loop's clock read), 250 a second, and it sees every image of the library's 50-ms
    exposure (it used to wait out a whole frame in TFC_Task whenever an image was due: 30 passes
    a second)."""
    src = tmp_path / "loop.c"
    src.write_text(LOOP)
    program = dataclasses.replace(build_program([src], kit="tfc"), isolate=isolate)
    r = drive(program, track="floor", time_limit_s=3.0)
    assert r.outcome == "controller_returned", r.message
    passes, ticks, frames = map(int, re.search(r"passes (\d+) ticks (\d+) frames (\d+)",
                                               capfd.readouterr().out).groups())
    assert passes >= 245 and ticks == passes and 19 <= frames <= 20


def test_the_c_call_reads_frames_without_waiting(tmp_path, capfd):
    """spinner_latest_image in C: in a timer interrupt at 1 kHz (where a wait is an error) it
    gives every frame once; after_frame at its own index gives nothing."""
    src = tmp_path / "latest.c"
    src.write_text(textwrap.dedent("""\
        #include <limits.h>
        #include <stdio.h>
        #include "spinner.h"
        static long long last;
        static int frames, skips, empty;
        static void tick(void) {
            uint8_t row[1024];
            size_t n = 0;
            long long f = spinner_latest_image(spinner_line_row(), 1, last, row, sizeof row, &n);
            if (n == 0) { empty++; return; }
            if (f != last + 1) skips++;
            last = f, frames++;
        }
        int main(void) {
            uint8_t row[1024];
            last = spinner_latest_image(spinner_line_row(), 0, LLONG_MAX, row, sizeof row, NULL);
            spinner_every(0.001, tick);
            spinner_sleep(1.0);
            printf("frames %d skips %d empty %d\\n", frames, skips, empty);
            return 0;
        }
        """))
    r = drive(build_program([src]), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    frames, skips, empty = map(int, re.search(r"frames (\d+) skips (\d+) empty (\d+)",
                                              capfd.readouterr().out).groups())
    assert frames >= 48 and skips == 0 and empty > frames  # 50 frames/s, 1000 looks


def test_the_latest_frame_keeps_its_exposure_when_the_exposure_changes_after_it():
    """The physical line camera: set_exposure moves the frame in progress, not the one that ended
    before it - latest_image then gives that frame as get_image gave it (bit for bit), not
    integrated over the new exposure (up to 20 grey levels off)."""
    out = {}

    def main(s):
        s.set_speed(1.0)
        s.sleep(0.3)
        img = s.get_image(60, False)
        out["frames"] = [s.latest_image(60, False)]
        s.set_exposure(s.get_exposure() / 2)
        s.set_exposure(s.get_exposure() / 2)  # (twice at one frame: the frame's own is kept)
        out["frames"].append(s.latest_image(60, False))
        out["img"], out["imager"] = img, s._s.imager is not None
        nxt = s.get_image(60, False)  # the next frame has the new exposure: darker
        out["darker"] = int(img.astype(int).sum() - nxt.astype(int).sum())

    r = drive(main, track="floor", time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    (f1, a), (f2, b) = out["frames"]
    assert out["imager"] and f1 == f2
    assert (a == out["img"]).all() and (b == out["img"]).all()
    assert out["darker"] > 0


def test_with_mcu_time_a_latest_image_call_is_charged_as_every_call():
    """--mcu-time FIXED charges each Spinner call, latest_image too (the program's time before it
    passes first: the frame it reads is the one the board would have by then)."""
    spent = []

    def main(s):
        t0 = s.get_time()
        for _ in range(10):
            s.latest_image(60, False)
        spent.append(s.get_time() - t0)

    r = drive(main, track="floor", time_limit_s=1.0, mcu_time=0.002)
    assert r.outcome == "controller_returned", r.message
    assert spent[0] >= 10 * 0.002


def test_the_latest_frame_is_blurred_by_the_motion_at_its_end_not_at_the_read():
    """The physical camera blurs a frame by the car's motion over its exposure: a frame read later
    with latest_image (the kits read it a step or two after its end) is the frame get_image gave,
    bit for bit, though the car has since changed speed and steering."""
    out = {}

    def main(s):
        s.set_speed_and_servo(1.5, 0.0)
        s.sleep(0.6)
        img = s.get_image(60, False)
        s.set_speed_and_servo(0.0, 0.4)  # brake and steer: the motion changes at once
        s.sleep(0.008)
        frame, late = s.latest_image(60, False)
        out.update(img=img, late=late, blur=s._s.imager.spec.motion_blur_samples,
                   moved=s.get_speed())

    r = drive(main, time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    assert out["blur"] > 1 and out["late"] is not None
    assert (out["late"] == out["img"]).all()
