r"""Input fields: the paper's test densities and test maps, preprocessing, and random training fields.

Densities (paper Sec. 5.2) are functions :math:`p: [0,1]^d \to \mathbb{R}`; before use they are evaluated at the
mesh vertices, shifted to minimum 0.1 and scaled to unit mass (:func:`preprocess_density`).  Beltrami test maps
(paper Sec. 5.1, Eqs. T1–T4) are analytic maps of the unit square; their exact Beltrami coefficient
:math:`\mu = f_{\bar z}/f_z` is computed by automatic differentiation in float64 (exact to round-off).

Random training fields follow paper Sec. 4.1: a smooth superposition of sinusoidal modes
:math:`\sum_k A_k \prod_i \mathrm{trig}(2\pi f_{k,i} x_i + \varphi_{k,i})` with log-uniform frequencies, plus sparse
non-smooth parts (steps, noise, compact high-frequency patches).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable

import numpy as np
import torch

from .mesh import check_dim, check_n, grid_mesh, grid_points

__all__ = [
    "DensityField",
    "BeltramiMap",
    "DENSITIES",
    "BELTRAMI_MAPS",
    "RECT_PEAK_BOX",
    "field_names",
    "get_field",
    "check_density",
    "check_mu",
    "vertex_weights",
    "preprocess_density",
    "sample_density",
    "RandomDensity",
    "RandomDensityConfig",
    "random_density",
    "RandomMap",
    "RandomBeltramiConfig",
    "random_boundary_map",
    "RandomBeltrami",
    "random_beltrami",
    "jittered_points",
]

TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------------------------------- validation
def check_density(values, *, name: str = "density", positive: bool = True) -> np.ndarray:
    """Return ``values`` as float64 array; raise ``ValueError`` on NaN/inf or non-positive entries."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        raise ValueError(f"{name} is empty")
    bad = ~np.isfinite(v)
    if bad.any():
        raise ValueError(f"{name} contains {int(bad.sum())} NaN or infinite value(s), e.g. {v[bad].flat[0]}")
    if positive and (v <= 0).any():
        raise ValueError(f"{name} must be strictly positive; minimum is {v.min():.6g}")
    return v


def check_mu(mu, *, name: str = "mu") -> np.ndarray:
    """Return ``mu`` as complex128 array; raise ``ValueError`` on NaN/inf or :math:`|\\mu| \\ge 1`."""
    m = np.asarray(mu)
    if not np.iscomplexobj(m):
        m = m.astype(np.float64)
    m = m.astype(np.complex128)
    bad = ~np.isfinite(m)
    if bad.any():
        raise ValueError(f"{name} contains {int(bad.sum())} NaN or infinite value(s)")
    a = np.abs(m)
    if (a >= 1).any():
        raise ValueError(f"|{name}| must be < 1 everywhere (quasi-conformality); max |{name}| = {a.max():.6g}")
    return m


# --------------------------------------------------------------------------------------------------- preprocessing
@lru_cache(maxsize=32)
def _grid_vertex_weights(n: int, dim: int) -> np.ndarray:
    mesh = grid_mesh(n, dim)
    w = vertex_weights(mesh.points, mesh.elements)
    w.setflags(write=False)
    return w


def vertex_weights(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    r"""Quadrature weights :math:`w_v = \sum_{T \ni v} |T| / (d+1)`.

    :math:`\sum_v w_v p_v` is the exact integral of the piecewise-linear interpolant of the vertex values
    :math:`p_v`, i.e. the total population in the paper's convention (element population = mean vertex value times
    element measure).
    """
    from .mesh import element_measures

    pts = np.asarray(points, dtype=np.float64)
    el = np.asarray(elements)
    meas = element_measures(pts, el)
    w = np.zeros(pts.shape[0])
    np.add.at(w, el.reshape(-1), np.repeat(meas / el.shape[1], el.shape[1]))
    return w


def preprocess_density(values, *, floor: float = 0.1, weights: np.ndarray | None = None) -> np.ndarray:
    r"""The paper's preprocessing: :math:`p \leftarrow p - \min p + 0.1`, then unit mass.

    Parameters
    ----------
    values : array, shape (N,)*d (a grid field) or (n,) with ``weights``
    floor : float
        Minimum after the shift.
    weights : array, shape (n,), optional
        Vertex quadrature weights (:func:`vertex_weights`); defaults to the ``N``-grid's.

    Returns
    -------
    ndarray, same shape, strictly positive, :math:`\int p = 1` for the piecewise-linear interpolant.
    """
    v = check_density(values, positive=False)
    p = v - v.min() + floor
    if weights is None:
        if v.ndim not in (2, 3) or len(set(v.shape)) != 1:
            raise ValueError(f"a grid density must have shape (N, N) or (N, N, N), got {v.shape}")
        weights = _grid_vertex_weights(v.shape[0], v.ndim).reshape(v.shape)
    mass = float((np.asarray(weights).reshape(p.shape) * p).sum())
    return p / mass


# --------------------------------------------------------------------------------------------------- test densities
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


#: The box of the rect-peak test (c): the paper leaves ``rect(x, y)`` unspecified; we add ``+2`` on this box.
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
        from .geometry import beltrami_from_jacobian

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
    """Names of the built-in fields; ``kind`` is ``'density'`` or ``'beltrami'``."""
    out = []
    if kind in (None, "density"):
        out += [k for k, f in DENSITIES.items() if dim is None or f.dim == dim]
    if kind in (None, "beltrami") and dim in (None, 2):
        out += list(BELTRAMI_MAPS)
    return out


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


# --------------------------------------------------------------------------------------------------- random fields
def _log_uniform(rng: np.random.Generator, lo: float, hi: float, size) -> np.ndarray:
    return np.exp(rng.uniform(math.log(lo), math.log(hi), size=size))


@dataclass(frozen=True)
class RandomDensityConfig:
    """Ranges of the random training densities (paper Sec. 5.2; 3D: modes [4, 40], frequencies [0.1, 5]).

    Attributes
    ----------
    dim : int
    modes : (int, int)
        Number of sinusoidal modes, uniform in this closed range.
    freq : (float, float)
        Log-uniform range of every frequency :math:`f_{k,i}`.
    contrast : (float, float)
        Log-uniform range of the raw field's peak-to-peak value before the shift (the shifted field then spans
        ``[0.1, 0.1 + contrast]``; the test fields span about 2).
    p_step, p_patch, p_noise : float
        Probabilities of adding a step (box indicator), a compact high-frequency patch, and vertex noise.
    """

    dim: int = 2
    modes: tuple[int, int] = (1, 50)
    freq: tuple[float, float] = (0.1, 8.0)
    contrast: tuple[float, float] = (0.3, 4.0)
    p_step: float = 0.3
    p_patch: float = 0.2
    p_noise: float = 0.1
    noise: float = 0.02

    @classmethod
    def for_dim(cls, dim: int, **kw) -> "RandomDensityConfig":
        if check_dim(dim) == 3:
            kw = {"modes": (4, 40), "freq": (0.1, 5.0), **kw}
        return cls(dim=dim, **kw)


class RandomDensity:
    r"""One random density :math:`p = s\,(p_{\text{smooth}} + p_{\text{nonsmooth}})` (paper Sec. 4.1).

    The smooth part is :math:`\sum_k A_k \sin(2\pi f_{k,1}x_1+\varphi_{k,1})\cos(2\pi f_{k,2}x_2+\varphi_{k,2})
    [\sin(2\pi f_{k,3} x_3 + \varphi_{k,3})]` with :math:`A_k \in [-1,1]`; the non-smooth part holds optional box
    steps and Gaussian-windowed high-frequency patches; the scale :math:`s` sets a random peak-to-peak contrast.
    Call it on points of shape (P, d) to get raw values (P,); :func:`preprocess_density` does shift and mass.
    """

    def __init__(self, rng: np.random.Generator, cfg: RandomDensityConfig = RandomDensityConfig()):
        d = check_dim(cfg.dim)
        self.dim = d
        k = int(rng.integers(cfg.modes[0], cfg.modes[1] + 1))
        self.amp = rng.uniform(-1, 1, size=k)
        self.freq = _log_uniform(rng, cfg.freq[0], cfg.freq[1], (k, d))
        self.phase = rng.uniform(0, TWO_PI, size=(k, d))
        self.steps = []
        if rng.random() < cfg.p_step:
            for _ in range(int(rng.integers(1, 3))):
                lo = rng.uniform(0, 0.8, size=d)
                hi = lo + rng.uniform(0.1, 0.4, size=d)
                self.steps.append((lo, hi, rng.uniform(-1, 1) * 0.5 * max(1.0, math.sqrt(k))))
        self.patches = []
        if rng.random() < cfg.p_patch:
            c = rng.uniform(0.15, 0.85, size=d)
            self.patches.append((c, rng.uniform(0.04, 0.1), rng.uniform(10, 20, size=d),
                                 rng.uniform(0, TWO_PI, size=d), 0.5 * max(1.0, math.sqrt(k))))
        self.noise = cfg.noise if rng.random() < cfg.p_noise else 0.0
        self.contrast = float(_log_uniform(rng, *cfg.contrast, ()))
        self._rng = np.random.default_rng(rng.integers(2**63))
        self.scale, noise, self.noise = 1.0, self.noise, 0.0
        probe = self.on_grid(33)
        self.noise = noise
        span = float(probe.max() - probe.min())
        self.scale = self.contrast / span if span > 1e-12 else 1.0

    def _raw(self, x: np.ndarray) -> np.ndarray:
        arg = TWO_PI * x[:, None, :] * self.freq[None] + self.phase[None]  # (P, K, d)
        t = np.sin(arg)
        if self.dim >= 2:
            t[..., 1] = np.cos(arg[..., 1])
        return (self.amp[None] * t.prod(-1)).sum(-1) + self._nonsmooth(x)

    def _nonsmooth(self, x: np.ndarray) -> np.ndarray:
        out = np.zeros(x.shape[0])
        for lo, hi, h in self.steps:
            out = out + h * ((x >= lo) & (x <= hi)).all(-1)
        for c, width, f, ph, a in self.patches:
            w = np.exp(-((x - c) ** 2).sum(-1) / (2 * width**2))
            out = out + a * w * np.sin(TWO_PI * (x * f).sum(-1) + ph[0])
        return out

    def on_grid(self, n: int) -> np.ndarray:
        """Raw values on the regular ``N``-grid, flat shape (N**d,), by separable evaluation of the modes."""
        t = np.linspace(0.0, 1.0, n)
        arg = TWO_PI * self.freq[:, :, None] * t[None, None, :] + self.phase[:, :, None]  # (K, d, N)
        tab = np.sin(arg)
        tab[:, 1] = np.cos(arg[:, 1])
        if self.dim == 2:
            smooth = np.einsum("k,ki,kj->ij", self.amp, tab[:, 0], tab[:, 1])
        else:
            smooth = np.einsum("k,ki,kj,kl->ijl", self.amp, tab[:, 0], tab[:, 1], tab[:, 2])
        out = smooth.reshape(-1) + self._nonsmooth(grid_points(n, self.dim))
        out = self.scale * out
        if self.noise:
            out = out + self.noise * self.contrast * self._rng.standard_normal(out.shape)
        return out

    def __call__(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.dim:
            raise ValueError(f"points must have shape (P, {self.dim}), got {x.shape}")
        out = self.scale * self._raw(x)
        if self.noise:
            out = out + self.noise * self.contrast * self._rng.standard_normal(out.shape)
        return out


def random_density(rng: np.random.Generator, cfg: RandomDensityConfig | None = None, dim: int = 2) -> RandomDensity:
    """Draw one random training density (see :class:`RandomDensity`)."""
    return RandomDensity(rng, cfg or RandomDensityConfig.for_dim(dim))


@dataclass(frozen=True)
class RandomBeltramiConfig:
    """Ranges of the random Beltrami training fields (paper Sec. 5.1).

    Attributes
    ----------
    modes : (int, int)
        Number of modes, uniform.
    freq : (float, float)
        Log-uniform frequency range.
    k : float
        Bound :math:`\\|\\mu\\|_\\infty \\le k < 1`.
    sup : (float, float)
        Range of the drawn sup-norm level (uniform), capped by ``k``.
    """

    modes: tuple[int, int] = (1, 50)
    freq: tuple[float, float] = (0.1, 8.0)
    k: float = 0.9
    sup: tuple[float, float] = (0.05, 0.9)


class RandomBeltrami:
    r"""A random Beltrami coefficient as in paper Eq. (train_beltrami).

    :math:`\mu = \tau(x)\, s \sum_i A_i \sin(2\pi f_{x,i} x + \phi_{x,i}) \cos(2\pi f_{y,i} y + \phi_{y,i})` with
    complex amplitudes :math:`A_i = |A_i| e^{i\theta_i}`, :math:`|A_i| \le 1`, a boundary taper
    :math:`\tau = \min(1, \mathrm{dist}(x, \partial\Omega)/0.1)` so that :math:`\mu = 0` on the boundary, and
    a scale :math:`s` making :math:`\|\mu\|_\infty` a random level :math:`\le k`.
    """

    def __init__(self, rng: np.random.Generator, cfg: RandomBeltramiConfig = RandomBeltramiConfig()):
        if not 0 < cfg.k < 1:
            raise ValueError(f"the bound k must lie in (0, 1), got {cfg.k}")
        n = int(rng.integers(cfg.modes[0], cfg.modes[1] + 1))
        self.amp = rng.uniform(0, 1, n) * np.exp(1j * rng.uniform(0, TWO_PI, n))
        self.freq = _log_uniform(rng, cfg.freq[0], cfg.freq[1], (n, 2))
        self.phase = rng.uniform(0, TWO_PI, (n, 2))
        probe = self._raw(grid_points(65, 2))
        level = min(cfg.k, rng.uniform(*cfg.sup))
        peak = np.abs(probe).max()
        self.scale = level / peak if peak > 0 else 0.0
        self.k = float(cfg.k)

    def _raw(self, x):
        arg = TWO_PI * x[:, None, :] * self.freq[None] + self.phase[None]
        base = (self.amp[None] * np.sin(arg[..., 0]) * np.cos(arg[..., 1])).sum(-1)
        dist = np.minimum(x, 1 - x).min(-1)
        return base * np.clip(dist / 0.1, 0, 1)

    def __call__(self, x) -> np.ndarray:
        """Complex :math:`\\mu` at points (P, 2)."""
        mu = self.scale * self._raw(np.asarray(x, dtype=np.float64))
        # the scale is set on a probe grid; between probe points |mu| can exceed the level by a few per cent,
        # so enforce the bound k exactly by a radial clip (inactive unless the level is within that of k)
        a = np.abs(mu)
        over = a > self.k
        if over.any():
            mu = np.where(over, mu * (self.k / np.maximum(a, 1e-300)), mu)
        return mu


def random_beltrami(rng: np.random.Generator, cfg: RandomBeltramiConfig | None = None) -> RandomBeltrami:
    """Draw one random Beltrami coefficient (see :class:`RandomBeltrami`)."""
    return RandomBeltrami(rng, cfg or RandomBeltramiConfig())


class RandomMap:
    r"""A random smooth map of the unit square that is the identity on the boundary, with its exact :math:`\mu`.

    :math:`f(x) = x + c\, b(x) \sum_i A_i \sin(2\pi f_{x,i}x + \phi_{x,i}) \cos(2\pi f_{y,i}y + \phi_{y,i})`
    with the bump :math:`b = 16\,x(1-x)\,y(1-y)` (one sum per component, paper-style modes), scaled by :math:`c`
    so that :math:`\|\mu\|_\infty` equals a random level :math:`\le k` with :math:`\det J > 0`.  Its exact
    :math:`\mu` (closed-form derivatives) is a Beltrami training input whose solution is known to be a
    homeomorphism fixing the boundary, unlike a tapered random :math:`\mu`.
    """

    dim = 2
    kind = "beltrami"

    def __init__(self, rng: np.random.Generator, cfg: RandomBeltramiConfig = RandomBeltramiConfig()):
        if not 0 < cfg.k < 1:
            raise ValueError(f"the bound k must lie in (0, 1), got {cfg.k}")
        n = int(rng.integers(cfg.modes[0], cfg.modes[1] + 1))
        self.amp = rng.uniform(-1, 1, (2, n))
        self.freq = TWO_PI * _log_uniform(rng, cfg.freq[0], cfg.freq[1], (2, n, 2))  # angular
        self.phase = rng.uniform(0, TWO_PI, (2, n, 2))
        self.scale = 1.0
        level = min(cfg.k, rng.uniform(*cfg.sup))
        pts = grid_points(65, 2)
        J0 = self.jacobian(pts) - np.eye(2)
        self.scale = self._fit_scale(J0, level)
        # |mu| can peak between probe points (up to a few per cent above the probe maximum): add fine local
        # grids around the largest values, a quarter of the previous spacing per round, and fit the scale again
        spacing = 1.0 / 64
        for _ in range(3):
            a0, b0 = self._wirtinger0(J0)
            top = pts[np.argsort(b0 / np.abs(1 + self.scale * a0))[-16:]]
            t = np.linspace(-spacing, spacing, 9)
            patch = np.stack(np.meshgrid(t, t, indexing="ij"), -1).reshape(1, -1, 2)
            local = np.clip(top[:, None, :] + patch, 0.0, 1.0).reshape(-1, 2)
            scale, self.scale = self.scale, 1.0
            J0 = np.concatenate([J0, self.jacobian(local) - np.eye(2)])
            self.scale = scale
            pts = np.concatenate([pts, local])
            spacing /= 4
            self.scale = self._fit_scale(J0, level)

    @staticmethod
    def _wirtinger0(J0):
        # with J = I + c J0: f_z = 1 + c a0 and f_zbar = c b0, so |mu| = c |b0| / |1 + c a0|; det J > 0 iff |mu| < 1
        a0 = 0.5 * ((J0[..., 0, 0] + J0[..., 1, 1]) + 1j * (J0[..., 1, 0] - J0[..., 0, 1]))
        b0 = np.abs(0.5 * ((J0[..., 0, 0] - J0[..., 1, 1]) + 1j * (J0[..., 1, 0] + J0[..., 0, 1])))
        return a0, b0

    @classmethod
    def _fit_scale(cls, J0, level):
        # sup|mu| of x + c D grows with c: bisection for sup|mu| = level
        a0, b0 = cls._wirtinger0(J0)

        def sup_mu(c):
            fz = np.abs(1 + c * a0)
            return np.inf if (fz <= c * b0).any() else float((c * b0 / fz).max())

        lo, hi = 0.0, 1.0
        while sup_mu(hi) < level and hi < 1e6:
            hi *= 2
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if sup_mu(mid) < level:
                lo = mid
            else:
                hi = mid
        return lo

    def _parts(self, x):
        x = np.asarray(x, dtype=np.float64)
        X, Y = x[..., 0], x[..., 1]
        ax = self.freq[..., 0] * X[..., None, None] + self.phase[..., 0]  # (..., 2, n)
        ay = self.freq[..., 1] * Y[..., None, None] + self.phase[..., 1]
        sx, cx, sy, cy = np.sin(ax), np.cos(ax), np.sin(ay), np.cos(ay)
        M = (self.amp * sx * cy).sum(-1)  # (..., 2)
        Mx = (self.amp * self.freq[..., 0] * cx * cy).sum(-1)
        My = (-self.amp * self.freq[..., 1] * sx * sy).sum(-1)
        b = 16 * X * (1 - X) * Y * (1 - Y)
        bx = 16 * (1 - 2 * X) * Y * (1 - Y)
        by = 16 * X * (1 - X) * (1 - 2 * Y)
        return b, bx, by, M, Mx, My

    def __call__(self, x) -> np.ndarray:
        """Image of the points ``x`` (..., 2)."""
        b, _, _, M, _, _ = self._parts(x)
        return np.asarray(x, dtype=np.float64) + self.scale * b[..., None] * M

    def jacobian(self, x) -> np.ndarray:
        """Exact Jacobian, shape (..., 2, 2)."""
        b, bx, by, M, Mx, My = self._parts(x)
        dx = self.scale * (bx[..., None] * M + b[..., None] * Mx)  # d f_c / dx, (..., 2)
        dy = self.scale * (by[..., None] * M + b[..., None] * My)
        return np.stack([dx, dy], -1) + np.eye(2)

    def mu(self, x) -> np.ndarray:
        """Exact Beltrami coefficient, complex (...)."""
        from .geometry import beltrami_from_jacobian

        return beltrami_from_jacobian(torch.as_tensor(self.jacobian(x))).numpy()


def random_boundary_map(rng: np.random.Generator, cfg: RandomBeltramiConfig | None = None) -> RandomMap:
    """Draw one random boundary-fixing map with its exact Beltrami coefficient (see :class:`RandomMap`)."""
    return RandomMap(rng, cfg or RandomBeltramiConfig())


# --------------------------------------------------------------------------------------------------- sampling
@lru_cache(maxsize=16)
def _sobol_base(count: int, dim: int) -> np.ndarray:
    from scipy.stats import qmc

    pts = qmc.Sobol(d=dim, scramble=False).random_base2(int(math.ceil(math.log2(max(count, 2)))))[:count]
    pts.setflags(write=False)
    return pts


def jittered_points(
    n: int,
    dim: int,
    rng: np.random.Generator,
    *,
    grad_magnitude: np.ndarray | None = None,
    strength: float = 0.2,
) -> np.ndarray:
    r"""Sobol-jittered vertices of the ``N``-grid (paper Sec. 5: stochastic jittered sampling).

    Vertex :math:`x_v` moves to :math:`x_v + \text{strength}\cdot h\cdot g_v\,(2 s_v - 1)` where :math:`s_v` is a
    randomly shifted (Cranley–Patterson) Sobol point in :math:`[0,1]^d` and :math:`g_v \in [0, 1]` is the local
    gradient magnitude of the field normalised by its maximum (1 everywhere when ``grad_magnitude`` is ``None``).
    Boundary vertices only slide along the boundary and corners stay fixed, so the jittered mesh still tiles
    :math:`[0,1]^d`; with ``strength <= 0.2`` no element can flip.  (A Kuhn tetrahedron can degenerate once its
    vertices move :math:`h/6` per axis, so in 3D the offsets are scaled by 3/4 to keep that guarantee.)

    Returns
    -------
    ndarray, shape (N**d, d)
    """
    n = check_n(n)
    dim = check_dim(dim)
    if not 0 <= strength <= 0.2:
        raise ValueError(f"jitter strength must lie in [0, 0.2] (fraction of the grid spacing), got {strength}")
    pts = grid_points(n, dim)
    sob = (_sobol_base(pts.shape[0], dim) + rng.random(dim)) % 1.0
    sob = sob[rng.permutation(pts.shape[0])]
    off = (2 * sob - 1) * (strength if dim == 2 else 0.75 * strength) / (n - 1)
    if grad_magnitude is not None:
        g = np.abs(np.asarray(grad_magnitude, dtype=np.float64)).reshape(-1)
        if g.shape[0] != pts.shape[0]:
            raise ValueError(f"grad_magnitude has {g.shape[0]} values for {pts.shape[0]} vertices")
        g = g / g.max() if g.max() > 0 else g
        off = off * g[:, None]
    on_wall = (pts <= 0) | (pts >= 1)
    off[on_wall] = 0.0
    return np.clip(pts + off, 0.0, 1.0)
