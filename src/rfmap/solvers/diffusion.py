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
   grid ``refine`` times finer, with :math:`M = \text{refine}\,(N-1) + 1` points per side (:func:`p1_upsample`).
   Starting from the P1 rather than the cosine interpolant of the vertex values avoids Gibbs ringing at steep
   features and lowers the final :math:`\mathrm{Std}(\tilde\rho)` markedly (e.g. 0.041 → 0.026 on rect-peak at
   ``N = 51``).
2. **Exact diffusion.**  The diffusion equation is solved exactly in the cosine basis of the box,

   .. math::

       \rho(x, t) = \sum_{k \in \{0..M-1\}^d} a_k \prod_{i=1}^d \cos(\pi k_i x_i)\; e^{-\pi^2 |k|^2 t},

   with :math:`a_k` from a type-I discrete cosine transform (:func:`cosine_coefficients`), so that
   :math:`\rho(\cdot, 0)` interpolates the fine-grid values.
3. **Velocity.**  :math:`\rho` and :math:`\nabla\rho` are evaluated on the fine grid by separable products with
   cosine / sine tables (dense matrix products, :math:`O(M^{d} K)` per evaluation with :math:`K \le M` the modes
   not yet decayed below 1e-17), :math:`v = -\nabla\rho/\rho` is formed there and interpolated multilinearly at the
   current vertex positions (:func:`rfmap.core.mesh.interpolate`).
4. **Time integration.**  :math:`\dot x = v(x, t)` is integrated with the embedded Bogacki–Shampine 3(2) pair
   (:func:`rfmap.solvers.bs32.bs32_flow`: FSAL, 3 evaluations per step) with the local error per step bounded by
   ``rtol`` times the grid spacing, until the remaining displacement, estimated as :math:`\max|v| / \lambda_1` with
   :math:`\lambda_1 = \pi^2` the decay rate of the slowest mode, falls below ``tol_end`` times the grid spacing.
   The flow's driver, this stopping rule and the blurred starts below are the cartogram diffusion's too
   (:mod:`rfmap.solvers.heatflow`); its field (step 3) and its integrator are this solver's own, as the results of
   both are kept bit for bit and the cartogram's must not import PyTorch.
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
  measured area of the mapped mesh is then 1 up to a discretisation error of order :math:`h` with a small constant
  (about :math:`3\cdot 10^{-4}` for ring at ``N = 51``).

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
import torch

from ..core.device import torch_threads
from ..core.inputs import is_uniform
from ..core.geometry import grid_min_measure
from ..core.mesh import grid_mesh, interpolate
from ..core.result import MapResult
from .bs32 import BS32Options
from .heatflow import SLOWEST_RATE, Settling, blur_start, diffuse
from .raster import DEM_BOUNDARIES, balanced_sea, check_grid_density, p1_upsample
from .spectral import cosine_coefficients, fft_workers

__all__ = [
    "solve_dem",
    "DiffusionOptions",
    "CosineDiffusion",
    "cosine_coefficients",
    "p1_upsample",
    "DEM_BOUNDARIES",
]


class CosineDiffusion:
    r"""Exact solution of the diffusion equation with no-flux walls on :math:`[0,1]^d` in the cosine basis.

    :math:`\rho(x,t) = \sum_k a_k \prod_i \cos(\pi k_i x_i)\, e^{-\pi^2 |k|^2 t}`, :math:`0 \le k_i \le M-1`,
    with :math:`a_k` such that :math:`\rho(\cdot, 0)` interpolates the grid values: with the unnormalised type-I DCT
    :math:`y = \mathrm{DCT\text{-}I}(p)` (``scipy.fft.dctn(p, type=1)``),
    :math:`a_k = y_k \prod_i c_{k_i} / (2(M-1))^d` where :math:`c_0 = c_{M-1} = 1` and :math:`c_k = 2` otherwise.
    :math:`\rho` and :math:`\nabla\rho` are evaluated on the same grid by separable products with the tables
    :math:`\cos(\pi k x_j)` and :math:`-\pi k \sin(\pi k x_j)`; modes whose per-axis decay factor
    :math:`e^{-\pi^2 k^2 t}` has dropped below ``1e-17`` are skipped, so late evaluations are cheap.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
        Grid values of the initial density at :math:`j/(M-1)` (positive).
    """

    def __init__(self, values: np.ndarray):
        self.dim = values.ndim
        self.m = m = values.shape[0]
        self.coef = torch.from_numpy(cosine_coefficients(values, workers=fft_workers()))
        k = np.arange(m)
        x = np.linspace(0.0, 1.0, m)
        arg = math.pi * np.outer(x, k)
        dsin = -math.pi * k[None, :] * np.sin(arg)  # d/dx cos(pi k x), (M, K)
        dsin[0] = dsin[-1] = 0.0  # exact zero normal derivative on the walls
        self.cos = torch.from_numpy(np.cos(arg))  # (M, K)
        self.dsin = torch.from_numpy(dsin)
        self.k2 = torch.from_numpy((math.pi * k) ** 2)  # per-axis decay rates

    def n_modes(self, t: float) -> int:
        """Modes per axis still significant at time ``t`` (per-axis decay factor above 1e-17)."""
        if t <= 0:
            return self.m
        return int(min(self.m, max(2, math.ceil(math.sqrt(39.2 / (math.pi**2 * t))) + 1)))

    def fields(self, t: float, window: tuple[tuple[int, int], ...] | None = None) -> torch.Tensor:
        r""":math:`\rho` and :math:`\nabla\rho` at time ``t`` on the grid (or on a window of it).

        Parameters
        ----------
        t : float
            Time (box units).
        window : tuple of d (start, stop) index pairs, optional
            Evaluate only on the grid nodes ``start <= j < stop`` along each axis (the whole grid by default).

        Returns
        -------
        Tensor, float64, shape (d+1, W_1, ..., W_d)
            ``[rho, d rho/dx_1, ..., d rho/dx_d]``; ``W_i = stop_i - start_i`` (``M`` without a window).
        """
        d = self.dim
        if window is None:
            window = ((0, self.m),) * d
        kk = self.n_modes(t)
        decay = torch.exp(-self.k2[:kk] * t)  # separable time factor
        C = [self.cos[lo:hi, :kk] * decay for lo, hi in window]  # per-axis (W_i, K) tables
        S = [self.dsin[lo:hi, :kk] * decay for lo, hi in window]
        w = [hi - lo for lo, hi in window]
        a = self.coef[(slice(0, kk),) * d]
        if d == 2:
            out = torch.empty(3, w[0], w[1], dtype=torch.float64)
            ac = a @ C[1].T  # (K, W_2): last axis transformed
            torch.mm(C[0], ac, out=out[0])
            torch.mm(S[0], ac, out=out[1])
            torch.mm(C[0], a @ S[1].T, out=out[2])
            return out
        out = torch.empty(4, w[0], w[1] * w[2], dtype=torch.float64)
        zc = a @ C[2].T  # (K, K, W_3)
        zs = a @ S[2].T
        plane = w[1] * w[2]
        ycc = torch.matmul(C[1], zc).reshape(kk, plane)  # (K, W_2, W_3) -> (K, W_2 W_3)
        torch.mm(C[0], ycc, out=out[0])
        torch.mm(S[0], ycc, out=out[1])
        torch.mm(C[0], torch.matmul(S[1], zc).reshape(kk, plane), out=out[2])
        torch.mm(C[0], torch.matmul(C[1], zs).reshape(kk, plane), out=out[3])
        return out.reshape(4, *w)

    def velocity(self, t: float, window: tuple[tuple[int, int], ...] | None = None) -> torch.Tensor:
        r"""The Gastner–Newman velocity :math:`v = -\nabla\rho/\rho` on the grid (or a window, see :meth:`fields`).

        Returns
        -------
        Tensor, float64, shape (d, W_1, ..., W_d)
        """
        f = self.fields(t, window)
        inv = f[0].reciprocal_().neg_()
        return f[1:].mul_(inv)

    def velocity_at(self, t: float, points: np.ndarray) -> np.ndarray:
        r""":math:`v(x, t)` at arbitrary points (P, d) of the unit box: multilinear interpolation of the grid velocity.

        The velocity is evaluated only on the window of grid nodes that covers the points' bounding box (much
        cheaper when the points occupy a small part of the box, as with the free boundary).

        Returns
        -------
        ndarray, shape (P, d)
        """
        top = self.m - 1
        lo = np.clip(np.floor(points.min(axis=0) * top).astype(int), 0, top - 1)
        hi = np.clip(np.ceil(points.max(axis=0) * top).astype(int), lo + 1, top)
        window = tuple((int(a), int(b) + 1) for a, b in zip(lo, hi))
        local = (points * top - lo) / (hi - lo)
        return interpolate(self.velocity(t, window)[None], local, check=False)[0].numpy()


#: fold rejections after which the diffusion flow is stopped at its last fold-free state
FOLD_STOP = 60


#: blur widths (vertex spacings) of the retries of a flow that keeps folding (``solve_dem(fold_guard=True)``)
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


def _flow(field: CosineDiffusion, y: np.ndarray, project, stepping: BS32Options, tol: float, turned_over,
          label: str | None) -> tuple[np.ndarray, dict]:
    r"""The vertices ``y`` carried by the diffusion flow (:func:`rfmap.solvers.heatflow.diffuse`, Bogacki--Shampine
    steps) until the remaining displacement is at most ``tol`` (box units), with a progress bar when ``label`` is
    given; the info of :func:`solve_dem` (``iterations``, ..., ``fold_stop``)."""
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
    r"""The options of :func:`solve_dem` with their defaults: a call names only those that differ.

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
        Torch threads for the dense transforms during the solve (restored afterwards).  Default: 1 in 2D (the
        products are too small to gain from threads, which only add synchronisation cost), torch's setting in 3D.
    fold_guard : bool
        Keep the mesh fold-free (default): a time step that would turn an element over is rejected and retried
        shorter.  The exact flow never folds, but its piecewise-linear image on the mesh can, where the density
        changes faster than the mesh resolves (near-zero regions beside sharp peaks); if the flow keeps folding
        (``FOLD_STOP`` rejections) it is redone from a blurred start (``FOLD_BLURS``, see the module docstring), and
        if it still folds with the widest blur the integration stops at its last fold-free state
        (``info["fold_stop"]`` gives that time).  ``False`` integrates the vertex trajectories regardless.
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


def solve_dem(density, options: DiffusionOptions | None = None, *, progress: bool = False, **kwargs) -> MapResult:
    r"""Diffusion density-equalizing map (Gastner & Newman 2004) of the unit square or cube.

    Every vertex :math:`x` of the ``N``-grid follows :math:`\dot x = -\nabla\rho(x,t)/\rho(x,t)` where
    :math:`\rho` solves :math:`\partial_t\rho = \Delta\rho` with no-flux walls, started from the
    piecewise-linear interpolant of the vertex densities (see the module docstring for the numerical method).

    Parameters
    ----------
    density : ndarray, shape (N, N) or (N, N, N)
        Preprocessed vertex densities on the ``N``-grid (strictly positive, finite; unit mass is the convention,
        any positive scale works).  The dimension is ``density.ndim``; ``N >= 3``.  A constant grid, of any value
        (:func:`rfmap.solvers.raster.check_grid_density`), is mapped to the identity exactly, without integrating.
    options : DiffusionOptions, optional
        The solver's options (:class:`DiffusionOptions`: ``boundary``, ``rtol``, ``tol_end``, ``refine``,
        ``margin``, ``max_steps``, ``num_threads``, ``fold_guard``); its defaults when ``None``.
    progress : bool
        Show a ``tqdm`` progress bar over simulated time.
    **kwargs
        Fields of :class:`DiffusionOptions` that replace those of ``options`` (``solve_dem(d, boundary="free")``).
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
        with torch_threads(threads):
            field = CosineDiffusion(fine)
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
