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
from .mesh import grid_size

__all__ = ["MapMetrics", "compute_metrics", "density_std", "element_population", "residual_scales"]


@dataclass
class MapMetrics:
    """Metrics of one map; entries that do not apply are ``None``.

    Attributes
    ----------
    std_rho_orig, std_rho_map : float
        :math:`\\mathrm{Std}(\\tilde\\rho)` on the reference and on the mapped mesh.
    min_jacobian : float
        Smallest element Jacobian determinant.
    n_flipped : int
        Elements with determinant :math:`\\le 0`.
    max_mu, mean_mu : float
        Max and mean of :math:`|\\mu|` over triangles (2D only).
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


def element_population(ref, elements, density) -> torch.Tensor:
    """Population of every element: mean vertex density times reference measure, shape (..., m)."""
    ref, dens = _t(ref), _t(density)
    el = torch.as_tensor(np.asarray(elements)).long()
    return dens[..., el].mean(-1) * signed_measures(ref, el)


def density_std(population: torch.Tensor, measure: torch.Tensor) -> float:
    r""":math:`\mathrm{Std}(\tilde\rho)` with :math:`\rho = \text{population}/\text{measure}`, ddof = 1."""
    rho = population / measure
    return float((rho / rho.mean()).std())


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
    ref, mapped : array, shape (n, d)
    elements : int array, shape (m, d+1)
    density : array, shape (n,), optional
        Vertex densities (preprocessed); enables the two ``std_rho`` metrics.
    exact_points : array, shape (n, d), optional
        A reference image of the vertices; enables ``mean_dd``.
    mu : complex array, shape (m,), optional
        Beltrami coefficient of the map (computed from the mesh when omitted in 2D).
    mu_ref : complex array, shape (m,), optional
        Reference Beltrami coefficient; enables ``mean_dmu``.
    """
    ref_t, map_t = _t(ref), _t(mapped)
    if ref_t.shape != map_t.shape or ref_t.dim() != 2:
        raise ValueError(f"ref and mapped points must both have shape (n, d); got {tuple(ref_t.shape)} and "
                         f"{tuple(map_t.shape)}")
    el = torch.as_tensor(np.asarray(elements)).long()
    d = ref_t.shape[1]
    out = MapMetrics(time=time)
    n_grid = grid_size(ref_t, el)
    if n_grid:  # the grid mesh: strided kernels instead of gathers (same values to rounding)
        ref_meas, map_meas = grid_signed_measures(torch.stack([ref_t, map_t]), n_grid)
    else:
        ref_meas, map_meas = signed_measures(ref_t, el), signed_measures(map_t, el)  # once each (large 3D meshes)
    det = map_meas / ref_meas  # as rfmap.geometry.jacobian_determinants
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


def residual_scales(ref, mapped, elements, density) -> dict[str, float]:
    r"""Split the residual density of a density-equalizing map into its element-scale and smooth parts.

    With :math:`r_e = \tilde\rho_e - 1` (the residual of :math:`\mathrm{Std}(\tilde\rho_{\text{map}})`), the smooth
    part is its average over the elements around each vertex, weighted by reference measure,
    :math:`\bar r_v = \sum_{e \ni v} |e|\, r_e / \sum_{e \ni v} |e|`, i.e. the residual seen at the scale of one
    grid cell.  A flow, a Poisson solve, or any smooth correction acts on :math:`\bar r`; what is left,
    :math:`r - \bar r`, alternates from element to element and is set by how the straight-sided elements
    approximate the curved image of the map (it shrinks like the grid spacing :math:`h`).

    Parameters
    ----------
    ref, mapped : array, shape (n, d)
    elements : array of int, shape (m, d+1)
    density : array, shape (n,)
        Vertex densities (any positive scale).

    Returns
    -------
    dict
        ``"std"``: :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` (ddof 1, as :func:`compute_metrics`);
        ``"smooth"``: the standard deviation of :math:`\bar r_v` over the vertices; ``"element_fraction"``: the
        fraction of the residual's variance not in the smooth part, :math:`1 - \mathrm{Var}(\bar r)/\mathrm{Var}(r)`.
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
    smooth = num / den
    std = float(r.std(ddof=1))
    sm = float(smooth.std())
    return {"std": std, "smooth": sm, "element_fraction": float(max(0.0, 1.0 - sm**2 / max(std**2, 1e-300)))}
