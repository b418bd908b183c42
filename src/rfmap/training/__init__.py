r"""Training of a surrogate (the recipes of paper Sec. 5.1 and 5.2), single-process or data-parallel, on CPU or GPU.

By default training needs no solved maps: a density model learns from its density loss alone, and a Beltrami model
from the difference between its map's coefficient and the input coefficient (the paper computes ground-truth maps
for its Beltrami training, though its loss compares coefficients only).

One concept per module: :mod:`~rfmap.training.config` holds the configurations and their scale presets;
:mod:`~rfmap.training.data` draws the batches (sample ``i`` of step ``t`` seeded by ``(seed, t, i)``, on a random
grid side in ``n_range``) in a thread or in worker processes; :mod:`~rfmap.training.averaging` keeps an exponential
moving average of the weights (``--ema``); :mod:`~rfmap.training.state` holds the run's state and its checkpoint,
with the parent a warm start (``--init``) came from; :mod:`~rfmap.training.loop` runs the steps, validates, chooses
and writes the shipped weights; :mod:`~rfmap.training.validation` draws the held-out fields and scores them;
:mod:`~rfmap.training.selection` chooses among saved weights after a run (``rfmap validate``);
:mod:`~rfmap.training.lineage` traces the chain of runs behind a weight file; :mod:`~rfmap.training.records` reads
the budgets and studies of the book; and :mod:`~rfmap.training.cli` is ``rfmap train`` (also
``python -m rfmap.training``).
"""
from ..core.device import resolve_device
from .averaging import WeightAverage
from .cli import build_parser, main, run
from .data import draw_step, single_blas_thread_env, step_size_n
from .loop import RunOptions, history, report_paper_fields, train, validate
from .state import TrainState, learning_rates, load_init, machine, memory_format, sha256

__all__ = ["train", "RunOptions", "validate", "report_paper_fields", "resolve_device", "load_init", "main", "TrainState",
           "WeightAverage", "memory_format", "draw_step", "history", "build_parser", "run", "single_blas_thread_env",
           "step_size_n", "machine", "sha256", "learning_rates"]
