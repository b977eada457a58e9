"""spinner_now (the simulated time without letting time pass; the kits' live timer counters read
it): its answer with --mcu-time, and the round trips it costs (spinner_host.c, now_known)."""
from __future__ import annotations

import collections
import dataclasses
import re

import pytest

from simrunner.run.native import bridge, build_program
from simrunner.run.runner import drive

NOW_AFTER_CALLS = """\
#include "spinner.h"
int main(void) {
    double a = spinner_now();
    spinner_set_servo(0.0);          /* queued: with --mcu-time it lets the code's time pass */
    double b = spinner_now();
    spinner_set_servo(0.0);
    double c = spinner_now();
    double d = spinner_now();        /* no call between: the same time */
    double e = spinner_get_time();
    spinner_add_textf("now %.0f %.0f %.0f %.0f", (b - a) * 1e6, (c - b) * 1e6, (d - c) * 1e6, (e - d) * 1e6);
    return 0;
}
"""


@pytest.fixture(scope="module")
def now_after_calls(tmp_path_factory):
    src = tmp_path_factory.mktemp("now") / "now.c"
    src.write_text(NOW_AFTER_CALLS)
    return build_program([src])


@pytest.mark.parametrize("isolate", [False, True])
def test_with_mcu_time_spinner_now_includes_the_time_of_the_calls_before_it(now_after_calls, tmp_path, isolate):
    """--mcu-time 0.002 (one 2-ms physics step a call): each spinner_set_servo lets 2 ms pass, so
    the time read after it is 2 ms later (the read itself lets none pass) - not the time cached at
    the read before it (a counter timing the code between two reads read 0)."""
    csv = tmp_path / "log.csv"
    r = drive(dataclasses.replace(now_after_calls, isolate=isolate), track="floor", time_limit_s=1.0,
              csv=csv, mcu_time=0.002)
    assert r.outcome == "controller_returned", r.message
    got = re.search(rb"now (\d+) (\d+) (\d+) (\d+)", csv.read_bytes())
    assert got and [int(v) for v in got.groups()] == [2000, 2000, 0, 4000], got  # (get_time: its charge, its step)
