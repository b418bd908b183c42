r"""Data-free training losses (paper Sec. 5), integrated over element measures.

Every loss is an average over elements weighted by the reference element measure, i.e. a quadrature of an
integral over :math:`\Omega`, so its value does not depend on the grid resolution.

Shapes: ``ref`` and ``mapped`` are (B, P, d) vertex positions, ``elements`` is (m, d+1).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor
from torch.nn import functional as F

from ..core.geometry import beltrami_coefficient, signed_measures

__all__ = ["Measures", "weighted_mean", "beltrami_loss", "density_loss", "beltrami_energy", "fold_penalty", "area_penalty",
           "element_density", "loss_integrands", "DENSITY_FLOOR"]

#: the floor of an element's mapped measure in :func:`element_density`, as a fraction of its reference measure
DENSITY_FLOOR = 0.01


@dataclass(frozen=True)
class Measures:
    """Element quantities of a batch computed once and shared by the loss terms; each one missing is computed from
    the mesh.

    Attributes
    ----------
    ref : Tensor, shape (B, m), optional
        Signed element measures before the map (e.g. by :func:`rfmap.core.geometry.grid_signed_measures` on a grid
        mesh).
    mapped : Tensor, shape (B, m), optional
        Signed element measures after the map.
    density : Tensor, shape (B, m), optional
        The mean vertex density of every element.
    """

    ref: Tensor | None = None
    mapped: Tensor | None = None
    density: Tensor | None = None

    def measures(self, ref: Tensor, mapped: Tensor, elements: Tensor) -> tuple[Tensor, Tensor]:
        """The reference and mapped measures, computed where not given."""
        return (signed_measures(ref, elements) if self.ref is None else self.ref,
                signed_measures(mapped, elements) if self.mapped is None else self.mapped)


NONE = Measures()


def weighted_mean(values: Tensor, weights: Tensor) -> Tensor:
    """:math:`\\sum_i w_i v_i / \\sum_i w_i` over the last axis, averaged over the batch."""
    return ((values * weights).sum(-1) / weights.sum(-1)).mean()


def beltrami_loss(ref: Tensor, mapped: Tensor, elements: Tensor, mu_target: Tensor) -> Tensor:
    r"""Beltrami loss :math:`\int_\Omega |\mu(u) - \mu_{\text{in}}|^2` (paper Sec. 5.1).

    Parameters
    ----------
    mu_target : complex Tensor, shape (B, m)
        Target coefficient per triangle.
    """
    area = signed_measures(ref, elements)
    mu = beltrami_coefficient(ref, mapped, elements)
    return weighted_mean((mu - mu_target).abs() ** 2, area)


def element_density(ref: Tensor, mapped: Tensor, elements: Tensor, density: Tensor, *, pre: Measures = NONE,
                    tangent: bool = False) -> tuple[Tensor, Tensor]:
    r"""Relative density :math:`\tilde\rho_i = (p_i / A_i) / (P / A)` on the mapped mesh, and reference measures.

    :math:`p_i` is the population of element :math:`i` (mean vertex density times reference measure),
    :math:`A_i` its mapped measure (floored at 1% of the reference measure, so the density and its gradient stay
    bounded when an element degenerates), :math:`P` and :math:`A` the totals.

    The measures and the elements' mean densities may be passed precomputed (``pre``, :class:`Measures`).

    With ``tangent=True`` the density below the floor :math:`a_0 = 0.01\,|T_i|` continues along its tangent,
    :math:`p_i/a_0\,(2 - A_i/a_0)`, instead of staying at :math:`p_i/a_0`: a collapsed or flipped element then
    still feels the density term pulling it open (with the clamp its gradient is zero there and only the fold
    penalty acts). The two agree, value and slope, at the floor and above it.

    Returns
    -------
    (rho_tilde, ref_measure) : Tensors, shape (B, m)
    """
    ref_meas, meas = pre.measures(ref, mapped, elements)
    elem_density = density[:, elements].mean(-1) if pre.density is None else pre.density
    pop = elem_density * ref_meas
    # guard: an element shrunk below 1% of its reference measure (or flipped) counts as 1% (the fold penalty
    # handles it); this keeps the density and its gradient bounded
    floor = DENSITY_FLOOR * ref_meas
    rho = pop / torch.maximum(meas, floor)
    if tangent:
        rho = torch.where(meas >= floor, rho, pop / floor * (2 - meas / floor))
    mean_rho = pop.sum(-1, keepdim=True) / meas.sum(-1, keepdim=True)
    return rho / mean_rho, ref_meas


def density_loss(ref: Tensor, mapped: Tensor, elements: Tensor, density: Tensor, beta: float = 1.0, *,
                 pre: Measures = NONE, tangent: bool = False) -> Tensor:
    r"""Density-equalizing loss :math:`\int_\Omega L(\tilde\rho_i - 1)` with smooth-L1 :math:`L`, where
    :math:`\tilde\rho_i = (p_i/A_i)/(P/A)` is the density of element :math:`i` after the map (population
    :math:`p_i`, mapped measure :math:`A_i`) relative to the mean density :math:`P/A` (total population over total
    mapped measure).

    Differs from the paper: its Sec. 5.2 writes :math:`L(p_i/A_i - P/A)`, the absolute difference.  The two are
    equal when :math:`P/A = 1`, that is for fixed walls (the mapped domain keeps measure 1) and a density of unit
    mass; they differ for a free boundary, where :math:`A` changes.  The relative form makes the loss invariant to a
    uniform rescaling of the mapped domain, so a free-boundary model cannot lower it by inflating the domain.

    Parameters
    ----------
    density : Tensor, shape (B, P)
        Vertex densities.
    pre : Measures
        Precomputed measures and element densities.
    tangent : bool
        Continue the density below its floor along the tangent (see :func:`element_density`).
    """
    rho, w = element_density(ref, mapped, elements, density, pre=pre, tangent=tangent)
    err = F.smooth_l1_loss(rho, torch.ones_like(rho), reduction="none", beta=beta)
    return weighted_mean(err, w)


def beltrami_energy(ref: Tensor, mapped: Tensor, elements: Tensor) -> Tensor:
    r"""Beltrami energy :math:`\int_\Omega |\mu(u)|^2` (paper Eq. (3)); the DEQ regulariser."""
    return weighted_mean(beltrami_coefficient(ref, mapped, elements).abs() ** 2, signed_measures(ref, elements))


def fold_penalty(ref: Tensor, mapped: Tensor, elements: Tensor, threshold: float = 0.02, *,
                 pre: Measures = NONE) -> Tensor:
    r"""Fold penalty :math:`\int_\Omega \mathrm{relu}(\tau - \det J)` that keeps elements away from flipping.

    An addition of this package, not in the paper's losses.  Its weight and :math:`\tau` are
    :class:`rfmap.tasks.base.LossWeights` ``fold`` and ``fold_threshold``; the weight a shipped model was trained
    with is in its configuration, ``get_config(name).loss`` (:mod:`rfmap.training.config`), not necessarily the
    default.
    """
    ref_meas, meas = pre.measures(ref, mapped, elements)
    det = meas / ref_meas
    return weighted_mean(torch.relu(threshold - det), ref_meas)


def area_penalty(ref: Tensor, mapped: Tensor, elements: Tensor, *, pre: Measures = NONE) -> Tensor:
    r"""Free-boundary area constraint :math:`(|u(\Omega)| / |\Omega| - 1)^2`.

    An addition of this package, not in the paper's losses: on a free boundary it keeps the mapped domain's
    measure equal to the reference's.  Its weight is :class:`rfmap.tasks.base.LossWeights` ``area``.
    """
    ref_meas, meas = pre.measures(ref, mapped, elements)
    ratio = meas.sum(-1) / ref_meas.sum(-1)
    return ((ratio - 1) ** 2).mean()


def loss_integrands(ref: Tensor, mapped: Tensor, elements: Tensor, *, density: Tensor | None = None,
                    mu_target: Tensor | None = None, fold_threshold: float = 0.02, beta: float = 1.0) -> dict:
    r"""The loss terms element by element, for drawing them on the mesh.

    Each entry ``e`` of shape (B, m) is the integrand of one loss, so that
    ``weighted_mean(e, weight)`` equals that loss:

    * ``density`` (with ``density``): :math:`L(\tilde\rho_i - 1)`, :func:`density_loss`;
    * ``mu2``: :math:`|\mu_i|^2`, :func:`beltrami_energy`;
    * ``beltrami`` (with ``mu_target``): :math:`|\mu_i - \mu_{\text{in},i}|^2`, :func:`beltrami_loss` (2D);
    * ``fold``: :math:`\mathrm{relu}(\tau - \det J_i)`, :func:`fold_penalty`;
    * ``weight``: the reference measures.

    ``area`` (shape (B,)) is the free-boundary constraint :math:`(|u(\Omega)|/|\Omega| - 1)^2` of
    :func:`area_penalty`, a number per map rather than an integrand.
    """
    ref_meas = signed_measures(ref, elements)
    meas = signed_measures(mapped, elements)
    out = {"weight": ref_meas}
    if density is not None:
        rho, _ = element_density(ref, mapped, elements, density, pre=Measures(ref_meas, meas))
        out["density"] = F.smooth_l1_loss(rho, torch.ones_like(rho), reduction="none", beta=beta)
    if ref.shape[-1] == 2:
        mu = beltrami_coefficient(ref, mapped, elements)
        out["mu2"] = mu.abs() ** 2
        if mu_target is not None:
            out["beltrami"] = (mu - mu_target).abs() ** 2
    out["fold"] = torch.relu(fold_threshold - meas / ref_meas)
    out["area"] = (meas.sum(-1) / ref_meas.sum(-1) - 1) ** 2
    return out
