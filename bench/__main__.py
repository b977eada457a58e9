"""Run every ``bench/bench_*.py`` module's ``main()`` in name order (``python -m bench``).

``python -m bench NAME ...`` runs only the modules whose name contains one of the NAMEs.
"""
from __future__ import annotations

import importlib
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> None:
    wanted = sys.argv[1:] if argv is None else argv
    for path in sorted(Path(__file__).resolve().parent.glob("bench_*.py")):
        if wanted and not any(w in path.stem for w in wanted):
            continue
        print(f"== {path.stem}")
        importlib.import_module(f"bench.{path.stem}").main()
        print()


if __name__ == "__main__":
    main()
