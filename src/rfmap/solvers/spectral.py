r"""Cosine transforms of the box :math:`[0,1]^d` shared by the diffusion and the flow-based solvers.

A grid field :math:`p_j` at the nodes :math:`j/(M-1)` has the cosine interpolant :math:`\sum_k a_k \prod_i
\cos(\pi k_i x_i)`, :math:`0 \le k_i \le M-1`, whose coefficients a type-I DCT gives (:func:`cosine_coefficients`).
The diffusion solver evolves it exactly (``rfmap.solvers.diffusion.CosineDiffusion``); the flow solver solves the
Poisson equation with it (:func:`poisson_flux`: :func:`half_coefficients`, :func:`laplacian_eigenvalues`,
:func:`flux_synthesis`) and blurs with it (:func:`gaussian_blur`); both integrate it over boxes
(:func:`box_mean`, :func:`interval_weights`).
"""
from __future__ import annotations

import math
import sys

import numpy as np
from scipy.fft import dct, dctn, dst

__all__ = ["fft_workers", "cosine_coefficients", "dct1", "half_coefficients", "laplacian_eigenvalues",
           "flux_synthesis", "poisson_flux", "gaussian_blur", "box_mean", "interval_weights", "contract"]


def fft_workers() -> int:
    """Threads for scipy's transforms: the torch thread count the solver runs with, or where torch is not loaded
    (the torch-free cartogram path) ``scipy.fft``'s current default (``scipy.fft.set_workers``)."""
    torch = sys.modules.get("torch")
    if torch is None:
        from scipy.fft import get_workers

        return get_workers()
    return max(1, torch.get_num_threads())


def cosine_coefficients(values: np.ndarray, workers: int | None = None) -> np.ndarray:
    r"""Coefficients :math:`a_k` of the cosine interpolant :math:`\sum_k a_k \prod_i \cos(\pi k_i x_i)` of grid values.

    With the unnormalised type-I DCT :math:`y = \mathrm{DCT\text{-}I}(p)` (``scipy.fft.dctn(p, type=1)``),
    :math:`a_k = y_k \prod_i c_{k_i} / (2(M-1))^d`, :math:`c_0 = c_{M-1} = 1`, :math:`c_k = 2` otherwise.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
        Values at the grid nodes :math:`j/(M-1)` of :math:`[0,1]^d`.
    workers : int, optional
        Threads of the transform (``scipy.fft``'s ``workers``; default one).

    Returns
    -------
    ndarray, shape (M,)*d, float32 for float32 values, else float64
    """
    d, m = values.ndim, values.shape[0]
    c = np.full(m, 2.0, dtype=np.result_type(values.dtype, np.float32))
    c[0] = c[-1] = 1.0
    coef = dctn(values, type=1, workers=workers) / (2.0 * (m - 1)) ** d
    for ax in range(d):
        shape = [1] * d
        shape[ax] = m
        coef = coef * c.reshape(shape)
    return coef


def dct1(x: np.ndarray, axis: int) -> np.ndarray:
    r"""Unnormalised type-I DCT along ``axis`` (may overwrite ``x``): :math:`\sum_k e_k x_k \cos(\pi k j/(M-1))` at the
    nodes ``j``, with :math:`e_k = 1` at both ends and 2 inside."""
    return dct(x, type=1, axis=axis, workers=fft_workers(), overwrite_x=True)


def half_coefficients(values: np.ndarray, dtype=np.float64) -> np.ndarray:
    r""":math:`b_k = \mathrm{DCT\text{-}I}(p)_k / (2(M-1))^d` (unnormalised transform) of grid values ``p``: the cosine
    coefficients :math:`a_k` of their interpolant with every interior index halved per axis (:math:`a_k = e_k b_k`,
    :math:`e_k = 1` at the ends and 2 inside).  A type-I DCT of :math:`b` along an axis is the cosine synthesis
    along it (:func:`dct1`).  Shape (M,)*d, of ``dtype``."""
    d, m = values.ndim, values.shape[0]
    y = dctn(np.asarray(values, dtype=dtype), type=1, workers=fft_workers())
    y *= y.dtype.type(1.0 / (2.0 * (m - 1)) ** d)
    return y


def laplacian_eigenvalues(d: int, m: int, dtype=np.float64) -> np.ndarray:
    r"""The Laplacian's eigenvalues :math:`\pi^2|k|^2` of the cosine modes, shape (M,)*d, with 1 at :math:`k = 0`
    (so that it can divide)."""
    k2 = (math.pi * np.arange(m, dtype=np.float64)) ** 2
    lam = np.zeros((m,) * d, dtype=dtype)
    for ax in range(d):
        lam += k2.astype(dtype).reshape([m if j == ax else 1 for j in range(d)])
    lam.flat[0] = 1.0
    return lam


def flux_synthesis(b: np.ndarray) -> np.ndarray:
    r"""The flux :math:`-\nabla\psi` at the grid nodes of the potential :math:`\psi = \sum_k e_k b_k \prod_i
    \cos(\pi k_i x_i)` given by its half coefficients ``b`` (:func:`half_coefficients`; consumed), shape (d, M..).

    :math:`-\partial_i\psi = \sum_k e_k b_k\,\pi k_i \sin(\pi k_i x_i) \prod_{j\ne i}\cos(\pi k_j x_j)`: cosine
    syntheses along the other axes and, along axis ``i``, the type-I DST of the interior coefficients (only interior
    :math:`k_i` contribute; zero on both walls).  Transforms along an axis commute with factors along another, so the
    cosine syntheses are shared between the components: in 3D eight one-axis transforms, and no transposed copies.
    """
    d, m = b.ndim, b.shape[0]
    k = (math.pi * np.arange(m)).astype(b.dtype)
    out = np.empty((d,) + (m,) * d, dtype=b.dtype)

    def deriv(g: np.ndarray, i: int) -> None:  # out[i]: the sine synthesis along axis i of g * pi k_i
        inner = tuple(slice(1, m - 1) if j == i else slice(None) for j in range(d))
        wall = [slice(None)] * d
        for end in (0, m - 1):
            wall[i] = end
            out[i][tuple(wall)] = 0.0
        g = g[inner] * k[1:-1].reshape([m - 2 if j == i else 1 for j in range(d)])
        out[i][inner] = dst(g, type=1, axis=i, workers=fft_workers(), overwrite_x=True)

    if d == 2:
        deriv(dct1(b.copy(), 1), 0)
        deriv(dct1(b, 0), 1)
        return out
    p2 = dct1(b.copy(), 2)  # cosine along axis 2: shared by components 0 and 1
    deriv(dct1(p2.copy(), 1), 0)
    deriv(dct1(p2, 0), 1)
    deriv(dct1(dct1(b, 0), 1), 2)
    return out


def poisson_flux(values: np.ndarray, dtype=np.float64) -> np.ndarray:
    r"""The flux :math:`-\nabla\phi` of :math:`\Delta\phi = \bar\rho - \rho_0` with no-flux walls on :math:`[0,1]^d`.

    :math:`\rho_0` is the cosine interpolant of the grid values (coefficients :math:`a_k`); then
    :math:`\phi = \sum_{k \ne 0} \frac{a_k}{\pi^2|k|^2} \prod_i \cos(\pi k_i x_i)` and
    :math:`-\partial_i\phi = \sum_k \frac{a_k\,\pi k_i}{\pi^2 |k|^2} \sin(\pi k_i x_i) \prod_{j\ne i}\cos(\pi k_j x_j)`.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
        Density at the grid nodes :math:`j/(M-1)` of :math:`[0,1]^d`.
    dtype : numpy dtype
        Precision of the transforms (``np.float32`` halves their time; the flow uses it).

    Returns
    -------
    ndarray, shape (d, M, ..., M), of ``dtype``
        The flux components on the grid; the normal component is exactly zero on the walls.
    """
    d, m = values.ndim, values.shape[0]
    b = half_coefficients(values, dtype)
    b /= laplacian_eigenvalues(d, m, b.dtype)
    b.flat[0] = 0.0
    return flux_synthesis(b)


def gaussian_blur(values: np.ndarray, sigma: float) -> np.ndarray:
    r"""Gaussian blur of width ``sigma`` (box units) with mirror walls: the cosine coefficients are multiplied by
    :math:`e^{-\pi^2|k|^2\sigma^2/2}` (the heat kernel at time :math:`\sigma^2/2`); the mean is kept.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
    sigma : float

    Returns
    -------
    ndarray, shape (M,)*d
    """
    d, m = values.ndim, values.shape[0]
    y = dctn(values, type=1, workers=fft_workers())
    g = np.exp(-0.5 * (math.pi * sigma * np.arange(m)) ** 2)
    for ax in range(d):
        shape = [1] * d
        shape[ax] = m
        y = y * g.reshape(shape)
    return dctn(y, type=1, workers=fft_workers()) / (2.0 * (m - 1)) ** d


def box_mean(values: np.ndarray) -> float:
    r"""Mean over :math:`[0,1]^d` of the cosine interpolant of grid values: its zero coefficient :math:`a_0`, which
    is the trapezoidal mean (end nodes weighted half along every axis) — without the transform.

    Parameters
    ----------
    values : ndarray, shape (M,)*d

    Returns
    -------
    float
    """
    v = np.asarray(values, dtype=np.float64)
    for _ in range(v.ndim):  # reduce the leading axis each time
        v = (v.sum(0) - 0.5 * (v[0] + v[-1])) / (v.shape[0] - 1)
    return float(v)


def interval_weights(m: int, lo: float, hi: float) -> np.ndarray:
    r"""Weights :math:`w_j` with :math:`\int_{lo}^{hi} \rho = \sum_j w_j p_j` for the 1D cosine interpolant of
    values :math:`p_j` at :math:`j/(M-1)`: :math:`w_j = e_j\,\mathrm{DCT\text{-}I}(I)_j / (2(M-1))` with
    :math:`I_k = \int_{lo}^{hi} \cos(\pi k y)\,dy` and :math:`e_j = 1` at the ends, 2 inside."""
    k = np.arange(m)
    integ = np.empty(m)
    integ[0] = hi - lo
    integ[1:] = (np.sin(math.pi * k[1:] * hi) - np.sin(math.pi * k[1:] * lo)) / (math.pi * k[1:])
    e = np.full(m, 2.0)
    e[0] = e[-1] = 1.0
    return e * dct(integ, type=1) / (2.0 * (m - 1))


def contract(values: np.ndarray, w: np.ndarray) -> float:
    r""":math:`\sum_j w_{j_1} \cdots w_{j_d} v_j` (the same 1D weights along every axis)."""
    out = values
    for _ in range(values.ndim):
        out = out @ w
    return float(out)
