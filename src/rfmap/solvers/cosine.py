r"""Type-I cosine and sine transforms of square vertex tables, by ``numpy.fft`` alone.

The classical cartogram solvers (:mod:`rfmap.solvers.cartoflow`, :mod:`rfmap.solvers.cartodiffusion`) expand the
density on the vertex grid :math:`(i, j)/(M-1)` of the unit square in cosine modes, which satisfy the square's
no-flux walls.  Along one axis of an (M, M) table,

.. math::

    \mathrm{DCT\text{-}I}(x)_k = x_0 + (-1)^k x_{M-1} + 2\sum_{j=1}^{M-2} x_j \cos\frac{\pi jk}{M-1},
    \qquad
    \mathrm{DST\text{-}I}(x)_j = 2\sum_{k=0}^{K-1} x_k \sin\frac{\pi (j+1)(k+1)}{K+1},

(``scipy.fft.dct(x, type=1)`` and ``scipy.fft.dst(x, type=1)``, unnormalised), the first the real part of the real
FFT of the even extension :math:`(x_0, \dots, x_{M-1}, x_{M-2}, \dots, x_1)`, the second minus the imaginary part of
that of the odd extension :math:`(0, x, 0, -\bar x)` (:math:`\bar x` reversed), both of length :math:`2(M-1)` when
:math:`K = M - 2` (the interior of an axis).  ``scipy.fft`` is not imported: its import alone takes most of a second,
longer than a small cartogram.

:class:`CosineTransforms` keeps the extension and the spectrum in two buffers between calls: a table of a few
hundred thousand numbers allocated afresh for every transform costs the operating system's page faults, about as
much as the FFT itself.
"""
from __future__ import annotations

import numpy as np

__all__ = ["CosineTransforms"]


class CosineTransforms:
    """DCT-I and DST-I along either axis of (M, M) tables (module docstring), sharing two buffers.

    Parameters
    ----------
    m : int
        The tables' side ``M`` (>= 3).

    Notes
    -----
    One object is not safe to share between threads (its buffers are overwritten by every call); results are
    fresh arrays.
    """

    def __init__(self, m: int):
        if m < 3:
            raise ValueError(f"the tables' side must be at least 3, got {m}")
        self.m = m
        self._ext = np.empty((m, 2 * (m - 1)))
        self._spec = np.empty((m, m), dtype=complex)

    def _rows(self, x: np.ndarray, axis: int, length: int) -> np.ndarray:
        """``x`` with the transformed axis (of ``length``) last: (M, length)."""
        want = (self.m, length) if axis in (1, -1) else (length, self.m)
        if axis not in (0, 1, -1) or x.shape != want:
            raise ValueError(f"expected a table of shape {want} transformed along axis {axis}, got {x.shape}")
        return x if axis in (1, -1) else x.T

    def dct(self, x: np.ndarray, axis: int, out: np.ndarray | None = None) -> np.ndarray:
        """DCT-I of ``x`` (M, M) along ``axis`` (0 or 1), shape (M, M): a fresh array, or written into ``out``."""
        m = self.m
        src = self._rows(x, axis, m)
        ext = self._ext
        ext[:, :m] = src
        ext[:, m:] = src[:, m - 2:0:-1]
        np.fft.rfft(ext, axis=-1, out=self._spec)
        return self._result(self._spec.real, axis, out, (m, m))

    def dst(self, x: np.ndarray, axis: int, out: np.ndarray | None = None) -> np.ndarray:
        """DST-I of ``x`` along ``axis`` (0 or 1), whose length along that axis is ``M - 2`` (an axis's interior):
        shape (M - 2, M) for ``axis=0``, (M, M - 2) for ``axis=1``; a fresh array, or written into ``out``."""
        m = self.m
        src = self._rows(x, axis, m - 2)
        ext = self._ext
        ext[:, 0] = 0.0
        ext[:, 1:m - 1] = src
        ext[:, m - 1] = 0.0
        np.negative(src[:, ::-1], out=ext[:, m:])
        np.fft.rfft(ext, axis=-1, out=self._spec)
        spec = self._spec.imag[:, 1:-1]
        np.negative(spec, out=spec)
        return self._result(spec, axis, out, (m, m - 2))

    @staticmethod
    def _result(rows: np.ndarray, axis: int, out: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
        """``rows`` (a view of the spectrum buffer, the transformed axis last) as the result along ``axis``."""
        if out is None:
            out = rows.copy()
            return out if axis in (1, -1) else out.T
        want = shape if axis in (1, -1) else shape[::-1]
        if out.shape != want:
            raise ValueError(f"out must have shape {want}, got {out.shape}")
        np.copyto(out if axis in (1, -1) else out.T, rows)
        return out
