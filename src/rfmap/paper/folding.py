"""The bijectivity chapter's examples: the first seeded hard field on which a surrogate's raw map folds, and what
the 2D repair does to the map's Beltrami coefficient."""
from __future__ import annotations

import numpy as np
import torch

from ..core.geometry import beltrami_coefficient
from ..finish import quiet_quality
from ..finish.repair import DELTA

__all__ = ["first_folding", "repaired_mu"]


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


def repaired_mu(raw, repaired) -> dict:
    r"""The Beltrami coefficient of a 2D map before and after its repair (two :class:`rfmap.core.result.MapResult`
    of one mesh): ``moved``, the triangles with a vertex the repair moved; ``same_outside``, whether :math:`\mu` is
    unchanged on every other triangle; ``max_mu``, the largest :math:`|\mu|` of the repaired map on the moved
    triangles; ``over_cap``, how many of them end above :math:`1 - \delta`
    (``rfmap.finish.repair.DELTA``), the cap of the truncated coefficient, which the rebuilt map need not meet."""
    ref, el = torch.as_tensor(raw.ref_points), torch.as_tensor(raw.elements)
    mu = [np.abs(beltrami_coefficient(ref, torch.as_tensor(r.mapped_points), el).numpy()) for r in (raw, repaired)]
    moved = (np.abs(repaired.mapped_points - raw.mapped_points).max(1) > 0)[raw.elements].any(1)
    return {"moved": int(moved.sum()), "same_outside": bool(np.array_equal(mu[0][~moved], mu[1][~moved])),
            "max_mu": float(mu[1][moved].max()) if moved.any() else 0.0,
            "over_cap": int((mu[1][moved] > 1 - DELTA).sum())}
