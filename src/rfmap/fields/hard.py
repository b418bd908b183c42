r"""Random fields built to be hard for a surrogate: the stress tests of the bijectivity repair.

Densities are positive fields sampled on an ``N``-grid and meant to be mapped with ``preprocess=False`` (so that
near-zero regions survive):

.. math::

   p &= p_{\min} + (p_{\max} - p_{\min})\,\frac{g - \min g}{\max g - \min g}, \\
   g &= \sum_k a_k\,\mathrm{bump}_k(x) + \text{steps} + \text{ramps},

with sharp Gaussian peaks (widths 0.01–0.06), box steps, linear ramps, and a contrast :math:`p_{\min}/p_{\max}`
drawn log-uniformly in :math:`[10^{-3}, 0.3]`.

Beltrami coefficients have a smooth random part plus one to three localized bulges (Gaussian, width 0.03–0.12),
are tapered to 0 at the boundary, and are scaled so that :math:`\|\mu\|_\infty` is drawn in :math:`[0.5, 0.95]`.

Each task draws its hard fields (:meth:`rfmap.tasks.base.Task.hard_field`); :func:`rfmap.paper.folding.first_folding`
finds among them one on which a given surrogate's raw map folds (the bijectivity chapter's examples).
:func:`self_crossing_map` is a 3D map that no element check can catch: every tetrahedron positive, the boundary
surface passing through itself.
"""
from __future__ import annotations

import math

import numpy as np

from ..core.mesh import grid_mesh, grid_points

__all__ = ["hard_density", "hard_beltrami", "self_crossing_map"]


def _log_uniform(rng, lo, hi):
    return float(np.exp(rng.uniform(math.log(lo), math.log(hi))))


def hard_density(rng: np.random.Generator, n: int, dim: int = 2, *, ratio: tuple[float, float] = (1e-3, 0.3)
                 ) -> np.ndarray:
    """One hard positive density on the ``N``-grid, shape ``(N,)*dim``; ``min/max`` is drawn in ``ratio``."""
    x = grid_points(n, dim)
    g = np.zeros(len(x))
    for _ in range(int(rng.integers(1, 6))):  # sharp peaks, positive or negative (holes)
        c = rng.uniform(0.1, 0.9, dim)
        w = _log_uniform(rng, 0.01, 0.06)
        g += rng.choice([-1.0, 1.0], p=[0.3, 0.7]) * rng.uniform(0.5, 3) * np.exp(-((x - c) ** 2).sum(1) / (2 * w * w))
    for _ in range(int(rng.integers(0, 3))):  # steps
        lo = rng.uniform(0, 0.7, dim)
        hi = lo + rng.uniform(0.1, 0.4, dim)
        g += rng.uniform(-1, 1) * ((x >= lo) & (x <= hi)).all(1)
    if rng.random() < 0.5:  # ramp
        g += rng.uniform(-2, 2) * (x @ rng.normal(size=dim))
    span = g.max() - g.min()
    g = (g - g.min()) / span if span > 1e-12 else np.ones_like(g)
    r = _log_uniform(rng, *ratio)
    return (r + (1 - r) * g).reshape((n,) * dim)


def hard_beltrami(rng: np.random.Generator, n: int, *, sup: tuple[float, float] = (0.5, 0.95)) -> np.ndarray:
    """One hard Beltrami coefficient at the vertices of the 2D ``N``-grid, complex, shape (N, N)."""
    x = grid_points(n, 2)
    mu = np.zeros(len(x), np.complex128)
    for _ in range(int(rng.integers(1, 8))):
        f = _log_uniform(rng, 0.3, 6.0)
        ph = rng.uniform(0, 2 * np.pi, 2)
        mu += rng.uniform(0, 1) * np.exp(1j * rng.uniform(0, 2 * np.pi)) * \
            np.sin(2 * np.pi * f * x[:, 0] + ph[0]) * np.cos(2 * np.pi * f * x[:, 1] + ph[1])
    for _ in range(int(rng.integers(1, 4))):
        c = rng.uniform(0.2, 0.8, 2)
        w = rng.uniform(0.03, 0.12)
        mu += 3 * np.exp(1j * rng.uniform(0, 2 * np.pi)) * np.exp(-((x - c) ** 2).sum(1) / (2 * w * w))
    mu *= np.clip(np.minimum(x, 1 - x).min(1) / 0.1, 0, 1)
    peak = np.abs(mu).max()
    mu *= rng.uniform(*sup) / peak if peak > 0 else 0.0
    return mu.reshape(n, n)


def self_crossing_map(n: int, turns: float = 1.3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""The unit cube bent around the :math:`z` axis through ``turns`` full turns, on the 3D ``N``-grid.

    :math:`u(x, y, z) = (r\cos\theta, r\sin\theta, z)` with :math:`\theta = 2\pi\,\text{turns}\,x` and
    :math:`r = 1.5 - y/2`: :math:`\det Du = \pi\,\text{turns}\,r > 0`, so every tetrahedron of a fine enough grid
    is positive, but for ``turns > 1`` the two ends of the bent bar pass through each other.

    Returns
    -------
    ref : ndarray, shape (N**3, 3)
        The grid vertices.
    mapped : ndarray, shape (N**3, 3)
        Their images.
    elements : int ndarray, shape (6 (N-1)**3, 4)
        The tetrahedra of :func:`rfmap.core.mesh.grid_mesh`.
    """
    m = grid_mesh(n, 3)
    x, y, z = m.points.T
    theta = 2 * np.pi * turns * x
    r = 1.5 - 0.5 * y
    return m.points, np.stack([r * np.cos(theta), r * np.sin(theta), z], 1), m.elements
