"""Bench results as files: ``bench/results/NAME.json``, the figures the docs show.

A bench that records its figures calls :func:`save` at the end of its ``main()``;
``tools/render_bench_tables.py`` (run by ``make bench``) renders them into the docs' marked
blocks, and ``tests/test_docs_tables.py`` checks that the docs show what the files hold. A file
holds the figures and what they were measured on (cores, the 1-minute load average, Python).
"""
from __future__ import annotations

import json
import os
import platform
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
RESULTS_FORMAT = "nxpcup-bench-results/1"  # tools/render_bench_tables.py's


def save(name: str, figures: dict, *, results: Path = RESULTS) -> Path:
    """Write ``figures`` (JSON-able) as ``results/NAME.json`` with the machine's cores, load
    and Python; returns the path."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    data = {"format": RESULTS_FORMAT, "bench": name,
            "machine": {"cpus": os.cpu_count(), "load_1min": None if load is None else round(load, 1),
                        "python": platform.python_version()},
            "figures": figures}
    results.mkdir(parents=True, exist_ok=True)
    path = results / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, path)
    return path
