"""Many runs of one controller: ``simrunner batch`` over tracks, seeds and parameter grids,
on all local cores or a Ray cluster (docs/batch.md).

    run_batch(controller, out_dir=..., tracks=[...], seeds=3, params=["speed=1.5,2.0"]) -> BatchResult

Modules, in data-flow order: :mod:`.spec` (inputs -> jobs), :mod:`.worker` (one job -> one
row, tracks loaded once per worker), :mod:`.scheduler` (jobs -> workers), :mod:`.pool`
(local processes), :mod:`.ray_backend` (Ray actors), :mod:`.results` (rows -> CSV/JSON),
:mod:`.plot` (summary.png), :mod:`.engine` (:func:`run_batch`).
"""
from simrunner.workflows.batch.engine import BatchResult, Selection, default_workers, run_batch
from simrunner.workflows.batch.results import NONDETERMINISTIC, deterministic, read_results
from simrunner.workflows.batch.spec import BatchError

__all__ = ["run_batch", "BatchResult", "BatchError", "Selection", "default_workers",
           "NONDETERMINISTIC", "deterministic", "read_results"]
