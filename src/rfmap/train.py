r"""Data-free training of a surrogate (paper Sec. 5), single-process or data-parallel, on the CPU or a GPU.

``rfmap train --config NAME [--preset ci|full|paper] [--device auto|cpu|cuda] [--init MODEL|FILE] [--resume]``
(also ``python -m rfmap.train``) trains the named configuration of :mod:`rfmap.training.config`.  Every step draws a fresh
batch of random fields (sample ``i`` of step ``t`` is seeded by ``(seed, t, i)``) on a random grid size in
``n_range``, with Sobol-jittered vertices.  With ``workers >= 1`` the batches are drawn ahead of the step by
worker processes; the batches, hence the weights, are the same for any number of workers.

Data-parallel: ``torchrun --nproc_per_node=K -m rfmap.train --config NAME ...`` runs K processes (gloo on CPU,
NCCL on GPU); rank ``r`` draws samples ``r*B .. (r+1)*B - 1`` of each step, so K processes with batch ``B`` train
the same model as one process with batch ``K*B``.

Validation and the choice of the shipped checkpoint use the held-out random fields of :mod:`rfmap.training.validation`
(seeds training never draws); the paper's test fields are evaluated once at the end as a report.

3D networks train in the ``channels_last_3d`` memory format (:func:`memory_format`): the same model and the same
arithmetic up to float rounding, but faster 3D convolutions.  2D networks keep the contiguous format.

``--ema DECAY`` keeps an exponential moving average of the weights (:class:`WeightAverage`); validation, the choice of
the shipped checkpoint and the shipped file then use the averaged weights, which bounce less between checkpoints than
the weights as trained.

``--init`` starts from shipped or saved weights with a fresh optimiser and schedule (a warm restart); the
metadata keeps the lineage (parent name and SHA-256, cumulative steps and wall time).

Outputs in ``--out`` (default ``runs/NAME``): ``log.jsonl`` (one JSON object per logged step and per
validation), ``checkpoint.pt`` (model, optimiser, scheduler, step; loaded with ``weights_only=True`` onto any
device), and the final ``NAME.safetensors`` + ``NAME.json`` (metadata: config, command, steps, wall time,
validation metrics, lineage, training history).

The code lives in the package :mod:`rfmap.training` (data, weight averaging, state and lineage, the loop, the command
line); this module gathers its public names under their historical path.
"""
from __future__ import annotations

import sys

from .core.device import resolve_device
from .training import (TrainState, WeightAverage, build_parser, draw_step, history, load_init, main,
                       memory_format, report_paper_fields, run, single_blas_thread_env, train, validate)

__all__ = ["train", "validate", "report_paper_fields", "resolve_device", "load_init", "main", "TrainState",
           "WeightAverage", "memory_format", "draw_step", "history", "build_parser", "run", "single_blas_thread_env"]

if __name__ == "__main__":
    sys.exit(main())
