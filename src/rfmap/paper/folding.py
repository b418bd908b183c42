"""The bijectivity chapter's examples: the first seeded hard field on which a surrogate's raw map folds."""
from __future__ import annotations

import numpy as np

from ..finish import quiet_quality

__all__ = ["first_folding"]


@quiet_quality()
def first_folding(sur, n: int, *, seed: int = 0, tries: int = 50) -> tuple[int, np.ndarray]:
    """The first seed from ``seed`` on whose hard field the raw map of surrogate ``sur`` on the ``N``-grid folds.

    The task of the surrogate draws the field and says how to map it (``Task.hard_field``: densities from
    :func:`rfmap.fields.hard.hard_density`, mapped with ``preprocess=False``, Beltrami coefficients from
    :func:`rfmap.fields.hard.hard_beltrami`).  Returns ``(seed, field)``; ``RuntimeError`` when none of ``tries``
    seeds folds.
    """
    task, dim = sur.spec.task, sur.spec.dim
    for s in range(seed, seed + tries):
        field, kw = task.hard_field(np.random.default_rng(s), n, dim)
        raw = sur.map(field, n, repair=False, **kw)
        if raw.metrics().n_flipped > 0:
            return s, field
    raise RuntimeError(f"the raw map folded on none of the hard fields with seeds {seed}..{seed + tries - 1}")
