"""The screening subset of the chain's fit windows (step 1 of :mod:`simrunner.workflows.gap.chain`):
about ``screen_max_s`` seconds of them, spread evenly through the log, with the first window of
each driving regime and the windows of the rare manoeuvres (the hardest steering each way, a
reverse command while rolling forward), so that a long log screens no slower than a 45-s one
and no rare manoeuvre is left out (:func:`screening_problem`)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from simrunner.workflows.gap.fit import Problem

# regimes that label a window for the screening subset (simrunner.workflows.gap.regimes)
SCREEN_REGIMES = ("coasting", "braking", "accelerating", "reversing", "high_lat_accel", "cornering", "straight")
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0  # screening_problem's even spread of grid slots


def window_labels(problem: Problem) -> list[str]:
    """One label per window of ``problem`` (the windows of all segments in turn): the regime of
    :data:`SCREEN_REGIMES` most over-represented in the window against all the problem's
    windows (its share of the window's samples over its share of all windows' samples; it
    must cover at least ``settings.screen_label_min_share`` of the window), ``"other"`` when none
    does. A window with the rare braking of a log is labelled ``braking``, one of a
    cornering-heavy log's few straights ``straight``."""
    from simrunner.workflows.gap.regimes import segment
    from simrunner.workflows.gap.replay import window_mask

    shares, total, count = [], np.zeros(len(SCREEN_REGIMES)), 0
    for seg in problem.segments:
        masks = segment(seg.log, seg.derived, problem.car, settings=problem.settings)
        inside = window_mask(len(seg.log), seg.windows)
        total += [float(np.count_nonzero(masks[r] & inside)) for r in SCREEN_REGIMES]
        count += int(np.count_nonzero(inside))
        for w in seg.windows:
            n = max(w.stop - w.start, 1)
            shares.append(np.array([np.count_nonzero(masks[r][w.start:w.stop]) / n for r in SCREEN_REGIMES]))
    overall = total / max(count, 1)
    labels = []
    for share in shares:
        score = np.where((share >= problem.settings.screen_label_min_share) & (overall > 0),
                         share / np.maximum(overall, 1e-12), 0.0)
        labels.append(SCREEN_REGIMES[int(np.argmax(score))] if score.max() > 0.0 else "other")
    return labels


def extreme_windows(problem: Problem) -> set[int]:
    """Indices (over the windows of all segments in turn) of the windows holding the largest
    steering command to each side. A smaller steering limit acts only where the car was
    asked to steer beyond it; a plan that steers at full lock in a few windows only (and a
    teleoperated log) gives a subset without them, which screens the limit at 0 %.
    Steering commands only: with the speed command's extremes and the fastest command
    changes too (up to 7 windows), they tilted a real log's screening towards those moments
    (DS2 then named mass_scale first; bench/results/gap-history.md) [shaped by the shared logs]."""
    feats: list[list[float]] = []
    for seg in problem.segments:
        steer = np.asarray(seg.log.steer_cmd_rad, float)
        for w in seg.windows:
            part = steer[w.start:w.stop]
            feats.append([_finite_max(part), _finite_max(-part)])
    if not feats:
        return set()
    out = set()
    for col in np.array(feats).T:
        if np.isfinite(col).any() and np.nanmax(col) > 0.0:
            out.add(int(np.argmax(np.where(np.isfinite(col), col, -np.inf))))
    return out


def reversal_windows(problem: Problem) -> set[int]:
    """Indices (over the windows of all segments in turn) of the windows where the car is
    asked to reverse while it still rolls forward
    (:func:`simrunner.workflows.gap.regimes.brake_to_reverse`, the car file's brake limit):
    an ESC that brakes before it reverses shows only there, and a plan reverses a few times
    in a long log, so every k-th window of a label can miss them all."""
    from simrunner.workflows.gap.regimes import reversal_onsets

    flags = [f for seg in problem.segments
             for f in reversal_onsets(seg.log, seg.derived, seg.windows, problem.car.drive.max_brake_mps2,
                                      settings=problem.settings)]
    return {i for i, f in enumerate(flags) if f}


def _finite_max(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(x.max()) if x.size else -math.inf


def screening_problem(problem: Problem, max_s: float | None = None) -> Problem:
    """``problem`` with about ``max_s`` seconds of its windows: with ``k = ceil(total /
    max_s)`` (the seconds of all windows over ``max_s``), the windows whose grid slot
    (:attr:`simrunner.workflows.gap.replay.Window.slot`) falls in the first ``1/k`` of a
    golden-ratio sequence (``frac(slot * 0.618...) < 1/k``: spread evenly through the log
    and through each label, whatever the held-out split's pattern, and each window's own
    choice, so a glitch that removes a window changes no other's; counting every k-th
    window did); the first window of each label of :func:`window_labels`, so a manoeuvre
    that a few windows hold (a hard brake, a coast, reversing) stays in the screening and
    the effects it reveals are ranked on it; and the windows of :func:`extreme_windows`
    (the hardest steering each way) and of :func:`reversal_windows` (a reverse command
    while rolling forward). ``max_s`` default: the problem's ``settings.screen_max_s``."""
    if max_s is None:
        max_s = problem.settings.screen_max_s
    total = sum(s.duration_s for s in problem.segments)
    k = max(1, math.ceil(total / max_s)) if max_s > 0 else 1
    if k == 1:
        return problem
    labels = iter(window_labels(problem))
    extremes = extreme_windows(problem) | reversal_windows(problem)
    seen: set[str] = set()  # labels met
    segs = []
    index = 0
    for seg in problem.segments:
        keep = []
        for w in seg.windows:
            label = next(labels)
            first = label not in seen
            seen.add(label)
            if first or (w.slot * GOLDEN) % 1.0 < 1.0 / k or index in extremes:
                keep.append(w)
            index += 1
        if keep:
            segs.append(dataclasses.replace(seg, windows=tuple(keep)))
    return dataclasses.replace(problem, segments=tuple(segs))


__all__ = ["screening_problem", "window_labels", "extreme_windows", "reversal_windows"]
