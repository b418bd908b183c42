r"""A classical teacher for density surrogates: the solver's map of a training field as a supervised target.

The paper trains its density surrogates without labelled data.  A teacher adds, for a share of every batch, the map that
a classical solver computes for the same field on the same grid as a target of the network's map, *beside* the data-free
losses (which stay).  The supervised term is the relative displacement error

.. math::

    \mathcal{L}_T = \frac{\sum_v |u(x_v) - u_T(x_v)|^2}{\max\big(\sum_v |u_T(x_v) - x_v|^2,\; P h^2\big)},

summed over the ``P`` vertices of a sample and averaged over the samples that have a target (``h = 1/(N-1)``).
A network that does nothing scores 1 on a field the teacher moves by more than a grid spacing; the floor keeps
nearly uniform fields, whose maps hardly move, from dominating the term.

The targets are computed in the batch workers from the field's values on the regular ``N``-grid
(:func:`teacher_map`) and carried to the sample's (jittered) vertices by multilinear interpolation of the
displacement (:func:`teacher_targets`).  With a free boundary the classical map lives in a sea and need not keep the
domain's area, while the network is asked to (``rfmap.tasks.losses.area_penalty``): its target is the classical map scaled
about its centroid to the domain's measure (equalization is invariant under scaling).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from ..core.geometry import signed_measures
from ..core.mesh import interpolate
from ..fields import preprocess_density
from ..solvers import ALIASES

__all__ = ["TeacherConfig", "TEACHER_METHODS", "teacher_map", "teacher_targets", "teacher_indices", "teacher_loss"]

#: classical solvers that can teach (``"dem"`` is accepted as another name of ``"diffusion"``, as by the solvers)
TEACHER_METHODS = ("none", "flow", "diffusion")


@dataclass(frozen=True)
class TeacherConfig:
    """The supervised term of a density model's training.

    Attributes
    ----------
    method : {"none", "flow", "diffusion"}
        The classical solver whose maps are targets (``"none"``: purely data-free, as in the paper).
    share : float
        Fraction of each batch's samples that carry a target, in (0, 1]; the first ``round(share * B)`` samples
        of every step (at least one).
    weight : float
        Weight of :math:`\\mathcal{L}_T` in the total loss.
    """

    method: str = "none"
    share: float = 0.5
    weight: float = 0.1

    def __post_init__(self):
        method = ALIASES.get(self.method, self.method)
        object.__setattr__(self, "method", method)
        if method not in TEACHER_METHODS:
            raise ValueError(f"unknown teacher {self.method!r}; expected one of {', '.join(TEACHER_METHODS)}")
        if not (0.0 < self.share <= 1.0):
            raise ValueError(f"the teacher's share of a batch must lie in (0, 1], got {self.share}")
        if not (np.isfinite(self.weight) and self.weight >= 0):
            raise ValueError(f"the teacher's weight must be a non-negative number, got {self.weight}")

    @property
    def active(self) -> bool:
        return self.method != "none" and self.weight > 0


def teacher_indices(batch: int, share: float) -> int:
    """How many samples of a batch of ``batch`` carry a target: ``round(share * batch)``, at least one."""
    return max(1, min(batch, int(round(share * batch))))


def teacher_map(raw_grid: np.ndarray, boundary: str, method: str) -> np.ndarray | None:
    """The classical map of a raw density on the regular grid.

    Parameters
    ----------
    raw_grid : ndarray, shape (N, N) or (N, N, N)
        Raw field values at the grid vertices (preprocessed here as ``rfmap map`` does).
    boundary : {"square", "free"}
    method : {"flow", "diffusion"}

    Returns
    -------
    ndarray, shape (N**d, d), or None
        Mapped vertices in grid order (for ``"free"`` scaled about their centroid to the domain's measure);
        ``None`` when the solver fails or its map folds (the sample then trains without a target).
    """
    from ..solvers import solve_dem  # solvers import torch-free modules only; kept local for worker start-up

    dens = preprocess_density(np.asarray(raw_grid, dtype=np.float64))
    try:
        r = solve_dem(dens, method=method, boundary=boundary, num_threads=1)
    except (RuntimeError, ValueError, FloatingPointError):
        return None
    m = r.metrics()
    if m.n_flipped or not np.all(np.isfinite(r.mapped_points)):
        return None
    mapped = np.asarray(r.mapped_points, dtype=np.float64)
    if boundary == "free":
        el = torch.as_tensor(r.elements)
        area = float(signed_measures(torch.as_tensor(mapped), el).sum())
        c = mapped.mean(0)
        mapped = c + (mapped - c) * (1.0 / area) ** (1.0 / mapped.shape[1])
    return mapped


def teacher_targets(points: np.ndarray, n: int, mapped_grid: np.ndarray) -> np.ndarray:
    """Targets at a sample's vertices: ``points + D(points)``, with ``D`` the multilinear interpolant of the grid
    map's displacement.

    Parameters
    ----------
    points : ndarray, shape (N**d, d)
        The sample's vertices (regular or jittered) in :math:`[0, 1]^d`.
    n : int
        The grid side ``N`` of ``mapped_grid``.
    mapped_grid : ndarray, shape (N**d, d)
        :func:`teacher_map` of the sample's field.

    Returns
    -------
    ndarray, shape (N**d, d)
    """
    d = points.shape[1]
    grid = np.stack(np.meshgrid(*([np.linspace(0.0, 1.0, n)] * d), indexing="ij"), -1).reshape(-1, d)
    disp = (mapped_grid - grid).reshape((n,) * d + (d,))
    vals = np.moveaxis(disp, -1, 0)[None]
    return points + interpolate(vals, points)[0]


def teacher_loss(mapped: Tensor, target: Tensor, ref: Tensor, mask: Tensor, n: int) -> Tensor:
    r""":math:`\mathcal{L}_T` averaged over the samples with ``mask`` set (see :mod:`rfmap.tasks.teacher`).

    Parameters
    ----------
    mapped, target, ref : Tensor, shape (B, P, d)
        The network's map, the teacher's targets and the reference vertices of each sample.
    mask : BoolTensor, shape (B,)
        The samples that have a teacher map.
    n : int
        The grid side ``N``; it sets the loss's floor, :math:`P h^2 = P/(N-1)^2` for ``P`` vertices (grid
        spacing :math:`h = 1/(N-1)`).
    """
    err = ((mapped - target) ** 2).sum((-1, -2))
    scale = ((target - ref) ** 2).sum((-1, -2))
    floor = ref.shape[1] / float(n - 1) ** 2
    rel = err / torch.clamp(scale, min=floor)
    w = mask.to(rel.dtype)
    return (rel * w).sum() / torch.clamp(w.sum(), min=1.0)
