r"""The paper's test fields: densities (paper Sec. 5.2) and analytic Beltrami test maps (paper Sec. 5.1).

Densities are functions :math:`p: [0,1]^d \to \mathbb{R}`; before use they are evaluated at the mesh vertices,
shifted to minimum 0.1 and scaled to unit mass (:func:`rfmap.core.inputs.preprocess_density`).  The Beltrami test
maps T1–T4 (paper Eqs. (23)–(26)) are analytic maps of the unit square; their exact Beltrami coefficient
:math:`\mu = f_{\bar z}/f_z` is computed by automatic differentiation in float64 (exact to round-off).

``TEST_FIELDS`` lists the fields of the paper's tables per (kind, dimension) and ``PAPER_N`` the grid sizes
of those tables.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from ..core.geometry import beltrami_from_jacobian
from ..core.inputs import preprocess_density
from ..core.mesh import check_n, element_centroids, grid_mesh, grid_points
from ..core.metrics import compute_metrics

__all__ = [
    "DensityField",
    "BeltramiMap",
    "DENSITIES",
    "BELTRAMI_MAPS",
    "RECT_PEAK_BOX",
    "TEST_FIELDS",
    "PAPER_N",
    "field_names",
    "get_field",
    "sample_density",
    "sample_mu",
]

TWO_PI = 2.0 * math.pi

#: The paper's population tests and Beltrami reconstructions: the test fields of each table, by (kind, dimension).
TEST_FIELDS: dict[tuple[str, int], tuple[str, ...]] = {
    ("density", 2): ("sin-cos", "exp-log", "rect-peak", "ring"),
    ("density", 3): ("sin-cos-3d", "shell-3d", "octant-3d", "prism-peak-3d"),
    ("beltrami", 2): ("T1", "T2", "T3", "T4"),
}

#: The grid size (vertices per side) of the paper's test tables, by dimension: 51 in 2D, 48 in 3D.
PAPER_N: dict[int, int] = {2: 51, 3: 48}


@dataclass(frozen=True)
class DensityField:
    """A named test density of the paper.

    Attributes
    ----------
    name : str
    dim : int
    fn : callable
        ``fn(x)`` with ``x`` of shape (..., d) returns the raw density, shape (...).
    label : str
        The paper's equation label.
    description : str
    """

    name: str
    dim: int
    fn: Callable[[np.ndarray], np.ndarray] = field(repr=False)
    label: str = ""
    description: str = ""
    kind: str = "density"

    def __call__(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-1] != self.dim:
            raise ValueError(f"field {self.name!r} is {self.dim}D; points have dimension {x.shape[-1]}")
        return self.fn(x)

    def sample(self, n: int, *, preprocess: bool = True) -> np.ndarray:
        """Vertex values on the ``N``-grid, shape ``(N,)*d`` (shifted and unit mass unless ``preprocess=False``)."""
        n = check_n(n)
        raw = self(grid_points(n, self.dim)).reshape((n,) * self.dim)
        return preprocess_density(raw) if preprocess else raw


#: The box of the rect-peak test (c), as ((x0, x1), (y0, y1), height): the paper leaves ``rect(x, y)`` unspecified,
#: and this package adds ``+2`` on this box, a plausible choice rather than the paper's.  The published
#: Std(ρ̃_orig) of the field cannot identify the box: of the many axis-aligned boxes searched, no more reproduce its
#: six printed digits than would by chance.  With this box the input's Std(ρ̃_orig) misses the published one by
#: more than :data:`rfmap.paper.verdicts.COMPARABLE_RTOL` allows (its description gives the miss), so rect-peak is
#: not compared with the paper's value.
RECT_PEAK_BOX = ((0.6, 0.8), (0.2, 0.4), 2.0)


def _sin_cos(x):
    return 2 + np.sin(TWO_PI * x[..., 0]) * np.cos(TWO_PI * x[..., 1])


def _exp_log(x):
    return 2 + np.sin(TWO_PI * np.exp(x[..., 0])) * np.cos(math.pi * np.log(2 * x[..., 1] + 0.1))


def _rect_peak(x):
    (x0, x1), (y0, y1), height = RECT_PEAK_BOX
    box = (x[..., 0] >= x0) & (x[..., 0] <= x1) & (x[..., 1] >= y0) & (x[..., 1] <= y1)
    return _sin_cos(x) + height * box


def _ring(x):
    r = np.sqrt((x[..., 0] - 0.5) ** 2 + (x[..., 1] - 0.5) ** 2)
    return np.exp(-((r - 1.0) ** 2) / (2 * 0.5**2))


def _multi_freq(x):
    return 2 + np.sin(2 * TWO_PI * x[..., 0]) * np.cos(2 * TWO_PI * x[..., 1]) + 0.3 * np.sin(3 * TWO_PI * x[..., 0])


def _sin_cos_3d(x):
    return 2 + np.sin(TWO_PI * x[..., 0]) * np.cos(TWO_PI * x[..., 1]) * np.sin(TWO_PI * x[..., 2])


def _shell_3d(x):
    def g(r):
        return np.exp(-((r - 1.0) ** 2) / (2 * 0.5**2))

    r = np.sqrt(((x - 0.5) ** 2).sum(-1))
    return g(math.sqrt(3) / 2) - g(r)  # max of the Gaussian term over the cube is at the corners


def _octant_3d(x):
    s = 1.0 / (1.0 + np.exp(-(x - 0.5) / 0.1))
    sx, sy, sz = s[..., 0], s[..., 1], s[..., 2]
    out = np.zeros(x.shape[:-1])
    for level, (a, b, c) in enumerate(
        [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)], start=1
    ):
        out = out + level * (sx if a else 1 - sx) * (sy if b else 1 - sy) * (sz if c else 1 - sz)
    return out


def _multi_freq_3d(x):
    return 2 + np.sin(2 * TWO_PI * x[..., 0]) * np.cos(TWO_PI * x[..., 1]) * np.cos(TWO_PI * x[..., 2])


def _prism_peak_3d(x):
    inside = (
        (x[..., 0] > 0.6) & (x[..., 0] < 1.0) & (x[..., 1] > 0.0) & (x[..., 1] < 0.4)
        & (x[..., 2] > 0.4) & (x[..., 2] < 0.8)
    )
    return np.where(inside, 1.0, _multi_freq_3d(x))


#: The paper's test densities by name (:class:`DensityField`): the 2D ones of the tables of paper Sec. 5.2 and of
#: its resolution tests, then the 3D ones.  Each is the raw density :math:`p` of :math:`(x, y)` or :math:`(x, y, z)`
#: in :math:`[0, 1]^d`, given with the paper's equation number (the densities of the resolution tests are unnumbered
#: displays in the paper); :func:`sample_density` then shifts it to minimum 0.1 and scales it to unit mass.
#:
#: * ``sin-cos``, Eq. (28): :math:`2 + \sin(2\pi x)\cos(2\pi y)`;
#: * ``exp-log``, Eq. (29): :math:`2 + \sin(2\pi e^{x})\cos(\pi\log(2y + 0.1))`;
#: * ``rect-peak``, Eq. (30): ``sin-cos`` plus 2 on the box :math:`[0.6, 0.8] \times [0.2, 0.4]`
#:   (:data:`RECT_PEAK_BOX`).  The paper leaves its :math:`\mathrm{rect}(x, y)` unspecified: this input is not the
#:   paper's;
#: * ``ring``, Eq. (31): :math:`\exp(-(r - 1)^2 / (2 \cdot 0.5^2))` with :math:`r` the distance to
#:   :math:`(0.5, 0.5)`.  On :math:`[0, 1]^2`, :math:`r \le \sqrt{2}/2`, so the ridge :math:`r = 1` lies outside
#:   the square: despite its name the density is a bowl, lowest at the centre and rising to the corners;
#: * ``multi-freq``, the 2D resolution tests: :math:`2 + \sin(4\pi x)\cos(4\pi y) + 0.3\sin(6\pi x)`;
#: * ``sin-cos-3d``, Eq. (33): :math:`2 + \sin(2\pi x)\cos(2\pi y)\sin(2\pi z)`;
#: * ``shell-3d``, Eq. (34): :math:`\max g - g(r)` with :math:`g(r) = \exp(-(r - 1)^2 / (2 \cdot 0.5^2))` and
#:   :math:`r` the distance to :math:`(0.5, 0.5, 0.5)`; the paper writes :math:`\max(p)`, read here as the largest
#:   value of the Gaussian term in the cube, at its corners (:math:`r = \sqrt{3}/2`);
#: * ``octant-3d``, Eqs. (35) and (36): the levels 1 to 8 of the eight octants blended by
#:   :math:`s(t) = 1 / (1 + e^{-(t - 0.5)/0.1})` along each axis, level :math:`1 + a + 2b + 4c` weighted by
#:   :math:`s_x^a (1 - s_x)^{1-a}\, s_y^b (1 - s_y)^{1-b}\, s_z^c (1 - s_z)^{1-c}` for :math:`a, b, c \in \{0, 1\}`;
#: * ``prism-peak-3d``, Eq. (37): 1 in the box :math:`(0.6, 1) \times (0, 0.4) \times (0.4, 0.8)`, elsewhere
#:   :math:`2 + \sin(4\pi x)\cos(2\pi y)\cos(2\pi z)`, as printed.  Its Std(ρ̃_orig) misses the paper's by more
#:   than :data:`rfmap.paper.verdicts.COMPARABLE_RTOL` allows: this input is not taken for the paper's either;
#: * ``multi-freq-3d``, the 3D resolution tests: :math:`2 + \sin(4\pi x)\cos(2\pi y)\cos(2\pi z)`.
DENSITIES: dict[str, DensityField] = {
    f.name: f
    for f in [
        DensityField("sin-cos", 2, _sin_cos, "eqn:sin-cos", "2 + sin(2 pi x) cos(2 pi y)"),
        DensityField("exp-log", 2, _exp_log, "eqn:exp-log", "2 + sin(2 pi e^x) cos(pi log(2y + 0.1))"),
        DensityField("rect-peak", 2, _rect_peak, "eqn:rect-peak",
                     "sin-cos + 2 on the box [0.6, 0.8] x [0.2, 0.4] (our choice of rect)"),
        DensityField("ring", 2, _ring, "eqn:ring", "exp(-(|x - c| - 1)^2 / (2 * 0.5^2)), c = (0.5, 0.5)"),
        DensityField("multi-freq", 2, _multi_freq, "exp:res_test_f", "2 + sin(4 pi x) cos(4 pi y) + 0.3 sin(6 pi x)"),
        DensityField("sin-cos-3d", 3, _sin_cos_3d, "eqn:sin-cos-3d", "2 + sin(2 pi x) cos(2 pi y) sin(2 pi z)"),
        DensityField("shell-3d", 3, _shell_3d, "eqn:sp-3d", "max(g) - g, g = exp(-(|x - c| - 1)^2 / (2 * 0.5^2))"),
        DensityField("octant-3d", 3, _octant_3d, "eqn:oct-3d", "smooth blend of levels 1..8 over the octants"),
        DensityField("prism-peak-3d", 3, _prism_peak_3d, "eqn:peak-3d",
                     "1 on (0.6,1)x(0,0.4)x(0.4,0.8), else 2 + sin(4 pi x) cos(2 pi y) cos(2 pi z)"),
        DensityField("multi-freq-3d", 3, _multi_freq_3d, "exp:res_test_f_3d", "2 + sin(4 pi x) cos(2 pi y) cos(2 pi z)"),
    ]
}


# --------------------------------------------------------------------------------------------------- test maps
@dataclass(frozen=True)
class BeltramiMap:
    """An analytic map of the unit square with its exact Beltrami coefficient.

    Attributes
    ----------
    name : str
    fn : callable
        ``fn(x)`` with a float64 tensor ``x`` of shape (..., 2) returns the image points, shape (..., 2).
    label : str
        The paper's equation label.
    """

    name: str
    fn: Callable[[torch.Tensor], torch.Tensor] = field(repr=False)
    label: str = ""
    description: str = ""
    dim: int = 2
    kind: str = "beltrami"

    def __call__(self, x) -> np.ndarray:
        """Image of the points ``x`` (..., 2) under the map."""
        t = torch.as_tensor(np.ascontiguousarray(x, dtype=np.float64))
        if t.shape[-1] != 2:
            raise ValueError(f"map {self.name!r} is 2D; points have dimension {t.shape[-1]}")
        return self.fn(t).numpy()

    def jacobian(self, x) -> np.ndarray:
        """Exact Jacobian :math:`\\partial f_a / \\partial x_b`, shape (..., 2, 2)."""
        t = torch.as_tensor(np.ascontiguousarray(x, dtype=np.float64)).clone().requires_grad_(True)
        f = self.fn(t)
        rows = [torch.autograd.grad(f[..., a].sum(), t, retain_graph=a == 0)[0] for a in range(2)]
        return torch.stack(rows, dim=-2).detach().numpy()

    def mu(self, x) -> np.ndarray:
        """Exact Beltrami coefficient at the points ``x`` (..., 2), complex128 of shape (...)."""
        return beltrami_from_jacobian(torch.as_tensor(self.jacobian(x))).numpy()


def _s(x):
    return torch.sin(math.pi * x[..., 0]) * torch.sin(math.pi * x[..., 1])


def _r2(x):
    return (x[..., 0] - 0.5) ** 2 + (x[..., 1] - 0.5) ** 2


def _t1(a, b):
    def f(x):
        X, Y = x[..., 0], x[..., 1]
        u = X + a * torch.sin(math.pi * X) * torch.sin(TWO_PI * Y)
        v = Y + b * torch.sin(TWO_PI * X) * torch.sin(math.pi * Y)
        return torch.stack([u, v], -1)

    return f


def _t2(x, a=0.03, b=0.02):
    X, Y = x[..., 0], x[..., 1]
    u = X + a * torch.sin(TWO_PI * Y) * torch.sin(math.pi * X) + b * torch.sin(2 * TWO_PI * Y) * torch.sin(TWO_PI * X)
    v = Y + a * torch.sin(TWO_PI * X) * torch.sin(math.pi * Y) + b * torch.sin(2 * TWO_PI * X) * torch.sin(TWO_PI * Y)
    return torch.stack([u, v], -1)


def _t3(x):
    X, Y = x[..., 0], x[..., 1]
    g = torch.exp(-_r2(x) / 0.045)
    s = _s(x)
    # implemented as printed: the -0.60 and +0.70 terms add up to a net +0.10 swirl
    u = X + s * (-0.60 * (Y - 0.5) * g + 0.70 * (Y - 0.5) * g + 0.06 * torch.sin(TWO_PI * Y))
    v = Y + s * (0.60 * (X - 0.5) * g - 0.70 * (X - 0.5) * g - 0.06 * torch.sin(TWO_PI * X))
    return torch.stack([u, v], -1)


def _t4(x, a=0.55, sigma=0.10):
    X, Y = x[..., 0], x[..., 1]
    w = a * _s(x) * torch.exp(-_r2(x) / sigma)
    return torch.stack([X + w * (X - 0.5), Y + w * (Y - 0.5)], -1)


#: The paper's analytic Beltrami test maps by name (:class:`BeltramiMap`): ``T1`` to ``T4`` (paper Sec. 5.1) and
#: ``T1-res``, the map T1 of the paper's resolution tests (Table 3).  Each maps :math:`(x, y)` of the unit square to
#: :math:`(u, v)`; below :math:`s = \sin(\pi x)\sin(\pi y)` and :math:`r^2 = (x - \tfrac12)^2 + (y - \tfrac12)^2`.
#:
#: * ``T1``, Eq. (23): :math:`u = x + a\sin(\pi x)\sin(2\pi y)`, :math:`v = y + b\sin(2\pi x)\sin(\pi y)`, with
#:   :math:`a = b = 0.08`;
#: * ``T2``, Eq. (24): :math:`u = x + a\sin(2\pi y)\sin(\pi x) + b\sin(4\pi y)\sin(2\pi x)`,
#:   :math:`v = y + a\sin(2\pi x)\sin(\pi y) + b\sin(4\pi x)\sin(2\pi y)`, with :math:`a = 0.03`, :math:`b = 0.02`;
#: * ``T3``, Eq. (25), as printed, with :math:`g = e^{-r^2/0.045}`:
#:
#:   .. math::
#:
#:      u &= x + s\,[-0.60\,(y - \tfrac12)\,g + 0.70\,(y - \tfrac12)\,g + 0.06\sin(2\pi y)],\\
#:      v &= y + s\,[0.60\,(x - \tfrac12)\,g - 0.70\,(x - \tfrac12)\,g - 0.06\sin(2\pi x)]
#:
#:   (the two Gaussian terms combine into one of coefficient 0.10 in :math:`u` and -0.10 in :math:`v`);
#: * ``T4``, Eq. (26): :math:`u = x + a\,s\,e^{-r^2/\sigma}(x - \tfrac12)`,
#:   :math:`v = y + a\,s\,e^{-r^2/\sigma}(y - \tfrac12)`, with :math:`a = 0.55`, :math:`\sigma = 0.10`;
#: * ``T1-res``, Eq. (23) with :math:`a = 0.06`, :math:`b = 0.04`.
BELTRAMI_MAPS: dict[str, BeltramiMap] = {
    m.name: m
    for m in [
        BeltramiMap("T1", _t1(0.08, 0.08), "eq:test_map_T1", "mild sinusoidal perturbation, a = b = 0.08"),
        BeltramiMap("T2", _t2, "eq:test_map_T2", "multi-frequency sinusoidal deformation, a = 0.03, b = 0.02"),
        BeltramiMap("T3", _t3, "eq:test_map_T3", "localized rotational deformation"),
        BeltramiMap("T4", _t4, "eq:test_map_T4", "boundary-preserving radial expansion, a = 0.55, sigma = 0.10"),
        BeltramiMap("T1-res", _t1(0.06, 0.04), "eq:test_map_T1", "T1 with a = 0.06, b = 0.04 (resolution test)"),
    ]
}


def field_names(kind: str | None = None, dim: int | None = None) -> list[str]:
    """Names of the built-in fields of task kind ``kind`` (each field's ``kind``) in ``dim`` dimensions; ``None``:
    any."""
    return [k for k, f in {**DENSITIES, **BELTRAMI_MAPS}.items() if kind in (None, f.kind) and dim in (None, f.dim)]


def get_field(name: str) -> DensityField | BeltramiMap:
    """Look up a built-in field by name (``ValueError`` listing the valid names if unknown)."""
    if name in DENSITIES:
        return DENSITIES[name]
    if name in BELTRAMI_MAPS:
        return BELTRAMI_MAPS[name]
    raise ValueError(f"unknown field {name!r}; known fields: {', '.join(field_names())}")


def sample_density(name: str, n: int) -> np.ndarray:
    """Preprocessed vertex values of the named density on the ``N``-grid, shape ``(N,)*d``."""
    f = get_field(name)
    if not isinstance(f, DensityField):
        raise ValueError(f"field {name!r} is a Beltrami test map, not a density")
    return f.sample(n)


def sample_mu(name: str, n: int | None = None, *, points=None, elements=None) -> np.ndarray:
    r"""Exact Beltrami coefficient of the named test map at the element centroids, complex128 of shape (m,).

    The elements are those of the ``N``-grid mesh (:func:`rfmap.core.mesh.grid_mesh`), or ``points``/``elements`` of any
    triangle mesh; the per-triangle :math:`\mu` is the input of :func:`rfmap.solvers.solve_lbs` and the reference
    of the ``mean |Δμ|`` metric.
    """
    f = get_field(name)
    if not isinstance(f, BeltramiMap):
        raise ValueError(f"field {name!r} is a density, not a Beltrami test map")
    if points is None:
        mesh = grid_mesh(n, 2)
        points, elements = mesh.points, mesh.elements
    return f.mu(element_centroids(points, elements))


def prism_peak_readings(n: int, heights=(0.5, 1.0, 1.5, 2.0)) -> dict:
    r"""Std(:math:`\tilde\rho_{\text{orig}}`) on the ``n``-grid (identity map, as every table's input column) of the
    two readings of the prism of paper Eq. (37): ``"replace"``, the value 1 inside the box as printed (the field
    ``prism-peak-3d``), and ``"add"``, the background plus a height :math:`h` inside the box, one value per height
    (a dict ``{h: std}``).  Each input is shifted and scaled as every density (:func:`preprocess_density`)."""
    mesh = grid_mesh(n, 3)
    pts = grid_points(n, 3)
    x = pts.reshape((n,) * 3 + (3,))
    inside = ((x[..., 0] > 0.6) & (x[..., 0] < 1.0) & (x[..., 1] > 0.0) & (x[..., 1] < 0.4)
              & (x[..., 2] > 0.4) & (x[..., 2] < 0.8))
    background = _multi_freq_3d(x)

    def std(raw):
        dens = preprocess_density(raw).reshape(-1)
        return float(compute_metrics(mesh.points, mesh.points, mesh.elements, density=dens).std_rho_orig)

    return {"replace": std(np.where(inside, 1.0, background)),
            "add": {float(h): std(background + h * inside) for h in heights}}
