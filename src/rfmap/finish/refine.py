r"""Weight refinement (paper Sec. 4.3): a stretching vector :math:`\alpha \in \mathbb{R}^d` applied to the output.

The refined map is :math:`u_\alpha = x + \mathcal{B}(x) \odot (\alpha \odot \psi(x))`, which keeps the boundary
condition for every :math:`\alpha`.  :math:`\alpha^* = \arg\min_\alpha \mathcal{J}(u_\alpha)` with
:math:`\mathcal{J} = \mathcal{L}_{\text{geom}} + \lambda \mathcal{P}` is found by derivative-free alternating
golden-section searches over the components; the result never has a larger :math:`\mathcal{J}` than
:math:`\alpha = (1, \dots, 1)`.  :func:`density_objective` and :func:`beltrami_objective` build
:math:`\mathcal{J}` for the two tasks; :class:`RefineConfig` holds the search interval, :math:`\lambda` and the
tolerance used by :meth:`rfmap.Surrogate.map`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from ..core.geometry import beltrami_from_jacobian, edge_matrices, grid_measure_coefficients, signed_measures
from ..core.metrics import density_std, element_population
from ..nn.model import boundary_mask

__all__ = ["golden_section", "refine_alpha", "RefineResult", "RefineConfig", "REFINE", "density_objective",
           "beltrami_objective", "MeasurePolynomial"]


@dataclass(frozen=True)
class RefineConfig:
    r"""Settings of weight refinement.

    Attributes
    ----------
    bounds : (float, float)
        Search interval of every component of :math:`\alpha`.
    flip_weight : float
        :math:`\lambda`, the weight of the flipped-element fraction :math:`\mathcal{P}` in :math:`\mathcal{J}`.
    tol : float
        Interval length at which each golden-section search stops.
    """

    bounds: tuple[float, float] = (0.1, 3.0)
    flip_weight: float = 10.0
    tol: float = 1e-2


#: The refinement settings of :meth:`rfmap.Surrogate.map`.
REFINE = RefineConfig()

_INV_PHI = (math.sqrt(5) - 1) / 2


def golden_section(f: Callable[[float], float], a: float, b: float, *, tol: float = 1e-3,
                   max_iter: int = 60) -> tuple[float, float]:
    """Minimise a scalar function on ``[a, b]`` by golden-section search; returns ``(x, f(x))`` of the best
    point evaluated (so it also behaves sensibly on non-unimodal functions)."""
    if not a < b:
        raise ValueError(f"golden_section needs a < b, got [{a}, {b}]")
    c, d = b - _INV_PHI * (b - a), a + _INV_PHI * (b - a)
    fc, fd = f(c), f(d)
    best = min((fc, c), (fd, d))
    for _ in range(max_iter):
        if b - a < tol:
            break
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - _INV_PHI * (b - a)
            fc = f(c)
            best = min(best, (fc, c))
        else:
            a, c, fc = c, d, fd
            d = a + _INV_PHI * (b - a)
            fd = f(d)
            best = min(best, (fd, d))
    return best[1], best[0]


@dataclass
class RefineResult:
    """Outcome of :func:`refine_alpha`: the stretching vector, its objective, the objective at
    :math:`\\alpha = 1`, and the number of evaluations."""

    alpha: np.ndarray
    objective: float
    objective_start: float
    evaluations: int = 0
    history: list = field(default_factory=list)


def refine_alpha(objective: Callable[[np.ndarray], float], dim: int, *, bounds: tuple[float, float] = REFINE.bounds,
                 sweeps: int = 2, tol: float = 1e-3) -> RefineResult:
    r"""Alternating golden-section search for :math:`\alpha^* = \arg\min \mathcal{J}(\alpha)` over
    :math:`\alpha \in [\text{lo}, \text{hi}]^d`.

    Parameters
    ----------
    objective : callable
        :math:`\mathcal{J}(\alpha)` for ``alpha`` of shape (d,); may return ``inf`` for inadmissible maps.
    dim : int
    bounds : (float, float)
        Search interval of every component.
    sweeps : int
        Passes over the components.
    """
    count = 0

    def J(a):
        nonlocal count
        count += 1
        v = float(objective(np.asarray(a, dtype=np.float64)))
        return v if math.isfinite(v) else math.inf

    alpha = np.ones(dim)
    j0 = J(alpha)
    best, history = j0, [(alpha.copy(), j0)]
    # first a common (isotropic) stretch, then alternating per-component searches
    s, js = golden_section(lambda t: J(np.full(dim, t)), *bounds, tol=tol)
    s_scan, js_scan = _rescan(lambda t: J(np.full(dim, t)), bounds, tol, s, js)
    jagged = js_scan < js  # the scan found what the search missed: guard the per-component searches too
    s, js = s_scan, js_scan
    if js < best:
        alpha, best = np.full(dim, s), js
        history.append((alpha.copy(), best))
    for _ in range(sweeps):
        for i in range(dim):
            def along(t, i=i):
                a = alpha.copy()
                a[i] = t
                return J(a)

            t, jt = golden_section(along, *bounds, tol=tol)
            if jagged:
                t, jt = _rescan(along, bounds, tol, t, jt)
            if jt < best:
                alpha[i], best = t, jt
                history.append((alpha.copy(), best))
    return RefineResult(alpha=alpha, objective=best, objective_start=j0, evaluations=count, history=history)


#: points of the coarse geometric scan of the isotropic stretch that guards the golden-section search (book: Design
#: decisions)
SCAN_POINTS = 9


def _rescan(f: Callable[[float], float], bounds: tuple[float, float], tol: float, s: float,
            js: float) -> tuple[float, float]:
    r"""Guard a golden-section result ``(s, js)`` against a non-unimodal objective: scan ``f`` at
    :data:`SCAN_POINTS` geometrically spaced points of ``bounds`` and, where one beats ``js``, search again between
    its neighbours.  (Folded maps make :math:`\mathcal{J}` jagged: when the map at :math:`\alpha = 1` overshoots
    and folds, both first probes can land among folded maps and the search then never reaches the fold-free
    minimum below 1.)  Returns ``(s, js)`` unchanged when no scanned point is better."""
    ts = np.geomspace(bounds[0], bounds[1], SCAN_POINTS)
    vals = [f(float(t)) for t in ts]
    k = int(np.argmin(vals))
    if not vals[k] < js:
        return s, js
    t, jt = golden_section(f, float(ts[max(k - 1, 0)]), float(ts[min(k + 1, len(ts) - 1)]), tol=tol)
    return (t, jt) if jt < vals[k] else (float(ts[k]), vals[k])


def density_objective(ref, psi, elements, density, boundary, flip_weight: float = REFINE.flip_weight,
                      grid_n: int | None = None):
    r""":math:`\mathcal{J}(\alpha) = \mathrm{Std}(\tilde\rho_{\text{map}}) + \lambda\,\#\text{flipped}/m` for
    weight refinement of density maps.

    Parameters
    ----------
    ref, psi : Tensor, float64, shape (n, d)
        Reference vertices and the network's displacement at them.
    elements : LongTensor, shape (m, d+1)
    density : array, shape (n,)
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
    :func:`refine_alpha` searches, :class:`MeasurePolynomial`).  ``grid_n``: the mesh is the ``N``-grid
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
    """Evaluate the polynomial of :func:`_measure_coefficients` at ``alpha`` (d,): :math:`2^d - 1` multiply-adds."""
    total = None
    for subset, c in coeffs:
        w = float(np.prod([alpha[a] for a in subset])) if subset else 1.0
        total = c * w if total is None else total.add(c, alpha=w)
    return total


class MeasurePolynomial:
    r"""The element measures :math:`|T(\alpha)| = \sum_S c_S \prod_{a \in S} \alpha_a` of
    :func:`_measure_coefficients`, evaluated along the lines that :func:`refine_alpha` searches.

    Along a line the polynomial collapses: with every component but :math:`\alpha_i` fixed it is affine,
    :math:`A + \alpha_i B`, and on the diagonal :math:`\alpha = t \mathbf{1}` it is the cubic (in 3D)
    :math:`\sum_k t^k \sum_{|S| = k} c_S`.  A call whose ``alpha`` differs from the previous one in a single
    component (or lies on the diagonal) reuses the collapsed coefficients, so a golden-section step costs one
    multiply-add over the elements (or :math:`d`) instead of :math:`2^d - 1`; any other ``alpha`` is evaluated in
    full.  Values equal :func:`_measures_at` up to rounding.

    Parameters
    ----------
    coeffs : list of (tuple, Tensor)
        ``[(S, c_S)]`` of :func:`_measure_coefficients`, ``c_S`` of shape (m,).
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


def beltrami_objective(ref, psi, elements, mu_in, boundary, flip_weight: float = REFINE.flip_weight):
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
