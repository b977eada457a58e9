"""mbed's InterruptIn in the tfc-mbed kit: a pin that --param encoder_PTxN (encoder_b_PTxN) gives
a wheel's encoder channel calls rise()/fall() handlers once an edge, at the kit's 1-kHz ticks."""
from __future__ import annotations

import re
import textwrap

import pytest

from simrunner.run.native import build_program
from simrunner.run.runner import drive

ENCODERS = "[encoders]\n"  # rear encoders, 512 lines, counted x4


def run(tmp_path, text, params=None, car=ENCODERS, name="main.cpp", time_limit_s=4.0):
    src = tmp_path / name
    src.write_text(textwrap.dedent(text))
    car_file = tmp_path / "car.toml"
    car_file.write_text(car)
    return drive(build_program([src], kit="tfc-mbed"), track="floor", car=car_file, params=params or {},
                 time_limit_s=time_limit_s, csv=tmp_path / "log.csv")


def numbers(r):
    """The integers of each spinner_add_textf line after its first word: {word: [ints]} (the lines
    of one frame are joined by " | ")."""
    lines = [part for s in r.log.data_text if s for part in s.split(" | ")]
    return {s.split()[0]: [int(v) for v in s.split()[1:]] for s in lines}


def test_rising_edges_count_the_encoders_lines_and_both_edges_its_x2_pulses(tmp_path):
    """1 s of driving: the rising edges of RL's channel A are its lines passed (its x4 count / 4)
    within one; rises and falls (the fall handler an object's method) are QEI's X2 pulses and,
    with channel B's edges (a lambda), its x4 count exactly; every handler runs at a tick (whole
    milliseconds) and reads the pin's level at its edge."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "QEI.h"
        #include "spinner.h"
        InterruptIn channel_a(PTA13), channel_b(PTA12);
        QEI qei(PTD4, PTD5, NC, 512);          // X2, on RL (the first encoder)
        volatile int rises, b_edges, off_tick, wrong_level;
        void on_rise() {
            rises++;
            if (us_ticker_read() % 1000) off_tick++;
            if (channel_a.read() != 1) wrong_level++;
        }
        struct Falls {
            int n = 0;
            void on_fall() { n++; if (channel_a.read() != 0) wrong_level++; }
        } falls;
        Ticker snapshot;
        volatile int at_rises, at_falls, at_b, at_qei;
        volatile long long at_count;
        void take() {
            at_rises = rises, at_falls = falls.n, at_b = b_edges, at_qei = qei.getPulses();
            at_count = spinner_get_encoder(SPINNER_WHEEL_RL);
        }
        int main() {
            TFC_Init();
            channel_a.rise(&on_rise);
            channel_a.fall(&falls, &Falls::on_fall);
            channel_b.rise([] { b_edges++; });
            channel_b.fall(callback([] { b_edges++; }));
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            snapshot.attach(&take, 1.0f);
            wait(1.2);
            spinner_add_textf("at %d %d %d %d %lld", at_rises, at_falls, at_b, at_qei, at_count);
            spinner_add_textf("checks %d %d", off_tick, wrong_level);
            return 0;
        }
        """, params={"encoder_PTA13": 2, "encoder_b_PTA12": 2})
    assert r.outcome == "controller_returned", r.message
    got = numbers(r)
    rises, falls, b_edges, qei_x2, count_x4 = got["at"]
    assert count_x4 > 4000  # the wheel turned
    assert abs(rises - count_x4 / 4) <= 1
    assert rises + falls == qei_x2 and abs(rises - falls) <= 1
    assert rises + falls + b_edges == count_x4
    assert got["checks"] == [0, 0]


def test_channel_b_read_in_channel_as_handler_gives_the_direction(tmp_path):
    """Forwards 0.8 s, backwards 0.8 s: a handler of channel A's rising edges that counts up when
    channel B (a DigitalIn on its pin) is high, down when low, follows the wheel's lines."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn channel_a(PTD4);
        DigitalIn channel_b(PTD5);
        volatile int lines;
        void on_rise() { lines += channel_b ? 1 : -1; }
        int main() {
            TFC_Init();
            channel_a.rise(&on_rise);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(0.8);
            spinner_add_textf("fwd %d %lld", lines, spinner_get_encoder(SPINNER_WHEEL_RR));
            TFC_SetMotorPWM(-0.4f, -0.4f);
            wait(0.8);
            spinner_add_textf("back %d %lld", lines, spinner_get_encoder(SPINNER_WHEEL_RR));
            return 0;
        }
        """, params={"encoder_PTD4": 3, "encoder_b_PTD5": 3})
    assert r.outcome == "controller_returned", r.message
    got = numbers(r)
    (fwd, fwd_count), (back, back_count) = got["fwd"], got["back"]
    assert fwd > 500 and back < fwd - 200  # it reversed
    # the count read a physics step after the handlers' tick: up to ~5 lines on
    assert abs(fwd - fwd_count / 4) <= 6 and abs(back - back_count / 4) <= 6


def test_disable_irq_stops_the_handlers_of_the_port(tmp_path):
    """disable_irq() on one InterruptIn of port A stops both its pins' handlers (the port's
    interrupt, as mbed's KL25Z code) while one on port D, on the same channel, goes on;
    enable_irq() calls the flagged pin's handler once, then every edge again."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn a_on_port_a(PTA13), b_on_port_a(PTA12), a_on_port_d(PTD4);
        volatile int a, b, d;
        int main() {
            TFC_Init();
            a_on_port_a.rise([] { a++; });
            b_on_port_a.rise([] { b++; });
            a_on_port_d.rise([] { d++; });
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(0.5);
            a_on_port_a.disable_irq();
            int a0 = a, b0 = b, d0 = d;
            wait(0.5);
            spinner_add_textf("off %d %d %d", a - a0, b - b0, d - d0);
            b_on_port_a.enable_irq();
            int a1 = a, b1 = b, d1 = d;
            wait(0.5);
            spinner_add_textf("on %d %d %d", a - a1, b - b1, d - d1);
            return 0;
        }
        """, params={"encoder_PTA13": 2, "encoder_b_PTA12": 2, "encoder_PTD4": 2})
    assert r.outcome == "controller_returned", r.message
    got = numbers(r)
    off_a, off_b, off_d = got["off"]
    assert off_a == off_b == 0 and off_d > 300
    on_a, on_b, on_d = got["on"]
    assert on_a == on_d + 1 and on_d > 300 and abs(on_b - on_a) <= 1  # B's rises: a quarter line off


def test_a_one_channel_counter_gives_a_rise_and_a_fall_a_line(tmp_path):
    """A Hall sensor counted as one channel (counting = "single"): its rises are the counter's
    count; each line is a rise and a fall in the same tick, and read() is 0."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn hall(PTA4);
        volatile int rises, falls, high;
        Ticker snapshot;
        volatile int at_rises, at_falls;
        volatile long long at_count;
        void take() { at_rises = rises, at_falls = falls, at_count = spinner_get_encoder(SPINNER_WHEEL_RL); }
        int main() {
            TFC_Init();
            hall.rise([] { rises++; });
            hall.fall([] { falls++; });
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            snapshot.attach(&take, 1.0f);
            for (int i = 0; i < 100; i++) { high += hall.read(); wait_ms(11); }
            spinner_add_textf("at %d %d %lld %d", at_rises, at_falls, at_count, high);
            return 0;
        }
        """, params={"encoder_PTA4": 2}, car='[encoders]\ncounting = "single"\nlines_per_rev = 20\n')
    assert r.outcome == "controller_returned", r.message
    rises, falls, count, high = numbers(r)["at"]
    assert count > 50 and rises == falls == count and high == 0


def test_an_unbound_pin_never_fires_and_reads_its_level(tmp_path):
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn free_a(PTA5), free_d(PTD3, PullUp);
        volatile int edges;
        void count() { edges++; }
        int main() {
            TFC_Init();
            free_a.rise(&count);
            free_a.fall(&count);
            free_d.mode(PullNone);
            free_d.rise(&count);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(1.0);
            spinner_add_textf("free %d %d %d", edges, free_a.read(), (int)free_d);
            return 0;
        }
        """, params={"digital_PTA5": 1})
    assert r.outcome == "controller_returned", r.message
    assert numbers(r)["free"] == [0, 1, 0]
    assert [re.sub(r"^[^:\s]*/", "", w) for w in r.warnings if "InterruptIn on" in w] == [  # said once a pin, at its first handler
        f"main.cpp:{line}: InterruptIn on {pin}: its handler never runs: no --param encoder_{pin}=W (or "
        f"encoder_b_{pin}=W, encoder_z_{pin}=W) puts a wheel's encoder channel on the pin (docs/firmware.md, "
        "--kit tfc-mbed)" for line, pin in ((9, "PTA5"), (12, "PTD3"))]


@pytest.mark.parametrize("line, params, car, words", [
    ("InterruptIn w(PTA13);", {"encoder_PTA13": 7}, ENCODERS,
     "InterruptIn::rise: --param encoder_PTA13=7: expected a wheel with an encoder (0..3: FL, FR, RL, RR; "
     "this car has them on RL RR)"),
    ("InterruptIn w(PTA13);", {"encoder_PTA13": 2}, "",
     "InterruptIn::rise: --param encoder_PTA13: the car has no wheel encoders: add [encoders]"),
    ("InterruptIn w(PTA13);", {"encoder_b_PTA13": 2}, '[encoders]\ncounting = "x2"\n',
     "InterruptIn::rise: --param encoder_b_PTA13: channel B's edges need the car's counter to count both "
     "channels (encoders.counting = \"x4\"; this car's: \"x2\")"),
    ("InterruptIn w(PTA13);", {"encoder_PTA13": 2, "encoder_b_PTA13": 3}, ENCODERS,
     "InterruptIn::rise: --param encoder_PTA13 and encoder_b_PTA13: a pin carries one channel"),
    ("InterruptIn w(PTC13);", {}, ENCODERS,
     "InterruptIn::rise: PTC13: the KL25Z's pins interrupt on ports A and D only"),
    ("InterruptIn w(PTC5);", {"encoder_z_PTC5": 2}, ENCODERS,
     "InterruptIn::rise: PTC5: the KL25Z's pins interrupt on ports A and D only"),
    ("InterruptIn w(PTD7);", {"encoder_z_PTD7": 2, "encoder_b_PTD7": 2}, ENCODERS,
     "InterruptIn::rise: --param encoder_b_PTD7 and encoder_z_PTD7: a pin carries one channel"),
    ("InterruptIn w(PTA13);", {"encoder_z_PTA13": 2}, '[encoders]\ncounting = "single"\n',
     "InterruptIn::rise: --param encoder_z_PTA13: the index channel needs the wheel's angle, which a "
     "one-channel counter does not keep"),
])
def test_bad_bindings_end_the_run_at_the_programs_call(tmp_path, line, params, car, words):
    r = run(tmp_path, f"""\
        #include "mbed.h"
        {line}
        void tick() {{}}
        int main() {{
            w.rise(&tick);
            while (1) wait(0.1);
        }}
        """, params=params, car=car, name="binding.cpp", time_limit_s=1.0)
    assert r.outcome == "controller_error"
    assert words in r.message and "binding.cpp:5" in r.message, r.message
    assert "\n" not in r.message


def test_a_handler_is_an_interrupt(tmp_path):
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        InterruptIn w(PTA13);
        void tick() {
            wait_ms(1);
        }
        int main() {
            TFC_Init();
            w.rise(&tick);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            while (1) wait(0.1);
        }
        """, params={"encoder_PTA13": 2}, name="isr_wait.cpp", time_limit_s=2.0)
    assert r.outcome == "controller_error"
    assert "wait_ms: not emulated" in r.message and "isr_wait.cpp:5" in r.message, r.message


def test_an_interruptin_deleted_in_its_handler_leaves_the_others_their_edges_in_order(tmp_path):
    """Three InterruptIns on pins of one wheel's channel A: the first deletes itself in its first
    rise; the same edge still reaches the other two, in the order they were made (b before c), and
    every later edge both; rise(NULL) stops a handler (d never counts)."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn d(PTA5);
        InterruptIn *a, *b, *c;
        volatile int nb, nc, nd, order_ok = 1, last = 'c';
        void on_a() { delete a; a = NULL; }
        void on_b() { nb++; if (last != 'c') order_ok = 0; last = 'b'; }
        void on_c() { nc++; if (last != 'b') order_ok = 0; last = 'c'; }
        void on_d() { nd++; }
        int main() {
            TFC_Init();
            a = new InterruptIn(PTA1);
            b = new InterruptIn(PTA2);
            c = new InterruptIn(PTA4);
            a->rise(&on_a);
            b->rise(&on_b);
            c->rise(&on_c);
            d.rise(&on_d);
            d.rise(NULL);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(0.4);
            spinner_add_textf("edges %d %d %d %d %d", nb, nc, nd, order_ok, a == NULL);
            return 0;
        }
        """, params={"encoder_PTA1": 2, "encoder_PTA2": 2, "encoder_PTA4": 2, "encoder_PTA5": 2})
    assert r.outcome == "controller_returned", r.message
    nb, nc, nd, order_ok, deleted = numbers(r)["edges"]
    assert nb > 10 and nc == nb and nd == 0 and order_ok == 1 and deleted == 1


def test_the_index_channel_rises_once_a_revolution_either_way_as_qei_counts_it(tmp_path):
    """Forwards 2 s, backwards 2 s, RL's index channel on PTA13 (--param encoder_z_PTA13): its
    rises are the revolutions the x4 count passed (the index is high at counts 0, 2048, ... mod
    512 lines x 4: it rises as the count comes to one, forwards or backwards), QEI's
    getRevolutions() with its index pin counts the same, each rise comes while channels A and B are
    both low (the gated index of a datasheet) and read() is 1 in the rise's handler, 0 in the
    fall's."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "QEI.h"
        #include "spinner.h"
        InterruptIn z(PTA13), channel_a(PTD4), channel_b(PTD5);
        QEI qei(PTA1, PTA2, PTA13, 512, QEI::X4_ENCODING);   // RL
        volatile int rises, falls, not_low, wrong_level;
        Ticker snapshot;
        volatile int at_rises, at_falls, at_revs, turns;
        volatile long long at_count, peak = -1000000, dir;
        void take() {  // every tick, after its edges' handlers
            long long count = spinner_get_encoder(SPINNER_WHEEL_RL);
            if ((count - at_count) * dir < 0) turns++;
            if (count != at_count) dir = count - at_count;
            if (count > peak) peak = count;
            at_rises = rises, at_falls = falls, at_revs = qei.getRevolutions(), at_count = count;
        }
        int main() {
            TFC_Init();
            z.rise([] {
                rises++;
                if (channel_a.read() || channel_b.read()) not_low++;
                if (z.read() != 1) wrong_level++;
            });
            z.fall([] { falls++; if (z.read() != 0) wrong_level++; });
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.35f, 0.35f);
            snapshot.attach_us(&take, 1000);
            wait(2.2);
            spinner_add_textf("fwd %d %d %d %lld", at_rises, at_falls, at_revs, at_count);
            TFC_SetMotorPWM(-0.45f, -0.45f);
            wait(2.5);
            spinner_add_textf("back %d %d %d %lld", at_rises, at_falls, at_revs, at_count);
            spinner_add_textf("checks %d %d %d %lld", not_low, wrong_level, turns, peak);
            return 0;
        }
        """, params={"encoder_z_PTA13": 2, "encoder_PTD4": 2, "encoder_b_PTD5": 2}, time_limit_s=6.0)
    assert r.outcome == "controller_returned", r.message
    got = numbers(r)
    per_rev = 512 * 4
    rises_f, falls_f, revs_f, count_f = got["fwd"]
    rises_b, falls_b, revs_b, count_b = got["back"]
    not_low, wrong_level, turns, peak = got["checks"]
    assert turns == 1  # up to the peak, then down
    assert count_f > 3 * per_rev and count_b < peak - 2 * per_rev  # 3+ turns forwards, 2+ back
    assert rises_f == count_f // per_rev and revs_f == rises_f  # from 0: 2048, 4096, ... reached
    back_rises = (peak - 1) // per_rev - (count_b - 1) // per_rev  # reached from above
    assert rises_b == peak // per_rev + back_rises and revs_b == rises_b
    assert abs(back_rises - (peak - count_b) / per_rev) <= 1  # the whole revolutions back
    assert abs(rises_b - falls_b) <= 1
    assert not_low == 0 and wrong_level == 0


def test_mbed_2s_chains_of_handlers(tmp_path):
    """mbed 2's rise_add / rise_add_front / rise_remove (and fall's): the handlers of one edge run in
    the chain's order (the front one first) at every edge; rise_remove of one stops it (a second
    remove of it is false) and leaves the others, also from inside the chain (the next one still
    runs that edge: the falls match another InterruptIn's on the same channel); rise() replaces the
    chain; removing the last handler stops the edge's interrupt; rise_add(NULL) adds nothing."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn enc(PTA13), same(PTA12);
        pFunctionPointer_t p_once;
        volatile int n_once, same_falls;
        void once() { n_once++; enc.fall_remove(p_once); }
        volatile int seq, bad_order, n1, n2, n0, n3, before_second = 2;
        void first() { n1++; if (seq != 1) bad_order++; seq = 2; }
        void second() { n2++; if (seq != before_second) bad_order++; seq = 0; }
        void front() { n0++; if (seq != 0) bad_order++; seq = 1; }
        void alone() { n3++; }
        struct Falls { int n = 0; void on_fall() { n++; } } falls;
        int main() {
            TFC_Init();
            pFunctionPointer_t p1 = enc.rise_add(&first);
            pFunctionPointer_t p2 = enc.rise_add(&second);
            pFunctionPointer_t p0 = enc.rise_add_front(&front);
            pFunctionPointer_t pf = enc.fall_add(&falls, &Falls::on_fall);
            p_once = enc.fall_add_front(&once);
            same.fall([] { same_falls++; });
            pFunctionPointer_t none = enc.rise_add(NULL);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(0.3);
            spinner_add_textf("chain %d %d %d %d %d %d", n0, n1, n2, falls.n, bad_order, none == NULL);
            spinner_add_textf("once %d %d %d", n_once, falls.n, same_falls);
            int removed = enc.rise_remove(p1), again = enc.rise_remove(p1);
            before_second = 1;  // front() now hands over to second()
            int b0 = n0, b1 = n1, b2 = n2;
            wait(0.3);
            spinner_add_textf("removed %d %d %d %d %d %d", removed, again, n0 - b0, n1 - b1, n2 - b2, bad_order);
            pFunctionPointer_t p3 = enc.rise(&alone);
            b0 = n0, b2 = n2;
            wait(0.3);
            spinner_add_textf("replaced %d %d %d %d", n0 - b0, n2 - b2, n3, enc.rise_remove(p0));
            int f_before = falls.n, gone = enc.fall_remove(pf), r3 = enc.rise_remove(p3), n3_before = n3;
            wait(0.3);
            spinner_add_textf("empty %d %d %d %d %d", gone, r3, falls.n - f_before, n3 - n3_before, p2 != NULL);
            return 0;
        }
        """, params={"encoder_PTA13": 2, "encoder_PTA12": 2})
    assert r.outcome == "controller_returned", r.message
    got = numbers(r)
    n0, n1, n2, falls, bad_order, none_null = got["chain"]
    n_once, falls_then, same_falls = got["once"]
    assert n_once == 1 and falls_then == same_falls
    assert n0 > 100 and n0 == n1 == n2 and abs(falls - n0) <= 1 and bad_order == 0 and none_null == 1
    removed, again, d0, d1, d2, bad_order = got["removed"]
    assert removed == 1 and again == 0 and d0 > 100 and d1 == 0 and d2 == d0 and bad_order == 0
    d0, d2, n3, p0_removed = got["replaced"]
    assert d0 == 0 and d2 == 0 and n3 > 100 and p0_removed == 0  # rise() freed the old chain
    gone, r3, d_falls, d3 = got["empty"][:4]
    assert gone == 1 and r3 == 1 and d_falls == 0 and d3 == 0


@pytest.mark.parametrize("counting, per_line", [("x2", 2), ("x1", 1)])
def test_the_index_is_one_count_of_a_coarser_counter_wide(tmp_path, counting, per_line):
    """A 20-line encoder counted x2 (x1): at every tick the index reads high exactly while the
    count is a whole revolution (40, 20 counts) from the start, and its rises are the revolutions
    reached."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn z(PTD2);
        volatile int rises, wrong, high;
        volatile long long count;
        Ticker check;
        void each_tick() {
            count = spinner_get_encoder(SPINNER_WHEEL_RR);
            int at_rev = count % PER_REV == 0;
            if (z.read() != at_rev) wrong++;
            high += at_rev;
        }
        int main() {
            TFC_Init();
            z.rise([] { rises++; });
            check.attach_us(&each_tick, 1000);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(1.5);
            spinner_add_textf("z %d %d %d %lld", rises, wrong, high, count);
            return 0;
        }
        """.replace("PER_REV", str(20 * per_line)), params={"encoder_z_PTD2": 3},
        car=f'[encoders]\ncounting = "{counting}"\nlines_per_rev = 20\n')
    assert r.outcome == "controller_returned", r.message
    rises, wrong, high, count = numbers(r)["z"]
    assert count > 3 * 20 * per_line and rises == count // (20 * per_line)
    assert wrong == 0 and high > 0


def test_a_handler_added_by_a_handler_waits_for_the_next_edge(tmp_path):
    """rise(fn) in a handler replaces the chain: fn was called at once for the same edge, so two
    handlers that hand the pin to each other (a state machine, mbed OS 5/6 style) ran for ever in
    one edge (the run stalled). A handler added by one (rise_add, rise_add_front, also once the
    first removed itself) waits for the next edge, and the rest of the chain still runs."""
    r = run(tmp_path, """\
        #include "mbed.h"
        #include "TFC.h"
        #include "spinner.h"
        InterruptIn enc(PTA13), ref(PTA12), chain(PTA5);
        volatile int na, nb, nref, n_first, n_front, n_late, n_last;
        void b();
        void a() { na++; enc.rise(&b); }
        void b() { nb++; enc.rise(&a); }
        pFunctionPointer_t p_first;
        void front() { n_front++; }
        void late() { n_late++; }
        void first() {  /* once: out of the chain, another in front and one at the end */
            n_first++;
            chain.rise_remove(p_first);
            chain.rise_add_front(&front);
            chain.rise_add(&late);
        }
        void last() { n_last++; }
        int main() {
            TFC_Init();
            enc.rise(&a);
            ref.rise([] { nref++; });
            p_first = chain.rise_add(&first);
            chain.rise_add(&last);
            TFC_HBRIDGE_ENABLE;
            TFC_SetMotorPWM(0.3f, 0.3f);
            wait(0.3);
            spinner_add_textf("swap %d %d %d", na, nb, nref);
            spinner_add_textf("chain %d %d %d %d", n_first, n_front, n_late, n_last);
            return 0;
        }
        """, params={"encoder_PTA13": 2, "encoder_PTA12": 2, "encoder_PTA5": 2}, time_limit_s=2.0)
    assert r.outcome == "controller_returned", r.message
    got = numbers(r)
    na, nb, nref = got["swap"]
    assert nref > 100 and na + nb == nref and na - nb in (0, 1)
    n_first, n_front, n_late, n_last = got["chain"]
    assert n_first == 1 and n_last == nref and n_front == n_late == nref - 1
