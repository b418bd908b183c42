"""Tasks: what a surrogate maps from, how its inputs are encoded, how training batches are drawn and scored.

Every kind of map is a :class:`.Task` registered under its name (:func:`.register_task`): :mod:`rfmap.tasks.density`
(density-equalizing maps) and :mod:`rfmap.tasks.beltrami` (maps from their Beltrami coefficient).  A
:class:`.TaskSpec` names a kind, a dimension and a boundary condition; ``spec.task`` is the kind's task object, which
the training, the surrogate, the finishing stages and the validation ask for everything that depends on the kind.
A new kind of map is a new :class:`~rfmap.tasks.base.Task` subclass with ``@register_task``.
"""
from __future__ import annotations

from .base import (Batch, LossWeights, MappedBatch, SampleOptions, Task, TaskSpec, batch_loss_terms, draw_samples,
                   encode, get_task, grid_elements, kinds, make_batch, register_task, registered_task,
                   sample_batch, task_loss)
from .density import DensityTask  # registered first: the default kind  # isort: skip
from .beltrami import BeltramiTask  # isort: skip
from .heldout import STREAMS, VALIDATION_SEED, ValidationField

__all__ = ["Task", "TaskSpec", "Batch", "LossWeights", "MappedBatch", "SampleOptions", "register_task", "registered_task",
           "get_task",
           "kinds", "encode", "grid_elements", "draw_samples", "make_batch", "sample_batch", "task_loss",
           "batch_loss_terms",
           "DensityTask", "BeltramiTask", "ValidationField", "VALIDATION_SEED", "STREAMS"]
