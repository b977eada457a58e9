"""How the gap bench scores a trial and summarises trials (``bench/bench_gap.py``): the
per-effect row of a method, the figures and the target table of a set of rows, and the glitch
injection of its ``glitch`` mode. A module of its own so tests use the same scoring as the
bench (tests import from here, not from the bench script)."""
from __future__ import annotations

import math

import numpy as np


SNR_MIN = 3.0
GLITCH_KINDS = ("jump", "heading", "frozen", "gap", "spike")  # ``glitch``: trial k puts in kind k % 5


def rel_error(effect: str, fitted: float | None, true: float) -> float | None:
    from simrunner.car.effects import EFFECTS

    if fitted is None:
        return None
    neutral = EFFECTS[effect].neutral[0]
    ref = abs(true) if math.isinf(neutral) else abs(true - neutral)
    return abs(fitted - true) / ref if ref > 0 else None


def replay_snr(car, exact, effects, values: dict, sigma: dict[str, float]) -> dict[str, float]:
    """Each hidden effect's SNR on a noise-free log ``exact``: the RMS over the sensors (``sigma``:
    column -> noise) of the change its value (``values``, by ``synth.RANGES`` field) makes to the
    replay of ``car`` (the truth without effects), over the sensor noise."""
    from simrunner.car.effects import with_effects
    from simrunner.workflows.gap.logs import derive
    from simrunner.workflows.gap.replay import make_windows, replay
    from simrunner.workflows.gap.synth import RANGES

    d = derive(exact, car.chassis.wheelbase_m, car.steering.limit_rad)
    w = make_windows(exact)
    p0 = replay(car, exact, d, w)
    out = {}
    for e in effects:
        f = RANGES[e][0]
        p1 = replay(with_effects(car, **{f: values[f]}), exact, d, w)
        ms = []
        for s, sd in sigma.items():
            diff = getattr(p1, s) - getattr(p0, s)
            if s == "yaw_rad":
                diff = (diff + math.pi) % (2 * math.pi) - math.pi
            ms.append(np.nanmean((diff / sd) ** 2))
        out[e] = float(np.sqrt(np.mean(ms)))
    return out


def method_row(named, params, truth_values, effects, held: dict, wall_s: float, extra: dict | None = None,
                sigma: dict | None = None, spans: dict | None = None) -> dict:
    """``sigma``: the method's standard error per parameter (the chain's), kept per effect with
    ``z`` = (fitted - true) / sigma; ``spans``: the interval the report gives instead for a
    parameter on a plateau, kept per effect with ``in_span`` (the truth inside it)."""
    from simrunner.workflows.gap.synth import RANGES

    per = {}
    for e in effects:
        f = RANGES[e][0]
        ok = e in named
        per[e] = {"named": ok, "fitted": params.get(f),
                  "rel_err": rel_error(e, params.get(f), truth_values[f]) if ok else None}
        if ok and sigma is not None and f in sigma:
            sd = sigma[f]
            per[e]["sigma"] = sd
            per[e]["z"] = (params[f] - truth_values[f]) / sd if sd and math.isfinite(sd) else None
        if ok and spans and f in spans:
            lo, hi = spans[f]
            per[e]["span"] = [lo, hi]
            per[e]["in_span"] = bool(lo <= truth_values[f] <= hi)
    return {"named": list(named), "parameters": params, "per_effect": per,
            "spurious": [n for n in named if n not in effects], "wall_s": wall_s, **held, **(extra or {})}


def inject_glitch(log, kind: str, rng: np.random.Generator):
    """``(log with one glitch of kind, t_start_s, t_end_s)`` (the span touched; see ``glitch``)."""
    t = log.t_s
    n = len(log)
    i = int(rng.integers(int(0.1 * n), int(0.9 * n)))
    if kind == "gap":
        t1 = float(t[i] + rng.uniform(0.5, 2.0))
        return log.subset(np.flatnonzero((t <= t[i]) | (t >= t1))), float(t[i]), t1
    if kind == "jump":
        j = i + 3
        angle, size = rng.uniform(-math.pi, math.pi), rng.uniform(0.5, 1.0)
        cols = {"x_m": log.x_m.copy(), "y_m": log.y_m.copy()}
        cols["x_m"][i:j] += size * math.cos(angle)
        cols["y_m"][i:j] += size * math.sin(angle)
    elif kind == "heading":
        j = i + int(rng.integers(2, 21))
        yaw = log.yaw_rad.copy()
        yaw[i:j] = (yaw[i:j] + rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 3.0) + math.pi) % (2 * math.pi) - math.pi
        cols = {"yaw_rad": yaw}
    elif kind == "spike":  # an encoder that missed or doubled ticks: 1-3 readings off by 1-2 m/s
        j = i + int(rng.integers(1, 4))
        speed = log.speed_mps.copy()
        speed[i:j] += rng.choice([-1.0, 1.0]) * rng.uniform(1.0, 2.0)
        cols = {"speed_mps": speed}
    elif kind == "frozen":
        j = int(np.searchsorted(t, t[i] + rng.uniform(1.0, 3.0)))
        cols = {c: getattr(log, c).copy() for c in ("x_m", "y_m", "yaw_rad")}
        for v in cols.values():
            v[i:j] = v[i]
    else:
        raise ValueError(f"glitch kind {kind!r}: expected one of {', '.join(GLITCH_KINDS)}")
    j = min(j, n - 1)
    return log.with_columns(**cols), float(t[i]), float(t[j])


def glitch_figures(rows: list[dict]) -> dict[str, tuple[float, int]]:
    """The ``glitch`` mode's figures (fraction, n): listed, names unchanged, changes qualified."""
    rows = [r for r in rows if r.get("mode") == "glitch"]
    same = [set(r["clean"]["named"]) == set(r["glitchy"]["named"]) for r in rows]

    def qualified(r) -> bool:  # a pair whose look-alike the run kept as well is no alternative (the report's rule)
        pairs = {frozenset((a, b)) for run in ("clean", "glitchy") for _, a, b, _ in r[run]["alike"]
                 if b not in r[run]["named"]}
        moved = set(r["clean"]["named"]) ^ set(r["glitchy"]["named"])
        return all(any(e in p for p in pairs) for e in moved)

    return {"listed": _frac([bool(r["glitch"]["listed"]) for r in rows]),
            "unchanged": _frac(same),
            "qualified": _frac([qualified(r) for r, ok in zip(rows, same) if not ok])}


def _med(v):
    v = [x for x in v if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else float("nan")


def _frac(hits: list[bool]) -> tuple[float, int]:
    return (sum(hits) / len(hits) if hits else float("nan")), len(hits)


def figures(rows: list[dict], method: str = "chain", only: set[str] | None = None) -> dict:
    """Naming, parameter and held-out figures of ``method`` over synthetic ``rows``
    (``only``: count only these effects as hidden / nameable, for E-SINDy)."""
    out = {}
    rs = [r for r in rows if method in r and "skipped" not in r[method]]

    def hidden(r):
        return [e for e in r["effects"] if only is None or e in only]

    single = [r for r in rs if len(r["effects"]) == 1 and hidden(r)]
    multi = [r for r in rs if len(r["effects"]) >= 2]
    empty = [r for r in rs if not r["effects"]]
    out["single_named_hi"] = _frac([r[method]["per_effect"][r["effects"][0]]["named"]
                                    for r in single if r["snr"][r["effects"][0]] >= SNR_MIN])
    out["single_exact_hi"] = _frac([r[method]["named"] == r["effects"]
                                    for r in single if r["snr"][r["effects"][0]] >= SNR_MIN])
    out["single_named_lo"] = _frac([r[method]["per_effect"][r["effects"][0]]["named"]
                                    for r in single if r["snr"][r["effects"][0]] < SNR_MIN])
    out["false_claims"] = _frac([bool([n for n in r[method]["named"] if only is None or n in only]) for r in empty])
    all_hi = [r for r in multi if hidden(r) and all(r["snr"][e] >= SNR_MIN for e in hidden(r))]
    out["multi_all_named_hi"] = _frac([all(r[method]["per_effect"][e]["named"] for e in hidden(r)) for r in all_hi])
    out["multi_effect_named_hi"] = _frac([r[method]["per_effect"][e]["named"] for r in multi for e in hidden(r)
                                          if r["snr"][e] >= SNR_MIN])
    out["multi_spurious"] = _frac([bool([n for n in r[method]["spurious"] if only is None or n in only])
                                   for r in multi])
    out["any_spurious"] = _frac([bool([n for n in r[method]["spurious"] if only is None or n in only])
                                 for r in rs if r["effects"]])
    out["spurious_per_log"] = _med([len(r[method]["spurious"]) for r in rs if r["effects"]])
    errs = lambda group: [p["rel_err"] for r in group for e, p in r[method]["per_effect"].items()  # noqa: E731
                          if (only is None or e in only) and p["named"] and p["rel_err"] is not None]
    out["single_perr"] = (_med(errs(single)), len(errs(single)))
    zs = [p.get("z") for r in rs if r["effects"] for e, p in r[method]["per_effect"].items()
          if (only is None or e in only) and p["named"] and "sigma" in p]
    out["within_2_sigma"] = _frac([z is not None and abs(z) <= 2.0 for z in zs])
    # of those the report gives one for (the others: on a plateau, pinned by one window, at a bound)
    out["within_2_sigma_given"] = _frac([abs(z) <= 2.0 for z in zs if z is not None])
    # what the report states: within 2 standard errors, or inside the interval of a plateau
    stated = [(p.get("z"), p.get("in_span")) for r in rs if r["effects"] for e, p in r[method]["per_effect"].items()
              if (only is None or e in only) and p["named"] and "sigma" in p]
    out["within_stated"] = _frac([bool(inside) or (z is not None and abs(z) <= 2.0) for z, inside in stated])
    out["multi_perr"] = (_med(errs(multi)), len(errs(multi)))
    with_eff = [r for r in rs if r["effects"]]
    pos = [r[method]["rmse_after"]["position_m"] / r[method]["rmse_before"]["position_m"]
           for r in with_eff if r[method]["rmse_before"].get("position_m")]
    out["pos_ratio"] = (_med(pos), len(pos))
    out["pos_ratio_single"] = (_med([r[method]["rmse_after"]["position_m"] / r[method]["rmse_before"]["position_m"]
                                     for r in single if r[method]["rmse_before"].get("position_m")]), len(single))
    out["gap_ratio"] = (_med([r[method]["gap_after"] / r[method]["gap_before"] for r in with_eff]), len(with_eff))
    out["wall_s"] = (_med([r[method]["wall_s"] for r in rs]), len(rs))
    return out


def fmt_figure(v: tuple[float, int], pct: bool = True) -> str:
    x, n = v
    if not math.isfinite(x):
        return f"n/a (n={n})"
    return f"{x:.0%} (n={n})" if pct else f"{x:.2f} (n={n})"
SYNTH_TARGETS = (
    ("single", "single_named_hi", "named where SNR >= 3", True, 0.95, True),
    ("single", "false_claims", "false claims, effect-free logs", False, 0.05, True),
    ("single", "single_perr", "median parameter error", False, 0.10, True),
    ("single", "pos_ratio", "median held-out position RMSE after/before", False, 0.3, False),
    ("single", "within_2_sigma", "named parameters within 2 sigma of the truth (ours)", True, 0.90, True),
    ("single", "within_2_sigma_given", "the same, of those with a standard error (ours)", True, 0.90, True),
    ("single", "within_stated", "named: within 2 sigma or their plateau's interval (ours)", True, 0.90, True),
    ("multi", "multi_all_named_hi", "every effect named, logs where each has SNR >= 3", True, 0.90, True),
    ("multi", "multi_spurious", "spurious extra effect", False, 0.10, True),
    ("multi", "multi_perr", "median parameter error", False, 0.15, True),
    ("multi", "within_2_sigma", "named parameters within 2 sigma of the truth (ours)", True, 0.90, True),
    ("multi", "within_2_sigma_given", "the same, of those with a standard error (ours)", True, 0.90, True),
    ("multi", "within_stated", "named: within 2 sigma or their plateau's interval (ours)", True, 0.90, True),
    ("speed_gyro", "single_named_hi", "one effect: named where SNR >= 3", True, 0.95, True),
    ("speed_gyro", "false_claims", "false claims, effect-free logs", False, 0.05, True),
    ("speed_gyro", "multi_all_named_hi", "two effects: every effect named where each SNR >= 3", True, 0.90, True),
    ("speed_gyro", "any_spurious", "spurious extra effect (logs with effects)", False, 0.10, True),
    ("tenth", "single_named_hi", "1:10 car, ~30 Hz: named where SNR >= 3", True, 0.95, True),
    ("tenth", "false_claims", "1:10 car, ~30 Hz: false claims, effect-free logs", False, 0.05, True),
    ("tenth", "single_perr", "1:10 car, ~30 Hz: median parameter error", False, 0.10, True),
    ("merged", "single_named_hi", "pose ~30 Hz, commands 50 Hz: named where SNR >= 3", True, 0.95, True),
    ("merged", "false_claims", "pose ~30 Hz, commands 50 Hz: false claims", False, 0.05, True),
    ("merged", "single_perr", "pose ~30 Hz, commands 50 Hz: median parameter error", False, 0.10, True),
    ("merged", "any_spurious", "pose ~30 Hz, commands 50 Hz: spurious extra effect", False, 0.10, True),
)


def sigma_text(sd: float | None) -> str:
    """A parameter's standard error as the report writes it (``report.text``)."""
    if sd is None:
        return ""
    return f" +- {sd:.2g}" if math.isfinite(sd) else " (+- not known: the log does not pin it)"


def target_rows(rows: list[dict]) -> list[dict]:
    """Every issue-10 target the rows measure: figure, n, goal, met (None: nothing measured)."""
    from simrunner.workflows.gap.report import worse_signals

    out = []

    def add(mode, what, value, n, goal, ok, text):
        out.append({"mode": mode, "target": what, "figure": value, "n": n, "goal": goal,
                    "met": None if (n == 0 or not math.isfinite(value)) else bool(ok), "text": text})

    groups = {"single": ("single",), "multi": ("multi", "compare"), "speed_gyro": ("speed_gyro",), "tenth": ("tenth",),
              "merged": ("merged",)}
    figs = {m: figures([r for r in rows if r.get("mode") in modes]) for m, modes in groups.items()}
    for mode, key, what, at_least, limit, pct in SYNTH_TARGETS:
        if not any(r.get("mode") in groups[mode] for r in rows):
            continue
        value, n = figs[mode][key]
        goal = f"{'>=' if at_least else '<='} {limit:.0%}" if pct else f"{'>=' if at_least else '<='} {limit:g}"
        add(mode, what, value, n, goal.replace("%", " %"), value >= limit if at_least else value <= limit,
            fmt_figure((value, n), pct))
    um = [r for r in rows if r.get("mode") == "unmodelled"]
    pull = [r for r in um if r["unmodelled"]["what"] == "reverse_pull_rad"]
    for what, hits in (("nothing named", [not r["chain"]["named"] for r in um]),
                       ("told so: an unexplained leftover listed", [bool(r["leftovers"]) for r in um]),
                       ("told so: a leftover, or a held-out signal made worse",
                        [bool(r["leftovers"]) or bool(r["chain"]["named"] and worse_signals(
                            r["chain"]["rmse_before"], r["chain"]["rmse_after"])) for r in um]),
                       ("reverse pull: a leftover in steering while reversing",
                        [any(d["signal"] in ("yaw_rate_radps", "yaw_rad", "position_m") and "reversing" in d["regimes"]
                             for d in r["leftovers"]) for r in pull])):
        if hits:
            value, n = _frac(hits)
            add("unmodelled", what, value, n, ">= 90 %", value >= 0.9, fmt_figure((value, n)))
    if any(r.get("mode") == "glitch" for r in rows):
        gf = glitch_figures(rows)
        for key, what, goal, limit in (("listed", "one glitch put in: listed", ">= 90 %", 0.9),
                                       ("unchanged", "one glitch put in: the names unchanged", "100 %", 1.0),
                                       ("qualified", "names changed: each change in a look-alike pair", "100 %", 1.0)):
            value, n = gf[key]
            add("glitch", what, value, n, goal, value >= limit, fmt_figure((value, n)))
    for r in rows:
        if r.get("mode") in ("real", "real_partial"):
            name, mode = r["log"], r["mode"]
            if "error" in r:
                add(mode, f"{name}: no traceback", 0.0, 1, "none", False, "traceback")
                continue
            g = r["gap_after"] / r["gap_before"]
            add(mode, f"{name}: held-out gap after/before", g, 1, "<= 0.6", g <= 0.6, f"{g:.3g}")
            # the position where the log has a pose; else each rate it measures
            for sig, unit in ((("position_m", "m"),) if "position_m" in r["rmse_before"] else
                              (("speed_mps", "m/s"), ("yaw_rate_radps", "rad/s"))):
                pb = r["rmse_before"].get(sig, float("nan"))
                pa = r["rmse_after"].get(sig, float("nan"))
                what = sig.rsplit("_", 1)[0].replace("_", " ")
                add(mode, f"{name}: held-out {what} RMSE not worse", pa / pb, 1, "after/before <= 1",
                    pa <= pb, f"{pb:.3f} -> {pa:.3f} {unit}")
            worse = [s for s in r["steps"] if not s[3] < s[2]]
            add(mode, f"{name}: every kept effect improves held-out", float(not worse), 1, "all", not worse,
                f"{len(r['steps']) - len(worse)} of {len(r['steps'])} steps")
            add(mode, f"{name}: no traceback", 1.0, 1, "none", True, "none")
        elif r.get("mode") == "timing":
            add("timing", f"whole chain, {r['log_s']:.0f}-s log, {r['jobs']} processes", r["wall_s"], 1, "<= 180 s",
                r["wall_s"] <= 180.0, f"{r['wall_s']:.0f} s")
    return out
