"""The result of a map computation, shared by classical solvers and neural surrogates, and its exports (.npz, VTK)."""
from __future__ import annotations

import os
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, field

import numpy as np
import torch

from .geometry import beltrami_coefficient, signed_measures
from .metrics import MapMetrics, compute_metrics, element_population

__all__ = ["MapResult", "ResultKind", "register_result_kind", "result_kinds_snapshot", "restore_result_kinds", "result_kind", "kind_of_field", "save_npz_atomic",
           "load_result", "to_pyvista", "setup_pyvista"]


@dataclass(frozen=True)
class ResultKind:
    """What the ``field`` of a kind of map's result holds.

    Attributes
    ----------
    name : str
        The kind, as in ``MapResult.kind``.
    vertex_density : bool
        The field is a vertex density: the density metrics (Std(ρ̃)) and the VTK export's ``density`` and ``rho``
        apply.
    complex_field : bool
        The field is complex (a Beltrami coefficient per element).
    """

    name: str
    vertex_density: bool = False
    complex_field: bool = False


_RESULT_KINDS: dict[str, ResultKind] = {}


def register_result_kind(kind: ResultKind) -> ResultKind:
    """Declare a kind of result (every registered task declares its own, :meth:`rfmap.tasks.base.Task.result_kind`)."""
    _RESULT_KINDS[kind.name] = kind
    return kind


def result_kinds_snapshot() -> dict[str, ResultKind]:
    """A copy of the declared kinds, for :func:`restore_result_kinds` (a kind declared for a while)."""
    return dict(_RESULT_KINDS)


def restore_result_kinds(snapshot: dict[str, ResultKind]) -> None:
    """Declare exactly the kinds of ``snapshot`` again (:func:`result_kinds_snapshot`)."""
    _RESULT_KINDS.clear()
    _RESULT_KINDS.update(snapshot)


def result_kind(name: str) -> ResultKind:
    """The declared kind ``name``; an undeclared kind's field is neither a density nor complex."""
    return _RESULT_KINDS.get(name) or ResultKind(name)


def kind_of_field(field: np.ndarray) -> str:
    """The first declared kind whose field is complex exactly when ``field`` is (a result file without ``kind``)."""
    return next(k.name for k in _RESULT_KINDS.values() if k.complex_field == np.iscomplexobj(field))


# the kinds that the classical solvers write, declared here because the solvers lie below the tasks
register_result_kind(ResultKind("density", vertex_density=True))
register_result_kind(ResultKind("beltrami", complex_field=True))


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
    ref_points : ndarray, shape (P, d)
    mapped_points : ndarray, shape (P, d)
    elements : ndarray, shape (m, d+1)
    field : ndarray
        The input field: vertex densities, shape (P,), or per-triangle Beltrami coefficients, shape (m,) complex
        (another registered kind: what its :class:`ResultKind` declares).
    kind : str
        A registered kind of result (:func:`register_result_kind`): ``'density'`` or ``'beltrami'`` for the
        library's own tasks and solvers, or one that a new task declares.
    time : float
        Seconds spent computing the map.
    info : dict or Mapping
        Method-specific extras (iterations, ...); for a map finished by the stages of :mod:`rfmap.finish` (every
        map of :meth:`rfmap.Surrogate.map`), a read-only view of their report (:class:`rfmap.finish.report.InfoView`).
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

    def rho(self) -> np.ndarray:
        r"""Per-element density :math:`\tilde\rho` on the mapped mesh (population / mapped measure, mean 1),
        shape (m,); density results only."""
        ref = torch.as_tensor(self.ref_points, dtype=torch.float64)
        mapped = torch.as_tensor(self.mapped_points, dtype=torch.float64)
        el = torch.as_tensor(self.elements)
        pop = element_population(ref, el, self.field.reshape(-1))
        rho = pop / signed_measures(mapped, el)
        return (rho / rho.mean()).numpy()

    def metrics(self, *, exact_points=None, mu_ref=None) -> MapMetrics:
        """Metrics in the paper's conventions (see :func:`rfmap.core.metrics.compute_metrics`)."""
        density = self.field.reshape(-1) if result_kind(self.kind).vertex_density else None
        return compute_metrics(self.ref_points, self.mapped_points, self.elements, density=density,
                               exact_points=exact_points, mu_ref=mu_ref, time=self.time)

    def save(self, path) -> None:
        """Save as ``.npz`` with keys ``ref_points``, ``mapped_points``, ``elements``, ``field``, ``kind``."""
        save_npz_atomic(path, ref_points=self.ref_points, mapped_points=self.mapped_points,
                        elements=self.elements, field=self.field, kind=np.array(self.kind),
                        time=np.array(self.time))

    def to_vtk(self, path=None):
        """The mapped mesh as a PyVista ``UnstructuredGrid`` (written to ``path`` when given, e.g. ``.vtu``)."""
        grid = to_pyvista(self)
        if path is not None:
            grid.save(os.fspath(path))
        return grid


def setup_pyvista():
    """Configure PyVista for off-screen rendering (EGL) and static images in notebooks; returns the module."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    pv.OFF_SCREEN = True
    try:
        pv.set_jupyter_backend("static")
    except (ImportError, ValueError):  # outside Jupyter, or without the IPython / trame extras
        pass
    return pv


def to_pyvista(result, *, mapped: bool = True):
    """A ``pyvista.UnstructuredGrid`` of the (mapped) mesh with point data ``displacement`` and ``density`` and
    cell data ``rho`` (density on the mapped mesh)."""
    pv = setup_pyvista()
    import vtk  # noqa: F401

    pts = np.asarray(result.mapped_points if mapped else result.ref_points, dtype=np.float64)
    el = np.asarray(result.elements)
    d = pts.shape[1]
    if d == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
        celltype = pv.CellType.TRIANGLE
    else:
        celltype = pv.CellType.TETRA
    cells = np.column_stack([np.full(len(el), el.shape[1]), el]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(len(el), celltype, dtype=np.uint8), pts)
    disp = result.mapped_points - result.ref_points
    grid.point_data["displacement"] = np.column_stack([disp, np.zeros(len(disp))]) if d == 2 else disp
    if result_kind(result.kind).vertex_density:
        grid.point_data["density"] = result.field.reshape(-1)
        grid.cell_data["rho"] = result.rho() if mapped else result.field.reshape(-1)[el].mean(1) / \
            result.field.reshape(-1)[el].mean(1).mean()
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
            kind = str(z["kind"]) if "kind" in z.files else kind_of_field(z["field"])
            return MapResult(z["ref_points"], z["mapped_points"], z["elements"], z["field"], kind=kind,
                             time=float(z["time"]) if "time" in z.files else 0.0)
    except _UNREADABLE as e:
        raise ValueError(f"cannot read {path}: {e}") from e
