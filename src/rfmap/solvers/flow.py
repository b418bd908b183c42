r"""Flow-based density-equalizing maps (Gastner, Seguy & More 2018) on the unit square and cube.

Instead of letting the density diffuse, the flow-based method prescribes its history: the density is interpolated
linearly in time between the input :math:`\rho_0` and its mean :math:`\bar\rho`,

.. math:: \rho_t(x) = (1 - t)\,\rho_0(x) + t\,\bar\rho, \qquad 0 \le t \le 1 .

The continuity equation :math:`\partial_t\rho_t + \nabla\cdot(\rho_t v) = 0` then asks for a flux
:math:`\rho_t v = -\nabla\phi` with

.. math:: \Delta\phi = \bar\rho - \rho_0, \qquad \partial_n\phi = 0 \text{ on the walls},

which does not depend on :math:`t`: one Poisson solve gives the velocity :math:`v(x, t) = -\nabla\phi(x)/\rho_t(x)`
at every time.  Every vertex is carried by :math:`\dot x = v(x, t)` from :math:`t = 0` to :math:`t = 1`; at
:math:`t = 1` the density is uniform and the vertex positions define the map.  The flow ends at a finite time
(the diffusion flow only approaches its end as :math:`t \to \infty`), which is why the method is fast.

Numerical method:

1. **Density raster.**  As in ``rfmap.solvers.diffusion``: the piecewise-linear (P1) interpolant of the vertex
   densities sampled on a grid ``refine`` times finer (``rfmap.solvers.raster.p1_upsample``), ``M`` points
   per side of the box.
2. **Poisson solve.**  With the cosine coefficients :math:`a_k` of the raster (type-I DCT,
   ``rfmap.solvers.spectral.cosine_coefficients``), :math:`\phi_k = a_k / (\pi^2 |k|^2)` for
   :math:`k \ne 0`; the flux :math:`-\nabla\phi` is evaluated on the raster by inverse type-I DCTs along the cosine
   axes and a type-I DST along the differentiated axis (``rfmap.solvers.spectral.flow_planes``, which the
   cartogram passes of ``rfmap.solvers.cartoflow`` share), :math:`O(M^d \log M)`.  Its normal
   component vanishes exactly on the walls (no-flux).
3. **Velocity at a point.**  The flux and :math:`\rho_0` are interpolated multilinearly at the vertex and
   :math:`v = -\nabla\phi / ((1-t)\rho_0 + t\bar\rho)` is formed there.  The Poisson solve and this table are
   single precision, whose rounding error is far below a step's tolerance (:doc:`Design decisions </book/design>`
   compares it with double precision); the vertex positions are integrated in double.
4. **Time steps.**  Predictor–corrector (Heun) steps (``rfmap.solvers.heun.heun_flow``, the cartogram
   passes' integrator), :math:`x^* = x + \Delta t\, v(x, t)`,
   :math:`x' = x + \tfrac{\Delta t}{2}\,(v(x, t) + v(x^*, t + \Delta t))`.  A step is accepted when the
   predictor–corrector difference :math:`\max|x' - x^*|` is at most ``rtol`` grid spacings *and* no element of the
   mesh has turned over (all signed measures stay positive; decided in single precision unless the smallest
   measure is too close to zero for it, ``F32_MARGIN``); otherwise it is retried with a smaller
   :math:`\Delta t`.  The step then grows or shrinks with the usual rule for an embedded first/second-order pair.
   A density jump sharper than the mesh can make the sampled velocity squeeze one element to zero measure in finite
   time, so that no step, however short, is accepted.  When the step falls below
   :data:`rfmap.solvers.heun.STALL_DT` (the pass has stalled), the pass is redone with the density blurred over 1,
   2, then 4 vertex spacings (``STALL_BLURS``; recorded in ``info["stall_blurs"]``) and later passes correct the
   residual the blur leaves.
5. **Passes.**  Interpolation and time-stepping leave a residual.  After a pass the density that remains on the
   mapped mesh, :math:`\tilde\rho_e = \text{population}_e / |T(e)|` (population of the element over its mapped
   measure), is turned into the P1 vertex field whose element means match it (:func:`.vertex_residual`) and
   rasterized by locating every raster node in the mapped mesh and interpolating linearly in its element
   (:func:`.rasterize_elements`); the next pass moves the mapped vertices by the flow of that density, composing the
   maps.  Passes stop when :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` is below ``tol`` or stops improving (by
   less than ``stall``).

Boundary conditions follow :func:`rfmap.solvers.diffusion.solve_diffusion`: ``"square"`` keeps the walls (boundary
vertices slide, corners stay); ``"free"`` embeds the square in :math:`[-L, 1+L]^d` filled with a sea whose level is
balanced so that the domain keeps its measure (``rfmap.solvers.raster.balanced_sea``), and later passes fill the
sea with the domain's mean residual density.  The flow's velocity :math:`-\nabla\phi/\rho_t` carries the density's
jumps into the map, and a steep jump from a dense coast to the sea can squeeze a coastal element to zero measure: on
held-out fields with a steep ramp against the coast (``rfmap.training.validation``) the pass stalls, and its blurred
retries leave much of the density unequalized, far above the diffusion solver's Std(ρ̃_map) (appendix B of the book,
*The flow solver and the hybrid in detail*, measures it with
:func:`rfmap.paper.flow_studies.sea_blend_study`).  A stalled first pass of a free boundary is therefore first
redone with a sea that starts at the coast's own density and blends to its level (``stall_blend``; only if it
stalls again is it redone with blurred densities); ``sea_blend`` asks for that sea from the start (see
:class:`rfmap.solvers.FlowOptions`).  A blend is a different sea, hence a different coastline, and not a uniform
gain: it helps steep ramps against the coast and can hurt raw densities of high contrast
(:func:`rfmap.paper.flow_studies.sea_blend_study` measures it).  The width is halved while the blended sea would not
be positive (down to an eighth of the request, then 0), and ``info["sea_blend"]`` records the width used.

The same passes finish any fold-free starting map (``start``): the first pass then flows the residual density of
the starting map.  :mod:`rfmap.finish.polish` uses this to polish a neural surrogate's map.

References
----------
M. T. Gastner, V. Seguy, P. More, "Fast flow-based algorithm for creating density-equalizing map projections",
Proc. Natl. Acad. Sci. USA 115(10), E2156–E2164 (2018).
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
from ..core.geometry import grid_element_mean, grid_min_measure, grid_signed_measures
from ..core.mesh import grid_mesh
from ..core.result import MapResult
from .heun import STALL_BLURS, STALL_DT, HeunOptions, Stalled, heun_flow
from .locate import rasterize_elements
from .raster import DEM_BOUNDARIES, balanced_sea, check_grid_density, p1_upsample
from .residual import lumped_residual, residual_density, vertex_residual
from .spectral import FlowVelocity, box_mean, flow_planes

__all__ = ["STALL_BLEND", "STALL_DT", "STALL_BLURS", "FlowOptions", "solve_flow", "rasterize_elements",
           "residual_density", "lumped_residual", "vertex_residual"]


#: The fold check of a step (:func:`rfmap.core.geometry.grid_min_measure`, with the same threshold) and
#: ``rfmap.surrogate.density_quality`` decide on float32 measures unless the smallest is below this fraction of the
#: reference element measure; float64 then decides (the float32 rounding error of a grid element's measure is about
#: 1e-6 / h of the mean, so this leaves a margin of about 20 at N = 1000).
F32_MARGIN = 1e-3


def _turned_over(x: np.ndarray, n: int) -> bool:
    """Whether an element of the ``N``-grid mesh with vertices at ``x`` (N**d, d) has non-positive measure
    (:func:`rfmap.core.geometry.grid_min_measure`: float32 unless the minimum is too close to zero for it, and only the
    minimum is formed)."""
    return grid_min_measure(x, n) <= 0.0


#: Default step tolerance per dimension (grid spacings): 3D steps cost about ten times 2D ones, so 3D takes a coarser
#: tolerance for nearly the same Std(ρ̃_map) (:doc:`Design decisions </book/design>`).
RTOL = {2: 0.2, 3: 0.4}


#: Default sea width L of the free boundary per dimension (the box is [-L, 1 + L]^d): the diffusion solver's 0.5 in 2D;
#: in 3D the sea box's transforms dominate the time, and a narrower sea gives the same Std
#: (:doc:`Design decisions </book/design>`).
MARGIN = {2: 0.5, 3: 0.25}


#: Sea blend (``solve_flow(stall_blend=...)``) of the first remedy for a stalled first pass of a free boundary's cold
#: start, tried before the blurred retries (``STALL_BLURS``): the width with the lowest mean Std(ρ̃_map) on the
#: validation stream (:doc:`Design decisions </book/design>`).  A pass that does not stall keeps the diffusion solver's
#: sea.
STALL_BLEND = 0.25


class _FlowPass:
    """One pass of the flow: the flux of one density raster and the time integration from t = 0 to 1."""

    def __init__(self, raster: np.ndarray, sigma: float = 0.0):
        self.dim = raster.ndim
        self.m = raster.shape[0]
        # the velocity table in single precision: torch's grid_sample is vectorised for float32 only (book: Design
        # decisions), and its error is far below the step's tolerance; the positions are integrated in float64.
        # Channels first, grid axes reversed: grid_sample takes the last point coordinate along the last grid axis
        self.grid = torch.from_numpy(flow_planes(raster, sigma, np.float32))[None]  # (1, d+1, M..): flux, density
        # the box mean of the cosine interpolant, which the blur keeps
        self.velocity = FlowVelocity(self._sample, box_mean(raster))

    def _sample(self, y: np.ndarray) -> np.ndarray:
        """The tables at points (P, d) of the box, bilinear (multilinear in 3D), float32, shape (P, d + 1)."""
        q = torch.from_numpy(y).float().flip(-1).mul_(2.0).sub_(1.0)  # float32 arithmetic: the table's precision
        # grid_sample runs its batch in parallel but one batch entry on one thread: split the points into one
        # batch entry per thread over the same (expanded, not copied) table (book: Design decisions)
        k, p = max(1, torch.get_num_threads()), len(y)
        rows = -(-p // k)
        if rows * k != p:
            q = torch.cat([q, q.new_zeros(rows * k - p, self.dim)])
        q = q.reshape(k, *([1] * (self.dim - 1)), rows, self.dim)
        f = torch.nn.functional.grid_sample(self.grid.expand(k, *self.grid.shape[1:]), q, mode="bilinear",
                                            padding_mode="border", align_corners=True)
        return f.reshape(k, self.dim + 1, rows).permute(0, 2, 1).reshape(k * rows, self.dim + 1)[:p].numpy()

    def run(self, y: np.ndarray, turned_over, project, *, h: float, rtol: float, max_steps: int,
            bar) -> tuple[np.ndarray, dict]:
        """The points ``y`` carried from t = 0 to 1 by the Heun steps of the cartogram pass
        (:func:`rfmap.solvers.heun.heun_flow`), from a first step of 1e-2 and with rejections shrinking the step
        by at least 0.2; ``Stalled`` when the step collapses."""

        def on_step(t: float) -> None:
            bar.n = round(t, 4)
            bar.refresh()

        stepping = HeunOptions(rtol * h, first_step=1e-2, max_steps=max_steps, floor=0.2)
        return heun_flow(self.velocity, y, project, stepping, turned_over,
                         on_step=on_step if bar is not None else None)


def _sea_raster(dens: np.ndarray, pad: int, refine: int, blend: float) -> tuple[np.ndarray, float, float]:
    """The free boundary's first raster with its balanced sea (``rfmap.solvers.raster.balanced_sea``) blended
    over ``blend``, halved while the blended sea would not be positive (down to an eighth, then 0); returns the
    raster, the sea level and the blend used.  ``RuntimeError`` if even the abrupt sea cannot be balanced."""
    floor = blend / 8
    while True:
        raster, sea = balanced_sea(dens, pad, refine, blend)
        if blend == 0 or (sea > 0 and raster.min() > 0):
            break
        blend = blend / 2 if blend > floor else 0.0
    if not sea > 0:
        raise RuntimeError(f"could not balance the sea density (got {sea:.4g})")
    return raster, float(sea), float(blend)


@dataclass(frozen=True)
class FlowOptions:
    r"""The options of :func:`solve_flow` with their defaults: a call names only those that differ.

    Attributes
    ----------
    boundary : {"square", "free"}
        As in :func:`rfmap.solvers.diffusion.solve_diffusion`: fixed walls of the unit square/cube, or a sea of the mean
        density around it in :math:`[-L, 1+L]^d`.
    tol : float
        Stop after the pass whose :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` is at most ``tol`` (no pass at all
        when the input's is).  ``tol=0`` turns this stop off, leaving the passes to ``max_passes`` and ``stall``: with
        ``max_passes=1``, exactly one pass runs on any density that is not exactly uniform, for a caller with its own
        stopping rule.
    rtol : float, optional
        Largest predictor–corrector difference of an accepted step, in grid spacings of the raster's box; default
        ``RTOL`` of the dimension (0.2 in 2D, 0.4 in 3D).
    refine : int
        The density raster is ``refine`` times finer than the vertex grid (``M = refine (N_box - 1) + 1``).
    margin : float, optional
        Sea width :math:`L` for ``boundary="free"``, rounded to whole grid cells (at least one); default
        ``MARGIN`` of the dimension (0.5 in 2D, 0.25 in 3D).
    sea_blend : float
        For ``boundary="free"`` only: the width (domain length units) over which the :term:`sea` around the domain
        blends from the coast's density to its own level; 0 (the default) starts the sea at its level at the coast,
        as the diffusion solver does.  The width used is ``info["sea_blend"]``; the module's description
        (:mod:`rfmap.solvers.flow`) says what a blend changes.
    stall_blend : float
        For a free boundary's cold start with ``sea_blend=0``: the sea blend of the one retry of a stalled first
        pass, before any blurred retry (:data:`.STALL_BLEND`; 0 skips it; ``info["sea_fallback"]``).
    max_passes : int
        Most passes; the passes also stop when one lowers :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` by less than
        the factor ``stall`` (the map with the lowest value is returned).
    stall : float
        See ``max_passes``; in (0, 1].
    blur : float
        Width (in vertex grid spacings) of a Gaussian blur of the first pass's density
        (``rfmap.solvers.spectral.gaussian_blur``),
        halved at every further pass, as cartogram programs do to soften sharp edges; 0 turns it off.
    max_steps : int
        Most (accepted + rejected) steps of one pass; ``RuntimeError`` if exceeded, or if a pass still stalls
        with the density blurred over the last of ``stall_blurs``.
    stall_blurs : tuple of float
        Blur widths (vertex spacings) of the retries of a stalled pass (see :mod:`rfmap.solvers.flow`); ``()`` makes a
        stall a ``RuntimeError`` at once (the hybrid then starts cold rather than blur a warm start).
    num_threads : int, optional
        Torch threads for the interpolation and the element measures (restored afterwards); as in
        :func:`rfmap.solvers.diffusion.solve_diffusion`, default 1 in 2D and torch's setting in 3D.
    keep_best : bool
        Return the map with the lowest :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` among the start and the passes
        (default), or ``False``: the map of the last pass, even where it is worse (to study what a pass does).
    """

    boundary: str = "square"
    tol: float = 1e-3
    rtol: float | None = None
    refine: int = 2
    margin: float | None = None
    sea_blend: float = 0.0
    stall_blend: float = STALL_BLEND
    max_passes: int = 1
    stall: float = 0.8
    blur: float = 0.0
    max_steps: int = 10_000
    stall_blurs: tuple[float, ...] = STALL_BLURS
    num_threads: int | None = None
    keep_best: bool = True

    def checked(self, d: int) -> "FlowOptions":
        """These options for a ``d``-dimensional density, with the defaults of the dimension filled in
        (``RTOL``, ``MARGIN``); ``ValueError`` for a value out of range."""
        rtol = RTOL[d] if self.rtol is None else self.rtol
        margin = MARGIN[d] if self.margin is None else self.margin
        for name, val in (("sea_blend", self.sea_blend), ("stall_blend", self.stall_blend), ("tol", self.tol)):
            if isinstance(val, bool) or not isinstance(val, numbers.Real) or not math.isfinite(val) or val < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {val!r}")
        for name, val in (("rtol", rtol), ("margin", margin), ("stall", self.stall)):
            if isinstance(val, bool) or not isinstance(val, numbers.Real) or not math.isfinite(val) or val <= 0:
                raise ValueError(f"{name} must be a positive finite number, got {val!r}")
        if self.stall > 1:
            raise ValueError(f"stall must lie in (0, 1], got {self.stall!r}")
        for name, val in (("refine", self.refine), ("max_passes", self.max_passes)):
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
                raise ValueError(f"{name} must be a positive integer, got {val!r}")
        return replace(self, rtol=rtol, margin=margin, sea_blend=float(self.sea_blend))


class _Box:
    """The flow's box :math:`[0, 1]^d` in the map's coordinates, ``y = (x + shift) / scale``: the unit square or cube
    itself, or with a free boundary the domain in a sea ``pad`` vertex spacings wide; ``nb`` vertex nodes and ``m``
    raster nodes per side, and the projection of box points back onto the box (and, for the square, its walls)."""

    def __init__(self, ref: np.ndarray, n: int, opts: FlowOptions):
        self.square = opts.boundary == "square"
        self.pad = 0 if self.square else max(1, int(round(opts.margin * (n - 1))))
        self.scale = 1.0 if self.square else (n - 1 + 2 * self.pad) / (n - 1)
        self.shift = self.pad / (n - 1)
        self.nb = n + 2 * self.pad
        self.m = int(opts.refine) * (self.nb - 1) + 1
        self.wall_idx = np.nonzero((ref == 0.0) | (ref == 1.0)) if self.square else None
        self.wall_val = ref[self.wall_idx] if self.square else None

    def project(self, p: np.ndarray) -> np.ndarray:
        """Clip points (P, d) to the box, in place; on the square, boundary vertices back onto their walls."""
        np.clip(p, 0.0, 1.0, out=p)
        if self.square:
            p[self.wall_idx] = self.wall_val
        return p


class _Equality:
    r""":math:`\mathrm{Std}(\tilde\rho_{\text{map}})` of maps of the ``N``-grid mesh of one vertex density."""

    def __init__(self, field: np.ndarray, n: int, d: int):
        self.n = n
        # populations: element means of the vertex density times the (equal) reference measures, by strided views
        mean = grid_element_mean(torch.from_numpy(field)[None], n, d)[0].numpy()
        self.pop = mean / (math.factorial(d) * (n - 1) ** d)

    def measures(self, x: np.ndarray) -> np.ndarray:
        return grid_signed_measures(torch.from_numpy(x)[None], self.n)[0].numpy()

    def std(self, x: np.ndarray | None = None) -> float:
        """Of the map ``x`` (N**d, d); of the identity when ``None``, whose elements keep their equal measures."""
        rho = self.pop if x is None else self.pop / self.measures(x)
        return float((rho / rho.mean()).std(ddof=1))


class _Run:
    """What one :func:`solve_flow` call carries from pass to pass: the counters, the stall retries and the free
    boundary's sea."""

    def __init__(self, dens: np.ndarray, elements: np.ndarray, opts: FlowOptions, box: _Box, warm: bool):
        self.dens, self.elements, self.opts, self.box, self.warm = dens, elements, opts, box, warm
        self.n = dens.shape[0]
        self.totals = {"steps": 0, "rejected": 0, "fold_rejections": 0, "evaluations": 0}
        self.stall_retries: list[float] = []
        self.sea: float | None = None
        self.sea_blend = opts.sea_blend
        self.sea_fallback = False  # whether a stalled first pass was redone with a blended sea
        self.fallback_tried = False

    def first_raster(self) -> np.ndarray:
        """The density raster of a cold start: the P1 upsampled density, with a free boundary in its sea."""
        if self.box.square:
            return p1_upsample(self.dens, int(self.opts.refine))
        raster, self.sea, self.sea_blend = _sea_raster(self.dens, self.box.pad, int(self.opts.refine), self.sea_blend)
        return raster

    def residual_raster(self, mapped: np.ndarray, y: np.ndarray, eq: _Equality) -> np.ndarray:
        """The residual density of the map ``mapped`` (box points ``y``), located exactly on the raster."""
        meas = eq.measures(mapped)
        rho = eq.pop / meas
        fill = 1.0
        if not self.box.square:  # the sea: the domain's mean residual density
            fill = float((rho * meas).sum() / meas.sum())
        vert = vertex_residual(self.elements, eq.pop, meas, len(mapped))
        return rasterize_elements(y, self.elements, vert / rho.mean(), self.box.m, fill / rho.mean(), at="vertices")

    def flow(self, raster: np.ndarray, y: np.ndarray, passes: int, bar) -> np.ndarray:
        """The box points ``y`` carried by one pass over ``raster``; a stalled pass is redone, first (a free
        boundary's first cold pass) with a blended sea, then with the density blurred over ``stall_blurs``."""
        opts, box, n = self.opts, self.box, self.n
        width = opts.blur * 0.5 ** passes
        retry = 0
        while True:
            fp = _FlowPass(raster, width / (n - 1) / box.scale)
            try:
                y_next, info = fp.run(y, lambda x: _turned_over(x, n), box.project, h=1.0 / (box.nb - 1),
                                      rtol=float(opts.rtol), max_steps=int(opts.max_steps), bar=bar)
            except Stalled as exc:
                self.totals["evaluations"] += fp.velocity.evaluations
                if (not box.square and not self.warm and passes == 0 and self.sea_blend == 0
                        and opts.stall_blend > 0 and not self.fallback_tried):
                    self.fallback_tried = True
                    # first remedy: the coast's jump to the sea is what collapses an element; blend it
                    raster, self.sea, self.sea_blend = _sea_raster(self.dens, box.pad, int(opts.refine),
                                                                   opts.stall_blend)
                    self.sea_fallback = self.sea_blend > 0
                    if self.sea_fallback:
                        continue
                if retry == len(opts.stall_blurs):
                    raise RuntimeError(f"flow map stalled with the density blurred over {width:g} grid "
                                       f"spacings: {exc}") from None
                # a density jump sharper than the mesh: blur it (as cartogram programs do) and redo the pass
                width = max(width, opts.stall_blurs[retry])
                self.stall_retries.append(width)
                retry += 1
                continue
            break
        for k in ("steps", "rejected", "fold_rejections"):
            self.totals[k] += info[k]
        self.totals["evaluations"] += fp.velocity.evaluations
        return y_next


def _checked_start(start, ref: np.ndarray, box: _Box, eq: _Equality, boundary: str) -> np.ndarray:
    """``start`` as a float64 copy; ``ValueError`` unless it is a fold-free map of the grid's vertices in the box."""
    mapped = np.array(start, dtype=np.float64)
    if mapped.shape != ref.shape:
        raise ValueError(f"start must have shape {ref.shape}, got {mapped.shape}")
    if not np.isfinite(mapped).all():
        raise ValueError("start contains NaN or infinite values")
    y_chk = (mapped + box.shift) / box.scale
    if y_chk.min() < -1e-9 or y_chk.max() > 1 + 1e-9:
        raise ValueError(f"start leaves the box of the {boundary!r} boundary")
    if eq.measures(mapped).min() <= 0:
        raise ValueError("start has folded (non-positively oriented) elements")
    return mapped


def solve_flow(density, options: FlowOptions | None = None, *, start=None, progress: bool = False,
               **kwargs) -> MapResult:
    r"""Flow-based density-equalizing map (Gastner, Seguy & More 2018) of the unit square or cube.

    Every vertex follows :math:`\dot x = -\nabla\phi(x) / ((1-t)\rho_0(x) + t\bar\rho)` for :math:`0 \le t \le 1`,
    :math:`\Delta\phi = \bar\rho - \rho_0` with no-flux walls, in passes until the density left on the mapped mesh
    is uniform to ``tol`` (:mod:`rfmap.solvers.flow` gives the numerical method).

    Parameters
    ----------
    density : ndarray, shape (N, N) or (N, N, N)
        Vertex densities on the ``N``-grid (strictly positive, finite; any positive scale).  ``N >= 3``.  A constant
        grid, of any value (:func:`rfmap.solvers.raster.check_grid_density`), is mapped to the identity exactly
        (no pass) when there is no ``start``.
    options : FlowOptions, optional
        The solver's options (:class:`FlowOptions`: ``boundary``, ``tol``, ``rtol``, ``refine``, ``margin``,
        ``sea_blend``, ``stall_blend``, ``max_passes``, ``stall``, ``blur``, ``max_steps``, ``stall_blurs``,
        ``num_threads``, ``keep_best``); its defaults when ``None``.
    start : ndarray, shape (N**d, d), optional
        A fold-free map of the grid's vertices to start from (for ``"square"`` inside the unit square/cube with
        boundary vertices on their walls; for ``"free"`` inside the sea box).  The first pass then flows the density
        that this map leaves on its image.
    progress : bool
        Show a ``tqdm`` progress bar over the time of each pass.
    **kwargs
        Fields of :class:`FlowOptions` that replace those of ``options`` (``solve_flow(d, boundary="free")``).

    Returns
    -------
    MapResult
        ``kind="density"``, ``field`` the vertex densities (N**d,), ``time`` the wall-clock seconds; ``info`` holds
        ``method="flow"``, ``passes``, ``steps`` / ``rejected`` / ``fold_rejections`` / ``evaluations`` summed over
        the passes, ``std_history`` (:math:`\mathrm{Std}(\tilde\rho_{\text{map}})` after each pass, preceded by the
        starting map's), ``eval_grid`` (``M``), ``box_grid``, ``rtol`` (the step tolerance used), ``stall_blurs``
        (the blur widths, in vertex spacings, of passes redone after a stall; usually empty) and, for ``"free"``,
        ``sea_density``.

    Raises
    ------
    ValueError
        For a bad density (as :func:`rfmap.solvers.diffusion.solve_diffusion`), an unknown ``boundary``, non-positive
        ``tol``/``rtol``/``margin``/``refine``/``max_passes``, ``stall`` outside (0, 1], or a ``start`` of the wrong
        shape, with non-finite values, outside the box, or folded.
    TypeError
        For a keyword that is not a field of :class:`FlowOptions`.
    """
    t_start = time.perf_counter()
    opts = replace(options or FlowOptions(), **kwargs)
    if opts.boundary not in DEM_BOUNDARIES:
        raise ValueError(f"unknown boundary {opts.boundary!r} for the flow solver; choose one of {DEM_BOUNDARIES}")
    dens = check_grid_density(density)
    opts = opts.checked(dens.ndim)
    d, n = dens.ndim, dens.shape[0]
    mesh = grid_mesh(n, d)
    ref, elements = mesh.points, mesh.elements
    field = dens.reshape(-1)
    box, eq = _Box(ref, n, opts), _Equality(field, n, d)
    run = _Run(dens, elements, opts, box, warm=start is not None)
    if start is None:
        mapped, raster = ref.copy(), run.first_raster()
    else:
        mapped, raster = _checked_start(start, ref, box, eq, opts.boundary), None
    # a uniform density left on the identity is equal already: no pass runs, the identity is returned exactly
    history = [0.0 if start is None and is_uniform(dens) else eq.std(None if start is None else mapped)]
    best, best_std = mapped, history[0]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=1.0, desc=f"flow {d}D N={n}", leave=False,
                   bar_format="{l_bar}{bar}| t={n:.4f}/1 [{elapsed}<{remaining}]")
    passes = 0
    threads = opts.num_threads if opts.num_threads is not None else (1 if d == 2 else None)
    try:
        with torch_threads(threads):
            while passes < opts.max_passes and best_std > opts.tol:
                y = box.project((mapped + box.shift) / box.scale)
                if raster is None:  # the residual density of the current map, located exactly on the raster
                    raster = run.residual_raster(mapped, y, eq)
                if bar is not None:
                    bar.set_description(f"flow {d}D N={n} pass {passes + 1}")
                    bar.n = 0
                    bar.refresh()
                y = run.flow(raster, y, passes, bar)
                passes += 1
                raster = None
                mapped = y * box.scale - box.shift
                if box.square:
                    mapped = box.project(mapped)
                history.append(eq.std(mapped))
                if history[-1] < best_std:
                    best, best_std = mapped, history[-1]
                if not history[-1] < opts.stall * history[-2]:
                    break
    finally:
        if bar is not None:
            bar.close()
    info = {"method": "flow", "boundary": opts.boundary, "n": n, "dim": d, "passes": passes, **run.totals,
            "std_history": history, "warm_start": start is not None, "eval_grid": box.m, "box_grid": box.nb,
            "rtol": float(opts.rtol), "stall_blurs": run.stall_retries}
    if run.sea is not None:
        info.update(sea_density=run.sea, sea_blend=float(run.sea_blend), sea_fallback=run.sea_fallback)
    return MapResult(ref_points=ref, mapped_points=best if opts.keep_best else mapped, elements=elements, field=field,
                     kind="density", time=time.perf_counter() - t_start, info=info)
