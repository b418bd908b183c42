r"""The flow-based density-equalizing map of the unit square for cartograms, in numpy alone.

The method is that of :mod:`rfmap.solvers.flow` (Gastner, Seguy & More 2018) with the square's walls fixed: the
density is interpolated linearly in time, :math:`\rho_t = (1 - t)\rho_0 + t\bar\rho`, the flux
:math:`-\nabla\phi` of :math:`\Delta\phi = \bar\rho - \rho_0` (no-flux walls) is computed once by cosine transforms
(:func:`rfmap.solvers.spectral.flow_planes`, the map solver's Poisson solve, here on the vertex grid and by the
``numpy.fft`` transforms of :class:`rfmap.solvers.cosine.CosineTransforms`), and
points follow :math:`\dot x = -\nabla\phi(x) / \rho_t(x)` from :math:`t = 0` to :math:`1`.  It is one pass of a
cartogram (:func:`rfmap.cartogram.resize.cartogram` with ``method="flow"``), which itself repeats passes on the mapped
polygons, so this module has no passes, residual rasters or free boundary of its own: what it keeps is lean.

* The points carried are a cartogram's distinct polygon vertices (a few thousand, where the grid has
  :math:`N^2`), so that no grid map is interpolated between them; or, by default, the ``N``-grid's vertices.
* The flux and the density are three planes of shape (N*N,), computed and stored in single precision
  (:data:`TABLE_DTYPE`, as the map solver's velocity table); the velocity at a point is their bilinear interpolant,
  evaluated by four gathers per plane and a weighted sum (:func:`bilinear`), and the points are carried in double
  precision.
* Time steps are predictor--corrector (Heun) pairs (:func:`rfmap.solvers.heun.heun_flow`, the time integration of
  the map solver :mod:`rfmap.solvers.flow` and of :mod:`rfmap.solvers.cartodiffusion` too): a step is accepted when
  :math:`\max|x' - x^*|` is at most ``rtol`` grid spacings and, for the grid, no triangle (each cell cut along its
  diagonal from :math:`(1, 0)` to :math:`(0, 1)`) has turned over (:func:`min_triangle_area`); otherwise it is
  retried shorter.  A grid step that falls below :data:`rfmap.solvers.heun.STALL_DT` redoes the pass with the
  density blurred over 1, 2, then 4 vertex spacings (:data:`rfmap.solvers.heun.STALL_BLURS`), as cartogram programs
  blur sharp edges.

PyTorch is never imported here (the whole cartogram command runs without it), nor ``scipy.fft``, whose import takes
most of a second: the transforms are real FFTs of ``numpy.fft`` (:class:`rfmap.solvers.cosine.CosineTransforms`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..core.mesh import multilinear
from .cosine import CosineTransforms
from .heun import STALL_BLURS, HeunOptions, Stalled, heun_flow
from .spectral import FlowVelocity, box_mean, flow_planes

__all__ = ["CartoFlowOptions", "GridFlow", "flow_square", "bilinear", "min_triangle_area", "square_inputs",
           "TABLE_DTYPE"]

#: Precision of a pass's flux and density tables (the transforms that compute them and the interpolation that reads
#: them): single precision halves the transforms' time on a cartogram's finest rasters, and its rounding (about 1e-7
#: of the largest value) is far below the step tolerance (:doc:`Design decisions </book/design>`)
TABLE_DTYPE = np.float32


@dataclass(frozen=True)
class CartoFlowOptions:
    """Options of :func:`flow_square`.

    Attributes
    ----------
    rtol : float
        Step tolerance: the largest predictor--corrector difference, in grid spacings (that of
        :mod:`rfmap.solvers.flow` in 2D).
    max_steps : int
        Most (accepted + rejected) steps; ``RuntimeError`` beyond.
    blur : float
        Width (vertex spacings) of a Gaussian blur of the density before the flow; 0 (default) turns it off.
    first_step : float
        Length of the first time step (of the unit interval): by default the whole flow, which the step control
        shortens as far as needed; a later pass of a cartogram, whose displacements are small, then takes one or two
        steps instead of doubling its way up from a short one.
    """

    rtol: float = 0.2
    max_steps: int = 10_000
    blur: float = 0.0
    first_step: float = 1.0

    def __post_init__(self):
        if not (self.rtol > 0 and self.blur >= 0 and 0 < self.first_step <= 1 and self.max_steps >= 1):
            raise ValueError(f"CartoFlowOptions need rtol > 0, blur >= 0, 0 < first_step <= 1 and max_steps >= 1; "
                             f"got {self}")


@dataclass
class GridFlow:
    """The map of the ``N``-grid's vertices by one flow.  It has the attributes of a
    :class:`rfmap.core.result.MapResult` that a cartogram reads, under the same names, and can stand in for one
    there.

    Attributes
    ----------
    ref_points : ndarray, shape (N*N, 2)
        The grid's vertices, vertex ``i*N + j`` at :math:`(i, j)/(N-1)`.
    mapped_points : ndarray, shape (N*N, 2)
        Their images by the flow.
    time : float
        Seconds.
    info : dict
        ``method="flow"``, ``passes=1``, ``steps``, ``rejected``, ``fold_rejections``, ``evaluations``,
        ``stall_blurs`` (blur widths of redone passes; usually empty), ``n``.
    """

    ref_points: np.ndarray
    mapped_points: np.ndarray
    time: float
    info: dict = field(default_factory=dict)


def bilinear(table: np.ndarray, pts: np.ndarray) -> np.ndarray:
    r"""Bilinear interpolant of a vertex table at points of the unit square.

    Parameters
    ----------
    table : ndarray, shape (N, N, C)
        ``table[i, j]`` at :math:`(i, j)/(N-1)`.
    pts : ndarray, shape (P, 2)
        Points in :math:`[0, 1]^2` (clamped to it).

    Returns
    -------
    ndarray, shape (P, C)
    """
    n = table.shape[0]
    return _bilinear_planes(np.ascontiguousarray(np.moveaxis(table, -1, 0)).reshape(table.shape[-1], n * n), n, pts)


def _bilinear_planes(planes: np.ndarray, n: int, pts: np.ndarray) -> np.ndarray:
    """:func:`bilinear` of channel planes (C, N*N): :func:`rfmap.core.mesh.multilinear` at the points in grid
    units (the cell and weights once, then one gather per corner and channel)."""
    return multilinear(planes.reshape(len(planes), n, n), pts * (n - 1))


def min_triangle_area(y: np.ndarray) -> float:
    r"""Twice the smallest signed area among the grid's triangles with vertices at ``y``, shape (N, N, 2): each
    cell's :math:`(0,0), (1,0), (0,1)` and :math:`(1,0), (1,1), (0,1)` triangles (positive when not turned over)."""
    p00, p10, p01, p11 = y[:-1, :-1], y[1:, :-1], y[:-1, 1:], y[1:, 1:]
    ax, ay = p10[..., 0] - p00[..., 0], p10[..., 1] - p00[..., 1]
    bx, by = p01[..., 0] - p00[..., 0], p01[..., 1] - p00[..., 1]
    first = (ax * by - ay * bx).min()
    cx, cy = p11[..., 0] - p10[..., 0], p11[..., 1] - p10[..., 1]
    dx, dy = p01[..., 0] - p10[..., 0], p01[..., 1] - p10[..., 1]
    return float(min(first, (cx * dy - cy * dx).min()))


def _velocity(dens: np.ndarray, sigma: float = 0.0) -> FlowVelocity:
    r""":class:`rfmap.solvers.spectral.FlowVelocity` of one density on the (N, N) vertex grid, blurred over
    ``sigma`` vertex spacings with mirror walls, its tables computed and read bilinearly in :data:`TABLE_DTYPE`."""
    n = dens.shape[0]
    tr = CosineTransforms(n, dtype=TABLE_DTYPE)
    planes = flow_planes(dens, sigma / (n - 1), TABLE_DTYPE, transforms=tr).reshape(3, -1)  # flux x, y, density
    return FlowVelocity(lambda pts: _bilinear_planes(planes, n, pts), box_mean(dens))


def _project(p: np.ndarray, n: int) -> np.ndarray:
    """Clip points (N*N, 2) to the unit square, in place, and keep the wall vertices on their walls."""
    np.clip(p, 0.0, 1.0, out=p)
    g = p.reshape(n, n, 2)
    g[0, :, 0], g[-1, :, 0], g[:, 0, 1], g[:, -1, 1] = 0.0, 1.0, 0.0, 1.0
    return p


def square_inputs(density, points) -> tuple[np.ndarray, np.ndarray, bool]:
    """The checked inputs of a map of the unit square: the density (N, N) in double precision, the points to carry
    (P, 2) (the ``N``-grid's vertices, ``i*N + j`` at :math:`(i, j)/(N-1)`, when ``points`` is None) and whether
    they are the grid's; ``ValueError`` for a density that is not square, finite and positive, or points not (P, 2)."""
    dens = np.asarray(density, dtype=np.float64)
    if dens.ndim != 2 or dens.shape[0] != dens.shape[1] or dens.shape[0] < 3:
        raise ValueError(f"density must have shape (N, N) with N >= 3, got {dens.shape}")
    if not (np.isfinite(dens).all() and dens.min() > 0):
        raise ValueError("density must be finite and strictly positive")
    if points is None:
        s = np.linspace(0.0, 1.0, dens.shape[0])
        return dens, np.stack(np.meshgrid(s, s, indexing="ij"), axis=-1).reshape(-1, 2), True
    ref = np.asarray(points, dtype=np.float64)
    if ref.ndim != 2 or ref.shape[1] != 2 or not np.isfinite(ref).all():
        raise ValueError(f"points must be finite with shape (P, 2), got shape {ref.shape}")
    return dens, ref, False


def _grid_turned_over(n: int):
    """The fold test of the ``N``-grid's vertices (N*N, 2): a cell triangle of non-positive area."""
    return lambda p: min_triangle_area(p.reshape(n, n, 2)) <= 0.0


def flow_square(density: np.ndarray, options: CartoFlowOptions | None = None, *,
                points: np.ndarray | None = None) -> GridFlow:
    r"""One flow-based map of the unit square with fixed walls (the module's description gives the method).

    Parameters
    ----------
    density : ndarray, shape (N, N)
        Strictly positive vertex densities, ``density[i, j]`` at :math:`(i, j)/(N-1)`.
    options : CartoFlowOptions, optional
    points : ndarray, shape (P, 2), optional
        Points of the unit square to carry by the flow itself (a cartogram's distinct polygon vertices: far fewer
        than the grid's, and no interpolation of a grid map between them).  Default: the ``N``-grid's vertices,
        with every step checked for turned-over triangles.

    Returns
    -------
    GridFlow
        The points (or the grid's vertices) and their images; a grid flow that stalls is redone blurred
        (``info["stall_blurs"]``).

    Raises
    ------
    ValueError
        For a density that is not a square 2D array of positive finite numbers.
    RuntimeError
        When the steps run out, or the flow stalls with the density blurred over the widest retry.
    """
    t0 = time.perf_counter()
    opts = options or CartoFlowOptions()
    dens, ref, grid = square_inputs(density, points)
    n = dens.shape[0]
    blurs, width, evaluations = [], opts.blur, 0
    project = (lambda p: _project(p, n)) if grid else (lambda p: np.clip(p, 0.0, 1.0, out=p))
    stepping = HeunOptions(opts.rtol * (1.0 / (n - 1)), first_step=opts.first_step, max_steps=opts.max_steps)
    while True:
        vel = _velocity(dens, width)
        try:
            mapped, info = heun_flow(vel, np.clip(ref, 0.0, 1.0), project, stepping,
                                     _grid_turned_over(n) if grid else None)
            break
        except Stalled as exc:
            evaluations += vel.evaluations
            if len(blurs) == len(STALL_BLURS):
                raise RuntimeError(f"flow map stalled with the density blurred over {width:g} spacings: {exc}") \
                    from None
            width = max(width, STALL_BLURS[len(blurs)])
            blurs.append(width)
    info.update(method="flow", passes=1, n=n, grid=grid, evaluations=evaluations + vel.evaluations, stall_blurs=blurs)
    return GridFlow(ref_points=ref, mapped_points=mapped, time=time.perf_counter() - t0, info=info)
