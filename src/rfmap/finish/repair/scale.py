r"""Fold-free displacement scaling: the repair of 3D maps, and of any mesh the Beltrami rebuild does not apply to.

:func:`scale_repair` shortens a folded map's displacement vertex by vertex, as little as it can: every element ends
with a positive measure, the vertices far from the folds keep their mapped positions exactly, and only a
neighbourhood of the folds is pulled back towards the identity.  The map keeps its boundary condition.  A formerly
folded element ends with at least :data:`ETA` of its reference measure.

**Method.** Write the map as :math:`u = x + d(x)` with the displacement :math:`d` (for a surrogate
:math:`d = \mathcal{B} \odot \psi`).  The identity (:math:`s = 0` in :math:`u_s = x + s\,d`) has every element
positive, and every :math:`u_s` satisfies the same boundary condition as :math:`u`.  For one element, with
:math:`E_x` and :math:`E_d` the matrices of its edge vectors under :math:`x` and under :math:`d`,
:math:`\det E(s) = \det(E_x + s E_d)` is a polynomial in :math:`s` of degree at most the dimension (2 or 3) with
:math:`\det E(0) > 0`, so its first root :math:`s_T` in :math:`(0, 1]` is computed exactly (closed form in 2D,
companion-matrix eigenvalues in 3D) for the elements that a cheap test cannot clear: on :math:`[0, 1]` a polynomial's
values are convex combinations of its Bernstein coefficients, so when they are all positive it has no root there.
The largest fold-free uniform scale is :math:`s^{*} = \min_T s_T`, and the map :math:`u_{s^{*}}` is fold-free.

Then the per-vertex scale :math:`s_v` is raised locally towards 1 by bisection: a proposed raise is kept unless an
element touching the vertex would drop below its threshold, in which case the vertices of every such element go back
to their accepted values (repeating until no element fails, which ends because the accepted state passes).  On grid
meshes the raises of a round go class by class (:func:`vertex_classes`: the parities of the grid coordinates, 4
classes in 2D and 8 in 3D, no two vertices of one class in an element), Gauss–Seidel fashion, so an element that
fails has a single raised vertex and only that one goes back.  Each round first tries the raise of all active
vertices at once and keeps it when no element fails (a fold-free target is then recovered in one step).  Vertices far
from the folds thus recover the input map exactly.

**Local start.** When the folds are local, the start itself is local: :math:`s^{*}` on the elements whose polynomial
has a root in :math:`(0, 1)`, rising linearly to :math:`s = 1` over 6, 12 or 24 vertex rings around them
(:data:`LOCAL_START_RINGS`), if one of these states verifies (else the uniform start), so the rounds touch only that
region.

**Why the result is fold-free.** Every accepted state is *verified* by direct evaluation of all element measures that
changed, the starting state :math:`u_{s^{*}}` is verified the same way (halving :math:`s` until it passes, the identity
being the last resort), and a rejected proposal restores an accepted state.  So the returned map has every element
measure above a positive threshold :math:`\tau_T` (a fraction :math:`\eta` = :data:`ETA` of the reference measure for
elements that were folded, :math:`\min(\eta |T|, \tfrac12 |u(T)|)` for the others) whatever the root-finding accuracy.

**Cost.** It follows the size of the folded region, not of the mesh, apart from one pass over all elements for the
polynomial coefficients: to verify a local start only the elements touching a vertex with :math:`s_v < 1` are
evaluated, since every other element keeps the target, which the root test cleared.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ...core.mesh import grid_points
from ...core.surface import boundary_crossings, boundary_loop

__all__ = ["scale_repair", "vertex_classes", "ETA", "LOCAL_START_RINGS"]


#: Fraction of the reference measure that a formerly folded element must reach in the displacement scaling.
ETA = 0.05


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


class _Verifier:
    """The element checks of :func:`scale_repair`: the vertices a state must give back, and the elements that touch a
    set of vertices (from the vertex -> elements incidence), so that a change is verified where it acts only.

    Parameters
    ----------
    ref : ndarray, shape (P, d)
    el : int ndarray, shape (m, d+1)
    cols : list of d + 1 int ndarrays, shape (m,)
        The columns of ``el``, contiguous.
    tau : ndarray, shape (m,)
        The threshold of every element's measure (:func:`_thresholds`).
    boundary : str
        With ``"free"`` in 2D on a grid mesh the boundary polygon must stay simple too.
    """

    def __init__(self, ref: np.ndarray, el: np.ndarray, cols: list[np.ndarray], tau: np.ndarray, boundary: str):
        self.n_pts, d = ref.shape
        self.el, self.cols, self.tau = el, cols, tau
        self.loop = None
        if boundary == "free" and d == 2:
            side = round(self.n_pts ** 0.5)
            if side * side == self.n_pts and np.allclose(ref, grid_points(side, 2)):
                self.loop = boundary_loop(side)
        self.on_loop = np.zeros(self.n_pts, bool)
        self.loop_pos = np.full(self.n_pts, -1)
        if self.loop is not None:
            self.on_loop[self.loop] = True
            self.loop_pos[self.loop] = np.arange(len(self.loop))
        order = np.argsort(el.ravel(), kind="stable")
        self.el_of = order // (d + 1)
        self.starts = np.searchsorted(el.ravel()[order], np.arange(self.n_pts + 1))

    def failing(self, u: np.ndarray, els: np.ndarray, moved: np.ndarray | None = None) -> np.ndarray:
        """Vertices to revert: those of elements below threshold (and of crossing free-boundary edges; the
        boundary is only re-checked when a vertex in ``moved`` lies on it, since nothing else can change it)."""
        # a contiguous transpose pays for many elements; for a few, strided gathers from u.T are cheaper
        det = _det(_edges(u.T if len(els) * 8 < self.n_pts else np.ascontiguousarray(u.T), self.cols, els))
        bad = els[~(det >= self.tau[els])]
        v = self.el[bad].ravel()
        loop = self.loop
        if loop is not None and (moved is None or self.on_loop[moved].any()):
            # a crossing needs a moved boundary vertex: the edges on either side of each one
            pos = None if moved is None else self.loop_pos[moved[self.on_loop[moved]]]
            c = boundary_crossings(u[loop], None if pos is None else np.concatenate([pos, pos - 1]))
            if len(c):
                v = np.concatenate([v, loop[c.ravel()], loop[(c.ravel() + 1) % len(loop)]])
        return _unique_ids(v, self.n_pts)

    def touching(self, verts: np.ndarray) -> np.ndarray:
        """The elements with a vertex in ``verts``, sorted."""
        if len(verts) == 0:
            return np.zeros(0, np.int64)
        first, count = self.starts[verts], self.starts[verts + 1] - self.starts[verts]
        pos = np.repeat(first - np.cumsum(count) + count, count) + np.arange(int(count.sum()))
        return _unique_ids(self.el_of[pos], len(self.el))


def _local_start(chk: _Verifier, ref: np.ndarray, disp: np.ndarray, sus: np.ndarray,
                 s0: float) -> tuple[np.ndarray | None, str]:
    """The local start of :func:`scale_repair`: the uniform scale ``s0`` only on the unsafe elements ``sus``, rising
    linearly to 1 over each of :data:`LOCAL_START_RINGS` vertex rings in turn, the target elsewhere (most folds are
    small clusters); ``(scales, label)`` of the first that verifies, ``(None, "uniform")`` if none does."""
    n_pts, el = chk.n_pts, chk.el
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
            front = _unique_ids(el[chk.touching(front)].ravel(), n_pts)
            front = front[~near[front]]
            near[front] = True
            ring[front] = grown
            wide = near.sum() > 0.5 * n_pts
        cand = s0 + (1.0 - s0) * np.minimum(ring / rings, 1.0)
        if (cand < 1).sum() > 0.5 * n_pts:
            break
        # elements with every vertex at s = 1 keep the target, where they are safe
        if len(chk.failing(ref + cand[:, None] * disp, chk.touching(np.flatnonzero(cand < 1)))) == 0:
            return cand, f"local ({rings} rings)"
    return None, "uniform"


def _uniform_start(chk: _Verifier, ref: np.ndarray, disp: np.ndarray, s0: float) -> tuple[np.ndarray, float]:
    """The uniform start of :func:`scale_repair`: ``s0``, halved until every element passes (the identity, ``s = 0``,
    always does); ``(scales, s0)``."""
    all_el = np.arange(len(chk.el))
    while True:
        s = np.full(chk.n_pts, s0)
        if s0 == 0 or len(chk.failing(ref + s[:, None] * disp, all_el)) == 0:
            return s, s0
        s0 = 0.0 if s0 < 1e-6 else 0.5 * s0


def _raise_scales(chk: _Verifier, ref: np.ndarray, disp: np.ndarray, s: np.ndarray, classes: list[np.ndarray],
                  rounds: int) -> np.ndarray:
    """``rounds`` rounds of per-vertex bisection of the verified scales ``s`` towards 1: each round tries the raise of
    every active vertex at once, else raises the vertex ``classes`` in turn (Gauss-Seidel), reverting the vertices
    of every element that fails until none does."""
    hi = np.ones(chk.n_pts)
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
            if len(chk.failing(u_all, chk.touching(active), active)) == 0:
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
                bad = chk.failing(u, chk.touching(changed), changed)
                bad = bad[prop[bad] != s[bad]]
                if len(bad) == 0:
                    break
                hi[bad] = np.minimum(hi[bad], prop[bad])
                prop[bad] = s[bad]
                u[bad] = ref[bad] + prop[bad, None] * disp[bad]  # only the reverted vertices move
                changed = bad
            s = prop
        hi = np.maximum(hi, s)
    return s


def scale_repair(ref: np.ndarray, target: np.ndarray, elements: np.ndarray, *, boundary: str = "fixed",
                 eta: float = ETA, rounds: int = 16) -> tuple[np.ndarray, dict]:
    r"""Fold-free map closest to ``target`` among :math:`u_v = x_v + s_v (t_v - x_v)`, :math:`s_v \in [0, 1]`.

    See the module docstring.  The start is the fold-free scale :math:`s^{*}` (the first root of the per-element
    determinant polynomials), applied on the elements with a root and rising linearly to 1 over 6, 12 or 24 vertex rings
    around them (:data:`LOCAL_START_RINGS`) when such a local start verifies, else on every vertex; then ``rounds``
    rounds of per-vertex bisection of :math:`s_v` towards 1 that keep every element above its threshold. Works on any
    simplicial mesh in 2D or 3D and keeps the boundary condition of ``target`` (the displacement is only shortened).

    Parameters
    ----------
    ref, target : ndarray, shape (P, d)
    elements : int ndarray, shape (m, d+1), positively oriented on ``ref``
    boundary : str
        With ``"free"`` in 2D the boundary polygon of a grid mesh must also stay simple.

    Returns
    -------
    points : ndarray, shape (P, d)
        The repaired map.
    info : dict
        ``s_uniform``: the start's fold-free scale, just below :math:`s^{*}` (halved until it verified where the
        uniform start needed that); ``start``: ``"local (R rings)"`` or ``"uniform"``; ``affected``: the number of
        vertices left with :math:`s_v < 1`; ``classes``: the number of vertex classes raised in turn
        (:func:`vertex_classes`; 1 on meshes that are not grids).
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
    chk = _Verifier(ref, el, cols, tau, boundary)
    s0 = 0.999 * s_star
    s, start = _local_start(chk, ref, disp, sus, s0) if len(sus) else (None, "uniform")
    if s is None:  # the identity (s = 0) always passes
        s, s0 = _uniform_start(chk, ref, disp, s0)
    color = vertex_classes(ref, el)
    classes = [np.arange(n_pts)] if color is None else [np.flatnonzero(color == c) for c in range(color.max() + 1)]
    s = _raise_scales(chk, ref, disp, s, classes, rounds)
    u = ref + s[:, None] * disp
    return u, {"s_uniform": float(s0), "start": start, "affected": int((s < 1.0).sum()),
               "classes": len(classes)}


def vertex_classes(ref: np.ndarray, elements: np.ndarray) -> np.ndarray | None:
    r"""Classes of vertices no two of which share an element, from the parity of grid coordinates, or ``None``.

    On a mesh whose elements lie in the cells of a regular grid (every mesh of :func:`rfmap.core.mesh.grid_mesh`), two
    vertices of one cell with the same parity :math:`(i_1 \bmod 2, \dots, i_d \bmod 2)` coincide, so the
    :math:`2^d` parity classes separate the vertices of every element.  The classes are computed from the
    vertex positions (an ``N^d`` grid spanning their bounding box) and checked on every element; ``None`` when
    the mesh is not of that kind.

    Shapes: ref (P, d), elements (m, d+1) -> (P,) ints in ``[0, 2^d)``.
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
