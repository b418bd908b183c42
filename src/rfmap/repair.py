r"""Making a computed map bijective: detect folded elements and repair them, in 2D and 3D.

A piecewise-linear map of a simplicial mesh is *folded* when an element has a non-positive signed measure
(:math:`\det J \le 0`).  With every element positively oriented, a map that keeps the boundary of the unit square or
cube on itself (``fixed`` or ``square`` boundary conditions) is a bijection of the domain onto itself (degree
argument); with a ``free`` boundary the image of the boundary must also be embedded: a simple polygon in 2D, a
surface without self-intersection in 3D (:func:`rfmap.surface.surface_intersections` on the mesh's boundary
triangles, an extra pass on every free 3D map: two far-apart parts of the surface pushed through each other leave
every tetrahedron positive).

:func:`repair_map` is the entry point.  It first runs a cheap check (strided grid measures,
:func:`rfmap.geometry.grid_signed_measures`, and on a free 2D boundary a bucketed segment-crossing test) and returns
the map untouched when nothing is folded.  Otherwise:

**2D, grid meshes: μ-truncation and the Linear Beltrami Solver.**  The Beltrami coefficient of the current map is
computed per triangle (paper Eq. (1)); a flipped triangle has :math:`|\mu| > 1`.  Every coefficient is radially
truncated,

.. math:: \mu \leftarrow \mu \, \min\Bigl(1, \frac{1 - \delta}{|\mu|}\Bigr), \qquad \delta = 0.1,

and the map is rebuilt from the truncated :math:`\mu` by :func:`rfmap.solvers.solve_lbs` with the model's boundary
condition: the identity on the boundary (``fixed``), vertices sliding on their walls (``square``), or the boundary
vertices where the network put them (``free``), after moving crossing boundary vertices back towards the square until
the boundary polygon is simple (:func:`untangle_boundary`).  Where the map was not folded and :math:`|\mu| \le 1 - \delta`
the coefficient is unchanged (flipped triangles get :math:`\mu = 0`, see :func:`cap_mu`), and the LBS reproduces a piecewise-linear map from its own coefficient, so the rebuilt
map stays close to the input.  The discrete LBS has no bijectivity theorem (its stiffness weights may be negative),
so its output is checked and, if still folded, handed to the displacement scaling below.

The rebuild is first tried on a patch (:func:`local_lbs_repair`): the truncated triangles grown by 2, 4, 8, then 16
vertex rings, the patch's rim and the domain boundary held where the map put them.  Folds of a network map are
usually a few small clusters, so a patch solve costs a fraction of the global one and leaves the rest of the map
exactly as the network made it.  Widespread folds (over 1 % of the triangles), a free boundary that crosses itself,
or a patch that stays folded go to the global rebuild.

**3D free boundary: an embedded surface.**  When the boundary surface of a fold-free 3D map crosses itself,
:func:`surface_repair` shortens the whole displacement, :math:`u_s = x + s\,(u - x)`, to the largest ``s`` found by
halving and bisection at which the map is fold-free and its surface embedded (``s = 0``, the identity, always is).
This is blunt (the whole map moves back, not only the crossing region), and it is rare: a network or solver map
would have to push one side of the cube through another.

**3D (and any mesh where the above does not apply): fold-free displacement scaling.**  Write the map as
:math:`u = x + d(x)` with the displacement :math:`d` (for a surrogate :math:`d = \mathcal{B} \odot \psi`).  The
identity (:math:`s = 0` in :math:`u_s = x + s\,d`) has every element positive, and every :math:`u_s` satisfies the
same boundary condition as :math:`u`.  For one element, :math:`\det E(s) = \det(E_x + s E_d)` is a polynomial of
degree :math:`d` in :math:`s` with :math:`\det E(0) > 0`, so its first root :math:`s_T` in :math:`(0, 1]` is computed
exactly (closed form in 2D, companion-matrix eigenvalues in 3D) for the elements that a cheap test cannot clear: a
polynomial is a convex combination of its Bernstein coefficients on :math:`[0, 1]`, so when they are all positive it
has no root there.  The largest fold-free uniform scale is
:math:`s^\* = \min_T s_T`, and the map :math:`u_{s^\*}` is fold-free.  Then the per-vertex scale :math:`s_v` is raised
locally towards 1 by bisection: a proposed raise is kept unless an element touching the vertex would drop below its
threshold, in which case the vertices of every such element go back to their accepted values (repeating until no
element fails, which ends because the accepted state passes).  On grid meshes the raises of a round go class by
class (:func:`vertex_classes`: the :math:`2^d` parities of the grid coordinates, no two of one class in an element),
Gauss–Seidel fashion, so an element that fails has a single raised vertex and only that one goes back; raising all
vertices at once would also send back the element's other vertices, whose raises were fine.  Each round first tries
the raise of all active vertices at once and keeps it when no element fails (a fold-free target is then recovered
in one step, where a class-by-class sweep could stall in a failing intermediate state).
Vertices far from the folds thus recover the input map
exactly and only a neighbourhood of the folds keeps a shortened displacement.  When the folds are local, the start
itself is local: :math:`s^\*` on the elements whose polynomial has a root in :math:`(0, 1)`, rising linearly to
:math:`s = 1` over 6, 12 or 24 vertex rings around them (grown only as far as the start being tried needs), if one of
these states verifies (else the uniform start), so the rounds touch only that region.  Only the elements touching a
vertex with :math:`s_v < 1` are evaluated to verify a local start: every other element keeps the target, which the
root test cleared.  The cost thus follows the size of the folded region, not of the mesh, apart from one pass over
all elements for the polynomial coefficients.

Why the result is fold-free: every accepted state is *verified* by direct evaluation of all element measures that
changed, the starting state :math:`u_{s^\*}` is verified the same way (halving :math:`s` until it passes, the identity
being the last resort), and a rejected proposal restores an accepted state.  So the returned map has every element
measure above a positive threshold :math:`\tau_T` (a fraction :math:`\eta = 0.05` of the reference measure for
elements that were folded, :math:`\min(\eta |T|, \tfrac12 |u(T)|)` for the others) whatever the root-finding accuracy.

References
----------
G. P. T. Choi, C. H. Rycroft, "Density-equalizing maps for simply connected open surfaces", SIAM J. Imaging Sci.
11(2), 1134–1178 (2018) (μ-truncation and LBS reconstruction to keep density-equalizing maps bijective).
"""
from __future__ import annotations

import math
import time
from typing import Any, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import torch

from .geometry import beltrami_coefficient, grid_element_mean, grid_min_measure, grid_signed_measures, grid_simplices, \
    signed_measures
from .mesh import grid_points
from .metrics import density_std
from .surface import boundary_crossings, boundary_faces, boundary_loop, grid_surface_intersections, \
    surface_intersections

__all__ = ["repair_map", "fold_free", "cap_mu", "untangle_boundary", "scale_repair", "surface_repair", "lbs_repair",
           "shorten_map", "vertex_classes", "DELTA", "SHORTEN_SAMPLES"]

#: Margin of the μ-truncation: :math:`|\mu| \le 1 - \delta` after repair.
#: the ``method`` values of :func:`repair_map`
REPAIR_METHODS = ("auto", "local", "lbs", "scale")
DELTA = 0.1
#: Fraction of the reference measure that a formerly folded element must reach in the displacement scaling.
ETA = 0.05


# ----------------------------------------------------------------------------------------------- detection
def _measures(points: np.ndarray, elements: np.ndarray, grid_n: int | None) -> np.ndarray:
    p = torch.as_tensor(np.asarray(points, dtype=np.float64))
    if grid_n is not None:
        return grid_signed_measures(p[None], grid_n)[0].numpy()
    return signed_measures(p, torch.as_tensor(np.asarray(elements))).numpy()


def fold_free(points: np.ndarray, elements: np.ndarray, *, grid_n: int | None = None,
              boundary: str = "fixed") -> bool:
    """True when every element has positive measure (and, for a free 2D grid boundary, the boundary is simple).

    ``grid_n``: the mesh is :func:`rfmap.mesh.grid_mesh` ``(N, d)`` and the strided measures are used (fast path).
    """
    if not np.isfinite(points).all():
        return False
    if (grid_min_measure(points, grid_n) if grid_n else _measures(points, elements, None).min()) <= 0:
        return False
    if boundary == "free" and points.shape[1] == 2 and grid_n is not None:
        return len(boundary_crossings(points[boundary_loop(grid_n)])) == 0
    if boundary == "free" and points.shape[1] == 3:
        return _surface_crossings(points, elements, grid_n) == 0
    return True


def _surface_crossings(points: np.ndarray, elements: np.ndarray, grid_n: int | None) -> int:
    """Number of intersecting pairs of boundary triangles of a 3D map (:func:`rfmap.surface.surface_intersections`,
    on a grid mesh :func:`rfmap.surface.grid_surface_intersections`)."""
    if grid_n:
        return len(grid_surface_intersections(points, grid_n))
    return len(surface_intersections(points, boundary_faces(np.asarray(elements))))


def surface_repair(ref: np.ndarray, mapped: np.ndarray, elements: np.ndarray, *, grid_n: int | None = None,
                   rounds: int = 8) -> tuple[np.ndarray, float]:
    r"""Shorten the displacement of a fold-free 3D free-boundary map until its boundary surface is embedded.

    :math:`u_s = x + s\,(u - x)`: ``s = 1`` is the input, ``s = 0`` the identity (embedded).  ``s`` is halved until
    :math:`u_s` is fold-free with an embedded boundary, then raised by bisection (``rounds`` steps) between the
    last passing and the first failing value; every returned state is verified by :func:`fold_free`.

    Returns
    -------
    (points, s)
    """
    ref = np.asarray(ref, np.float64)
    disp = np.asarray(mapped, np.float64) - ref

    def ok(s: float) -> bool:
        return fold_free(ref + s * disp, elements, grid_n=grid_n, boundary="free")

    hi, lo = 1.0, 0.0
    s = 0.5
    while s > 1e-3:
        if ok(s):
            lo = s
            break
        hi, s = s, s / 2
    for _ in range(rounds if lo > 0 else 0):
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return ref + lo * disp, lo


#: Uniform samples of the scale in :func:`shorten_map` before the golden-section refinement around the best
SHORTEN_SAMPLES = 10


def shorten_map(ref: np.ndarray, mapped: np.ndarray, density: np.ndarray, n: int | None = None, *, boundary: str,
                elements: np.ndarray | None = None, samples: int = SHORTEN_SAMPLES,
                rounds: int = 12) -> tuple[np.ndarray, dict[str, Any]]:
    r"""The most equal fold-free map among the shortened maps :math:`u_s = x + s\,(u - x)`, :math:`0 \le s \le 1`.

    A density map that leaves the density less equal than it was (a field unlike a surrogate's training fields, or
    a repair that had to squeeze a region) is worse than no map at all: the identity (:math:`s = 0`) leaves
    :math:`\mathrm{Std}(\tilde\rho_{\text{map}}) = \mathrm{Std}(\tilde\rho_{\text{orig}})`.  Along the segment
    from the identity to the map, the objective

    .. math:: J(s) = \mathrm{Std}(\tilde\rho(u_s)) \text{ if } u_s \text{ is fold-free (and, on a free boundary,
       embedded; :func:`fold_free`)}, \quad +\infty \text{ otherwise},

    is sampled at ``samples + 1`` equally spaced scales (both ends included) and refined by ``rounds`` golden-section
    steps between the neighbours of the best sample.  The returned map is never less equal than either end: it is at
    least as good as the input map when that is fold-free, and as the identity in any case.  Every :math:`u_s`
    keeps the boundary condition of :math:`u` (walls stay walls; the identity and the map both satisfy it and the
    condition is linear).

    Parameters
    ----------
    ref, mapped : ndarray, shape (P, d)
        The mesh's vertices and their images: the ``N``-grid (:func:`rfmap.mesh.grid_points` order, ``P = N**d``)
        with ``n``, or any simplicial mesh with ``elements``.
    density : ndarray, shape (P,)
        Vertex densities (the population of an element is its mean vertex density times its measure, as in
        :mod:`rfmap.metrics`).
    n : int, optional
        Grid side (the fast strided measures of the grid mesh).
    boundary : {"fixed", "square", "free"}
        Selects the embedding check of :func:`fold_free` (free boundaries).
    elements : int ndarray, shape (m, d+1), optional
        The elements of a general mesh (e.g. the Delaunay mesh of query points); exactly one of ``n`` and
        ``elements`` is given.

    Returns
    -------
    (points, report)
        ``report``: ``scale`` (the chosen :math:`s`), ``std_before`` (of the input map; ``inf`` if folded),
        ``std_identity``, ``std_after``, ``evaluations``, ``time`` (s) and ``curve``, the evaluated
        ``[s, J(s)]`` pairs in increasing ``s``.
    """
    t0 = time.perf_counter()
    ref = np.asarray(ref, np.float64)
    disp = np.asarray(mapped, np.float64) - ref
    d = ref.shape[1]
    if (n is None) == (elements is None):
        raise ValueError("shorten_map needs exactly one of n (a grid mesh) and elements (a general mesh)")
    if ref.shape != disp.shape or (n is not None and ref.shape[0] != n ** d):
        want = f"the N-grid's {n ** d} points" if n is not None else "matching points"
        raise ValueError(f"shorten_map needs {want} and their images; got {ref.shape} and {disp.shape}")
    if samples < 1 or rounds < 0:
        raise ValueError(f"samples must be at least 1 and rounds non-negative, got {samples} and {rounds}")
    dens = torch.as_tensor(np.asarray(density, dtype=np.float64)).reshape(1, -1)
    if dens.shape[1] != ref.shape[0]:
        raise ValueError(f"density has {dens.shape[1]} values for {ref.shape[0]} vertices")
    if n is not None:  # equal reference measures: the element means are the populations up to a common factor
        pop = grid_element_mean(dens, n, d)[0]
    else:
        el = np.asarray(elements)
        pop = dens[0, torch.as_tensor(el)].mean(-1) * torch.as_tensor(_measures(ref, el, None))
    cache: dict[float, float] = {}

    def J(s: float) -> float:
        if s not in cache:
            pts = ref + s * disp
            ok = s == 0.0 or fold_free(pts, elements, grid_n=n, boundary=boundary)
            meas = torch.as_tensor(_measures(pts, elements, n))
            cache[s] = density_std(pop, meas) if ok else math.inf
        return cache[s]

    grid = [k / samples for k in range(samples + 1)]
    vals = [J(s) for s in grid]
    k = int(np.argmin(vals))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, samples)]
    g = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    for _ in range(rounds):
        if J(a) <= J(b):
            hi, b = b, a
            a = hi - g * (hi - lo)
        else:
            lo, a = a, b
            b = lo + g * (hi - lo)
    best = min(cache, key=lambda s: (cache[s], -s))
    report = {"scale": float(best), "std_before": cache[1.0], "std_identity": cache[0.0], "std_after": cache[best],
              "evaluations": len(cache), "time": time.perf_counter() - t0,
              "curve": [[float(k), cache[k]] for k in sorted(cache)]}
    return (np.asarray(mapped) if best == 1.0 else ref + best * disp), report


# ----------------------------------------------------------------------------------------------- 2D: μ and LBS
def cap_mu(mu: np.ndarray, delta: float = DELTA) -> tuple[np.ndarray, np.ndarray]:
    r"""Truncate a Beltrami coefficient into the disk :math:`|\mu| \le 1 - \delta`.

    Orientation-preserving triangles with :math:`1 - \delta < |\mu| < 1` are truncated radially,
    :math:`\mu \leftarrow \mu\,(1-\delta)/|\mu|`; flipped triangles (:math:`|\mu| \ge 1`, where :math:`\mu` no
    longer describes a distortion of the triangle) and non-finite values get :math:`\mu = 0`.  (Truncating a flipped
    triangle radially to :math:`1 - \delta`, or reflecting it to :math:`1/\bar\mu`, leaves most single-vertex folds
    in place after the LBS solve; :math:`\mu = 0` removes them.)

    Returns
    -------
    (capped, mask) : complex ndarray (m,) and the boolean mask of the changed entries.
    """
    mu = np.asarray(mu, dtype=np.complex128)
    bad = ~np.isfinite(mu)
    a = np.abs(np.where(bad, 0, mu))
    over = a > 1 - delta
    out = np.where(over, mu * ((1 - delta) / np.maximum(a, 1e-300)), mu)
    out[bad | (a >= 1)] = 0
    return out, over | bad


def untangle_boundary(ref_b: np.ndarray, mapped_b: np.ndarray, *, max_rounds: int = 30) -> np.ndarray:
    r"""Move boundary vertices towards their reference positions until the boundary polygon is simple.

    The polygon :math:`q_v = x_v + t_v (p_v - x_v)` starts at :math:`t = 1`; the endpoints of every crossing edge
    get :math:`t_v \leftarrow t_v / 2`, round after round.  If crossings remain after ``max_rounds``, a uniform
    :math:`t` is halved instead; :math:`t = 0` is the square itself, which is simple.

    Parameters
    ----------
    ref_b, mapped_b : ndarray, shape (k, 2), in boundary order (:func:`boundary_loop`)
    """
    ref_b, mapped_b = np.asarray(ref_b, np.float64), np.asarray(mapped_b, np.float64)
    t = np.ones(len(ref_b))
    for _ in range(max_rounds):
        q = ref_b + t[:, None] * (mapped_b - ref_b)
        c = boundary_crossings(q)
        if len(c) == 0:
            return q
        v = np.unique(np.concatenate([c.ravel(), (c.ravel() + 1) % len(q)]))
        t[v] *= 0.5
    s = 1.0
    while s > 1e-6:
        s *= 0.5
        q = ref_b + s * t[:, None] * (mapped_b - ref_b)
        if len(boundary_crossings(q)) == 0:
            return q
    return ref_b.copy()


def lbs_repair(mapped: np.ndarray, n: int, boundary: str, delta: float = DELTA,
               passes: int = 3) -> tuple[np.ndarray, np.ndarray]:
    r"""Rebuild a 2D grid map from its truncated Beltrami coefficient with the Linear Beltrami Solver.

    Up to ``passes`` times: :math:`\mu` of the current map, :func:`cap_mu`, LBS; stops as soon as no triangle is
    flipped.

    Parameters
    ----------
    mapped : ndarray, shape (N**2, 2)
        The map on :func:`rfmap.mesh.grid_mesh` ``(N, 2)``.
    boundary : {"fixed", "square", "free"}
        ``fixed``: identity on the boundary; ``square`` and ``free``: Dirichlet values at the boundary positions of
        ``mapped``, untangled by :func:`untangle_boundary`.  On the square the vertices stay on their walls, as
        ``mapped`` keeps them there and the untangling only shortens displacements; if a vertex has passed its
        neighbour along a wall, the walls slide instead (:func:`rfmap.solvers.solve_lbs`, ``boundary="square"``).
        Keeping the map's own boundary needs one factorisation for both components, where sliding walls need one
        per component: at N = 160 on folded ``deq2d-square`` outputs, half the time and a 2 % lower
        Std(rho~_map) than sliding walls.

    Returns
    -------
    (points, capped) : the rebuilt map (N**2, 2) and the mask of the triangles whose :math:`\mu` was truncated.
    """
    from .mesh import grid_mesh
    from .solvers.lbs import solve_lbs

    mesh = grid_mesh(n, 2)
    ref_t, el_t = torch.as_tensor(mesh.points), torch.as_tensor(mesh.elements)
    bv = None
    if boundary in ("free", "square"):
        loop = boundary_loop(n)
        bv = mesh.points.copy()
        bv[loop] = untangle_boundary(mesh.points[loop], mapped[loop])
        if boundary == "square":
            # on the walls, every boundary edge must keep its direction (a vertex that passed its neighbour along a
            # wall folds back on a straight line, which no crossing test sees); otherwise the walls slide
            q, x = bv[loop], mesh.points[loop]
            if (((np.roll(q, -1, 0) - q) * (np.roll(x, -1, 0) - x)).sum(1) <= 0).any():
                bv = None
    capped = np.zeros(len(mesh.elements), bool)
    out = np.asarray(mapped, np.float64)
    for _ in range(passes):
        mu = beltrami_coefficient(ref_t, torch.as_tensor(out), el_t).numpy()
        mu_c, mask = cap_mu(mu, delta)
        capped |= mask
        if bv is None:
            out = solve_lbs(mu_c, n, boundary=boundary).mapped_points
        else:
            out = solve_lbs(mu_c, n, boundary="fixed", boundary_values=bv).mapped_points
        if _measures(out, mesh.elements, n).min() > 0:
            break
    return out, capped


#: ring counts of the successive patches of :func:`local_lbs_repair`
LOCAL_RINGS = (2, 4, 8, 16)
#: a patch larger than this fraction of the vertices (and than ``LOCAL_MIN_GIVE_UP`` vertices) is given up for the
#: global :func:`lbs_repair`
LOCAL_MAX_FRACTION = 0.25
LOCAL_MIN_GIVE_UP = 2000
#: more truncated triangles than this fraction of all (and than 100) go straight to the global :func:`lbs_repair`
LOCAL_MAX_CAPPED = 0.01


def local_lbs_repair(mapped: np.ndarray, n: int, boundary: str, delta: float = DELTA, *,
                     rings: Sequence[int] = LOCAL_RINGS, max_fraction: float = LOCAL_MAX_FRACTION,
                     passes: int = 3) -> tuple[np.ndarray, np.ndarray] | None:
    r"""Rebuild a 2D grid map from its truncated Beltrami coefficient on a patch around the folds only.

    The triangles whose :math:`\mu` :func:`cap_mu` changes (flipped, :math:`|\mu| > 1 - \delta`, non-finite) are
    grown by ``r`` vertex rings.  On the patch of triangles touching the grown vertices, the LBS system
    :math:`\nabla\cdot(A\nabla u) = 0` with the truncated :math:`\mu` is solved for the grown vertices off the
    domain boundary; every other vertex of the patch keeps its position (Dirichlet values).  As in
    :func:`lbs_repair`, up to ``passes`` times the :math:`\mu` of the rebuilt patch is truncated again and the
    patch solved again while a triangle is flipped (the discrete LBS has no bijectivity theorem).  Patches of
    ``rings[0]``, ``rings[1]``, ... rings are tried until one ends fold-free (or folds remain that touch no vertex
    of the patch's rim, which a larger patch would not undo).  Outside the patch the map is not touched, and the
    cost is that of sparse solves the size of the patch.

    Returns
    -------
    (points, capped) as :func:`lbs_repair`, or ``None`` when more than ``LOCAL_MAX_CAPPED`` of the triangles (and
    more than 100) are truncated, when no patch of at most ``rings[-1]`` rings and
    ``max_fraction`` of the vertices (or ``LOCAL_MIN_GIVE_UP`` vertices on small grids) ends fold-free, or when a free boundary crosses itself (boundary vertices keep
    their positions in a local solve, so only :func:`lbs_repair` can untangle it).
    """
    from .mesh import grid_mesh
    from .solvers.lbs import assemble_stiffness, beltrami_matrices

    mesh = grid_mesh(n, 2)
    el = mesh.elements
    n_pts = mesh.points.shape[0]
    out = np.where(np.isfinite(mapped), mapped, mesh.points).astype(np.float64)
    if boundary == "free" and len(boundary_crossings(out[boundary_loop(n)])):
        return None
    ref_t = torch.as_tensor(mesh.points)
    mu = beltrami_coefficient(ref_t, torch.as_tensor(out), torch.as_tensor(el)).numpy()
    mu_c, capped = cap_mu(mu, delta)
    capped |= _measures(out, el, None) <= 0
    if not capped.any() or capped.sum() > max(LOCAL_MAX_CAPPED * len(el), 100):
        return None  # nothing to do, or folds so widespread that the global rebuild costs no more than a patch
    on_edge = mesh.boundary_mask()
    grown = np.zeros(n_pts, bool)
    grown[el[capped]] = True
    done = 0
    for r in sorted(rings):
        for _ in range(r - done):  # one more ring: every vertex of a triangle touching the set
            grown[el[grown[el].any(1)]] = True
        done = r
        free = np.flatnonzero(grown & ~on_edge)
        if free.size > max(max_fraction * n_pts, LOCAL_MIN_GIVE_UP):
            return None
        patch = np.flatnonzero(grown[el].any(1))
        el_p = el[patch]
        fixed = np.setdiff1d(np.unique(el_p), free)
        is_fixed = np.zeros(n_pts, bool)
        is_fixed[fixed] = True
        mu_p = mu_c[patch]
        for _ in range(passes):
            K = assemble_stiffness(mesh.points, el_p, beltrami_matrices(mu_p)).tocsc()
            rhs = -(K[free][:, fixed] @ out[fixed])
            lu = spla.splu(sp.csc_matrix(K[free][:, free]), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
            trial = out.copy()
            trial[free] = lu.solve(np.ascontiguousarray(rhs))
            if not np.isfinite(trial).all():
                break
            meas = _measures(trial, el_p, None)
            if meas.min() > 0:
                hit = np.zeros(len(el), bool)
                hit[patch] = True
                return trial, capped & hit
            mu_p, more = cap_mu(beltrami_coefficient(ref_t, torch.as_tensor(trial), torch.as_tensor(el_p)).numpy(),
                                delta)
            capped[patch] |= more
        if np.isfinite(trial).all() and not is_fixed[el_p[meas <= 0]].any():
            return None  # folds left inside the patch, away from its rim: a larger patch would not help
    return None


# ----------------------------------------------------------------------------------------------- any dim: scaling
def _edges(PT: np.ndarray, cols: Sequence[np.ndarray], els=None) -> list[list[np.ndarray]]:
    """Edge vectors of elements as contiguous component arrays: ``E[i][j]`` is component ``j`` of the edge from
    vertex 0 to vertex ``i + 1``, shape (k,), for the elements ``els`` (all when ``None``).

    ``PT`` is the (d, n) transpose of the points and ``cols`` the d + 1 columns of the element array; gathering
    per component is several times faster than gathering (k, d, d) blocks."""
    idx = cols if els is None else [c[els] for c in cols]
    x0 = [row[idx[0]] for row in PT]
    return [[row[ik] - x0[j] for j, row in enumerate(PT)] for ik in idx[1:]]


def _det(E: list[list[np.ndarray]]) -> np.ndarray:
    """Determinant of the matrix with rows ``E[0], E[1](, E[2])`` (component arrays from :func:`_edges`)."""
    if len(E) == 2:
        return E[0][0] * E[1][1] - E[0][1] * E[1][0]
    a, b, c = E
    return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])


def _det_coefficients(E_ref: list[list[np.ndarray]], E_d: list[list[np.ndarray]]) -> np.ndarray:
    r"""Coefficients :math:`c_k` of :math:`\det(E_x + s E_d) = \sum_k c_k s^k`, shape (m, d+1).

    The determinant is multilinear in the rows, so :math:`c_k` sums the determinants with ``k`` rows taken from
    :math:`E_d` and the others from :math:`E_x` (rows: edge vectors from :func:`_edges`)."""
    d = len(E_ref)
    out = np.zeros((len(E_ref[0][0]), d + 1))
    for mask in range(2 ** d):
        rows = [E_d[i] if mask >> i & 1 else E_ref[i] for i in range(d)]
        out[:, bin(mask).count("1")] += _det(rows)
    return out


def _bernstein(c: np.ndarray) -> np.ndarray:
    r"""Bernstein coefficients on :math:`[0, 1]` of the polynomials ``sum_k c[:, k] s^k``, shape (m, deg+1).

    :math:`b_i = \sum_{k \le i} \binom{i}{k} / \binom{n}{k}\, c_k`; the polynomial is a convex combination of
    its Bernstein coefficients on :math:`[0, 1]`, so it is positive there when they all are."""
    deg = c.shape[1] - 1
    out = np.zeros_like(c)
    for i in range(deg + 1):
        for k in range(i + 1):
            out[:, i] += math.comb(i, k) / math.comb(deg, k) * c[:, k]
    return out


def _first_root(c: np.ndarray) -> np.ndarray:
    """Smallest root in (0, 1] of every polynomial ``sum_k c[:, k] s^k`` with ``c[:, 0] > 0``; 1 where none."""
    out = np.ones(len(c))
    if len(c) == 0:
        return out
    scale = np.abs(c).max(1)
    deg = c.shape[1] - 1
    roots = np.full((len(c), deg), np.nan, dtype=np.complex128)
    lead = np.abs(c[:, -1]) > 1e-12 * scale
    if deg == 3 and lead.any():
        cc = c[lead] / c[lead, 3:4]
        comp = np.zeros((len(cc), 3, 3))
        comp[:, 1, 0] = comp[:, 2, 1] = 1.0
        comp[:, :, 2] = -cc[:, :3]
        roots[lead] = np.linalg.eigvals(comp)
    quad = ~lead if deg == 3 else np.ones(len(c), bool)
    if quad.any():  # c0 + c1 s + c2 s^2 (c3 negligible in 3D)
        c0, c1, c2 = c[quad, 0], c[quad, 1], c[quad, 2]
        disc = np.sqrt((c1 * c1 - 4 * c0 * c2).astype(np.complex128))
        big = np.abs(c2) > 1e-12 * scale[quad]
        r1 = np.where(big, (-c1 + disc) / np.where(big, 2 * c2, 1), -c0 / np.where(c1 == 0, 1, c1))
        r2 = np.where(big, (-c1 - disc) / np.where(big, 2 * c2, 1), np.nan)
        roots[quad, 0], roots[quad, 1] = r1, r2
    real = np.abs(roots.imag) <= 1e-9 * np.maximum(1, np.abs(roots.real))
    r = np.where(real & (roots.real > 0) & (roots.real <= 1), roots.real, np.inf).min(1)
    return np.minimum(out, r)


def _thresholds(ref_meas: np.ndarray, target_meas: np.ndarray, eta: float) -> np.ndarray:
    folded = target_meas <= 0
    return np.where(folded, eta * ref_meas, np.minimum(eta * ref_meas, 0.5 * np.maximum(target_meas, 0)))


#: vertex rings over which the local start of :func:`scale_repair` rises from the uniform fold-free scale to 1
#: (each tried in turn until one verifies)
LOCAL_START_RINGS = (6, 12, 24)


def _unique_ids(idx: np.ndarray, size: int) -> np.ndarray:
    """Sorted distinct entries of ``idx`` (integers in ``[0, size)``): a mask for large inputs, a sort for small."""
    if len(idx) * 32 < size:  # sort and drop repeats (numpy's hashing np.unique is slower at these sizes)
        out = np.sort(idx)
        return out[np.concatenate(([True], out[1:] != out[:-1]))] if len(out) else out
    mark = np.zeros(size, bool)
    mark[idx] = True
    return np.flatnonzero(mark)


def scale_repair(ref: np.ndarray, target: np.ndarray, elements: np.ndarray, *, boundary: str = "fixed",
                 eta: float = ETA, rounds: int = 16) -> tuple[np.ndarray, dict]:
    r"""Fold-free map closest to ``target`` among :math:`u_v = x_v + s_v (t_v - x_v)`, :math:`s_v \in [0, 1]`.

    See the module docstring: a verified fold-free uniform scale :math:`s^\*` (first root of the per-element
    determinant polynomials; applied only on the unsafe elements and rising linearly to 1 over 6, 12 or 24
    vertex rings around them (``LOCAL_START_RINGS``), when such a start verifies), then ``rounds`` rounds of per-vertex bisection of :math:`s_v` towards 1 that keep
    every element above its threshold.  Works on any simplicial mesh in 2D or 3D and keeps the boundary condition
    of ``target`` (the displacement is only shortened).

    Parameters
    ----------
    ref, target : ndarray, shape (n, d)
    elements : int ndarray, shape (m, d+1), positively oriented on ``ref``
    boundary : str
        With ``"free"`` in 2D the boundary polygon of a grid mesh must also stay simple.

    Returns
    -------
    (points, info) : the repaired map (n, d) and ``{"s_uniform", "start", "affected", "classes"}``: the scale
    :math:`s^\*`, ``"local (R rings)"`` or ``"uniform"``, the vertices left with :math:`s_v < 1`, and the number of
    vertex classes raised in turn (:func:`vertex_classes`; 1 on meshes that are not grids).
    """
    ref = np.asarray(ref, np.float64)
    target = np.asarray(target, np.float64)
    el = np.asarray(elements, np.int64)
    n_pts, d = ref.shape
    disp = np.where(np.isfinite(target), target - ref, 0.0)
    cols = [np.ascontiguousarray(el[:, k]) for k in range(d + 1)]
    refT, dispT = np.ascontiguousarray(ref.T), np.ascontiguousarray(disp.T)
    coef = _det_coefficients(_edges(refT, cols), _edges(dispT, cols))
    ref_meas = coef[:, 0]
    tau = _thresholds(ref_meas, coef.sum(1), eta)
    q = coef.copy()
    q[:, 0] -= tau
    safe = (_bernstein(q) > 0).all(1)  # q > 0 on [0, 1] when its Bernstein coefficients are
    sus = np.flatnonzero(~safe)
    roots = _first_root(q[sus])
    s_star = float(roots.min()) if len(sus) else 1.0
    sus = sus[(roots < 1.0) | (q[sus].sum(1) <= 0)]  # elements with no root in (0, 1) are safe too
    loop = None
    if boundary == "free" and d == 2:
        side = round(n_pts ** 0.5)
        if side * side == n_pts and np.allclose(ref, grid_points(side, 2)):
            loop = boundary_loop(side)

    on_loop = np.zeros(n_pts, bool)
    loop_pos = np.full(n_pts, -1)
    if loop is not None:
        on_loop[loop] = True
        loop_pos[loop] = np.arange(len(loop))

    def failing(u, els, moved=None):
        """Vertices to revert: those of elements below threshold (and of crossing free-boundary edges; the
        boundary is only re-checked when a vertex in ``moved`` lies on it, since nothing else can change it)."""
        # a contiguous transpose pays for many elements; for a few, strided gathers from u.T are cheaper
        det = _det(_edges(u.T if len(els) * 8 < n_pts else np.ascontiguousarray(u.T), cols, els))
        bad = els[~(det >= tau[els])]
        v = el[bad].ravel()
        if loop is not None and (moved is None or on_loop[moved].any()):
            # a crossing needs a moved boundary vertex: the edges on either side of each one
            pos = None if moved is None else loop_pos[moved[on_loop[moved]]]
            c = boundary_crossings(u[loop], None if pos is None else np.concatenate([pos, pos - 1]))
            if len(c):
                v = np.concatenate([v, loop[c.ravel()], loop[(c.ravel() + 1) % len(loop)]])
        return _unique_ids(v, n_pts)

    # vertex -> elements incidence, for evaluating only the elements touched by a change
    order = np.argsort(el.ravel(), kind="stable")
    el_of = order // (d + 1)
    starts = np.searchsorted(el.ravel()[order], np.arange(n_pts + 1))

    def touching(verts):
        if len(verts) == 0:
            return np.zeros(0, np.int64)
        first, count = starts[verts], starts[verts + 1] - starts[verts]
        pos = np.repeat(first - np.cumsum(count) + count, count) + np.arange(int(count.sum()))
        return _unique_ids(el_of[pos], len(el))

    all_el = np.arange(len(el))
    s0 = 0.999 * s_star
    s, start = None, "uniform"
    if len(sus):
        # a local start: the uniform scale only on the unsafe elements grown by LOCAL_START_RINGS vertex rings, the
        # target elsewhere; used when it verifies (most folds are small clusters), the uniform start otherwise
        top = max(LOCAL_START_RINGS)
        ring = np.full(n_pts, float(top))  # vertex rings away from the unsafe elements (capped at the largest)
        near = np.zeros(n_pts, bool)
        near[el[sus]] = True
        ring[near] = 0
        front = np.flatnonzero(near)
        grown, wide = 0, False  # rings computed so far (grown only as far as the start being tried needs)
        for rings in LOCAL_START_RINGS:  # s* on them, rising linearly to 1 over `rings` rings
            while grown < rings - 1 and not wide:
                grown += 1
                front = _unique_ids(el[touching(front)].ravel(), n_pts)
                front = front[~near[front]]
                near[front] = True
                ring[front] = grown
                wide = near.sum() > 0.5 * n_pts
            cand = s0 + (1.0 - s0) * np.minimum(ring / rings, 1.0)
            if (cand < 1).sum() > 0.5 * n_pts:
                break
            # elements with every vertex at s = 1 keep the target, where they are safe
            if len(failing(ref + cand[:, None] * disp, touching(np.flatnonzero(cand < 1)))) == 0:
                s, start = cand, f"local ({rings} rings)"
                break
    while s is None:  # verify the uniform start; the identity (s = 0) always passes
        s = np.full(n_pts, s0)
        if s0 == 0 or len(failing(ref + s[:, None] * disp, all_el)) == 0:
            break
        s, s0 = None, (0.0 if s0 < 1e-6 else 0.5 * s0)
    color = vertex_classes(ref, el)
    classes = [np.arange(n_pts)] if color is None else [np.flatnonzero(color == c) for c in range(color.max() + 1)]
    hi = np.ones(n_pts)
    u = ref + s[:, None] * disp

    def raised(s, active):
        """The scales with those of ``active`` raised by bisection towards their bound ``hi`` (to 1 if unbounded)."""
        prop = s.copy()
        prop[active] = np.where(hi[active] >= 1.0, 1.0, 0.5 * (s[active] + hi[active]))
        return prop

    for _ in range(rounds):
        active_all = s < 1.0
        if not active_all.any():
            break
        if len(classes) > 1:  # first the raise of every active vertex at once: kept when no element fails
            active = np.flatnonzero(active_all)
            prop = raised(s, active)
            u_all = u.copy()
            u_all[active] = ref[active] + prop[active, None] * disp[active]
            if len(failing(u_all, touching(active), active)) == 0:
                s, u = prop, u_all
                hi = np.maximum(hi, s)
                continue
        for members in classes:  # Gauss-Seidel over classes of vertices that share no element
            active = members[active_all[members]]
            if len(active) == 0:
                continue
            prop = raised(s, active)
            changed = active
            u[active] = ref[active] + prop[active, None] * disp[active]
            while len(changed):
                bad = failing(u, touching(changed), changed)
                bad = bad[prop[bad] != s[bad]]
                if len(bad) == 0:
                    break
                hi[bad] = np.minimum(hi[bad], prop[bad])
                prop[bad] = s[bad]
                u[bad] = ref[bad] + prop[bad, None] * disp[bad]  # only the reverted vertices move
                changed = bad
            s = prop
        hi = np.maximum(hi, s)
    u = ref + s[:, None] * disp
    return u, {"s_uniform": float(s0), "start": start, "affected": int((s < 1.0).sum()),
               "classes": len(classes)}


def vertex_classes(ref: np.ndarray, elements: np.ndarray) -> np.ndarray | None:
    r"""Classes of vertices no two of which share an element, from the parity of grid coordinates, or ``None``.

    On a mesh whose elements lie in the cells of a regular grid (every mesh of :func:`rfmap.mesh.grid_mesh`), two
    vertices of one cell with the same parity :math:`(i_1 \bmod 2, \dots, i_d \bmod 2)` coincide, so the
    :math:`2^d` parity classes separate the vertices of every element.  The classes are computed from the
    vertex positions (an ``N^d`` grid spanning their bounding box) and checked on every element; ``None`` when
    the mesh is not of that kind.

    Shapes: ref (n, d), elements (m, d+1) -> (n,) ints in ``[0, 2^d)``.
    """
    n_pts, d = ref.shape
    lo = ref.min(0)
    span = ref.max(0) - lo
    side = round(n_pts ** (1.0 / d))
    if side ** d != n_pts or side < 2 or not (span > 0).all():
        return None
    idx = (ref - lo) / span * (side - 1)
    ijk = np.rint(idx).astype(np.int64)
    if not np.allclose(idx, ijk, atol=1e-6):
        return None
    color = ((ijk % 2) << np.arange(d)).sum(1)
    c = np.sort(color[elements], axis=1)
    return color if bool((c[:, 1:] != c[:, :-1]).all()) else None


# ----------------------------------------------------------------------------------------------- entry point
def _metrics(ref, pts, elements, density, mu_ref) -> dict:
    from .metrics import compute_metrics

    m = compute_metrics(ref, pts, elements, density=density, mu_ref=mu_ref).to_dict()
    m.pop("time", None)
    return m


def repair_map(ref: np.ndarray, mapped: np.ndarray, elements: np.ndarray, *, boundary: str,
               grid_n: int | None = None, density: np.ndarray | None = None, mu: np.ndarray | None = None,
               delta: float = DELTA, method: str = "auto") -> tuple[np.ndarray, dict[str, Any]]:
    r"""Return a fold-free version of the map ``ref -> mapped`` and a report of what was done.

    Parameters
    ----------
    ref, mapped : ndarray, shape (n, d)
    elements : int ndarray, shape (m, d+1), positively oriented on ``ref``
    boundary : {"fixed", "square", "free"}
        The boundary condition the repaired map must keep.
    grid_n : int, optional
        Set when the mesh is :func:`rfmap.mesh.grid_mesh` ``(N, d)``: enables the fast strided check and, in 2D,
        the LBS repair.
    density : ndarray (n,), optional
        Vertex densities, for the density metrics in the report.
    mu : complex ndarray (m,), optional
        Target Beltrami coefficient, for ``mean_dmu`` in the report.
    delta : float
        Truncation margin, :math:`|\mu| \le 1 - \delta`.
    method : {"auto", "local", "lbs", "scale"}
        ``local``: :func:`local_lbs_repair`, falling back to ``lbs`` when no patch ends fold-free; ``lbs``:
        :func:`lbs_repair` on the whole grid; ``scale``: :func:`scale_repair`.  Any of them ends with
        :func:`scale_repair` if its result is still folded.  ``auto``: ``local`` for 2D grid meshes, ``scale``
        otherwise.

    Returns
    -------
    (points, report)
        ``points`` is ``mapped`` itself (the same object) when nothing was folded.  ``report`` holds ``needed``,
        ``method``, ``n_flipped_before``, ``n_flipped_after``, ``affected`` (triangles with truncated :math:`\mu`
        for the LBS, vertices with a shortened displacement for the scaling), ``time`` (s), ``metrics_before`` and
        ``metrics_after``; for a 3D free boundary also ``surface_crossings_before``/``_after`` (intersecting pairs
        of boundary triangles) and, when :func:`surface_repair` ran, ``surface_scale``.
    """
    t0 = time.perf_counter()
    if method not in REPAIR_METHODS:
        raise ValueError(f"unknown repair method {method!r}; choose one of {REPAIR_METHODS}")
    ref = np.asarray(ref, np.float64)
    d = ref.shape[1]
    el = np.asarray(elements)
    mapped = np.asarray(mapped)
    finite = bool(np.isfinite(mapped).all())
    if grid_n and finite:
        m = grid_min_measure(mapped, grid_n)
        min_jac = m * (grid_n - 1) ** d * (2 if d == 2 else 6)
    elif finite:
        meas = _measures(mapped, el, None) / _measures(ref, el, None)
        m = min_jac = float(meas.min())
    ok = finite and m > 0
    if ok and boundary == "free" and d == 2 and grid_n:
        ok = len(boundary_crossings(mapped[boundary_loop(grid_n)])) == 0
    crossings = 0
    if ok and boundary == "free" and d == 3:
        crossings = _surface_crossings(mapped, el, grid_n)
        ok = crossings == 0
    if ok:
        cheap = {"n_flipped": 0, "min_jacobian": float(min_jac)}
        return mapped, {"needed": False, "method": "none", "n_flipped_before": 0, "n_flipped_after": 0,
                        "affected": 0, "time": time.perf_counter() - t0, "metrics_before": cheap,
                        "metrics_after": dict(cheap)}
    mapped = np.asarray(mapped, np.float64)
    before = _metrics(ref, np.where(np.isfinite(mapped), mapped, ref), el, density, mu)
    if method == "auto":
        method = "local" if d == 2 and grid_n else "scale"
    affected = 0
    out = mapped
    used = method
    if method == "local":
        if not (d == 2 and grid_n):
            raise ValueError("the local LBS repair needs a 2D grid mesh (grid_n)")
        local = local_lbs_repair(np.where(np.isfinite(mapped), mapped, ref), grid_n, boundary, delta)
        if local is not None:
            out, capped = local
            affected = int(capped.sum())
        else:  # no patch ended fold-free: the global rebuild
            method = used = "lbs"
    if method == "lbs":
        if not (d == 2 and grid_n):
            raise ValueError("the LBS repair needs a 2D grid mesh (grid_n)")
        out, capped = lbs_repair(np.where(np.isfinite(mapped), mapped, ref), grid_n, boundary, delta)
        affected = int(capped.sum())
    if method == "scale" or not fold_free(out, el, grid_n=grid_n, boundary=boundary):
        out, info = scale_repair(ref, out, el, boundary=boundary)
        affected = max(affected, info["affected"])
        used = "scale" if method == "scale" else method + "+scale"
    report: dict[str, Any] = {}
    if boundary == "free" and d == 3:
        report["surface_crossings_before"] = crossings if crossings else _surface_crossings(
            np.where(np.isfinite(mapped), mapped, ref), el, grid_n)
        if _surface_crossings(out, el, grid_n):
            out, s = surface_repair(ref, out, el, grid_n=grid_n)
            used += "+surface"
            affected = len(out)
            report["surface_scale"] = s
        report["surface_crossings_after"] = _surface_crossings(out, el, grid_n)
    after = _metrics(ref, out, el, density, mu)
    return out, {"needed": True, "method": used, "n_flipped_before": int(before["n_flipped"]),
                 "n_flipped_after": int(after["n_flipped"]), "affected": affected,
                 "time": time.perf_counter() - t0, "metrics_before": before, "metrics_after": after, **report}
