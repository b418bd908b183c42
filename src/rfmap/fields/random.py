r"""Random training fields (paper Sec. 4.1): densities, Beltrami coefficients and boundary-fixing maps.

A smooth superposition of sinusoidal modes :math:`\sum_k A_k \prod_i \mathrm{trig}(2\pi f_{k,i} x_i + \varphi_{k,i})`
with log-uniform frequencies, plus sparse non-smooth parts (steps, noise, compact high-frequency patches).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..core.geometry import beltrami_from_jacobian
from ..core.mesh import check_dim, grid_points

__all__ = [
    "RandomDensity",
    "RandomDensityConfig",
    "random_density",
    "RandomMap",
    "RandomBeltramiConfig",
    "random_boundary_map",
    "RandomBeltrami",
    "random_beltrami",
]

TWO_PI = 2.0 * math.pi


def _log_uniform(rng: np.random.Generator, lo: float, hi: float, size) -> np.ndarray:
    return np.exp(rng.uniform(math.log(lo), math.log(hi), size=size))


@dataclass(frozen=True)
class RandomDensityConfig:
    r"""Ranges of the random training densities (paper Sec. 5.2; 3D: modes [4, 40], frequencies [0.1, 5]).  The
    generator they feed, :class:`RandomDensity`, is the one of the paper's Sec. 4.1; Sec. 5.2 gives its ranges.

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
    p_step : float
        Probability of adding a step (a box indicator).
    p_patch : float
        Probability of adding a compact high-frequency patch.
    p_noise : float
        Probability of adding vertex noise.
    p_peak : float
        Probability of adding a narrow Gaussian peak (width 0.02–0.08); 0 by default (no peaks).
    p_ramp : float
        Probability of adding a steep tanh ramp across a random direction (width 0.01–0.05); 0 by default, like
        ``p_peak``.
    ramp_width : (float, float)
        Uniform range of a ramp's width.
    ramp_scale : float
        A ramp's height is uniform in :math:`[-1, 1]` times this factor (and the modes' typical amplitude): larger
        values give ramp-dominated fields whose equalizing maps must move points far (the same random stream for
        every value).
    p_hard : float
        Probability that the field is a *hard* one instead: a single steep ramp
        :math:`1 + \tfrac{k-1}{2}(1 + \tanh((x\cdot n - o)/w))` or a single narrow peak
        :math:`1 + t\cdot(x - \tfrac12) + h\,e^{-|x-c|^2/2w^2}` (equal chances) over a faint copy of the
        random modes. After the density preprocessing (minimum shifted to 0.1, an inference from the paper's
        Std(ρ̃_orig), see :mod:`rfmap.core.inputs`) half of the domain of a ramp carries 1/(10k - 9) of the
        density of the other half, so the equalizing map must shrink that half to a few per cent of its measure:
        the kind of field where an untrained map folds.  0 by default.
    hard_contrast : (float, float)
        Uniform range of a hard ramp's height ratio :math:`k` (raw values from 1 to k); a hard peak's height
        :math:`h` is log-uniform in [1, 2(k_max - 1)].
    hard_background : float
        The faint modes' peak-to-peak value is uniform in [0, this] (the hard feature's is 1 to 10).
    """

    dim: int = 2
    modes: tuple[int, int] = (1, 50)
    freq: tuple[float, float] = (0.1, 8.0)
    contrast: tuple[float, float] = (0.3, 4.0)
    p_step: float = 0.3
    p_patch: float = 0.2
    p_noise: float = 0.1
    noise: float = 0.02
    p_peak: float = 0.0
    p_ramp: float = 0.0
    ramp_width: tuple[float, float] = (0.01, 0.05)
    ramp_scale: float = 1.0
    p_hard: float = 0.0
    hard_contrast: tuple[float, float] = (1.5, 6.0)
    hard_background: float = 0.3

    @classmethod
    def for_dim(cls, dim: int, **kw) -> "RandomDensityConfig":
        """The default distribution in dimension ``dim``, with the paper's ranges: in 3D ``modes=(4, 40)`` and
        ``freq=(0.1, 5.0)`` (paper Eq. (32)), in 2D the defaults above; ``kw`` overrides any field."""
        if check_dim(dim) == 3:
            kw = {"modes": (4, 40), "freq": (0.1, 5.0), **kw}
        return cls(dim=dim, **kw)


class RandomDensity:
    r"""One random density :math:`p = s\,(p_{\text{smooth}} + p_{\text{nonsmooth}})` (paper Sec. 4.1).

    The smooth part is :math:`\sum_k A_k \sin(2\pi f_{k,1}x_1+\varphi_{k,1})\cos(2\pi f_{k,2}x_2+\varphi_{k,2})
    [\sin(2\pi f_{k,3} x_3 + \varphi_{k,3})]` with :math:`A_k \in [-1,1]`; the non-smooth part holds optional box
    steps and Gaussian-windowed high-frequency patches; the scale :math:`s` sets a random peak-to-peak contrast.
    Call it on points of shape (P, d) to get raw values (P,); :func:`~rfmap.core.inputs.preprocess_density` does
    shift and mass.

    Differs from the paper: its Sec. 4.1 allows additive noise, step regions and high-frequency patches, which this
    class draws, while its experiments (Sec. 5.2) list sums of sine modes alone; the contrast scale :math:`s`
    (peak-to-peak range log-uniform in ``RandomDensityConfig.contrast``) and the optional peaks, ramps and hard
    fields are this package's additions.
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
        # sharp features drawn last, so that configurations without them keep their earlier random streams
        self.peaks, self.ramps = [], []
        big = max(1.0, math.sqrt(k))
        if cfg.p_peak and rng.random() < cfg.p_peak:
            self.peaks.append((rng.uniform(0.1, 0.9, size=d), rng.uniform(0.02, 0.08), rng.uniform(1.0, 3.0) * big))
        if cfg.p_ramp and rng.random() < cfg.p_ramp:
            nrm = rng.normal(size=d)
            nrm /= np.linalg.norm(nrm)
            self.ramps.append((nrm, float(nrm @ rng.uniform(0.2, 0.8, size=d)), rng.uniform(*cfg.ramp_width),
                               rng.uniform(-1.0, 1.0) * big * cfg.ramp_scale))
        self.scale, noise, self.noise = 1.0, self.noise, 0.0
        self.hard = None
        probe = self.on_grid(33)
        self.noise = noise
        span = float(probe.max() - probe.min())
        self.scale = self.contrast / span if span > 1e-12 else 1.0
        # a hard field (drawn last, after the probe, so the fields of p_hard = 0 keep their random streams)
        if cfg.p_hard and rng.random() < cfg.p_hard:
            k = rng.uniform(*cfg.hard_contrast)
            if rng.random() < 0.5:
                nrm = rng.normal(size=d)
                nrm /= np.linalg.norm(nrm)
                self.hard = ("ramp", nrm, float(nrm @ rng.uniform(0.3, 0.7, size=d)), rng.uniform(*cfg.ramp_width), k)
            else:
                h = float(np.exp(rng.uniform(0.0, math.log(2.0 * (cfg.hard_contrast[1] - 1.0)))))
                self.hard = ("peak", rng.uniform(0.2, 0.8, size=d), rng.uniform(0.03, 0.08), h,
                             rng.uniform(-0.3, 0.3, size=d))
            self.scale *= rng.uniform(0.0, cfg.hard_background) / self.contrast
            self.noise = 0.0

    def _raw(self, x: np.ndarray) -> np.ndarray:
        # float64 sin/cos through torch (vectorised, about 4x numpy's on this kind of CPU); one (P, K) factor per axis
        arg = torch.addcmul(torch.from_numpy(self.phase)[None], torch.from_numpy(x)[:, None, :],
                            torch.from_numpy(TWO_PI * self.freq)[None])  # (P, K, d)
        t = torch.sin(arg[..., 0])
        if self.dim >= 2:
            t = t * torch.cos(arg[..., 1])
        if self.dim >= 3:
            t = t * torch.sin(arg[..., 2])
        return (t @ torch.from_numpy(self.amp)).numpy() + self._nonsmooth(x)

    def _nonsmooth(self, x: np.ndarray) -> np.ndarray:
        out = np.zeros(x.shape[0])
        for lo, hi, h in self.steps:
            out = out + h * ((x >= lo) & (x <= hi)).all(-1)
        for c, width, f, ph, a in self.patches:
            w = np.exp(-((x - c) ** 2).sum(-1) / (2 * width**2))
            out = out + a * w * np.sin(TWO_PI * (x * f).sum(-1) + ph[0])
        for c, width, h in getattr(self, "peaks", ()):
            out = out + h * np.exp(-((x - c) ** 2).sum(-1) / (2 * width**2))
        for nrm, off, width, h in getattr(self, "ramps", ()):
            out = out + h * np.tanh((x @ nrm - off) / width)
        return out

    def _hard(self, x: np.ndarray) -> np.ndarray | float:
        """The hard feature (unscaled, added after the modes' scale) at points (P, d), or 0."""
        hard = getattr(self, "hard", None)
        if hard is None:
            return 0.0
        if hard[0] == "ramp":
            _, nrm, off, width, k = hard
            return 1.0 + 0.5 * (k - 1.0) * (1.0 + np.tanh((x @ nrm - off) / width))
        _, c, width, h, tilt = hard
        return 1.0 + (x - 0.5) @ tilt + h * np.exp(-((x - c) ** 2).sum(-1) / (2 * width**2))

    def on_grid(self, n: int) -> np.ndarray:
        """Raw values on the regular ``N``-grid, flat shape (N**d,), by separable evaluation of the modes."""
        t = np.linspace(0.0, 1.0, n)
        arg = TWO_PI * self.freq[:, :, None] * t[None, None, :] + self.phase[:, :, None]  # (K, d, N)
        tab = np.sin(arg)
        tab[:, 1] = np.cos(arg[:, 1])
        # sum_k A_k s_k(x) c_k(y) [s_k(z)] as matrix products (BLAS) rather than an unoptimised einsum loop
        a = self.amp[:, None] * tab[:, 0]  # (K, N)
        if self.dim == 2:
            smooth = a.T @ tab[:, 1]
        else:
            k = len(self.amp)
            smooth = ((a[:, :, None] * tab[:, 1, None, :]).reshape(k, n * n).T @ tab[:, 2]).reshape(n, n, n)
        pts = grid_points(n, self.dim)
        out = self.scale * (smooth.reshape(-1) + self._nonsmooth(pts)) + self._hard(pts)
        if self.noise:
            out = out + self.noise * self.contrast * self._rng.standard_normal(out.shape)
        return out

    def __call__(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.dim:
            raise ValueError(f"points must have shape (P, {self.dim}), got {x.shape}")
        out = self.scale * self._raw(x) + self._hard(x)
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
    low : float
        Share of low-frequency fields, whose number of modes and frequencies are drawn from ``low_modes`` and
        ``low_freq`` instead.  At equal :math:`\\|\\mu\\|_\\infty` a map with a few slow modes (like the test
        maps T1–T4) moves the mesh much further than one with many fast modes, so a model trained on the default
        ranges alone reconstructs such maps less well.  :doc:`Appendix C </notebooks/16_appendix_budgets>` compares a
        model's vertex error on the two families (:func:`rfmap.paper.generalization.generalization_table` with ``low_frequency=True``).
    low_modes : (int, int)
        Number of modes of a low-frequency field, uniform.
    low_freq : (float, float)
        Log-uniform frequency range of a low-frequency field.
    """

    modes: tuple[int, int] = (1, 50)
    freq: tuple[float, float] = (0.1, 8.0)
    k: float = 0.9
    sup: tuple[float, float] = (0.05, 0.9)
    low: float = 0.0
    low_modes: tuple[int, int] = (1, 4)
    low_freq: tuple[float, float] = (0.25, 2.0)

    def __post_init__(self):
        if not 0.0 <= self.low <= 1.0:
            raise ValueError(f"the share of low-frequency fields must lie in [0, 1], got {self.low}")

    def draw_ranges(self, rng: np.random.Generator) -> tuple[tuple[int, int], tuple[float, float]]:
        """The mode-count and frequency ranges of one field: the low-frequency ones with probability ``low``."""
        # low = 0 draws no extra random number, so configurations without the share keep their random streams
        if self.low > 0 and rng.random() < self.low:
            return self.low_modes, self.low_freq
        return self.modes, self.freq


class RandomBeltrami:
    r"""A random Beltrami coefficient as in paper Sec. 5.1, Eq. (22).

    :math:`\mu = \tau(x)\, s \sum_i A_i \sin(2\pi f_{x,i} x + \phi_{x,i}) \cos(2\pi f_{y,i} y + \phi_{y,i})` with
    complex amplitudes :math:`A_i = |A_i| e^{i\theta_i}`, :math:`|A_i| \le 1`, a boundary taper
    :math:`\tau = \min(1, \mathrm{dist}(x, \partial\Omega)/0.1)` so that :math:`\mu = 0` on the boundary, and
    a scale :math:`s` making :math:`\|\mu\|_\infty` a random level :math:`\le k`.

    Differs from the paper: Eq. (22) has real amplitudes :math:`A_i \in [-1, 1]` (so a real :math:`\mu`) and sets
    :math:`\mu` to zero on :math:`\partial\Omega` without saying how; here the amplitudes are complex, so that
    :math:`\mu` takes every direction, and the zero boundary value comes from the linear taper :math:`\tau`.
    The Beltrami task's default training fields are those of :class:`RandomMap`, not these.
    """

    def __init__(self, rng: np.random.Generator, cfg: RandomBeltramiConfig = RandomBeltramiConfig()):
        if not 0 < cfg.k < 1:
            raise ValueError(f"the bound k must lie in (0, 1), got {cfg.k}")
        modes, freq = cfg.draw_ranges(rng)
        n = int(rng.integers(modes[0], modes[1] + 1))
        self.amp = rng.uniform(0, 1, n) * np.exp(1j * rng.uniform(0, TWO_PI, n))
        self.freq = _log_uniform(rng, freq[0], freq[1], (n, 2))
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

    Differs from the paper: the paper draws :math:`\mu` itself by its Eq. (22) (here :class:`RandomBeltrami`) and
    trains on ground-truth maps computed from it by a numerical solver; the Beltrami task's default draws a map and
    takes its exact :math:`\mu`, so that no solver is needed to know the map.
    """

    dim = 2
    kind = "beltrami"

    def __init__(self, rng: np.random.Generator, cfg: RandomBeltramiConfig = RandomBeltramiConfig()):
        if not 0 < cfg.k < 1:
            raise ValueError(f"the bound k must lie in (0, 1), got {cfg.k}")
        modes, freq = cfg.draw_ranges(rng)
        n = int(rng.integers(modes[0], modes[1] + 1))
        self.amp = rng.uniform(-1, 1, (2, n))
        self.freq = TWO_PI * _log_uniform(rng, freq[0], freq[1], (2, n, 2))  # angular
        self.phase = rng.uniform(0, TWO_PI, (2, n, 2))
        self.scale = 1.0
        level = min(cfg.k, rng.uniform(*cfg.sup))
        pts = grid_points(65, 2)
        J0 = self.jacobian_grid(65) - np.eye(2)
        self.scale = self._fit_scale(J0, level)
        # |mu| can peak between probe points (up to a few per cent above the probe maximum): add fine local
        # grids around the largest values, a quarter of the previous spacing per round, and fit the scale again
        spacing = 1.0 / 64
        for _ in range(3):
            a0, b0 = self._wirtinger0(J0)
            top = pts[np.argsort(b0 / np.abs(1 + self.scale * a0))[-16:]]
            t = np.linspace(-spacing, spacing, 9)
            # 9 x 9 patches around the top points, clipped to the square (clipping acts per axis, so every patch
            # stays a tensor product and its Jacobian is evaluated separably)
            xs, ys = np.clip(top[:, 0, None] + t, 0.0, 1.0), np.clip(top[:, 1, None] + t, 0.0, 1.0)
            local = np.stack([np.repeat(xs, 9, axis=1), np.tile(ys, (1, 9))], -1).reshape(-1, 2)
            scale, self.scale = self.scale, 1.0
            J0 = np.concatenate([J0, self._jacobian_from(self._parts_tensor(xs, ys)) - np.eye(2)])
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

    def _parts_grid(self, n: int):
        """:meth:`_parts` on the regular ``N``-grid (:func:`rfmap.core.mesh.grid_points` order), by separable tables
        (:meth:`_parts_tensor` with one patch)."""
        t = np.linspace(0.0, 1.0, n)
        return self._parts_tensor(t[None], t[None])

    def _parts_tensor(self, xs: np.ndarray, ys: np.ndarray):
        """:meth:`_parts` at the points of tensor-product patches: patch ``p`` holds the points
        :math:`(x_{p,a}, y_{p,b})`, listed patch by patch with ``a`` major (``meshgrid(..., indexing='ij')``).
        Every mode factorises into a function of :math:`x` times one of :math:`y`, so the sums are contractions of
        (2, K, P, A) and (2, K, P, B) tables instead of (P * A * B, 2, K) transcendental evaluations.

        Parameters
        ----------
        xs : ndarray, shape (P, A)
        ys : ndarray, shape (P, B)
        """
        xs, ys = np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64)
        f, ph = self.freq[..., None, None], self.phase[..., None, None]  # (2, K, 2, 1, 1)
        ax = f[:, :, 0] * xs + ph[:, :, 0]  # (2, K, P, A) over x
        ay = f[:, :, 1] * ys + ph[:, :, 1]  # (2, K, P, B) over y
        sx, cx, sy, cy = np.sin(ax), np.cos(ax), np.sin(ay), np.cos(ay)
        a = self.amp[..., None, None]  # (2, K, 1, 1)
        fx, fy = self.freq[..., 0, None, None], self.freq[..., 1, None, None]
        M = np.einsum("ckpa,ckpb->pabc", a * sx, cy).reshape(-1, 2)
        Mx = np.einsum("ckpa,ckpb->pabc", a * fx * cx, cy).reshape(-1, 2)
        My = np.einsum("ckpa,ckpb->pabc", -a * fy * sx, sy).reshape(-1, 2)
        X = np.broadcast_to(xs[:, :, None], (xs.shape[0], xs.shape[1], ys.shape[1])).reshape(-1)
        Y = np.broadcast_to(ys[:, None, :], (xs.shape[0], xs.shape[1], ys.shape[1])).reshape(-1)
        b = 16 * X * (1 - X) * Y * (1 - Y)
        bx = 16 * (1 - 2 * X) * Y * (1 - Y)
        by = 16 * X * (1 - X) * (1 - 2 * Y)
        return b, bx, by, M, Mx, My

    def _jacobian_from(self, parts) -> np.ndarray:
        b, bx, by, M, Mx, My = parts
        dx = self.scale * (bx[..., None] * M + b[..., None] * Mx)  # d f_c / dx, (..., 2)
        dy = self.scale * (by[..., None] * M + b[..., None] * My)
        return np.stack([dx, dy], -1) + np.eye(2)

    def jacobian_grid(self, n: int) -> np.ndarray:
        """Exact Jacobian at the vertices of the ``N``-grid, shape (N**2, 2, 2) (separable evaluation)."""
        return self._jacobian_from(self._parts_grid(n))

    def mu_grid(self, n: int) -> np.ndarray:
        """Exact Beltrami coefficient at the vertices of the ``N``-grid, complex (N**2,)."""
        return beltrami_from_jacobian(torch.as_tensor(self.jacobian_grid(n))).numpy()

    def _parts(self, x):
        # the (..., 2, K) mode arrays are evaluated with torch (vectorised float64 sin/cos, about 2.5x faster
        # than numpy's here); the values are the same to rounding
        x = np.asarray(x, dtype=np.float64)
        xt = torch.from_numpy(x)
        f, ph, amp = (torch.from_numpy(a) for a in (self.freq, self.phase, self.amp))
        ax = torch.addcmul(ph[..., 0], f[..., 0], xt[..., 0, None, None])  # (..., 2, K)
        ay = torch.addcmul(ph[..., 1], f[..., 1], xt[..., 1, None, None])
        sx, cx, sy, cy = torch.sin(ax), torch.cos(ax), torch.sin(ay), torch.cos(ay)
        M = (amp * sx * cy).sum(-1).numpy()  # (..., 2)
        Mx = ((amp * f[..., 0]) * cx * cy).sum(-1).numpy()
        My = (-(amp * f[..., 1]) * sx * sy).sum(-1).numpy()
        X, Y = x[..., 0], x[..., 1]
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
        return self._jacobian_from(self._parts(x))

    def mu(self, x) -> np.ndarray:
        """Exact Beltrami coefficient, complex (...)."""
        return beltrami_from_jacobian(torch.as_tensor(self.jacobian(x))).numpy()


def random_boundary_map(rng: np.random.Generator, cfg: RandomBeltramiConfig | None = None) -> RandomMap:
    """Draw one random boundary-fixing map with its exact Beltrami coefficient (see :class:`RandomMap`)."""
    return RandomMap(rng, cfg or RandomBeltramiConfig())
