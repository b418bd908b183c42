r"""Diffusion-based density-equalizing maps (Gastner & Newman 2004) on the unit square and cube.

The density :math:`\rho(x, 0)` given at the vertices of the ``N``-grid is diffused with no-flux walls on the box
:math:`[0,1]^d`,

.. math:: \partial_t \rho = \Delta \rho, \qquad \partial_n \rho = 0 \text{ on the walls},

and every vertex is carried by the velocity field :math:`v = -\nabla\rho / \rho`.  The continuity equation
:math:`\partial_t\rho + \nabla\cdot(\rho v) = 0` holds, so the mass of every material region is conserved while the
density tends to its mean; the vertex positions at :math:`t \to \infty` define the density-equalizing map.

Numerical method:

1. **Initial density.**  The piecewise-linear (P1) interpolant of the vertex values on the simplicial mesh of
   :func:`rfmap.core.mesh.grid_mesh` -- the density whose element integrals :mod:`rfmap.core.metrics` uses -- is sampled on a
   grid ``refine`` times finer, with :math:`M = \text{refine}\,(N-1) + 1` points per side (:func:`.p1_upsample`).
   Starting from the P1 rather than the cosine interpolant of the vertex values avoids the oscillations that a sum
   of cosines makes beside a steep feature (Gibbs ringing), which would be carried into the map.
2. **Exact diffusion.**  The diffusion equation is solved exactly in the cosine basis of the box,

   .. math::

       \rho(x, t) = \sum_{k \in \{0..M-1\}^d} a_k \prod_{i=1}^d \cos(\pi k_i x_i)\; e^{-\pi^2 |k|^2 t},

   with :math:`a_k` from a type-I discrete cosine transform, so that :math:`\rho(\cdot, 0)` interpolates the
   fine-grid values.
3. **Velocity.**  :math:`\rho` and :math:`\nabla\rho` are evaluated on the fine grid by separable products with
   cosine / sine tables (dense matrix products, :math:`O(M^{d} K)` per evaluation with :math:`K \le M` the modes
   not yet decayed below 1e-17), :math:`v = -\nabla\rho/\rho` is formed there and interpolated multilinearly at the
   current vertex positions.  Steps 2 and 3 are the diffusion's heat field,
   :class:`rfmap.solvers.heatfield.HeatField` (numpy), which the cartogram diffusion evaluates too, on its own
   raster and dividing at the points.
4. **Time integration.**  :math:`\dot x = v(x, t)` is integrated with the embedded Bogacki–Shampine 3(2) pair
   (:func:`rfmap.solvers.bs32.bs32_flow`: 3 velocity evaluations per step, since the last of a step is the first
   of the next), with the local error per step bounded by ``rtol`` times the grid spacing, until the remaining
   displacement, estimated as :math:`\max|v| / \lambda_1` with :math:`\lambda_1 = \pi^2` the decay rate of the
   slowest mode, falls below ``tol_end`` times the grid spacing.
   The flow's driver, this stopping rule and the blurred starts below are the cartogram diffusion's too
   (:mod:`rfmap.solvers.heatflow`); its integrator is this solver's own (the cartogram passes take Heun steps).
5. **Fold guard.**  A step after which an element of the mesh would be turned over is rejected and retried with half
   the step.  The exact flow is a diffeomorphism, but its image of a straight-sided element is not straight, and
   where the density varies faster than the mesh resolves (a sharp peak beside a near-empty region) the vertex
   trajectories cross however short the step.  After ``FOLD_STOP`` such rejections the flow is redone with the
   vertices starting to move at :math:`t_0 = (\sigma h)^2/2`, when diffusion has blurred the density over
   :math:`\sigma` = 1, 2, then 4 vertex spacings (``FOLD_BLURS``; recorded in ``info["fold_blurs"]``), as cartogram
   programs blur sharp inputs.

Boundary conditions:

* ``"square"`` (the unit cube in 3D): the box is the unit square itself.  The sine factor of the normal derivative
  vanishes on the walls, so boundary vertices slide along their walls; they are re-projected onto their walls after
  every step (round-off only) and corners stay fixed.  The total area (volume) is exactly conserved.
* ``"free"``: the unit square sits in a larger box :math:`[-L, 1+L]^d` (same grid spacing, ``margin`` :math:`= L`)
  filled with a "sea" of (nearly) the mean density; all mesh vertices move and the boundary deforms.  The sea level
  is chosen so that the exact flow conserves the domain's area (see ``rfmap.solvers.raster.balanced_sea``); the
  measured area of the mapped mesh is then 1 up to a discretisation error of order :math:`h` with a small
  constant.

References
----------
M. T. Gastner, M. E. J. Newman, "Diffusion-based method for producing density-equalizing maps",
Proc. Natl. Acad. Sci. USA 101(20), 7499–7504 (2004).
"""
from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass, replace

import numpy as np

from ..core.device import torch_threads
from ..core.inputs import is_uniform
from ..core.geometry import grid_min_measure
from ..core.mesh import grid_mesh
from ..core.result import MapResult
from .bs32 import BS32Options
from .cosine import ScipyTransforms, fft_workers
from .heatfield import HeatField, blas_threads
from .heatflow import SLOWEST_RATE, Settling, blur_start, diffuse
from .raster import DEM_BOUNDARIES, balanced_sea, check_grid_density, p1_upsample
from .spectral import cosine_coefficients

__all__ = [
    "solve_diffusion",
    "DiffusionOptions",
    "cosine_coefficients",
    "p1_upsample",
    "DEM_BOUNDARIES",
]


#: Fold rejections after which the diffusion flow is stopped at its last fold-free state.
FOLD_STOP = 60


#: Blur widths (vertex spacings) of the retries of a flow that keeps folding (``solve_diffusion(fold_guard=True)``).
FOLD_BLURS = (1.0, 2.0, 4.0)


class _Progress:
    """A ``tqdm`` bar over simulated time, its end re-estimated as the flow slows down (an ``on_step`` of
    :func:`rfmap.solvers.heatflow.diffuse`, reading the speed of its :class:`rfmap.solvers.heatflow.Settling`)."""

    def __init__(self, label: str, settling: Settling):
        self.label, self.settling, self.bar = label, settling, None

    def __call__(self, t: float) -> None:
        if self.bar is None:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=round(self.settling.remaining(t), 4), desc=self.label, leave=False,
                            bar_format="{l_bar}{bar}| t={n:.4f}/{total:.4f} [{elapsed}<{remaining}]")
        self.bar.total = round(self.settling.remaining(t), 4)
        self.bar.n = round(t, 4)
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.total = self.bar.n
            self.bar.refresh()
            self.bar.close()


def _flow(field: HeatField, y: np.ndarray, project, stepping: BS32Options, tol: float, turned_over,
          label: str | None) -> tuple[np.ndarray, dict]:
    r"""The vertices ``y`` carried by the diffusion flow (:func:`rfmap.solvers.heatflow.diffuse`, Bogacki--Shampine
    steps) until the remaining displacement is at most ``tol`` (box units), with a progress bar when ``label`` is
    given; the info of :func:`solve_diffusion` (``iterations``, ..., ``fold_stop``)."""
    settling = Settling(tol)
    bar = _Progress(label, settling) if label is not None else None
    try:
        y, out = diffuse(field, y, project, stepping, settling, turned_over, on_step=bar)
    finally:
        if bar is not None:
            bar.close()
    keys = ("rejected", "evaluations", "t_end", "residual_velocity", "fold_rejections", "fold_stop")
    return y, {"iterations": out["steps"], **{k: out[k] for k in keys}}


@dataclass(frozen=True)
class DiffusionOptions:
    r"""The options of the diffusion solver (:func:`solve_diffusion`)
    with their defaults: a call names only those that differ.

    Attributes
    ----------
    boundary : {"square", "free"}
        ``"square"``: the walls of the unit square/cube are fixed, boundary vertices slide along them, corners stay.
        ``"free"``: the domain floats in a sea of its mean density inside :math:`[-L, 1+L]^d`; all vertices move.
    rtol : float
        Bound on the local error of one time step (max over vertices of the Euclidean error estimate), relative to
        the grid spacing :math:`h`.  The default 1e-2 keeps the final positions within about :math:`0.01\,h` of a
        converged integration.
    tol_end : float
        Stop when the estimated remaining displacement :math:`\max|v|/\pi^2` (box units) is below
        ``tol_end`` times the grid spacing.
    refine : int
        The initial density is the piecewise-linear interpolant sampled on a grid ``refine`` times finer than the
        vertex grid (``M = refine (N_box - 1) + 1`` points per side, ``N_box = N`` for ``"square"``); its cosine
        interpolant is diffused and :math:`v` is evaluated and interpolated on that grid.  ``refine=1`` uses the
        cosine interpolant of the vertex values.
    margin : float
        Sea width :math:`L` for ``boundary="free"``, rounded to whole grid cells (at least one).
    max_steps : int
        Maximum number of (accepted + rejected) time steps; ``RuntimeError`` if exceeded.
    num_threads : int, optional
        Threads of the solve (restored afterwards): the heat field's matrix products
        (:func:`rfmap.solvers.heatfield.blas_threads`) and transform, and torch's fold check.  Default: 1 in 2D (the
        products are too small to gain from threads, which only add synchronisation cost), torch's setting in 3D.
    fold_guard : bool
        Keep the mesh fold-free (default): a time step that would turn an element over is rejected and retried
        shorter.  The exact flow never folds, but its piecewise-linear image on the mesh can, where the density
        changes faster than the mesh resolves (near-zero regions beside sharp peaks); if the flow keeps folding
        (``FOLD_STOP`` rejections) it is redone from a blurred start (``FOLD_BLURS``, see
        :mod:`rfmap.solvers.diffusion`), and if it still folds with the widest blur the integration stops at its
        last fold-free state (``info["fold_stop"]`` gives that time).  ``False`` integrates the vertex trajectories
        regardless.
    """

    boundary: str = "square"
    rtol: float = 1e-2
    tol_end: float = 1e-4
    refine: int = 2
    margin: float = 0.5
    max_steps: int = 10_000
    num_threads: int | None = None
    fold_guard: bool = True

    def check(self) -> None:
        """``ValueError`` for an unknown boundary or a non-positive ``rtol``/``tol_end``/``margin``/``refine``."""
        if self.boundary not in DEM_BOUNDARIES:
            raise ValueError(f"unknown boundary {self.boundary!r} for the diffusion solver; choose one of "
                             f"{DEM_BOUNDARIES}")
        for name in ("rtol", "tol_end", "margin"):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, numbers.Real) or not math.isfinite(val) or val <= 0:
                raise ValueError(f"{name} must be a positive finite number, got {val!r}")
        r = self.refine
        if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or r < 1:
            raise ValueError(f"refine must be a positive integer, got {r!r}")


def solve_diffusion(density, options: DiffusionOptions | None = None, *, progress: bool = False,
                    **kwargs) -> MapResult:
    r"""Diffusion density-equalizing map (Gastner & Newman 2004) of the unit square or cube.

    Every vertex :math:`x` of the ``N``-grid follows :math:`\dot x = -\nabla\rho(x,t)/\rho(x,t)` where
    :math:`\rho` solves :math:`\partial_t\rho = \Delta\rho` with no-flux walls, started from the
    piecewise-linear interpolant of the vertex densities (:mod:`rfmap.solvers.diffusion` gives the numerical method).

    Parameters
    ----------
    density : ndarray, shape (N, N) or (N, N, N)
        Preprocessed vertex densities on the ``N``-grid (strictly positive, finite; unit mass is the convention,
        any positive scale works).  The dimension is ``density.ndim``; ``N >= 3``.  A constant grid, of any value
        (:func:`rfmap.solvers.raster.check_grid_density`), is mapped to the identity exactly, without integrating.
    options : DiffusionOptions, optional
        The solver's options (:class:`.DiffusionOptions`: ``boundary``, ``rtol``, ``tol_end``, ``refine``,
        ``margin``, ``max_steps``, ``num_threads``, ``fold_guard``); its defaults when ``None``.
    progress : bool
        Show a ``tqdm`` progress bar over simulated time.
    **kwargs
        Fields of :class:`.DiffusionOptions` that replace those of ``options``
        (``solve_diffusion(d, boundary="free")``).

    Returns
    -------
    MapResult
        ``kind="density"``, ``field`` the vertex densities (shape (N**d,)), ``elements`` from
        :func:`rfmap.core.mesh.grid_mesh`, ``time`` the wall-clock seconds; ``info`` holds ``iterations`` (accepted
        steps), ``rejected``, ``evaluations`` (velocity-field evaluations), ``t_end`` (simulated time, box units),
        ``residual_velocity``, ``fold_rejections``, ``fold_blurs`` (blur widths of the redone flows, in vertex
        spacings; usually empty), ``fold_stop`` (the simulated time at which the flow was stopped to stay
        fold-free, else ``None``), ``eval_grid`` (``M``), ``box_grid`` (``N_box``) and, for
        ``"free"``, ``sea_density``.

    Raises
    ------
    ValueError
        For a density that is not an (N,)*d array with ``d`` in {2, 3} and ``N >= 3``, contains NaN/inf or
        non-positive values (and is not constant), an unknown ``boundary``, or non-positive ``rtol``/``tol_end``/``refine``/``margin``.
    """
    t_start = time.perf_counter()
    opts = replace(options or DiffusionOptions(), **kwargs)
    opts.check()
    boundary, refine = opts.boundary, opts.refine
    dens = check_grid_density(density)
    d, n = dens.ndim, dens.shape[0]
    mesh = grid_mesh(n, d)
    ref = mesh.points

    # the diffusion box is [0, 1]^d in its own coordinates y; x = scale * y - shift
    if boundary == "square":
        pad, scale = 0, 1.0
        fine = p1_upsample(dens, int(refine))
    else:
        pad = max(1, int(round(opts.margin * (n - 1))))
        fine, sea = balanced_sea(dens, pad, int(refine))  # sea close to the mean density
        if not sea > 0:
            raise RuntimeError(f"could not balance the sea density (got {sea:.4g})")
        scale = (n - 1 + 2 * pad) / (n - 1)
    shift = pad / (n - 1)
    nb = n + 2 * pad
    y0 = (ref + shift) / scale

    if boundary == "square":
        wall_idx = np.nonzero((ref == 0.0) | (ref == 1.0))
        wall_val = ref[wall_idx]

        def project(p: np.ndarray) -> np.ndarray:
            np.clip(p, 0.0, 1.0, out=p)
            p[wall_idx] = wall_val  # boundary vertices stay exactly on their walls
            return p
    else:

        def project(p: np.ndarray) -> np.ndarray:
            return np.clip(p, 0.0, 1.0, out=p)

    def turned_over(p: np.ndarray) -> bool:
        return not grid_min_measure(p, n) > 0.0

    if is_uniform(dens):  # a uniform density does not diffuse: every vertex stays where it is, exactly
        mapped, m = ref.copy(), fine.shape[0]
        info = {"iterations": 0, "rejected": 0, "evaluations": 0, "t_end": 0.0, "residual_velocity": 0.0,
                "fold_rejections": 0, "fold_stop": None, "fold_blurs": []}
    else:
        threads = opts.num_threads if opts.num_threads is not None else (1 if d == 2 else None)
        with torch_threads(threads), blas_threads(fft_workers()):  # the threads torch runs with, now set
            field = HeatField(fine, divide="grid", transforms=ScipyTransforms(workers=fft_workers()))
            h = 1.0 / (nb - 1)
            # from the decay time of the fastest mode, which the step control grows
            stepping = BS32Options(float(opts.rtol) * h, first_step=1.0 / (SLOWEST_RATE * (field.m - 1) ** 2),
                                   max_steps=int(opts.max_steps), fold_stop=FOLD_STOP)
            blurs: list[float] = []
            for retry in range(len(FOLD_BLURS) + 1):
                # a retry starts the vertices moving when diffusion has blurred the density over FOLD_BLURS spacings
                t0 = 0.0 if retry == 0 else blur_start(FOLD_BLURS[retry - 1], nb)
                y, info = _flow(field, y0.copy(), project, replace(stepping, t0=t0), float(opts.tol_end) * h,
                                turned_over if opts.fold_guard else None, f"DEM {d}D N={n}" if progress else None)
                if info["fold_stop"] is None or retry == len(FOLD_BLURS):
                    break
                blurs.append(FOLD_BLURS[retry])
            info["fold_blurs"] = blurs
        mapped = y * scale - shift
        if boundary == "square":
            mapped = project(mapped)
        m = field.m
    elapsed = time.perf_counter() - t_start
    info = {"method": "diffusion", "boundary": boundary, "n": n, "dim": d, **info, "eval_grid": m, "box_grid": nb}
    if boundary == "free":
        info["sea_density"] = sea
    return MapResult(ref_points=ref, mapped_points=mapped, elements=mesh.elements, field=dens.reshape(-1),
                     kind="density", time=elapsed, info=info)


# the former name of solve_diffusion, kept for code that imports it from here (rfmap.solvers.solve_dem is the function
# that chooses between the methods)
solve_dem = solve_diffusion
