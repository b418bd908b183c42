r"""The weight refinement's objectives :math:`\mathcal{J}(\alpha)` (paper Sec. 4.3), one per task, and the element
measures of the stretched map as a polynomial in :math:`\alpha`.

The refined map is :math:`u_\alpha = x + \mathcal{B}(x) \odot (\alpha \odot \psi(x))`;
:math:`\mathcal{J} = \mathcal{L}_{\text{geom}} + \lambda \mathcal{P}` with :math:`\mathcal{P}` the fraction of
flipped elements.  :func:`density_objective` serves :class:`rfmap.tasks.density.DensityTask` and
:func:`beltrami_objective` :class:`rfmap.tasks.beltrami.BeltramiTask` (``Task.refine_objective``); the search for
:math:`\alpha^*` is :func:`rfmap.finish.refine.refine_alpha`.
"""
from __future__ import annotations

import numpy as np
import torch

from ..core.geometry import beltrami_from_jacobian, edge_matrices, grid_measure_coefficients, signed_measures
from ..core.metrics import density_std, element_population
from ..nn.model import boundary_mask

__all__ = ["FLIP_WEIGHT", "density_objective", "beltrami_objective", "MeasurePolynomial"]

#: :math:`\lambda`, the weight of the flipped-element fraction in :math:`\mathcal{J}`.
FLIP_WEIGHT = 10.0


def density_objective(ref, psi, elements, density, boundary, flip_weight: float = FLIP_WEIGHT,
                      grid_n: int | None = None):
    r""":math:`\mathcal{J}(\alpha) = \mathrm{Std}(\tilde\rho_{\text{map}}) + \lambda\,\#\text{flipped}/m` for
    weight refinement of density maps.

    Parameters
    ----------
    ref, psi : Tensor, float64, shape (P, d)
        Reference vertices and the network's displacement at them.
    elements : LongTensor, shape (m, d+1)
    density : array, shape (P,)
        Vertex densities (unit mass).
    boundary : str
        The boundary condition of :func:`rfmap.nn.apply_displacement`.
    flip_weight : float
        :math:`\lambda`.
    grid_n : int, optional
        Set when ``ref``/``elements`` are :func:`rfmap.core.mesh.grid_mesh` ``(N, d)``; the polynomial's
        coefficients are then expanded with the grid's edges as numbers
        (:func:`rfmap.core.geometry.grid_measure_coefficients`, same values, several times faster on 3D grids).
    """
    disp = boundary_mask(ref, boundary) * psi  # the refined map is ref + alpha * disp
    poly = MeasurePolynomial(_measure_coefficients(ref, disp, elements, grid_n))
    # c_{} is the measure of the reference mesh itself
    pop = element_population(ref, elements, np.asarray(density, dtype=np.float64), measures=poly.constant,
                             grid_n=grid_n)
    m = pop.shape[-1]
    meas, rho = torch.empty_like(pop), torch.empty_like(pop)  # buffers reused by every evaluation

    def J(alpha):
        poly(alpha, out=meas)
        flipped = 0.0 if float(meas.min()) > 0 else int(torch.count_nonzero(meas <= 0)) / m
        return density_std(pop, meas, out=rho) + flip_weight * flipped

    return J


def _measure_coefficients(ref, disp, elements, grid_n):
    r"""Signed measures of :math:`x + \alpha \odot D` as a polynomial in :math:`\alpha`.

    Scaling coordinate :math:`a` of the displacement scales row :math:`a` of every edge matrix, and the
    determinant is linear in each row, so :math:`|T(\alpha)| = \sum_{S \subseteq \{0..d-1\}} c_S
    \prod_{a \in S} \alpha_a`, where :math:`c_S` is the measure of the element whose coordinates :math:`a \in S`
    come from :math:`D` and the others from :math:`x`.  Returns ``[(S, c_S)]`` (``c_S`` of shape (m,)); one
    objective evaluation is then :math:`2^d` multiply-adds instead of a mesh pass (and one along the lines that
    :func:`.refine_alpha` searches, :class:`MeasurePolynomial`).  ``grid_n``: the mesh is the ``N``-grid
    (:func:`rfmap.core.geometry.grid_measure_coefficients`).
    """
    if grid_n:
        return grid_measure_coefficients(ref, disp, grid_n)
    d = ref.shape[-1]
    out = []
    for bits in range(2 ** d):
        subset = tuple(a for a in range(d) if bits >> a & 1)
        pts = torch.stack([disp[:, a] if a in subset else ref[:, a] for a in range(d)], -1)
        c = signed_measures(pts, elements)
        out.append((subset, c))
    return out


def _measures_at(coeffs, alpha) -> torch.Tensor:
    """Evaluate the polynomial of ``_measure_coefficients`` at ``alpha`` (d,): :math:`2^d - 1` multiply-adds."""
    total = None
    for subset, c in coeffs:
        w = float(np.prod([alpha[a] for a in subset])) if subset else 1.0
        total = c * w if total is None else total.add(c, alpha=w)
    return total


class MeasurePolynomial:
    r"""The element measures :math:`|T(\alpha)| = \sum_S c_S \prod_{a \in S} \alpha_a` (the polynomial of
    :func:`rfmap.core.geometry.grid_measure_coefficients`), evaluated along the lines that
    :func:`~rfmap.finish.refine.refine_alpha` searches.

    Along a line the polynomial collapses: with every component but :math:`\alpha_i` fixed it is affine,
    :math:`A + \alpha_i B`, and on the diagonal :math:`\alpha = t \mathbf{1}` it is the cubic (in 3D)
    :math:`\sum_k t^k \sum_{|S| = k} c_S`.  A call whose ``alpha`` differs from the previous one in a single
    component (or lies on the diagonal) reuses the collapsed coefficients, so a golden-section step costs one
    multiply-add over the elements (or :math:`d`) instead of :math:`2^d - 1`; any other ``alpha`` is evaluated in
    full.  Values equal those of the full evaluation up to rounding.

    Parameters
    ----------
    coeffs : list of (tuple, Tensor)
        ``[(S, c_S)]`` over the subsets ``S`` of the axes, as
        :func:`rfmap.core.geometry.grid_measure_coefficients` returns them, ``c_S`` of shape (m,).
    """

    def __init__(self, coeffs):
        self.coeffs = coeffs
        self.dim = max((len(s) for s, _ in coeffs), default=0)
        self.constant = next(c for s, c in coeffs if not s)
        self._powers = None  # diagonal: [sum_{|S| = k} c_S for k = 0..d]
        self._line = None  # (axis, the alpha it was collapsed at, A, B)
        self._last = None

    def __call__(self, alpha, out: torch.Tensor | None = None) -> torch.Tensor:
        """The measures (m,) at ``alpha`` (d,), written to ``out`` when given."""
        a = np.asarray(alpha, dtype=np.float64)
        last, self._last = self._last, a.copy()
        if np.all(a == a[0]):
            return self._diagonal(float(a[0]), out)
        if self._line is not None:
            axis, rest, A, B = self._line
            if np.array_equal(np.delete(a, axis), np.delete(rest, axis)):
                return torch.add(A, B, alpha=float(a[axis]), out=out)
        if last is not None and last.shape == a.shape and np.count_nonzero(a != last) == 1:
            axis = int(np.flatnonzero(a != last)[0])
            A, B = self._collapse(a, axis)
            self._line = (axis, a.copy(), A, B)
            return torch.add(A, B, alpha=float(a[axis]), out=out)
        total = _measures_at(self.coeffs, a)
        return total if out is None else out.copy_(total)

    def _diagonal(self, t: float, out: torch.Tensor | None) -> torch.Tensor:
        if self._powers is None:
            self._powers = [None] * (self.dim + 1)
            for s, c in self.coeffs:
                k = len(s)
                self._powers[k] = c.clone() if self._powers[k] is None else self._powers[k].add_(c)
        total = torch.add(self._powers[-2], self._powers[-1], alpha=t, out=out)  # Horner
        for p in reversed(self._powers[:-2]):
            total.mul_(t).add_(p)
        return total

    def _collapse(self, a: np.ndarray, axis: int) -> tuple[torch.Tensor, torch.Tensor]:
        """``(A, B)`` with :math:`|T| = A + a_{axis} B` for the other components of ``a`` fixed."""
        A = B = None
        for s, c in self.coeffs:
            w = float(np.prod([a[k] for k in s if k != axis]))
            if axis in s:
                B = c * w if B is None else B.add_(c, alpha=w)
            else:
                A = c * w if A is None else A.add_(c, alpha=w)
        return A, B


def beltrami_objective(ref, psi, elements, mu_in, boundary, flip_weight: float = FLIP_WEIGHT):
    r""":math:`\mathcal{J}(\alpha) = \mathrm{mean}|\mu(u_\alpha) - \mu_{\text{in}}| + \lambda\,\#\text{flipped}/m`
    for weight refinement of Beltrami reconstructions (``mu_in``: the input coefficient per triangle, shape (m,))."""
    mu_in_t = torch.as_tensor(np.asarray(mu_in))
    # the Jacobian of x + alpha * D is I + diag(alpha) K with K = E_D E_ref^{-1}: precomputed once
    disp = boundary_mask(ref, boundary) * psi
    K = edge_matrices(disp, elements) @ torch.linalg.inv(edge_matrices(ref, elements))  # (m, 2, 2)
    eye = torch.eye(2, dtype=K.dtype)

    def J(alpha):
        jac = eye + torch.as_tensor(alpha, dtype=K.dtype)[:, None] * K
        det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
        mu = beltrami_from_jacobian(jac)
        return float((mu - mu_in_t).abs().mean()) + flip_weight * float((det <= 0).double().mean())

    return J
