r"""Search for the paper's under-specified test inputs: which box on which background reproduces a published
:math:`\mathrm{Std}(\tilde\rho_{\text{orig}})`.

The rect-peak test (paper Eq. (rect-peak)) adds an unspecified ``rect(x, y)`` to the sin-cos field, and the printed
prism-peak test (Eq. (peak-3d)) does not reproduce its published input statistic.  Both are a background :math:`b`
(a test field of :mod:`rfmap.fields.paper`) with an axis-aligned box :math:`B` on it:

* ``add``: :math:`p = b + h\,\mathbf 1_B` (the form of Eq. (rect-peak));
* ``replace``: :math:`p = c` on :math:`B`, :math:`b` elsewhere (the form of Eq. (peak-3d)).

A *family* fixes the background, the grid side, the box edges (multiples of ``step`` in :math:`[0, 1]`, each end
closed or open; boxes with the same vertices counted once), how the box is sampled (``vertex``: the box term at the
mesh vertices, as every other test field; ``centroid``: per element, from its centroid, which for edges on grid lines
is the exact integral) and whether the paper's shift (minimum to 0.1) precedes the normalisation (scaling to unit
mass does not change the statistic).  The statistic is that of :func:`rfmap.core.metrics.compute_metrics` on the
identity map: element means :math:`\rho_e` of the vertex values (the element measures are equal),
:math:`\mathrm{Std}(\rho)/\operatorname{mean}(\rho)` with ddof = 1.

**Every box at once.**  For a box value :math:`\alpha` (:math:`h`, or :math:`c` shifted), :math:`\rho = P + \alpha Q`
where :math:`P, Q` are built from the background's element means :math:`B` and the box's element terms
:math:`F = \operatorname{mean}_e \mathbf 1_B` and :math:`H = \operatorname{mean}_e b\,\mathbf 1_B`; the statistic needs
only :math:`\sum\rho` and :math:`\sum\rho^2`, i.e. seven sums (:math:`\sum F, \sum H, \sum BF, \sum BH, \sum F^2,
\sum FH, \sum H^2`).  The box indicator is a product of one interval indicator per axis, so each sum is a fixed tensor
over the grid cells contracted with one (intervals x cells) matrix per axis: the sums of all boxes in a few matrix
products (2D, 0.05 edges: 235,225 boxes in about a second).

**What a match means.**  A statistic printed to 6 digits is matched by chance about once in :math:`10^5`-:math:`10^6`
candidates, so a family of many boxes always holds some.  :func:`search` therefore reports beside the matches the
distinct statistics among them (boxes that a symmetry of the background maps onto each other share one) and the
number of those *expected by chance* (the distinct statistics within :math:`5\cdot 10^{-4}` of the target, over
1000): a family whose matches are no more than that has not identified the input.

    python benchmarks/paper_inputs.py [--field rect-peak|prism-peak-3d] [--step S] [--n N] [--values V ...] [--top K]

prints, per field and family, the candidates, the matches, the distinct matches and those expected by chance, then the
closest inputs (checked with :func:`rfmap.core.metrics.compute_metrics`) and, for the prism, the printed box alone with
the values that reproduce the statistic exactly.  Defaults: the paper's grids (51, 48), edges on multiples of 0.05 in
2D and 0.1 in 3D (``--step 0.05`` in 3D: 1.6e8 boxes per family, 12 minutes in all and 8 GB), values 0.5, 1,
..., 5.
"""
from __future__ import annotations

import argparse
import functools
import itertools
from dataclasses import dataclass, field

import numpy as np

from rfmap.core.geometry import grid_cell_simplices
from rfmap.core.inputs import DENSITY_FLOOR, preprocess_density
from rfmap.core.mesh import grid_mesh
from rfmap.core.metrics import compute_metrics
from rfmap.fields.paper import PAPER_N, get_field
from rfmap.paper.tables import paper_table

#: The two under-specified inputs: (the paper's table, dimension, backgrounds to try, the paper's box when it prints
#: one).  The 3D background ``multi-freq-3d`` is the "otherwise" branch of Eq. (peak-3d).
SEARCHES = {
    "rect-peak": ("tab:population_test", 2, ("sin-cos",), None),
    "prism-peak-3d": ("tab:3d_population_test", 3, ("multi-freq-3d", "sin-cos-3d"),
                      ((0.6, 1.0), (0.0, 0.4), (0.4, 0.8))),
}
#: Default box values: the heights h (``add``) and inside values c (``replace``).
VALUES = tuple(np.arange(0.5, 5.01, 0.5).round(2))
#: A statistic "reproduces" the paper when it rounds to the printed value; the chance rate is counted in this window.
CHANCE_WINDOW = 5e-4
_TOL = 1e-9  # a vertex within this of an edge lies on it


def published_std(name: str) -> float:
    """The paper's Std(rho~_orig) of the test field ``name`` (``rect-peak`` or ``prism-peak-3d``)."""
    table, *_ = SEARCHES[name]
    return paper_table(table)["rows"][name]["std_rho_orig"]


@dataclass(frozen=True)
class Family:
    """A family of candidate inputs: one background, grid side, edge step, sampling and preprocessing."""

    background: str
    n: int
    step: float = 0.05
    sampling: str = "vertex"
    shift: bool = True

    @property
    def dim(self) -> int:
        return get_field(self.background).dim

    def label(self) -> str:
        return f"{self.background}, {self.sampling}, {'shift' if self.shift else 'no shift'}"


@dataclass(frozen=True)
class Candidate:
    """One input: a family, a box (one interval label per axis, e.g. ``[0.6, 0.8]``), a variant and its value."""

    family: Family
    box: tuple[str, ...]
    variant: str
    value: float
    std: float

    def describe(self) -> str:
        op = f"+ {self.value:.6g} on" if self.variant == "add" else f"= {self.value:.6g} on"
        return f"{self.family.background} {op} {' x '.join(self.box)}"

    def vertex_field(self) -> np.ndarray:
        """The raw vertex values, shape (N,)*d (vertex sampling only)."""
        f = self.family
        if f.sampling != "vertex":
            raise ValueError("a centroid-sampled box is not a vertex field")
        b = get_field(f.background).sample(f.n, preprocess=False)
        inside = _box_mask(self.box, f.n, f.dim)
        return b + self.value * inside if self.variant == "add" else np.where(inside, self.value, b)

    def verify(self) -> float:
        """Std(rho~_orig) through :func:`rfmap.core.metrics.compute_metrics` (vertex sampling only)."""
        f = self.family
        raw = self.vertex_field()
        dens = preprocess_density(raw) if f.shift else raw / raw.sum()
        mesh = grid_mesh(f.n, f.dim)
        return compute_metrics(mesh.points, mesh.points, mesh.elements, density=dens.reshape(-1)).std_rho_orig


def _interval_label(lo: float, hi: float, closed_lo: bool, closed_hi: bool) -> str:
    return f"{'[' if closed_lo else '('}{lo:g}, {hi:g}{']' if closed_hi else ')'}"


def _inside(t: np.ndarray, label: str) -> np.ndarray:
    lo, hi = (float(s) for s in label[1:-1].split(","))
    above = t >= lo - _TOL if label[0] == "[" else t > lo + _TOL
    below = t <= hi + _TOL if label[-1] == "]" else t < hi - _TOL
    return above & below


def _box_mask(box: tuple[str, ...], n: int, dim: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    axes = [_inside(t, lab) for lab in box]
    return np.logical_and.reduce(np.meshgrid(*axes, indexing="ij")) if dim > 1 else axes[0]


def _cell_offsets(dim: int) -> list[tuple[float, ...]]:
    """The centroid of each simplex type of the grid cell, in cell units."""
    return [tuple(np.mean(corners, axis=0)) for corners in grid_cell_simplices(dim)]


def axis_intervals(n: int, step: float, sampling: str = "vertex", dim: int = 2):
    """The intervals of one axis with edges on multiples of ``step`` in [0, 1], each end closed or open.

    Intervals that hold the same points are kept once (under the first label, closed ends first); empty ones are
    dropped.  The points are the vertices :math:`i/(N-1)` (``vertex``) or the element centroids
    :math:`(i + o)/(N-1)` for each centroid offset :math:`o` of the cell's simplices (``centroid``).

    Returns
    -------
    labels : list of str, length R
    indicators : dict
        ``vertex``: (R, N) float array; ``centroid``: offset -> (R, N-1) float array.
    """
    k = int(round(1 / step))
    t = np.linspace(0.0, 1.0, n)
    offsets = sorted({o for c in _cell_offsets(dim) for o in c}) if sampling == "centroid" else []
    labels, rows, seen = [], [], set()
    for k0, k1 in itertools.combinations(range(k + 1), 2):
        for closed in ((1, 1), (1, 0), (0, 1), (0, 0)):
            lab = _interval_label(k0 / k, k1 / k, *closed)
            pts = [_inside(t, lab)] if sampling == "vertex" else [_inside(t[:-1] + o / (n - 1), lab) for o in offsets]
            key = b"".join(p.tobytes() for p in pts)
            if key in seen or not any(p.any() for p in pts):
                continue
            seen.add(key)
            labels.append(lab)
            rows.append(pts)
    if sampling == "vertex":
        return labels, {"vertex": np.array([r[0] for r in rows], dtype=np.float64)}
    return labels, {o: np.array([r[i] for r in rows], dtype=np.float64) for i, o in enumerate(offsets)}


def _contract(tensor: np.ndarray, mats: list[np.ndarray]) -> np.ndarray:
    """:math:`\\sum_c T[c] \\prod_a M_a[r_a, c_a]` for all (r_1, ..., r_d): shape (R_1, ..., R_d)."""
    out = tensor
    for m in mats:
        out = np.tensordot(out, m, axes=([0], [1]))
    return out


def _view(v: np.ndarray, corner) -> np.ndarray:
    n = v.shape[0]
    return v[tuple(slice(o, o + n - 1) for o in corner)]


@dataclass
class BoxSums:
    """The sums over elements that fix Std(rho~_orig) of every box of a family (arrays of shape (R,)*d)."""

    family: Family
    labels: list[str]
    sums: dict[str, np.ndarray] = field(repr=False)
    m: int = 0
    b_min: float = 0.0
    valid: np.ndarray | None = field(default=None, repr=False)


def _vertex_sums(b: np.ndarray, X: np.ndarray) -> dict[str, np.ndarray]:
    """The seven sums for vertex sampling: F and H are means over each simplex's corners of 1_B and b 1_B."""
    d, n = b.ndim, b.shape[0]
    k = d + 1
    tensors: dict[tuple, dict[str, np.ndarray]] = {}

    def add(key, name, value):
        slot = tensors.setdefault(key, {})
        slot[name] = slot.get(name, 0) + value

    for corners in grid_cell_simplices(d):
        B = sum(_view(b, c) for c in corners) / k
        for u in corners:
            bu = _view(b, u)
            key = tuple((o, o) for o in u)
            add(key, "F", np.ones_like(bu) / k)
            add(key, "H", bu / k)
            add(key, "BF", B / k)
            add(key, "BH", B * bu / k)
            for v in corners:  # F^2, FH, H^2: pairs of corners, a product of two shifted indicators per axis
                bv = _view(b, v)
                key2 = tuple((min(p, q), max(p, q)) for p, q in zip(u, v))
                add(key2, "FF", np.ones_like(bu) / k**2)
                add(key2, "FH", bv / k**2)
                add(key2, "HH", bu * bv / k**2)
    out: dict[str, np.ndarray] = {}
    for key, named in tensors.items():
        mats = [X[:, lo:lo + n - 1] * X[:, hi:hi + n - 1] for lo, hi in key]
        for name, tensor in named.items():
            out[name] = out.get(name, 0) + _contract(tensor, mats)
    return out


def _centroid_sums(b: np.ndarray, X: dict) -> dict[str, np.ndarray]:
    """The seven sums for centroid sampling: F = 1_B(centroid) in {0, 1}, H = B F."""
    d = b.ndim
    s = {"F": 0, "BF": 0, "BBF": 0}
    for corners, cen in zip(grid_cell_simplices(d), _cell_offsets(d)):
        B = sum(_view(b, c) for c in corners) / (d + 1)
        mats = [X[o] for o in cen]
        s["F"] = s["F"] + _contract(np.ones_like(B), mats)
        s["BF"] = s["BF"] + _contract(B, mats)
        s["BBF"] = s["BBF"] + _contract(B * B, mats)
    return {"F": s["F"], "H": s["BF"], "BF": s["BF"], "BH": s["BBF"], "FF": s["F"], "FH": s["BF"], "HH": s["BBF"]}


def box_sums(family: Family) -> BoxSums:
    """Sums over elements of the background and of every box of ``family`` (see the module docstring)."""
    f = family
    b = get_field(f.background).sample(f.n, preprocess=False)
    b_min = float(b.min())
    if f.shift:
        b = b - b_min + DENSITY_FLOOR
    labels, X = axis_intervals(f.n, f.step, f.sampling, f.dim)
    sums = _vertex_sums(b, X["vertex"]) if f.sampling == "vertex" else _centroid_sums(b, X)
    B = np.concatenate([(sum(_view(b, c) for c in corners) / (f.dim + 1)).ravel()
                        for corners in grid_cell_simplices(f.dim)])
    sums["B"], sums["BB"] = np.float64(B.sum()), np.float64(B @ B)
    valid = np.ones((len(labels),) * f.dim, dtype=bool)
    if f.shift and f.sampling == "vertex":  # a box over every minimum vertex of b would change the shift
        lows = np.argwhere(b == b.min())
        covered = sum(functools.reduce(np.multiply, np.ix_(*[X["vertex"][:, i] for i in low])) for low in lows)
        valid = covered < len(lows)
    return BoxSums(f, labels, sums, B.size, b_min, valid)


def _affine_sums(s: dict, variant: str, m: int, below: bool):
    """(sum P, sum Q, sum P^2, sum PQ, sum Q^2) of rho = P + alpha Q."""
    if variant == "add":
        return s["B"], s["F"], s["BB"], s["BF"], s["FF"]
    p1, p2, pq = s["B"] - s["H"], s["BB"] - 2 * s["BH"] + s["HH"], s["BF"] - s["FH"]
    if not below:  # c at or above the background's minimum: rho = (B - H) + c' F
        return p1, s["F"], p2, pq, s["FF"]
    f = DENSITY_FLOOR  # c below it: the minimum is c; rho = (B - H + f F) + (b_min - c)(1 - F)
    P1 = p1 + f * s["F"]
    P2 = p2 + f * f * s["FF"] + 2 * f * pq
    PF = pq + f * s["FF"]
    return P1, m - s["F"], P2, P1 - PF, m - 2 * s["F"] + s["FF"]


def box_std(bs: BoxSums, variant: str, value: float) -> np.ndarray:
    """Std(rho~_orig) of every box of the family with height (``add``) or inside value (``replace``) ``value``;
    NaN where the box covers every minimum of the background (the shift would differ).  Shape (R,)*d."""
    if variant not in ("add", "replace"):
        raise ValueError(f"variant must be 'add' or 'replace', got {variant!r}")
    below = variant == "replace" and bs.family.shift and value < bs.b_min
    p1, q1, p2, pq, q2 = _affine_sums(bs.sums, variant, bs.m, below)
    if variant == "add" or not bs.family.shift:
        alpha = value
    else:
        alpha = bs.b_min - value if below else value - bs.b_min + DENSITY_FLOOR
    s1 = p1 + alpha * q1
    s2 = p2 + 2 * alpha * pq + alpha * alpha * q2
    m = bs.m
    std = np.sqrt(np.maximum(s2 - s1 * s1 / m, 0.0) / (m - 1)) / (s1 / m)
    return np.where(bs.valid | below, std, np.nan)


def solve_value(bs: BoxSums, variant: str, target: float) -> list[np.ndarray]:
    """The values (heights h for ``add``, inside values c for ``replace``) at which each box reproduces ``target``
    exactly: the roots of the quadratic :math:`m^2 \\sum\\rho^2/(m-1) = (m/(m-1) + T^2)(\\sum\\rho)^2` in the
    box value, kept where they fall in the regime they were solved in (h > 0; c above or below the background's
    minimum).  A list of arrays of shape (R,)*d, NaN where a box has no such root."""
    m, shift, f = bs.m, bs.family.shift, DENSITY_FLOOR
    k = m / (m - 1) + target * target
    regimes = [False] if variant == "add" or not shift else [False, True]
    out = []
    for below in regimes:
        p1, q1, p2, pq, q2 = _affine_sums(bs.sums, variant, m, below)
        a = m * m * q2 / (m - 1) - k * q1 * q1
        b = 2 * (m * m * pq / (m - 1) - k * p1 * q1)
        c = m * m * p2 / (m - 1) - k * p1 * p1
        disc = np.sqrt(np.where(b * b - 4 * a * c >= 0, b * b - 4 * a * c, np.nan))
        for sign in (-1.0, 1.0):
            with np.errstate(divide="ignore", invalid="ignore"):
                alpha = (-b + sign * disc) / (2 * a)
            if variant == "add" or not shift:
                value, ok = alpha, alpha > 0
            elif below:
                value, ok = bs.b_min - alpha, (alpha > 0) & (bs.b_min - alpha >= 0)
            else:
                value, ok = alpha + bs.b_min - f, alpha >= f
            out.append(np.where(ok & (bs.valid | below), value, np.nan))
    return out


def search(family: Family | BoxSums, target: float, *, values=VALUES, variants=("add", "replace"),
           top: int = 5) -> list[dict]:
    """Every box of ``family`` (or of its precomputed :class:`BoxSums`) with every value, against the published
    ``target``.

    Returns
    -------
    list of dict, one per variant: ``family``, ``variant``, ``candidates`` (boxes x values), ``matches`` (the
    candidates whose statistic rounds to ``target`` at 6 digits), ``distinct`` (the distinct statistics among them:
    boxes that the background's symmetries map onto each other share one), ``chance`` (distinct matches expected by
    chance: the distinct statistics within :data:`CHANCE_WINDOW` of the target, scaled to the half-unit of the 6th
    digit) and ``best`` (the ``top`` closest :class:`Candidate` objects, closest first).
    """
    bs = family if isinstance(family, BoxSums) else box_sums(family)
    rows = []
    for variant in variants:
        count, near, best = 0, [], []
        for value in values:
            std = box_std(bs, variant, value)
            ok = np.isfinite(std)
            count += int(ok.sum())
            err = np.where(ok, np.abs(std - target), np.inf).ravel()
            near.append(std.ravel()[err < CHANCE_WINDOW])
            for i in np.argpartition(err, min(top, err.size - 1))[:top]:
                box = tuple(bs.labels[j] for j in np.unravel_index(i, std.shape))
                best.append(Candidate(bs.family, box, variant, float(value), float(std.ravel()[i])))
        near = np.concatenate(near)
        hits = near[np.round(near, 6) == round(target, 6)]
        best.sort(key=lambda c: abs(c.std - target))
        rows.append({"family": bs.family, "variant": variant, "candidates": count, "matches": hits.size,
                     "distinct": np.unique(hits.round(12)).size,
                     "chance": np.unique(near.round(12)).size * 5e-7 / CHANCE_WINDOW, "best": best[:top]})
    return rows


def _families(name: str, step: float, n: int | None) -> list[Family]:
    _, dim, backgrounds, _ = SEARCHES[name]
    n = n or PAPER_N[dim]
    return [Family(bg, n, step, sampling, shift) for bg in backgrounds for sampling in ("vertex", "centroid")
            for shift in (True, False)]


def project_std(name: str, n: int | None = None) -> float:
    """Std(rho~_orig) of the project's own test field ``name`` (:mod:`rfmap.fields.paper`) on the paper's grid."""
    f = get_field(name)
    n = n or PAPER_N[f.dim]
    mesh = grid_mesh(n, f.dim)
    return compute_metrics(mesh.points, mesh.points, mesh.elements,
                           density=f.sample(n).reshape(-1)).std_rho_orig


def _report(name: str, step: float, n: int | None, values, top: int) -> None:
    target = published_std(name)
    paper_box = SEARCHES[name][3]
    print(f"\n### {name}: published Std(rho~_orig) = {target:.6f}, the project's field {project_std(name, n):.6f}; "
          f"box edges on multiples of {step:g}\n")
    print("| family | variant | candidates | reproduce (6 digits) | distinct | expected by chance | closest input |")
    print("|---|---|---|---|---|---|---|")
    best, printed, exact = [], [], []
    for fam in _families(name, step, n):
        bs = box_sums(fam)
        for row in search(bs, target, values=values, top=top):
            c = row["best"][0]
            print(f"| {fam.label()} | {row['variant']} | {row['candidates']} | {row['matches']} | "
                  f"{row['distinct']} | {row['chance']:.1f} | {c.describe()}: {c.std:.6f} |")
            best += row["best"]
        printed += printed_box_candidates(bs, paper_box, values)
        exact += printed_box_candidates(bs, paper_box, solve=target)
    best.sort(key=lambda c: abs(c.std - target))
    print(f"\nClosest {top} inputs (vertex sampling checked with rfmap.core.metrics.compute_metrics):\n")
    _print_candidates(best[:top])
    if paper_box is not None:
        printed.sort(key=lambda c: abs(c.std - target))
        hits = sum(round(c.std, 6) == target for c in printed)
        print(f"\nThe printed box only: {len(printed)} inputs, {hits} reproduce {target:.6f}; the closest:\n")
        _print_candidates(printed[:top])
        exact.sort(key=lambda c: abs(c.value - round(c.value)))
        print("\nThe printed box: the values that reproduce it exactly, nearest to a whole number first:\n")
        _print_candidates(exact[:top])


def _print_candidates(cands) -> None:
    print("| Std | checked | input | sampling, preprocessing |\n|---|---|---|---|")
    for c in cands:
        ok = f"{c.verify():.6f}" if c.family.sampling == "vertex" else "-"
        print(f"| {c.std:.6f} | {ok} | {c.describe()} | {c.family.sampling}, "
              f"{'shift' if c.family.shift else 'no shift'} |")


def printed_box_candidates(bs: BoxSums, paper_box, values=VALUES, *, solve: float | None = None) -> list[Candidate]:
    """Every variant and value on the paper's printed box (each choice of closed or open ends), ``[]`` without one;
    with ``solve``, the values that reproduce the statistic ``solve`` exactly (:func:`solve_value`) instead."""
    if paper_box is None:
        return []
    idx = [[i for i, lab in enumerate(bs.labels) if lab[1:-1].replace(" ", "") == f"{lo:g},{hi:g}"]
           for lo, hi in paper_box]
    out = []
    for variant in ("add", "replace"):
        if solve is None:
            grids = [(np.full(bs.valid.shape, v), box_std(bs, variant, v)) for v in values]
        else:
            grids = [(r, np.full(r.shape, solve)) for r in solve_value(bs, variant, solve)]
        for vals, std in grids:
            out += [Candidate(bs.family, tuple(bs.labels[i] for i in ix), variant, float(vals[ix]), float(std[ix]))
                    for ix in itertools.product(*idx) if np.isfinite(vals[ix])]
    return out


def main(argv=None) -> None:
    """Print the search tables (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--field", choices=sorted(SEARCHES), action="append", help="default: both")
    p.add_argument("--step", type=float, default=None, help="edge step (default 0.05 in 2D, 0.1 in 3D)")
    p.add_argument("--n", type=int, default=None, help="grid side (default: the paper's, 51 / 48)")
    p.add_argument("--values", type=float, nargs="+", default=list(VALUES), help="heights / inside values")
    p.add_argument("--top", type=int, default=5)
    a = p.parse_args(argv)
    for name in a.field or sorted(SEARCHES, reverse=True):
        step = a.step or (0.05 if SEARCHES[name][1] == 2 else 0.1)
        _report(name, step, a.n, a.values, a.top)


if __name__ == "__main__":
    main()
