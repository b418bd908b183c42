r"""The heat field of the diffusion method (Gastner & Newman 2004): one engine for the maps and the cartograms.

The method (the heat equation with no-flux walls, points following :math:`v = -\nabla\rho/\rho`) is stated in
:mod:`rfmap.solvers.diffusion`; this module evaluates the density and its velocity, and
:mod:`rfmap.solvers.heatflow` carries the points.  The cosine modes of the box solve the equation exactly: from
grid values :math:`p_j` at the nodes :math:`j/(M-1)` of a raster of
:math:`M` points per side,

.. math::

    \rho(x, t) &= \sum_{k \in \{0..M-1\}^d} a_k \prod_{i=1}^d \cos(\pi k_i x_i)\, e^{-\pi^2 k_i^2 t}, \\
    \partial_j \rho(x, t) &= \sum_k a_k\, (-\pi k_j) \sin(\pi k_j x_j)
    \prod_{i \ne j} \cos(\pi k_i x_i) \prod_{i=1}^d e^{-\pi^2 k_i^2 t},

with :math:`a_k = b_k \prod_i e_{k_i}` (:math:`e = 1` at both ends of an axis, 2 inside) from the half coefficients
:math:`b_k = \mathrm{DCT\text{-}I}(p)_k / (2(M-1))^d` (:func:`rfmap.solvers.spectral.half_coefficients`), so that
:math:`\rho(\cdot, 0)` interpolates the raster.  :class:`HeatField` evaluates these sums on the raster's nodes as
separable products: along every axis a table :math:`C_{jk} = \cos(\pi k x_j)\,e^{-\pi^2 k^2 t}` or
:math:`S_{jk} = -\pi k \sin(\pi k x_j)\,e^{-\pi^2 k^2 t}` (exactly 0 on the walls) multiplies the coefficient
array, one axis after the other,

.. math:: \rho = C^{(1)} \bigl(a \times_d C^{(d)} \cdots\bigr), \qquad
          \partial_1\rho = S^{(1)} \bigl(a \times_d C^{(d)} \cdots\bigr), \ \dots

(dense matrix products, :math:`O(W^d K)` for a window of :math:`W` nodes per axis and :math:`K` modes), the
products shared between :math:`\rho` and its derivatives.  Two savings keep them cheap, cheaper than the fast
cosine transforms of the whole raster on the solvers' grids: modes whose per-axis decay :math:`e^{-\pi^2 k^2 t}` is
below :math:`10^{-17}` are skipped (:meth:`HeatField.n_modes`; after a short time only a few remain), and only the
window of nodes around the points asked for is evaluated.

What the two solvers set differently:

* **The raster.**  The maps (:func:`rfmap.solvers.diffusion.solve_diffusion`) diffuse the piecewise-linear interpolant
  of the vertex densities sampled ``refine`` times finer (:func:`rfmap.solvers.raster.p1_upsample`, or the sea of
  the free boundary, :func:`rfmap.solvers.raster.balanced_sea`); the cartograms
  (:func:`rfmap.solvers.cartodiffusion.diffusion_square`) their raster of cell means itself.  The field takes the
  raster as it is given.
* **Where the velocity is divided** (``divide``).  ``"grid"``: :math:`v = -\nabla\rho/\rho` is formed on the
  raster's nodes and its multilinear interpolant is evaluated at the points (the maps); ``"points"``:
  :math:`\rho` and :math:`\nabla\rho` are interpolated and divided at the points (the cartograms).  The two differ
  by the interpolation error, :math:`O(h^2)`, and each solver's results are kept as they are.
* **The transform of the coefficients** (``transforms``): ``scipy.fft`` in any dimension (the maps), or
  ``numpy.fft`` on a square (:class:`rfmap.solvers.cosine.CosineTransforms`), as the cartogram passes must not
  import ``scipy.fft`` (nor PyTorch).

:func:`blas_threads` sets the threads of the products (the maps' ``num_threads``).

The module uses numpy only.

References
----------
M. T. Gastner, M. E. J. Newman, "Diffusion-based method for producing density-equalizing maps",
Proc. Natl. Acad. Sci. USA 101(20), 7499–7504 (2004).
"""
from __future__ import annotations

import contextlib
import ctypes
import math
import os
from functools import lru_cache

import numpy as np

from ..core.mesh import multilinear
from .cosine import ScipyTransforms
from .spectral import damp, half_coefficients, heat_factor

__all__ = ["HeatField", "DIVISIONS", "DROPPED_RATE", "blas_threads"]

#: Where :class:`HeatField` divides :math:`-\nabla\rho` by :math:`\rho`: on the raster's nodes before interpolating
#: (the maps), or at the points after interpolating both (the cartograms).
DIVISIONS = ("grid", "points")
#: The largest decay exponent :math:`L` of a mode: modes whose per-axis exponent :math:`\pi^2 k^2 t` exceeds it
#: are skipped (:meth:`HeatField.n_modes`); :math:`e^{-L}` is below :math:`10^{-17}`
#: (:math:`-\ln 10^{-17} = 39.14`), under double precision's round-off.
DROPPED_RATE = 39.2


class HeatField:
    r"""The diffusing density :math:`\rho(x, t)` of a raster on :math:`[0,1]^d`, its gradient and the velocity
    :math:`v = -\nabla\rho/\rho` (the module's description gives the sums and their products).

    Parameters
    ----------
    values : ndarray, shape (M,)*d, d in {2, 3}
        The raster of the initial density at the nodes :math:`j/(M-1)` (positive; ``M >= 3``).
    divide : {"grid", "points"}
        Where :meth:`velocity_at` divides (:data:`DIVISIONS`): ``"grid"`` forms :math:`v` on the raster's nodes and
        interpolates it; ``"points"`` interpolates :math:`\rho` and :math:`\nabla\rho` and divides at the points.
    transforms : optional
        The type-I cosine transform of the coefficients: :class:`rfmap.solvers.cosine.ScipyTransforms` (default,
        threaded as :func:`rfmap.solvers.cosine.fft_workers`) or, for a square raster,
        :class:`rfmap.solvers.cosine.CosineTransforms`.

    Attributes
    ----------
    dim : int
        The dimension :math:`d`.
    m : int
        The raster's side :math:`M`.
    divide : str
        Where :meth:`velocity_at` divides.
    coef : ndarray, shape (M,)*d
        The cosine coefficients :math:`a_k` of the initial density.
    """

    def __init__(self, values: np.ndarray, divide: str = "grid", transforms=None):
        if divide not in DIVISIONS:
            raise ValueError(f"unknown divide {divide!r}; choose one of {DIVISIONS}")
        values = np.asarray(values, dtype=np.float64)
        self.dim, self.m, self.divide = values.ndim, values.shape[0], divide
        m = self.m
        edges = np.full(m, 2.0)
        edges[0] = edges[-1] = 1.0
        b = half_coefficients(values, transforms=transforms if transforms is not None else ScipyTransforms())
        self.coef = damp(b, edges, out=b)  # a_k = e_k b_k: exact (powers of two)
        k = np.arange(m)
        arg = math.pi * np.outer(np.linspace(0.0, 1.0, m), k)
        dsin = -math.pi * k[None, :] * np.sin(arg)  # d/dx cos(pi k x), (M, K)
        dsin[0] = dsin[-1] = 0.0  # exact zero normal derivative on the walls
        self._tables = np.stack([np.cos(arg), dsin])  # (2, M, K): cosine, derivative
        self._buffers: dict[str, np.ndarray] = {}  # the tables of velocity_at's evaluations, reused

    def n_modes(self, t: float) -> int:
        r"""Modes per axis still significant at time ``t``: :math:`K = \lceil\sqrt{L/(\pi^2 t)}\,\rceil + 1`
        with :math:`L` = :data:`DROPPED_RATE`, so that every skipped mode :math:`k \ge K` has decayed by
        :math:`e^{-\pi^2 k^2 t} < e^{-L} < 10^{-17}`; at least 2, all ``M`` at :math:`t \le 0`."""
        if t <= 0:
            return self.m
        return int(min(self.m, max(2, math.ceil(math.sqrt(DROPPED_RATE / (math.pi**2 * t))) + 1)))

    def _axis_tables(self, window: tuple[int, int], decay: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``out`` (2, W, K): the cosine and derivative tables :math:`[C, S]` of one axis's nodes
        ``start <= j < stop``, decayed (the ``K = len(decay)`` modes kept)."""
        lo, hi = window
        return np.multiply(self._tables[:, lo:hi, :len(decay)], decay, out=out)

    def fields(self, t: float, window: tuple[tuple[int, int], ...] | None = None) -> np.ndarray:
        r""":math:`\rho` and :math:`\nabla\rho` at time ``t`` on the raster's nodes (or a window of them).

        Parameters
        ----------
        t : float
            Time (box units).
        window : tuple of d (start, stop) index pairs, optional
            Evaluate only on the nodes ``start <= j < stop`` along each axis (the whole raster by default).

        Returns
        -------
        ndarray, float64, shape (d+1, W_1, ..., W_d)
            ``[rho, d rho/dx_1, ..., d rho/dx_d]``; ``W_i = stop_i - start_i`` (``M`` without a window).
        """
        return self._fields(t, window, {})

    def _fields(self, t: float, window, buffers: dict[str, np.ndarray]) -> np.ndarray:
        """:meth:`fields`, its tables taken from ``buffers`` where they are there in the right shape (and left
        there), so that evaluations one after the other do not ask the system for new pages every time."""
        d = self.dim
        if window is None:
            window = ((0, self.m),) * d
        kk = self.n_modes(t)
        decay = heat_factor(kk, t)  # the separable time factor of the modes kept
        w = [hi - lo for lo, hi in window]
        tab = [self._axis_tables(window[j], decay, _buffer(buffers, f"tables{j}", (2, w[j], kk)))
               for j in range(d)]  # per axis j (from 0): [C_j, S_j], (2, W_j, K)
        a = self.coef[(slice(0, kk),) * d]
        if d == 2:
            out = _buffer(buffers, "out", (3, w[0], w[1]))
            z = np.matmul(a, tab[1].reshape(2 * w[1], kk).T, out=_buffer(buffers, "z", (kk, 2 * w[1])))
            # z = [a C_1^T | a S_1^T] (K, 2 W_1): the last axis (1) transformed
            np.matmul(tab[0].reshape(2 * w[0], kk), z[:, :w[1]], out=out[:2].reshape(2 * w[0], w[1]))  # rho, d1
            np.matmul(tab[0][0], z[:, w[1]:], out=out[2])  # d2
            return out
        plane = w[1] * w[2]
        z = np.matmul(a.reshape(kk * kk, kk), tab[2].reshape(2 * w[2], kk).T,
                      out=_buffer(buffers, "z", (kk * kk, 2 * w[2]))).reshape(kk, kk, 2 * w[2])
        # per k_1, the products along axis 1 of z's halves zc = a C_2^T, zs = a S_2^T: [C_1 zc; S_1 zc; C_1 zs]
        y = _buffer(buffers, "y", (kk, 3 * w[1], w[2]))
        np.matmul(tab[1].reshape(2 * w[1], kk), z[:, :, :w[2]], out=y[:, :2 * w[1]])
        np.matmul(tab[1][0], z[:, :, w[2]:], out=y[:, 2 * w[1]:])
        y = y.reshape(kk, 3, plane)
        out = _buffer(buffers, "out", (4, w[0], plane))
        np.matmul(tab[0].reshape(2 * w[0], kk), y[:, 0], out=out[:2].reshape(2 * w[0], plane))  # rho, d1
        np.matmul(tab[0][0], y[:, 1], out=out[2])  # d2
        np.matmul(tab[0][0], y[:, 2], out=out[3])  # d3
        return out.reshape(4, *w)

    def velocity(self, t: float, window: tuple[tuple[int, int], ...] | None = None) -> np.ndarray:
        r""":math:`v = -\nabla\rho/\rho` on the raster's nodes (or a window, see :meth:`fields`).

        Returns
        -------
        ndarray, float64, shape (d, W_1, ..., W_d)
        """
        return self._velocity(t, window, {})

    def _velocity(self, t: float, window, buffers: dict[str, np.ndarray]) -> np.ndarray:
        """:meth:`velocity` on the tables of ``buffers`` (:meth:`_fields`)."""
        f = self._fields(t, window, buffers)
        inv = np.divide(-1.0, f[0])  # -1/rho
        v = f[1:]
        v *= inv
        return v

    def velocity_at(self, t: float, points: np.ndarray) -> np.ndarray:
        r""":math:`v(x, t)` at points (P, d) of the unit box, divided where ``divide`` says.

        Only the window of nodes that covers the points' bounding box is evaluated (much cheaper when the points
        occupy a small part of the box, as with the free boundary).

        Returns
        -------
        ndarray, shape (P, d)
        """
        top = self.m - 1
        lo = np.clip(np.floor(points.min(axis=0) * top).astype(int), 0, top - 1)
        hi = np.clip(np.ceil(points.max(axis=0) * top).astype(int), lo + 1, top)
        window = tuple((int(a), int(b) + 1) for a, b in zip(lo, hi))
        u = points * top - lo  # in the window's index units
        if self.divide == "grid":
            return multilinear(self._velocity(t, window, self._buffers), u)
        f = multilinear(self._fields(t, window, self._buffers), u)  # rho, grad rho at the points
        v = np.divide(f[:, 1:], f[:, :1])
        return np.negative(v, out=v)


def _buffer(buffers: dict[str, np.ndarray], name: str, shape: tuple[int, ...]) -> np.ndarray:
    """``buffers[name]`` if it has ``shape``, else a new float64 array of that shape stored there."""
    buf = buffers.get(name)
    if buf is None or buf.shape != shape:
        buf = buffers[name] = np.empty(shape)
    return buf


# ------------------------------------------------------------------------------------------------ threads
#: the thread count functions of OpenBLAS, as its builds name them (``{}``: ``set`` or ``get``)
_OPENBLAS_NAMES = ("scipy_openblas_{}_num_threads64_", "scipy_openblas_{}_num_threads", "openblas_{}_num_threads64_",
                   "openblas_{}_num_threads")


@lru_cache(maxsize=1)
def _openblas_threads() -> tuple:
    """``(set, get)`` thread functions of every OpenBLAS library loaded in this process (numpy's among them),
    found by their paths in ``/proc/self/maps``; empty where there is none or no such file (not Linux)."""
    try:
        with open("/proc/self/maps", encoding="utf-8") as fh:
            paths = sorted({line.split()[-1] for line in fh if "openblas" in line.lower() and "/" in line})
    except OSError:
        return ()
    found = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path, mode=getattr(os, "RTLD_NOLOAD", 0) | ctypes.RTLD_LOCAL)
        except OSError:
            continue
        for name in _OPENBLAS_NAMES:
            setter, getter = getattr(lib, name.format("set"), None), getattr(lib, name.format("get"), None)
            if setter is not None and getter is not None:
                setter.argtypes, setter.restype, getter.restype = [ctypes.c_int], None, ctypes.c_int
                found.append((setter, getter))
                break
    return tuple(found)


@contextlib.contextmanager
def blas_threads(n: int | None):
    """Temporarily run numpy's matrix products on ``n`` threads (``None``: leave them alone).

    Only an OpenBLAS (on Linux) is adjusted; another BLAS keeps its own setting.
    """
    libs = _openblas_threads() if n is not None else ()
    old = [get() for _, get in libs]
    for set_threads, _ in libs:
        set_threads(max(1, int(n)))
    try:
        yield
    finally:
        for (set_threads, _), count in zip(libs, old):
            set_threads(count)
