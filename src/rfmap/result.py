"""The result of a map computation, shared by classical solvers and neural surrogates."""
from __future__ import annotations

import os
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, field

import numpy as np
import torch

from .geometry import beltrami_coefficient
from .metrics import MapMetrics, compute_metrics

__all__ = ["MapResult", "save_npz_atomic", "load_result"]


def save_npz_atomic(path, **arrays) -> None:
    """Write an ``.npz`` file atomically: either the complete file appears at ``path`` or nothing does."""
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=d, suffix=".npz.part")
    try:
        # write through the open handle: given a file name, np.savez would append ".npz" to it
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


@dataclass
class MapResult:
    """A computed map of a simplicial mesh.

    Attributes
    ----------
    ref_points : ndarray, shape (n, d)
    mapped_points : ndarray, shape (n, d)
    elements : ndarray, shape (m, d+1)
    field : ndarray
        The input field: vertex densities, shape (n,), or per-triangle Beltrami coefficients, shape (m,) complex.
    kind : str
        ``'density'`` or ``'beltrami'``.
    time : float
        Seconds spent computing the map.
    info : dict
        Method-specific extras (iterations, ...).
    """

    ref_points: np.ndarray
    mapped_points: np.ndarray
    elements: np.ndarray
    field: np.ndarray
    kind: str = "density"
    time: float = 0.0
    info: dict = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return int(self.ref_points.shape[1])

    @property
    def displacement(self) -> np.ndarray:
        return self.mapped_points - self.ref_points

    def mu(self) -> np.ndarray:
        """Per-triangle Beltrami coefficient of the piecewise-linear map (2D), complex128 of shape (m,)."""
        return beltrami_coefficient(torch.as_tensor(self.ref_points, dtype=torch.float64),
                                    torch.as_tensor(self.mapped_points, dtype=torch.float64),
                                    torch.as_tensor(self.elements)).numpy()

    def metrics(self, *, exact_points=None, mu_ref=None) -> MapMetrics:
        """Metrics in the paper's conventions (see :func:`rfmap.metrics.compute_metrics`)."""
        density = self.field.reshape(-1) if self.kind == "density" else None
        return compute_metrics(self.ref_points, self.mapped_points, self.elements, density=density,
                               exact_points=exact_points, mu_ref=mu_ref, time=self.time)

    def save(self, path) -> None:
        """Save as ``.npz`` with keys ``ref_points``, ``mapped_points``, ``elements``, ``field``, ``kind``."""
        save_npz_atomic(path, ref_points=self.ref_points, mapped_points=self.mapped_points,
                        elements=self.elements, field=self.field, kind=np.array(self.kind),
                        time=np.array(self.time))

    def to_vtk(self, path=None):
        """The mapped mesh as a PyVista ``UnstructuredGrid`` (written to ``path`` when given, e.g. ``.vtu``)."""
        from .viz import to_pyvista

        grid = to_pyvista(self)
        if path is not None:
            grid.save(os.fspath(path))
        return grid


#: What reading a damaged or missing ``.npz`` raises: I/O errors, a bad or truncated zip archive, a corrupt member.
_UNREADABLE = (OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


def load_result(path) -> MapResult:
    """Read a result written by :meth:`MapResult.save` (or by ``rfmap solve`` / ``rfmap map``)."""
    try:
        z = np.load(os.fspath(path), allow_pickle=False)
    except _UNREADABLE as e:
        raise ValueError(f"cannot read {path}: {e}") from e
    except ValueError as e:
        # numpy takes any file that is neither .npy nor .npz for a pickle and suggests allow_pickle=True, which
        # would execute code from the file: name the file and say what is wrong instead
        raise ValueError(f"cannot read {path}: not an .npz result file") from e
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise ValueError(f"cannot read {path}: a single .npy array, not an .npz result file")
    try:
        with z:
            missing = {"ref_points", "mapped_points", "elements", "field"} - set(z.files)
            if missing:
                raise ValueError(f"{path}: not a map result, missing keys {sorted(missing)}")
            kind = str(z["kind"]) if "kind" in z.files else (
                "beltrami" if np.iscomplexobj(z["field"]) else "density")
            return MapResult(z["ref_points"], z["mapped_points"], z["elements"], z["field"], kind=kind,
                             time=float(z["time"]) if "time" in z.files else 0.0)
    except _UNREADABLE as e:
        raise ValueError(f"cannot read {path}: {e}") from e
