r"""Type-I cosine and sine transforms along the axes of grid tables: the one place the cosine solvers transform.

The classical solvers (:mod:`rfmap.solvers.spectral`, and through it the flow and diffusion maps and their cartogram
passes) expand a density on the vertex grid :math:`j/(M-1)` of the unit box in cosine modes, which satisfy the box's
no-flux walls.  Along one axis,

.. math::

    \mathrm{DCT\text{-}I}(x)_k &= x_0 + (-1)^k x_{M-1} + 2\sum_{j=1}^{M-2} x_j \cos\frac{\pi jk}{M-1}, \\
    \mathrm{DST\text{-}I}(x)_j &= 2\sum_{k=0}^{K-1} x_k \sin\frac{\pi (j+1)(k+1)}{K+1},

(``scipy.fft.dct(x, type=1)`` and ``scipy.fft.dst(x, type=1)``, unnormalised).  Two objects compute them with one
interface (``dct(x, axis, out=None)``, ``dst(x, axis, out=None)``, ``dctn(x)``):

* :class:`ScipyTransforms`: ``scipy.fft`` along any axis of a table of any dimension and precision, threaded as the
  solver runs (:func:`fft_workers`); the maps of :mod:`rfmap.solvers.flow` and :mod:`rfmap.solvers.diffusion`.
* :class:`CosineTransforms`: (M, M) tables by ``numpy.fft`` alone, for the torch-free cartogram passes.  The first
  transform is the real part of the real FFT of the even extension :math:`(x_0, \dots, x_{M-1}, x_{M-2}, \dots,
  x_1)`, the second minus the imaginary part of that of the odd extension :math:`(0, x, 0, -\bar x)` (:math:`\bar x`
  reversed), both of length :math:`2(M-1)` when :math:`K = M - 2` (the interior of an axis).  Tables of a side of
  at least ``SCIPY_SIDE`` go to scipy's type-I transforms, which skip the extension and are faster on large tables
  (:func:`type1_transforms`).  The extension and the spectrum of a block of rows are kept in two buffers reused
  between calls, which saves their allocation and bounds the memory on a cartogram's finest raster.
"""
# Implementation notes.  The smaller tables do not load scipy at all, since importing scipy.fft (a few tenths of a
# second) takes longer than a small cartogram.  A table of a few hundred thousand numbers allocated afresh for every
# transform costs the operating system's page faults, about as much as the FFT itself, and a table of millions would
# need two more tables' worth of memory at once: hence the two reused buffers.
from __future__ import annotations

import functools
import sys

import numpy as np

__all__ = ["CosineTransforms", "ScipyTransforms", "fft_workers", "type1_transforms"]


#: Rows transformed at a time by :class:`CosineTransforms`, as a count of numbers in its extension buffer: a table of
#: a 2049-vertex side then runs through buffers of 8 MB (256 rows) instead of two of 67 MB, for the same FFTs.
BLOCK_NUMBERS = 1 << 20
#: Tables of at least this side are transformed by scipy's pocketfft (:func:`type1_transforms`, loaded on the
#: first of them).
SCIPY_SIDE = 1025


def fft_workers() -> int:
    """Threads for scipy's transforms: the torch thread count the solver runs with, or where torch is not loaded
    (the torch-free cartogram path) ``scipy.fft``'s current default (``scipy.fft.set_workers``)."""
    torch = sys.modules.get("torch")
    if torch is None:
        from scipy.fft import get_workers

        return get_workers()
    return max(1, torch.get_num_threads())


class _Type1:
    """``dct`` and ``dst`` (``type=1``, along ``axis``, unnormalised, one thread) by scipy's pocketfft extension
    module itself, as ``scipy.fft.dct`` and ``scipy.fft.dst`` call it for a float32 or float64 table (the same
    numbers), in the precision of ``out`` where given (``x`` itself, or an array that does not overlap it), else of
    ``x`` (float64 unless float32)."""

    def __init__(self, module):
        self._pfft = module

    def dct(self, x: np.ndarray, type: int, axis: int,  # noqa: A002 (scipy.fft's keyword)
            out: np.ndarray | None = None) -> np.ndarray:
        return self._pfft.dct(_as_float(x, out), type, (axis,), 0, out, 1, None)

    def dst(self, x: np.ndarray, type: int, axis: int,  # noqa: A002
            out: np.ndarray | None = None) -> np.ndarray:
        return self._pfft.dst(_as_float(x, out), type, (axis,), 0, out, 1, None)


def _as_float(x: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    """``x`` in the precision of ``out`` (float32 or float64), or without ``out`` in its own float32 or else
    float64: the input pocketfft's transforms take."""
    dtype = out.dtype if out is not None else (np.float32 if x.dtype == np.float32 else np.float64)
    return np.asarray(x, dtype=dtype)


class _Public:
    """:class:`_Type1`'s transforms by ``scipy.fft`` itself, the result copied into ``out`` where given."""

    def __init__(self, fft):
        self._fft = fft

    def dct(self, x: np.ndarray, type: int, axis: int,  # noqa: A002
            out: np.ndarray | None = None) -> np.ndarray:
        return _into(out, self._fft.dct(x, type=type, axis=axis))

    def dst(self, x: np.ndarray, type: int, axis: int,  # noqa: A002
            out: np.ndarray | None = None) -> np.ndarray:
        return _into(out, self._fft.dst(x, type=type, axis=axis))


def _into(out: np.ndarray | None, y: np.ndarray) -> np.ndarray:
    """``y``, or ``out`` with ``y`` copied into it."""
    if out is None:
        return y
    out[...] = y
    return out


@functools.lru_cache(maxsize=None)
def type1_transforms():
    """The type-I transforms of :class:`CosineTransforms`'s large tables: an object with ``dct(x, type, axis,
    out=None)`` and ``dst(x, type, axis, out=None)`` for float64 tables: the extension module that ``scipy.fft``
    calls for them, loaded without importing ``scipy.fft`` (which loads much more of scipy) unless that is loaded
    already, and ``scipy.fft`` itself where loading the module alone fails."""
    # importing scipy.fft loads scipy.special and scipy's array-API layer too: half a second, a fifth of the whole
    # command on a map of a country's subdivisions
    if "scipy.fft" not in sys.modules:
        try:
            return _Type1(_load_pocketfft())
        except Exception:  # noqa: BLE001 (any failure: the public module instead)
            pass
    import scipy.fft

    return _Public(scipy.fft)


def _load_pocketfft():
    """scipy's pocketfft extension module, loaded from its file without importing ``scipy.fft``."""
    import importlib.machinery
    import importlib.util
    import os

    spec = importlib.util.find_spec("scipy")
    folder = os.path.join(spec.submodule_search_locations[0], "fft", "_pocketfft")
    names = (os.path.join(folder, "pypocketfft" + suffix) for suffix in importlib.machinery.EXTENSION_SUFFIXES)
    files = [f for f in names if os.path.isfile(f)]
    loader = importlib.machinery.ExtensionFileLoader("pypocketfft", files[0])
    module = importlib.util.module_from_spec(importlib.util.spec_from_file_location("pypocketfft", files[0],
                                                                                    loader=loader))
    loader.exec_module(module)
    return module


class ScipyTransforms:
    """DCT-I and DST-I along any axis of tables of any dimension and float precision, by ``scipy.fft`` (imported on
    construction), with ``workers`` threads (default :func:`fft_workers` at construction).

    ``out=x`` transforms in place (``overwrite_x``); another ``out`` receives a copy of the result.
    """

    def __init__(self, workers: int | None = None):
        import scipy.fft

        self._fft = scipy.fft
        self.workers = fft_workers() if workers is None else workers

    def _apply(self, transform, x: np.ndarray, axis: int, out: np.ndarray | None) -> np.ndarray:
        y = transform(x, type=1, axis=axis, workers=self.workers, overwrite_x=out is x)
        if out is None or y is out:
            return y
        out[...] = y
        return out

    def dct(self, x: np.ndarray, axis: int, out: np.ndarray | None = None) -> np.ndarray:
        """DCT-I of ``x`` along ``axis``: a fresh array, or written into ``out`` (``x`` itself: in place)."""
        return self._apply(self._fft.dct, x, axis, out)

    def dst(self, x: np.ndarray, axis: int, out: np.ndarray | None = None) -> np.ndarray:
        """DST-I of ``x`` along ``axis``: a fresh array, or written into ``out``."""
        return self._apply(self._fft.dst, x, axis, out)

    def dctn(self, x: np.ndarray) -> np.ndarray:
        """DCT-I along every axis of ``x``: a fresh array."""
        return self._fft.dctn(x, type=1, workers=self.workers)


class CosineTransforms:
    """DCT-I and DST-I along either axis of (M, M) float64 or float32 tables by ``numpy.fft`` (the module's
    description gives how), sharing two buffers.

    Parameters
    ----------
    m : int
        The tables' side ``M`` (>= 3).
    block : int, optional
        Rows transformed at a time (default: as many as fit ``BLOCK_NUMBERS`` numbers of extension, at least
        one): the buffers hold ``block`` rows, not ``M``.
    use_scipy : bool, optional
        Transform by ``scipy.fft`` (default: when ``M`` is at least ``SCIPY_SIDE``).
    dtype : {numpy.float64, numpy.float32}, optional
        The precision of the transforms and of the tables they return (inputs of another precision are converted):
        single precision takes about half the time of double on large tables.

    Notes
    -----
    One object is not safe to share between threads (its buffers are overwritten by every call); results are
    fresh arrays.
    """

    def __init__(self, m: int, block: int | None = None, use_scipy: bool | None = None, dtype=np.float64):
        if m < 3:
            raise ValueError(f"the tables' side must be at least 3, got {m}")
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype must be float32 or float64, got {self.dtype}")
        self.m = m
        self._scipy = None
        if use_scipy if use_scipy is not None else m >= SCIPY_SIDE:
            self._scipy = type1_transforms()
        self.block = int(block) if block is not None else max(1, BLOCK_NUMBERS // (2 * (m - 1)))
        if self.block < 1:
            raise ValueError(f"block must be a positive number of rows, got {block!r}")
        rows = min(self.block, m) if self._scipy is None else 0
        self._ext = np.empty((rows, 2 * (m - 1)), dtype=self.dtype)
        self._spec = np.empty((rows, m), dtype=np.result_type(self.dtype, np.complex64))

    def _rows(self, x: np.ndarray, axis: int, length: int) -> np.ndarray:
        """``x`` with the transformed axis (of ``length``) last: (M, length)."""
        want = (self.m, length) if axis in (1, -1) else (length, self.m)
        if axis not in (0, 1, -1) or x.shape != want:
            raise ValueError(f"expected a table of shape {want} transformed along axis {axis}, got {x.shape}")
        return x if axis in (1, -1) else x.T

    def _by_scipy(self, transform, src: np.ndarray, rows: np.ndarray, result: np.ndarray) -> np.ndarray:
        """``rows`` (the result with the transformed axis last) filled by the type-I ``scipy.fft`` ``transform`` of
        ``src``'s rows, a block at a time, each written straight into its rows (no temporary table, no block
        allocated afresh); returns ``result``."""
        for a in range(0, src.shape[0], self.block):
            transform(src[a:a + self.block], 1, -1, out=rows[a:a + self.block])
        return result

    def _spectra(self, src: np.ndarray, fill):
        """For each block of rows ``src[a:b]``: ``fill(ext, rows)`` writes their extension into ``ext`` (b - a,
        2(M - 1)), whose real FFT is then yielded as ``(a, b, spectrum)`` (a view of the spectrum buffer)."""
        for a in range(0, src.shape[0], self.block):
            b = min(a + self.block, src.shape[0])
            ext, spec = self._ext[:b - a], self._spec[:b - a]
            fill(ext, src[a:b])
            np.fft.rfft(ext, axis=-1, out=spec)
            yield a, b, spec

    def dct(self, x: np.ndarray, axis: int, out: np.ndarray | None = None) -> np.ndarray:
        """DCT-I of ``x`` (M, M) along ``axis`` (0 or 1), shape (M, M): a fresh array, or written into ``out``
        (which may be ``x`` itself: each block of rows is read before it is written)."""
        m = self.m
        src = self._rows(x, axis, m)
        result, rows = self._target(out, axis, (m, m))
        if self._scipy is not None:
            return self._by_scipy(self._scipy.dct, src, rows, result)

        def fill(ext, part):
            ext[:, :m] = part
            ext[:, m:] = part[:, m - 2:0:-1]

        for a, b, spec in self._spectra(src, fill):
            rows[a:b] = spec.real
        return result

    def dctn(self, x: np.ndarray) -> np.ndarray:
        """DCT-I of ``x`` (M, M) along both axes, the first axis first: a fresh array."""
        y = self.dct(x, 0)
        return self.dct(y, 1, out=y)

    def dst(self, x: np.ndarray, axis: int, out: np.ndarray | None = None) -> np.ndarray:
        """DST-I of ``x`` along ``axis`` (0 or 1), whose length along that axis is ``M - 2`` (an axis's interior):
        shape (M - 2, M) for ``axis=0``, (M, M - 2) for ``axis=1``; a fresh array, or written into ``out``."""
        m = self.m
        src = self._rows(x, axis, m - 2)
        result, rows = self._target(out, axis, (m, m - 2))
        if self._scipy is not None:
            return self._by_scipy(self._scipy.dst, src, rows, result)

        def fill(ext, part):
            ext[:, 0] = 0.0
            ext[:, 1:m - 1] = part
            ext[:, m - 1] = 0.0
            np.negative(part[:, ::-1], out=ext[:, m:])

        for a, b, spec in self._spectra(src, fill):
            np.negative(spec.imag[:, 1:-1], out=rows[a:b])
        return result

    def _target(self, out: np.ndarray | None, axis: int, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """The result along ``axis`` (``out``, or a fresh array of the transforms' precision) and its view with the
        transformed axis last, of shape ``shape``."""
        if out is None:
            rows = np.empty(shape, dtype=self.dtype)
            return (rows if axis in (1, -1) else rows.T), rows
        want = shape if axis in (1, -1) else shape[::-1]
        if out.shape != want:
            raise ValueError(f"out must have shape {want}, got {out.shape}")
        if out.dtype != self.dtype:
            raise ValueError(f"out must be {self.dtype}, got {out.dtype}")
        return out, (out if axis in (1, -1) else out.T)
