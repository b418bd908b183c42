r"""Quality metrics of a computed map, following the paper's table conventions.

* Population of an element = mean of its vertex densities times its reference measure (exact integral of the
  piecewise-linear density).
* :math:`\rho = \text{population} / \text{measure}` on the reference (``orig``) or mapped (``map``) mesh,
  :math:`\tilde\rho = \rho / \operatorname{mean}(\rho)`; ``Std`` uses ``ddof = 1``.
* Jacobian of an element = determinant of its affine map; flipped when :math:`\le 0`.
* :math:`|\mu|` per triangle (paper Eq. (1)); :math:`|\Delta d|` per vertex (Euclidean); :math:`|\Delta\mu|` per
  triangle.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields

import numpy as np
import torch

from .geometry import beltrami_coefficient, grid_element_mean, grid_signed_measures, signed_measures
from .mesh import grid_points, grid_size

__all__ = ["MapMetrics", "block_std", "compute_metrics", "density_std", "element_population", "residual_parts",
           "residual_scales", "rotational_share"]


@dataclass
class MapMetrics:
    """Metrics of one map; entries that do not apply are ``None``.

    Attributes
    ----------
    std_rho_orig : float
        :math:`\\mathrm{Std}(\\tilde\\rho)` on the reference mesh: how far the input is from uniform.
    std_rho_map : float
        :math:`\\mathrm{Std}(\\tilde\\rho)` on the mapped mesh: the spread the map leaves (0 for a perfect
        density-equalizing map).
    min_jacobian : float
        Smallest element Jacobian determinant.
    n_flipped : int
        Elements with determinant :math:`\\le 0`.
    max_mu : float
        Largest :math:`|\\mu|` over the triangles (2D only).
    mean_mu : float
        Mean of :math:`|\\mu|` over the triangles (2D only).
    mean_dd : float
        Mean vertex distance to a reference map.
    mean_dmu : float
        Mean :math:`|\\mu - \\mu_{\\text{ref}}|` over triangles.
    time : float
        Seconds taken to compute the map.
    """

    std_rho_orig: float | None = None
    std_rho_map: float | None = None
    min_jacobian: float | None = None
    n_flipped: int | None = None
    max_mu: float | None = None
    mean_mu: float | None = None
    mean_dd: float | None = None
    mean_dmu: float | None = None
    time: float | None = None

    def to_dict(self, drop_none: bool = True) -> dict:
        d = asdict(self)
        return {k: v for k, v in d.items() if v is not None} if drop_none else d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @staticmethod
    def columns() -> list[str]:
        return [f.name for f in fields(MapMetrics)]

    def row(self, keys: list[str] | None = None, fmt: str = "{:.6g}") -> str:
        """One Markdown table row of the chosen (default: non-empty) metrics."""
        keys = keys or list(self.to_dict())
        vals = [getattr(self, k) for k in keys]
        return "| " + " | ".join("—" if v is None else (str(v) if isinstance(v, int) else fmt.format(v))
                                  for v in vals) + " |"

    def __str__(self) -> str:
        return ", ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.to_dict().items())


def _t(x) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x, dtype=np.float64)) if not isinstance(x, torch.Tensor) else x.double()


def element_population(ref, elements, density, measures: torch.Tensor | None = None,
                       grid_n: int | None = None) -> torch.Tensor:
    """Population of every element: mean vertex density times reference measure, shape (..., m).  ``measures``:
    the reference measures (m,) when the caller has them already; ``grid_n``: the mesh is
    :func:`grid_mesh(N, d) <rfmap.core.mesh.grid_mesh>` and ``density`` has shape (N**d,) (the means then come from
    strided views, :func:`rfmap.core.geometry.grid_element_mean`)."""
    ref, dens = _t(ref), _t(density)
    el = torch.as_tensor(np.asarray(elements)).long()
    if grid_n and dens.ndim == 1:
        mean = grid_element_mean(dens[None], grid_n, ref.shape[-1])[0]
    else:
        mean = dens[..., el].mean(-1)
    return mean * (signed_measures(ref, el) if measures is None else measures)


def density_std(population: torch.Tensor, measure: torch.Tensor, out: torch.Tensor | None = None) -> float:
    r""":math:`\mathrm{Std}(\tilde\rho)` with :math:`\rho = \text{population}/\text{measure}` and
    :math:`\tilde\rho = \rho / \bar\rho`, ddof = 1.

    Computed as :math:`\mathrm{Std}(\rho) / |\bar\rho|` from the sums :math:`\sum \rho` and
    :math:`\sum \rho^2` (one pass each, several times faster than ``torch.std_mean`` on a CPU); in float64 the
    cancellation costs a relative error of about :math:`10^{-16}\,\bar\rho^2/\mathrm{Var}(\rho)`, far below the digits
    reported.  ``out``: a buffer of the shape of ``population`` for :math:`\rho` (saves an allocation when called
    many times).  Shapes: population, measure (m,) -> float."""
    rho = torch.div(population, measure, out=out).reshape(-1)
    m = rho.numel()
    s1, s2 = float(rho.sum()), float(torch.dot(rho, rho))
    mean = s1 / m
    var = max(s2 - s1 * mean, 0.0) / (m - 1)
    return math.sqrt(var) / abs(mean)


def block_std(result, cells: int) -> float:
    r""":math:`\mathrm{Std}(\tilde\rho)` of a density map of a grid over blocks of ``cells`` x ``cells`` grid cells.

    Each block pools its elements: its density is the sum of their populations over the sum of their mapped
    measures.  With ``cells = 1`` the blocks are the grid's squares (cubes); a map of the ``(2N - 1)``-grid with
    ``cells = 2`` is thus measured on the squares of the ``N``-grid, where it can be set beside a map of that grid.

    Parameters
    ----------
    result : rfmap.core.result.MapResult
        A density map of a regular grid of the unit square or cube (``ref_points`` on the lattice).
    cells : int
        Grid cells per block and axis; it must divide ``N - 1``.

    Returns
    -------
    float
        The sample standard deviation (ddof = 1) of the block densities over their mean.
    """
    ref, el = np.asarray(result.ref_points), np.asarray(result.elements)
    d = ref.shape[1]
    n = round(len(ref) ** (1 / d))
    if (n - 1) % cells:
        raise ValueError(f"{cells} cells per block do not divide the {n - 1} cells of the grid")
    pop = element_population(ref, el, result.field).numpy()
    meas = signed_measures(_t(result.mapped_points), torch.as_tensor(el).long()).numpy()
    per_axis = (n - 1) // cells
    corner = np.floor(ref[el].mean(1) * (n - 1) / cells).astype(int).clip(0, per_axis - 1)
    block = np.ravel_multi_index(tuple(corner.T), (per_axis,) * d)
    rho = np.bincount(block, pop, per_axis**d) / np.bincount(block, meas, per_axis**d)
    return float(rho.std(ddof=1) / rho.mean())


def compute_metrics(
    ref,
    mapped,
    elements,
    *,
    density=None,
    exact_points=None,
    mu=None,
    mu_ref=None,
    time: float | None = None,
) -> MapMetrics:
    """All metrics that the given inputs allow.

    Parameters
    ----------
    ref, mapped : array, shape (P, d)
    elements : int array, shape (m, d+1)
    density : array, shape (P,), optional
        Vertex densities (preprocessed); enables the two ``std_rho`` metrics.
    exact_points : array, shape (P, d), optional
        A reference image of the vertices; enables ``mean_dd``.
    mu : complex array, shape (m,), optional
        Beltrami coefficient of the map (computed from the mesh when omitted in 2D).
    mu_ref : complex array, shape (m,), optional
        Reference Beltrami coefficient; enables ``mean_dmu``.
    """
    ref_t, map_t = _t(ref), _t(mapped)
    if ref_t.shape != map_t.shape or ref_t.dim() != 2:
        raise ValueError(f"ref and mapped points must both have shape (P, d); got {tuple(ref_t.shape)} and "
                         f"{tuple(map_t.shape)}")
    el = torch.as_tensor(np.asarray(elements)).long()
    d = ref_t.shape[1]
    out = MapMetrics(time=time)
    n_grid = grid_size(ref_t, el)
    if n_grid:  # the grid mesh: strided kernels instead of gathers (same values to rounding)
        ref_meas, map_meas = grid_signed_measures(torch.stack([ref_t, map_t]), n_grid)
    else:
        ref_meas, map_meas = signed_measures(ref_t, el), signed_measures(map_t, el)  # once each (large 3D meshes)
    det = map_meas / ref_meas  # as rfmap.core.geometry.jacobian_determinants
    out.min_jacobian = float(det.min())
    out.n_flipped = int((det <= 0).sum())
    if density is not None:
        dens = _t(density).reshape(-1)
        if dens.shape[0] != ref_t.shape[0]:
            raise ValueError(f"density has {dens.shape[0]} values for {ref_t.shape[0]} vertices")
        mean = grid_element_mean(dens[None], n_grid, d)[0] if n_grid else dens[..., el].mean(-1)
        pop = mean * ref_meas  # element_population
        out.std_rho_orig = density_std(pop, ref_meas)
        out.std_rho_map = density_std(pop, map_meas)
    if d == 2:
        m = beltrami_coefficient(ref_t, map_t, el) if mu is None else torch.as_tensor(np.asarray(mu))
        a = m.abs()
        out.max_mu, out.mean_mu = float(a.max()), float(a.mean())
        if mu_ref is not None:
            out.mean_dmu = float((m - torch.as_tensor(np.asarray(mu_ref))).abs().mean())
    if exact_points is not None:
        out.mean_dd = float((map_t - _t(exact_points)).norm(dim=-1).mean())
    for k, v in out.to_dict().items():
        if isinstance(v, float) and not math.isfinite(v):
            setattr(out, k, float("nan"))
    return out


def residual_parts(ref, mapped, elements, density) -> tuple[np.ndarray, np.ndarray]:
    r"""The residual density of a density-equalizing map and its smooth part (see :func:`residual_scales`).

    Parameters
    ----------
    ref, mapped : array, shape (P, d)
    elements : array of int, shape (m, d+1)
    density : array, shape (P,)
        Vertex densities (any positive scale).

    Returns
    -------
    r : ndarray, shape (m,)
        :math:`r_e = \tilde\rho_e - 1` per element, :math:`\tilde\rho` on the mapped mesh.
    smooth : ndarray, shape (P,)
        :math:`\bar r_v = \sum_{e \ni v} |e|\, r_e / \sum_{e \ni v} |e|` per vertex, :math:`|e|` the reference
        measure.

    Raises
    ------
    ValueError
        When the map has folded elements (the residual density is not defined).
    """
    ref_t, el = _t(ref), torch.as_tensor(np.asarray(elements), dtype=torch.long)
    pop = element_population(ref_t, el, _t(density))
    meas_ref = signed_measures(ref_t, el)
    meas = signed_measures(_t(mapped), el)
    if not bool((meas > 0).all()):
        raise ValueError("the map has folded elements; its residual density is not defined")
    rho = pop / meas
    r = (rho / rho.mean() - 1.0).numpy()
    w = meas_ref.numpy()
    k = el.shape[1]
    num = np.bincount(el.reshape(-1).numpy(), np.repeat(r * w, k), minlength=ref_t.shape[0])
    den = np.bincount(el.reshape(-1).numpy(), np.repeat(w, k), minlength=ref_t.shape[0])
    return r, num / den


def residual_scales(ref, mapped, elements, density) -> dict[str, float]:
    r"""Split the residual density of a density-equalizing map into its element-scale and smooth parts.

    With :math:`r_e = \tilde\rho_e - 1` (the residual of :math:`\mathrm{Std}(\tilde\rho_{\text{map}})`), the smooth
    part is its average over the elements around each vertex, weighted by reference measure,
    :math:`\bar r_v = \sum_{e \ni v} |e|\, r_e / \sum_{e \ni v} |e|`, i.e. the residual seen at the scale of one
    grid cell (:func:`residual_parts` returns both).  A flow, a Poisson solve, or any smooth correction acts on
    :math:`\bar r`; what is left, :math:`r - \bar r`, alternates from element to element and is set by how the
    straight-sided elements approximate the curved image of the map (it shrinks like the grid spacing :math:`h`).

    Parameters
    ----------
    ref, mapped, elements, density
        As for :func:`residual_parts`.

    Returns
    -------
    dict
        ``"std"``: :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` (ddof 1, as :func:`compute_metrics`);
        ``"smooth"``: the standard deviation of :math:`\bar r_v` over the vertices; ``"element_fraction"``: the
        fraction of the residual's variance not in the smooth part, :math:`1 - \mathrm{Var}(\bar r)/\mathrm{Var}(r)`.
    """
    r, smooth = residual_parts(ref, mapped, elements, density)
    std = float(r.std(ddof=1))
    sm = float(smooth.std())
    return {"std": std, "smooth": sm, "element_fraction": float(max(0.0, 1.0 - sm**2 / max(std**2, 1e-300)))}


def _wall_coefficients(values: np.ndarray, axis: int) -> np.ndarray:
    r"""Amplitudes of the trigonometric interpolant of nodal values ``values`` (shape (N,)*d) that vanish on the two
    walls normal to ``axis``: sines :math:`\sin(\pi k x)`, :math:`1 \le k \le N-2`, along ``axis`` and cosines
    :math:`\cos(\pi k x)`, :math:`0 \le k \le N-1`, along the other axes, so that
    ``values`` :math:`= \sum_k c_k \prod_i \varphi_{k_i}(x_i)` at the nodes :math:`x = j/(N-1)`.  Shape (N,)*d,
    zero at :math:`k_{\text{axis}} \in \{0, N-1\}` (no such sine)."""
    from scipy.fft import dct, dst

    n = values.shape[0]
    inner = np.take(values, np.arange(1, n - 1), axis=axis)
    c = dst(inner, type=1, axis=axis) / (n - 1)  # unnormalized DST-I over the N-2 interior nodes
    e = np.full(n, 2.0)
    e[[0, -1]] = 1.0
    for ax in range(values.ndim):
        if ax != axis:  # cosine amplitudes: DCT-I / (2 (N-1)), doubled inside
            shape = [1] * values.ndim
            shape[ax] = n
            c = dct(c, type=1, axis=ax) * (e / (2.0 * (n - 1))).reshape(shape)
    pad = [(0, 0)] * values.ndim
    pad[axis] = (1, 1)
    return np.pad(c, pad)


def rotational_share(ref, mapped) -> float:
    r"""The share of a map's displacement that is not a gradient: :math:`\|\psi - P\psi\| / \|\psi\|`.

    What it is for: two density-equalizing maps of the same density can differ by a rotational part of their
    displacements, which this share measures (0 for a displacement that is a gradient); it tells the maps of
    methods that move along gradients, such as the diffusion method, from those that do not.

    The displacement :math:`\psi = u - \mathrm{id}` of a map of the ``N``-grid of the unit square or cube whose
    boundary vertices stay on their walls (``boundary="square"``) is expanded, component :math:`i` in sines along
    axis :math:`i` and cosines along the others (the series that vanish on the walls normal to that axis).  A
    gradient :math:`\nabla\chi` of :math:`\chi = \sum_k \chi_k \prod_i \cos(\pi k_i x_i)` (no flux through the walls)
    has, mode by mode, coefficients parallel to :math:`k`; :math:`P` projects every mode's coefficient vector onto
    :math:`k`, which is the :math:`L^2` orthogonal (Helmholtz) projection of the interpolant onto such gradients.
    The norms are the :math:`L^2` norms of the interpolants (Parseval).

    A density-equalizing map must have :math:`\det Du = \rho_0/\bar\rho`, which fixes the map only up to such
    rotational parts.  The diffusion flow's velocity :math:`-\nabla \log\rho_t` is a gradient at every instant;
    the flow-based solver's :math:`-\nabla\phi/\rho_t` is not where :math:`\nabla\rho_t` is not parallel to
    :math:`\nabla\phi`.

    Parameters
    ----------
    ref : array, shape (N**d, d)
        The vertices of ``rfmap.core.mesh.grid_points(N, d)``, d = 2 or 3.
    mapped : array, shape (N**d, d)
        Their images; every boundary vertex on its walls (to 1e-9).

    Returns
    -------
    float
        In [0, 1]: 0 for a gradient displacement (and for the identity), 1 for a divergence-free one.

    Notes
    -----
    The highest cosine :math:`\cos(\pi (N-1) x)` has a derivative that vanishes at every node, so along an axis
    where a mode is that high its wavenumber counts as 0: the nodal samples of every such gradient are kept whole.
    """
    ref = np.asarray(ref, dtype=np.float64)
    mapped = np.asarray(mapped, dtype=np.float64)
    if ref.ndim != 2 or ref.shape[1] not in (2, 3) or mapped.shape != ref.shape:
        raise ValueError(f"ref and mapped must both have shape (N**d, d), d = 2 or 3; got {ref.shape} and "
                         f"{mapped.shape}")
    d = ref.shape[1]
    n = int(round(ref.shape[0] ** (1.0 / d)))
    if n < 3 or n**d != ref.shape[0] or not np.allclose(ref, grid_points(n, d), rtol=0.0, atol=1e-12):
        raise ValueError("ref must be the vertices of rfmap.core.mesh.grid_points(N, d) with N >= 3")
    if not np.isfinite(mapped).all():
        raise ValueError("the map has non-finite points")
    psi = (mapped - ref).T.reshape(d, *(n,) * d)
    for i in range(d):
        wall = np.take(psi[i], [0, n - 1], axis=i)
        if np.abs(wall).max() > 1e-9:
            raise ValueError("the boundary vertices must stay on their walls (a map with boundary 'square'); "
                             f"the largest normal displacement on a wall is {np.abs(wall).max():.3g}")
    coef = np.stack([_wall_coefficients(psi[i], i) for i in range(d)])
    k = np.arange(n, dtype=np.float64)
    k[-1] = 0.0  # the highest cosine's derivative vanishes at the nodes
    ks = np.stack(np.meshgrid(*([k] * d), indexing="ij"))  # (d, N, ..., N)
    k2 = (ks**2).sum(0)
    dot = (ks * coef).sum(0)
    grad = ks * np.divide(dot, k2, out=np.zeros_like(dot), where=k2 > 0)
    w1 = np.full(n, 0.5)
    w1[0] = 1.0  # integral of the squared cosine (or sine) over [0, 1]
    weight = np.ones((n,) * d)
    for ax in range(d):
        shape = [1] * d
        shape[ax] = n
        weight = weight * w1.reshape(shape)
    total = float((weight * (coef**2).sum(0)).sum())
    if total == 0.0:
        return 0.0
    return float(np.sqrt((weight * ((coef - grad) ** 2).sum(0)).sum() / total))
