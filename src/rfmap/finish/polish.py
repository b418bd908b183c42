r"""Neural warm starts: a surrogate's density-equalizing map finished by the flow-based solver.

The network gives a map :math:`u_0` of the ``N``-grid in milliseconds, but leaves a residual density
:math:`\tilde\rho_e = \text{population}_e / |u_0(e)|` whose variation is well above what the classical solvers
reach (chapter 11 of the book, *Fast classical maps and neural warm starts*, measures both).  :func:`polish_map`
removes it with :func:`rfmap.solvers.solve_flow` started from :math:`u_0`:

1. The residual density is evaluated *exactly* on the flow's raster: it is turned into the P1 vertex field whose
   element means are :math:`\tilde\rho_e` (``rfmap.solvers.residual.vertex_residual``), and every raster node is
   located in the mapped mesh and interpolated in its element (``rfmap.solvers.locate.rasterize_elements``).
   Binning element centroids on a coarse raster instead blurs :math:`\tilde\rho` at the scale of the error it should
   remove, and reading :math:`\tilde\rho_e` itself at the nodes shifts it by up to half an element; the finishing
   flow transports either error faithfully.
2. The finishing flow moves :math:`u_0`'s points: a vertex at :math:`u_0(x)` is carried by the flow that equalizes
   the residual density, so the result is the composition :math:`F \circ u_0`.  This needs nothing but the mapped
   positions and the raster, the element populations stay those of the reference mesh (so the metrics are the
   usual ones), and since :math:`F` keeps every element positively oriented (its steps are rejected otherwise) and
   :math:`u_0` is fold-free, so is the result.  Running the flow on the deformed mesh instead (solving in the
   reference frame for a map :math:`G` with :math:`u_0 \circ G` equalizing) would ask for a transport to the
   non-uniform target :math:`J_{u_0}`, which the density-equalizing flow does not solve.
3. No flow removes a residual that alternates from element to element (``rfmap.core.metrics.residual_scales``), and the
   network's map has such a part: its displacement carries pixel-scale ripples of the working grid, which the
   bilinear resampling onto a finer output grid turns into kinks.  ``Surrogate.map(polish=...)`` therefore smooths
   the displacement before the flow:

   a. on the working grid, by :func:`smooth_passes` passes of the binomial filter (:func:`smooth_displacement`,
      edges continued as :data:`SMOOTH_EDGES` says);
   b. where the output grid is not the working grid, after the resampling, by :data:`OUTPUT_PASSES` more passes on
      the output grid, where the resampling's kinks sit (:func:`smooth_grid_displacement`);
   c. the flow starts from the smoothed map when that map is fold-free, from the network's map otherwise; the
      report's ``"surrogate"`` stage is still the network's own map.
4. A poor network map is not worth finishing: when :math:`u_0` has folded elements, leaves the sea box, or removes
   less than half of the input's density variation (:data:`POOR`), the flow starts cold from the identity instead,
   and the report says so.  ``Surrogate.map(polish=...)`` then skips its bijectivity repair of a folded map, which
   the cold start would throw away (on a 3D map with hundreds of folded tetrahedra the repair can cost more than the
   whole flow).  The flow also starts cold when the warm flow stalls (more than :data:`WARM_STEPS` steps, or a step
   below :data:`rfmap.solvers.heun.STALL_DT`: a near-degenerate element of :math:`u_0` keeps cutting the fold-free
   step; the warm flow is not retried with a blurred density).
5. Even a good network map does not guarantee a better finish: on held-out fields the warm flow often ends above
   the cold flow, and nothing measured before the cold flow predicts which (:data:`GUARD`; the numbers are on the
   book's page *Design decisions*).  The guard therefore runs the cold flow after every warm one and keeps the map
   with the lower :math:`\mathrm{Std}(\tilde\rho_{\text{map}})`; the report says which (``kept``) and records both.
   The polished map is never worse than the flow-based solver's, at the price of that solver's time on top.

The report of :func:`polish_map` holds ``start`` (``"warm"`` or ``"cold"``), ``reason`` (why cold, else ``None``),
``smoothed`` (whether the warm flow started from the smoothed map), ``tol``, ``passes``, ``steps``, ``std_history``
(of the flow whose map is returned), ``kept`` (``"warm"`` or ``"cold"``: the flow whose map is returned), ``time``
(s, the polish only, both flows with the guard) and ``stages``: ``{"surrogate": ..., "polish": ...}``, each with
its ``time``, ``std_rho_map``, ``n_flipped`` and ``min_jacobian``, and with the guard after a warm flow ``"warm"``
and ``"cold"``, the two candidates (each with its own flow's ``time``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..core.geometry import grid_element_mean, grid_signed_measures
from ..core.metrics import density_std
from ..core.wording import counted
from ..solvers import flow
from ..solvers.flow import MARGIN

__all__ = ["GUARD", "POOR", "UNGUARDED", "WARM_STEPS", "SMOOTH_EDGES", "SMOOTH_PASSES", "SMOOTH_PASSES_FINER", "OUTPUT_PASSES",
           "PolishOptions", "polish_map", "polish_tolerance", "smooth_displacement", "smooth_grid_displacement", "smooth_passes"]

#: Most time steps of a warm flow before it is abandoned for a cold start.
WARM_STEPS = 500

#: The polish's guard (``PolishOptions.guard``, on by default): after a warm flow, run the cold flow as well and keep
#: the better map; the warm flow often loses, and nothing measured beforehand predicts when
#: (:doc:`Design decisions </book/design>`).
GUARD = True

#: A network map is *poor* when its Std(ρ̃_map) is above this fraction of the input's Std(ρ̃_orig).
POOR = 0.5


#: Binomial-filter passes of :func:`smooth_displacement` before a polish, per (dimension, boundary), when the output
#: grid is the working grid: the best polished / cold-flow Std(ρ̃_map) on validation fields
#: (:doc:`Design decisions </book/design>`).
SMOOTH_PASSES = {(2, "square"): 2, (3, "square"): 8, (2, "free"): 2, (3, "free"): 2}
#: Passes per boundary when the map is resampled onto a finer output grid (followed by :data:`OUTPUT_PASSES` on the
#: output grid), chosen as :data:`SMOOTH_PASSES` (:doc:`Design decisions </book/design>`).
SMOOTH_PASSES_FINER = {"square": 8, "free": 4}
#: Passes of the same filter on the output grid, after the smoothed displacement is resampled onto a finer one: the
#: multilinear resampling puts a kink at every working-grid line, which the working-grid passes cannot remove
#: (numbers: :doc:`Design decisions </book/design>`).
OUTPUT_PASSES = 2
#: How :func:`smooth_displacement` continues the displacement past the grid's edges, per boundary: a free boundary
#: moves with its edge values, which a replicated edge would flatten (:doc:`Design decisions </book/design>`).
SMOOTH_EDGES = {"square": "replicate", "free": "linear"}


def smooth_passes(dim: int, n: int, work_n: int, boundary: str = "square") -> int:
    """Passes of :func:`smooth_displacement` before polishing a ``dim``-D map of the ``n``-grid computed on a
    ``work_n``-grid (:data:`SMOOTH_PASSES`, :data:`SMOOTH_PASSES_FINER`)."""
    if (dim, boundary) not in SMOOTH_PASSES:
        raise ValueError(f"no smoothing passes for a {dim}D map with boundary {boundary!r}")
    return SMOOTH_PASSES_FINER[boundary] if n > work_n else SMOOTH_PASSES[dim, boundary]


def smooth_grid_displacement(psi_q, n: int, passes: int = OUTPUT_PASSES, edges: str = "replicate"):
    r""":func:`smooth_displacement` of a displacement given at the vertices of the ``N``-grid.

    Parameters
    ----------
    psi_q : tensor, shape (N**d, d)
        Displacement at the vertices of ``rfmap.core.mesh.grid_points(N, d)``.
    n : int
        Grid side ``N``.
    passes, edges
        As :func:`smooth_displacement`.

    Returns
    -------
    tensor, shape (N**d, d)
    """
    psi_q = torch.as_tensor(psi_q)
    d = psi_q.shape[1]
    if psi_q.shape[0] != n**d:
        raise ValueError(f"expected the {n ** d} vertices of the {n}-grid, got {psi_q.shape[0]}")
    grid = psi_q.T.reshape(1, d, *(n,) * d)
    return smooth_displacement(grid, passes, edges)[0].reshape(d, -1).T.contiguous()


def smooth_displacement(psi, passes: int = 2, edges: str = "replicate"):
    r"""The displacement :math:`\psi` on its working grid smoothed by ``passes`` of the binomial filter
    :math:`(1, 2, 1)/4` along every axis, shape (B, d, N, ..., N) -> same.

    Each pass damps the grid-scale (Nyquist) mode to zero and a mode of wavelength :math:`\lambda` grid spacings
    by :math:`\cos^2(\pi/\lambda)` per axis, so smooth parts of the map are kept (a wavelength of 16 spacings
    loses 4 % per pass) while the network's pixel-scale ripples, which no flow can remove, are gone.

    ``edges``: how the filter sees past the grid's edges (:data:`SMOOTH_EDGES`): ``"replicate"`` repeats the edge
    value, ``"linear"`` continues the last two values linearly (:math:`2\psi_0 - \psi_1`), so that a linear
    displacement is kept up to the edge.
    """
    import torch.nn.functional as F

    if edges not in ("replicate", "linear"):
        raise ValueError(f"edges must be 'replicate' or 'linear', got {edges!r}")
    out = torch.as_tensor(psi)
    for _ in range(int(passes)):
        for ax in range(2, out.dim()):
            x = out.movedim(ax, -1)
            shape = x.shape
            if edges == "linear":
                x = torch.cat([2 * x[..., :1] - x[..., 1:2], x, 2 * x[..., -1:] - x[..., -2:-1]], -1)
            else:
                x = F.pad(x.reshape(-1, 1, shape[-1]), (1, 1), mode="replicate").reshape(*shape[:-1], shape[-1] + 2)
            out = (0.25 * x[..., :-2] + 0.5 * x[..., 1:-1] + 0.25 * x[..., 2:]).movedim(-1, ax)
    return out.contiguous()


def polish_tolerance(polish) -> float | None:
    """The flow's stopping tolerance for ``Surrogate.map(polish=...)``: ``True`` gives the solver's default
    (``None``), a positive number is the tolerance on Std(ρ̃_map); ``ValueError`` otherwise."""
    if polish is True:
        return None
    if isinstance(polish, bool) or not isinstance(polish, (int, float, np.floating)) or not 0 < polish < np.inf:
        raise ValueError(f"polish must be True, False or a positive tolerance on Std(ρ̃_map), got {polish!r}")
    return float(polish)


class _Summary:
    """The density metrics of maps of the ``N``-grid mesh, as :func:`rfmap.core.metrics.compute_metrics` gives them
    (same kernels), without the 2D Beltrami coefficient that it also computes; the reference measures and
    element populations are computed once."""

    def __init__(self, ref: np.ndarray, density: np.ndarray, n: int):
        self.n, d = n, ref.shape[1]
        self.ref_meas = self._measures(ref)
        dens = torch.as_tensor(np.asarray(density, dtype=np.float64).reshape(-1))
        self.pop = grid_element_mean(dens[None], n, d)[0] * self.ref_meas
        self.std_orig = density_std(self.pop, self.ref_meas)

    def _measures(self, points: np.ndarray):
        return grid_signed_measures(torch.from_numpy(np.ascontiguousarray(points, dtype=np.float64))[None],
                                    self.n)[0]

    def __call__(self, mapped: np.ndarray, seconds: float) -> dict[str, Any]:
        meas = self._measures(mapped)
        det = meas / self.ref_meas
        out = {"time": seconds, "std_rho_map": density_std(self.pop, meas), "std_rho_orig": self.std_orig,
               "n_flipped": int((det <= 0).sum()), "min_jacobian": float(det.min())}
        return {k: (float("nan") if isinstance(v, float) and not math.isfinite(v) else v) for k, v in out.items()}


def _in_box(points: np.ndarray, boundary: str, n: int) -> bool:
    """Whether ``points`` lie in the flow's box: the unit square/cube, or for a free boundary the sea box
    :math:`[-L, 1 + L]^d` (``L``: ``solve_flow``'s default margin of the dimension, whole cells)."""
    pad = 0.0 if boundary == "square" else max(1, round(MARGIN[points.shape[1]] * (n - 1))) / (n - 1)
    return bool(points.min() >= -pad and points.max() <= 1 + pad)


def _fits(points: np.ndarray, elements: np.ndarray, boundary: str, n: int) -> bool:
    """Whether ``points`` (a map of the ``N``-grid mesh) can start a warm flow: finite, fold-free, and inside the
    flow's box (:func:`_in_box`)."""
    return bool(np.isfinite(points).all() and _in_box(points, boundary, n)
                and (grid_signed_measures(torch.from_numpy(np.ascontiguousarray(points))[None], n) > 0).all())


@dataclass(frozen=True)
class PolishOptions:
    r"""How :func:`polish_map` finishes a map.

    Attributes
    ----------
    tol : float, optional
        Stopping tolerance on :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` (default: the solver's).
    guard : bool
        After a warm flow, also run the cold flow from the identity and keep whichever map has the lower
        :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` (:data:`GUARD` explains why no cheaper test will do), so that
        the result is never worse than the flow-based solver alone; ``False`` returns the warm flow's map.
    poor : float
        Start cold when Std(ρ̃_map) of :math:`u_0` exceeds ``poor`` times Std(ρ̃_orig).
    progress : bool
        Progress bar of the flow.
    """

    tol: float | None = None
    guard: bool = GUARD
    poor: float = POOR
    progress: bool = False


def polish_map(result, *, n: int, boundary: str, options: PolishOptions = PolishOptions(), stage_time: float = 0.0,
               start: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    r"""Finish the map ``ref -> mapped`` of the ``N``-grid with the flow-based solver.

    Parameters
    ----------
    result : MapResult
        The network's map :math:`u_0` of the grid: ``ref_points`` and ``mapped_points`` (N**d, d), ``elements`` of
        :func:`rfmap.core.mesh.grid_mesh` ``(N, d)`` and ``field`` the vertex densities (N**d,, unit mass).
    n : int
        Grid side ``N``.
    boundary : {"square", "free"}
    options : PolishOptions
        Tolerance, guard, what counts as a poor start, progress bar.
    stage_time : float
        Seconds already spent computing :math:`u_0` (recorded in the report).
    start : ndarray, shape (N**d, d), optional
        The map the warm flow starts from instead of ``mapped`` when it is fold-free and stays in the box (a
        smoothed :math:`u_0`, see :mod:`rfmap.finish.polish`); whether and why ``mapped`` is good enough to start
        warm is still judged on ``mapped``.

    Returns
    -------
    (points, report)
        The polished positions (N**d, d) and a ``report`` dict: which start the flow took and why, which flow's
        map was kept, its passes, steps and time, and the metrics of the network's and the polished map
        (``report["stages"]``).  The description of :mod:`rfmap.finish.polish` lists its keys.
    """
    t0 = time.perf_counter()
    ref, mapped, elements, density = result.ref_points, result.mapped_points, result.elements, result.field
    tol, poor, guard, progress = options.tol, options.poor, options.guard, options.progress
    d = ref.shape[1]
    if boundary not in ("square", "free"):
        raise ValueError(f"polishing needs a density map with boundary 'square' or 'free', got {boundary!r}")
    summary = _Summary(ref, density, n)
    before = summary(mapped, stage_time)
    reason = None
    if before["n_flipped"]:
        reason = f"the network's map has {counted(before['n_flipped'], 'folded element')}"
    elif not before["std_rho_map"] <= poor * before["std_rho_orig"]:
        reason = (f"the network's map is poor: Std(ρ̃_map) {before['std_rho_map']:.3g} > {poor:g} x "
                  f"Std(ρ̃_orig) {before['std_rho_orig']:.3g}")
    elif boundary == "free" and not _in_box(mapped, boundary, n):
        reason = "the network's map leaves the sea box"
    kw = {} if tol is None else {"tol": tol}
    grid = np.asarray(density, dtype=np.float64).reshape((n,) * d)
    res = None
    smoothed = False
    if reason is None:
        first = mapped
        if start is not None and _fits(start, elements, boundary, n):
            first, smoothed = start, True
        try:  # a warm flow whose steps keep being cut (near-degenerate elements of u0) is abandoned early
            res = flow.solve_flow(grid, boundary=boundary, start=first, progress=progress, max_steps=WARM_STEPS,
                             stall_blurs=(), **kw)
        except RuntimeError as e:
            reason = f"the warm flow stalled ({e})"
            smoothed = False
    stages = {"surrogate": before}
    kept = "warm" if res is not None else "cold"
    if res is not None and guard:  # the cold flow too; keep the better map
        t1 = time.perf_counter()
        cold = flow.solve_flow(grid, boundary=boundary, progress=progress, **kw)
        stages["warm"] = summary(res.mapped_points, res.time)
        stages["cold"] = summary(cold.mapped_points, time.perf_counter() - t1)
        if stages["cold"]["std_rho_map"] < stages["warm"]["std_rho_map"]:
            res, kept = cold, "cold"
    if res is None:
        res = flow.solve_flow(grid, boundary=boundary, progress=progress, **kw)
    seconds = time.perf_counter() - t0
    stages["polish"] = summary(res.mapped_points, seconds)
    report = {"start": "cold" if reason else "warm", "reason": reason, "smoothed": smoothed, "tol": kw.get("tol"),
              "passes": res.info["passes"], "steps": res.info["steps"], "std_history": res.info["std_history"],
              "kept": kept, "guard": bool(guard), "time": seconds, "stages": stages}
    return res.mapped_points, report


#: The row of the hybrid's warm flow alone, as ``polish_map`` without its guard would have returned it, beside the
#: guarded polish (``rfmap.paper.benchmarks.compare_methods``).
UNGUARDED = "hybrid (no guard)"
