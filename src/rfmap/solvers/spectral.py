r"""The cosine method on the box :math:`[0,1]^d`, shared by the diffusion and the flow-based solvers, maps and
cartograms alike.

A grid field :math:`p_j` at the nodes :math:`j/(M-1)` has the cosine interpolant :math:`\sum_k a_k \prod_i
\cos(\pi k_i x_i)`, :math:`0 \le k_i \le M-1`, whose coefficients a type-I DCT gives (:func:`cosine_coefficients`,
:func:`half_coefficients`).  On them the diffusion solvers evolve the density exactly (:func:`heat_factor`;
:class:`rfmap.solvers.heatfield.HeatField`, the maps' and the cartograms' heat field), the flow solvers solve the
Poisson equation (:func:`poisson_flux`, :func:`flow_planes`: :func:`divide_by_laplacian`, :func:`flux_synthesis`),
read their velocity from its tables (:class:`FlowVelocity`) and blur (:func:`gaussian_blur`, :func:`blur_factor`);
both integrate the interpolant over boxes (:func:`box_mean`, :func:`interval_weights`).

Every function takes the transforms it runs on (:mod:`rfmap.solvers.cosine`): by default ``scipy.fft`` in any
dimension and precision (:class:`rfmap.solvers.cosine.ScipyTransforms`, the maps of :mod:`rfmap.solvers.flow` and
:mod:`rfmap.solvers.diffusion`), or ``numpy.fft`` on (M, M) tables (:class:`rfmap.solvers.cosine.CosineTransforms`,
the torch-free cartogram passes, which must not import ``scipy.fft``): one method, two engines.
"""
from __future__ import annotations

import math

import numpy as np

from .cosine import ScipyTransforms, fft_workers

__all__ = ["fft_workers", "cosine_coefficients", "half_coefficients", "laplacian_eigenvalues", "divide_by_laplacian",
           "flux_synthesis", "poisson_flux", "flow_planes", "heat_factor", "blur_factor", "damp", "gaussian_blur",
           "box_mean", "interval_weights", "contract", "FlowVelocity"]


def _edge_factors(m: int, dtype) -> np.ndarray:
    r""":math:`e_k`: 1 at both ends of an axis of ``m`` modes, 2 inside."""
    e = np.full(m, 2.0, dtype=dtype)
    e[0] = e[-1] = 1.0
    return e


def _along(v: np.ndarray, ax: int, d: int) -> np.ndarray:
    """A 1D array ``v`` shaped to broadcast along axis ``ax`` of a ``d``-dimensional table."""
    return v.reshape([len(v) if j == ax else 1 for j in range(d)])


def half_coefficients(values: np.ndarray, dtype=np.float64, transforms=None) -> np.ndarray:
    r""":math:`b_k = \mathrm{DCT\text{-}I}(p)_k / (2(M-1))^d` (unnormalised transform) of grid values ``p``.

    These are the cosine coefficients :math:`a_k` of the interpolant with every interior index halved per axis
    (:math:`a_k = e_k b_k`, :math:`e_k = 1` at the ends and 2 inside); a type-I DCT of :math:`b` along an axis is the
    cosine synthesis along it, so ``transforms.dctn(b)`` gives the values back.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
    dtype : numpy dtype
        Precision of the transform.
    transforms : optional
        :class:`rfmap.solvers.cosine.ScipyTransforms` (default) or :class:`rfmap.solvers.cosine.CosineTransforms`.

    Returns
    -------
    ndarray, shape (M,)*d, of ``dtype``
    """
    tr = transforms if transforms is not None else ScipyTransforms()
    d, m = values.ndim, values.shape[0]
    y = tr.dctn(np.asarray(values, dtype=dtype))
    y /= (2.0 * (m - 1)) ** d
    return y


def cosine_coefficients(values: np.ndarray, workers: int | None = None) -> np.ndarray:
    r"""Coefficients :math:`a_k` of the cosine interpolant :math:`\sum_k a_k \prod_i \cos(\pi k_i x_i)` of grid values.

    :math:`a_k = b_k \prod_i e_{k_i}` with the half coefficients :math:`b_k` (:func:`half_coefficients`):
    :math:`a_k = \mathrm{DCT\text{-}I}(p)_k \prod_i e_{k_i} / (2(M-1))^d`, :math:`e_0 = e_{M-1} = 1`, :math:`e_k = 2`
    otherwise.

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
    dtype = np.result_type(values.dtype, np.float32)
    coef = half_coefficients(values, dtype, ScipyTransforms(workers=1 if workers is None else workers))
    e = _edge_factors(m, dtype)
    for ax in range(d):
        coef = coef * _along(e, ax, d)
    return coef


def laplacian_eigenvalues(d: int, m: int, dtype=np.float64) -> np.ndarray:
    r"""The Laplacian's eigenvalues :math:`\pi^2|k|^2` of the cosine modes, shape (M,)*d, with 1 at :math:`k = 0`
    (so that it can divide)."""
    k2 = (math.pi * np.arange(m, dtype=np.float64)) ** 2
    lam = np.zeros((m,) * d, dtype=dtype)
    for ax in range(d):
        lam += _along(k2.astype(dtype), ax, d)
    lam.flat[0] = 1.0
    return lam


def divide_by_laplacian(b: np.ndarray, rows: int = 256) -> np.ndarray:
    r"""``b`` (M,)*d divided in place by the eigenvalues :math:`\pi^2|k|^2` (:func:`laplacian_eigenvalues`, in
    ``b``'s precision), the mean mode set to 0: the coefficients of :math:`\Delta^{-1} b` orthogonal to constants.

    The divisors are formed ``rows`` indices of the first axis at a time (a table of them at a 2049 raster would
    hold 34 MB); the values are those of the whole table.
    """
    d, m = b.ndim, b.shape[0]
    k2 = ((math.pi * np.arange(m, dtype=np.float64)) ** 2).astype(b.dtype)
    for a in range(0, m, rows):
        block = _along(k2[a:a + rows], 0, d) + _along(k2, 1, d)  # summed axis by axis, as the whole table
        for ax in range(2, d):
            block = block + _along(k2, ax, d)
        if a == 0:
            block.flat[0] = 1.0
        b[a:a + rows] /= block
    b.flat[0] = 0.0
    return b


def flux_synthesis(b: np.ndarray, transforms=None, out: np.ndarray | None = None) -> np.ndarray:
    r"""The flux :math:`-\nabla\psi` at the grid nodes of :math:`\psi = \sum_k e_k b_k \prod_i \cos(\pi k_i x_i)`
    given by its half coefficients ``b`` (:func:`half_coefficients`; consumed).

    :math:`-\partial_i\psi = \sum_k e_k b_k\,\pi k_i \sin(\pi k_i x_i) \prod_{j\ne i}\cos(\pi k_j x_j)`: cosine
    syntheses along the other axes and, along axis ``i``, the type-I DST of the interior coefficients (only interior
    :math:`k_i` contribute; zero on both walls).  Transforms along an axis commute with factors along another, so the
    cosine syntheses are shared between the components: in 3D eight one-axis transforms, and no transposed copies.

    Parameters
    ----------
    b : ndarray, shape (M,)*d, d in {2, 3}
    transforms : optional
        As in :func:`half_coefficients` (a :class:`rfmap.solvers.cosine.CosineTransforms` in 2D only).
    out : ndarray, shape (d, M, ..., M), optional

    Returns
    -------
    ndarray, shape (d, M, ..., M), of ``b``'s dtype
    """
    tr = transforms if transforms is not None else ScipyTransforms()
    d, m = b.ndim, b.shape[0]
    k = (math.pi * np.arange(m)).astype(b.dtype)
    if out is None:
        out = np.empty((d,) + (m,) * d, dtype=b.dtype)

    def deriv(g: np.ndarray, i: int) -> None:  # out[i]: the sine synthesis along axis i of g * pi k_i (g consumed)
        inner = tuple(slice(1, m - 1) if j == i else slice(None) for j in range(d))
        wall = [slice(None)] * d
        for end in (0, m - 1):
            wall[i] = end
            out[i][tuple(wall)] = 0.0
        g *= _along(k, i, d)  # in place: no table allocated per component
        tr.dst(g[inner], i, out=out[i][inner])

    if d == 2:
        deriv(tr.dct(b, 1), 0)
        deriv(tr.dct(b, 0, out=b), 1)
        return out
    p2 = tr.dct(b, 2)  # cosine along axis 2: shared by components 0 and 1
    deriv(tr.dct(p2, 1), 0)
    deriv(tr.dct(p2, 0, out=p2), 1)
    q = tr.dct(b, 0, out=b)
    deriv(tr.dct(q, 1, out=q), 2)
    return out


def poisson_flux(values: np.ndarray, dtype=np.float64, transforms=None) -> np.ndarray:
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
    transforms : optional
        As in :func:`half_coefficients`.

    Returns
    -------
    ndarray, shape (d, M, ..., M), of ``dtype``
        The flux components on the grid; the normal component is exactly zero on the walls.
    """
    return flow_planes(values, dtype=dtype, transforms=transforms, density=False)


def flow_planes(values: np.ndarray, sigma: float = 0.0, dtype=np.float64, transforms=None,
                density: bool = True) -> np.ndarray:
    r"""The tables of a flow-based map: the flux :math:`-\nabla\phi` of the density (:func:`poisson_flux`) and the
    density itself, both of the density blurred over ``sigma`` (:func:`gaussian_blur`) when ``sigma > 0``; the
    blur and the Poisson solve share one forward transform.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
    sigma : float
        Blur width in box units; 0 leaves the density as it is.
    dtype, transforms
        As in :func:`half_coefficients`.
    density : bool
        Whether to append the density as the last table.

    Returns
    -------
    ndarray, shape (d + 1, M, ..., M) (d without ``density``), of ``dtype``
    """
    tr = transforms if transforms is not None else ScipyTransforms()
    d, m = values.ndim, values.shape[0]
    planes = np.empty((d + int(density),) + (m,) * d, dtype=dtype)
    b = half_coefficients(values, dtype, tr)
    if sigma > 0:
        damp(b, blur_factor(m, sigma, dtype), out=b)
        if density:
            planes[d] = tr.dctn(b)
    elif density:
        planes[d] = values
    flux_synthesis(divide_by_laplacian(b), tr, out=planes[:d])
    return planes


class FlowVelocity:
    r"""The velocity of a flow-based map, :math:`v(y, t) = -\nabla\phi(y) / ((1-t)\rho_0(y) + t\bar\rho)`, from
    the tables of :func:`flow_planes` read at the points by an interpolation the solver chooses: the one formula of
    the map solver (:mod:`rfmap.solvers.flow`, any dimension) and the cartogram passes
    (:mod:`rfmap.solvers.cartoflow`, torch-free).

    Parameters
    ----------
    lookup : callable
        ``lookup(y)`` with points ``y``, shape (P, d), in :math:`[0,1]^d`, returns the tables there, shape
        (P, d + 1): the flux :math:`-\nabla\phi`, then the density :math:`\rho_0`. The velocity is computed in
        its precision.
    mean : float
        :math:`\bar\rho`, the box mean of the density (:func:`box_mean`).

    Attributes
    ----------
    evaluations : int
        How many times the velocity was evaluated.

    Examples
    --------
    >>> import numpy as np
    >>> v = FlowVelocity(lambda y: np.tile([0.5, 0.0, 2.0], (len(y), 1)), mean=1.0)
    >>> v(0.0, np.zeros((1, 2))), v(1.0, np.zeros((1, 2)))
    (array([[0.25, 0.  ]]), array([[0.5, 0. ]]))
    """

    def __init__(self, lookup, mean: float):
        self.lookup = lookup
        self.mean = float(mean)
        self.evaluations = 0

    def __call__(self, t: float, y: np.ndarray) -> np.ndarray:
        """The velocity (P, d), float64, at time ``t`` in [0, 1] and points ``y`` (P, d)."""
        self.evaluations += 1
        f = self.lookup(y)
        rho = f[:, -1] * (1.0 - t) + t * self.mean
        return (f[:, :-1] / rho[:, None]).astype(np.float64, copy=False)


def heat_factor(m: int, t: float, dtype=np.float64) -> np.ndarray:
    r"""The per-axis decay :math:`e^{-\pi^2 k^2 t}` of the cosine modes :math:`k = 0..M-1` after diffusing for time
    ``t``: the heat equation's solution multiplies :math:`b_k` by their product over the axes (:func:`damp`)."""
    return np.exp(-((math.pi * np.arange(m)) ** 2) * t).astype(dtype, copy=False)


def blur_factor(m: int, sigma: float, dtype=np.float64) -> np.ndarray:
    r"""The per-axis factor :math:`e^{-\pi^2 k^2 \sigma^2/2}` of a Gaussian blur of width ``sigma`` (box units) with
    mirror walls: the heat kernel at time :math:`\sigma^2/2` (:func:`heat_factor`)."""
    return np.exp(-0.5 * (math.pi * sigma * np.arange(m)) ** 2).astype(dtype, copy=False)


def damp(b: np.ndarray, g: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    r"""``b`` (M,)*d times :math:`\prod_i g_{k_i}` (a separable factor, one axis after the other): a fresh array,
    or written into ``out`` (``b`` itself: in place)."""
    d = b.ndim
    out = np.multiply(b, _along(g, 0, d), out=out)
    for ax in range(1, d):
        out *= _along(g, ax, d)
    return out


def gaussian_blur(values: np.ndarray, sigma: float, transforms=None) -> np.ndarray:
    r"""Gaussian blur of width ``sigma`` (box units) with mirror walls: the cosine coefficients are multiplied by
    :math:`e^{-\pi^2|k|^2\sigma^2/2}` (:func:`blur_factor`, the heat kernel at time :math:`\sigma^2/2`); the mean
    is kept.

    Parameters
    ----------
    values : ndarray, shape (M,)*d
    sigma : float
    transforms : optional
        As in :func:`half_coefficients`.

    Returns
    -------
    ndarray, shape (M,)*d
    """
    tr = transforms if transforms is not None else ScipyTransforms()
    b = half_coefficients(values, np.result_type(values.dtype, np.float32), tr)
    return tr.dctn(damp(b, blur_factor(values.shape[0], sigma, b.dtype), out=b))


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
    from scipy.fft import dct

    k = np.arange(m)
    integ = np.empty(m)
    integ[0] = hi - lo
    integ[1:] = (np.sin(math.pi * k[1:] * hi) - np.sin(math.pi * k[1:] * lo)) / (math.pi * k[1:])
    return _edge_factors(m, np.float64) * dct(integ, type=1) / (2.0 * (m - 1))


def contract(values: np.ndarray, w: np.ndarray) -> float:
    r""":math:`\sum_j w_{j_1} \cdots w_{j_d} v_j` (the same 1D weights along every axis)."""
    out = values
    for _ in range(values.ndim):
        out = out @ w
    return float(out)
