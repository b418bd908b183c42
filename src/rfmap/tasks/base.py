r"""What every task shares: the specification, the registry of task kinds, the encoding, batches and the loss.

A *task* is what a surrogate computes: from an input field (a density, a Beltrami coefficient, ...) a map of the
unit square or cube.  Each kind of task is a class derived from :class:`Task` in a module of its own
(:mod:`rfmap.tasks.density`, :mod:`rfmap.tasks.beltrami`) and registered by :func:`register_task`; it owns its
input encoding, its random training fields, its loss terms, its refinement objective, its validation record, its
metric names, its classical reference solver and the checks of its input.  Everything else asks the task
(``spec.task``), so a new kind of map is one new module.

The input encoding (paper Sec. 4.1) stacks the vertex coordinates and the task's parameter channels,
:math:`\mathcal{U} = [x_1, \dots, x_d, p_1, \dots, p_c]`, as a ``(B, d+c, *S)`` tensor in grid order (``c`` parameter
channels, the paper's :math:`m`; here ``m`` counts a mesh's elements).
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any, Callable, ClassVar, Iterator

import numpy as np
import torch
from torch import Tensor

from . import losses as L
from ..core.geometry import grid_signed_measures, signed_measures
from ..core.mesh import grid_mesh, grid_points
from ..nn.model import BOUNDARIES, apply_displacement
from ..core.result import ResultKind, register_result_kind, restore_result_kinds, result_kinds_snapshot
from ..fields.random import RandomBeltramiConfig, RandomDensityConfig
from .teacher import TeacherConfig, teacher_indices, teacher_loss

__all__ = ["Task", "TaskSpec", "SampleOptions", "Batch", "LossWeights", "register_task", "registered_task", "get_task", "kinds",
           "encode", "grid_elements", "draw_samples", "make_batch", "sample_batch", "task_loss", "batch_loss_terms"]

_TASKS: dict[str, "Task"] = {}


def register_task(cls: type["Task"]) -> type["Task"]:
    """Class decorator: register a :class:`Task` subclass under its ``kind`` (one instance serves every spec)."""
    if not getattr(cls, "kind", None):
        raise ValueError(f"task class {cls.__name__} has no kind")
    _TASKS[cls.kind] = task = cls()
    register_result_kind(task.result_kind())
    return cls


@contextmanager
def registered_task(cls: type["Task"]) -> Iterator["Task"]:
    """Register a :class:`Task` subclass for the duration of a ``with`` block (a kind tried out, or a test's), then
    restore both registries (task kinds and result kinds) as they were; yields the task instance."""
    saved = dict(_TASKS), result_kinds_snapshot()
    try:
        register_task(cls)
        yield _TASKS[cls.kind]
    finally:
        _TASKS.clear()
        _TASKS.update(saved[0])
        restore_result_kinds(saved[1])


def kinds() -> tuple[str, ...]:
    """The registered task kinds, in order of registration."""
    return tuple(_TASKS)


def get_task(kind: str) -> "Task":
    """The task registered under ``kind``; ``ValueError`` naming the known kinds otherwise."""
    try:
        return _TASKS[kind]
    except (KeyError, TypeError):
        raise ValueError(f"unknown task kind {kind!r}; expected one of {kinds()}") from None


@dataclass(frozen=True)
class TaskSpec:
    """What a surrogate computes.

    Attributes
    ----------
    kind : str
        A registered task kind (:func:`kinds`): ``'density'`` (DEM / DEQ), ``'beltrami'`` (reconstruction of a map
        from its Beltrami coefficient), ...
    dim : int
        2 or 3 (each task says which it supports, ``Task.dims``).
    boundary : str
        ``'square'`` (sliding walls), ``'fixed'`` (identity on the boundary) or ``'free'``.
    """

    kind: str = "density"
    dim: int = 2
    boundary: str = "square"

    def __post_init__(self):
        task = get_task(self.kind)
        if self.dim not in (2, 3):
            raise ValueError(f"dimension must be 2 or 3, got {self.dim}")
        if self.dim not in task.dims:
            raise ValueError(f"{task.title} tasks are {' or '.join(f'{d}D' for d in task.dims)}, not {self.dim}D")
        if self.boundary not in BOUNDARIES:
            raise ValueError(f"unknown boundary {self.boundary!r}; expected one of {BOUNDARIES}")

    @property
    def task(self) -> "Task":
        """The registered :class:`Task` of this kind."""
        return get_task(self.kind)

    @property
    def n_params(self) -> int:
        """Number of parameter channels of the encoding."""
        return self.task.n_params(self.dim)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "dim": self.dim, "boundary": self.boundary}


@dataclass(frozen=True)
class SampleOptions:
    """How random training fields are drawn; each task reads the entries that concern it.

    Attributes
    ----------
    jitter : float
        Strength of the Sobol jitter of the vertices (0: the regular grid).
    density_cfg : RandomDensityConfig, optional
        Random densities (default ``RandomDensityConfig.for_dim(d)``).
    beltrami_cfg : RandomBeltramiConfig, optional
        Random Beltrami coefficients or maps.
    beltrami_source : str
        ``'map'`` (the exact coefficient of a random map) or ``'mu'`` (a random coefficient).
    teacher : TeacherConfig, optional
        A classical solver's maps as targets, for the tasks whose ``teacher`` attribute is true (:class:`Task`).
    """

    jitter: float = 0.2
    density_cfg: RandomDensityConfig | None = None
    beltrami_cfg: RandomBeltramiConfig | None = None
    beltrami_source: str = "map"
    teacher: TeacherConfig | None = None

    @property
    def teaching(self) -> bool:
        return self.teacher is not None and self.teacher.active


@dataclass
class Batch:
    """A training batch on an ``N``-grid (possibly jittered).

    Attributes
    ----------
    inputs : Tensor, shape ``(B, d+c, *S)``
    ref : Tensor, shape (B, P, d)
    elements : LongTensor, shape (m, d+1)
    density : Tensor, shape (B, P) — density tasks
    mu_target : complex Tensor, shape (B, m) — Beltrami tasks: target per triangle
    extra : dict
        What else a task's loss needs (tensors move with the batch), e.g. a teacher's ``target``.
    """

    inputs: Tensor
    ref: Tensor
    elements: Tensor
    n: int
    density: Tensor | None = None
    mu_target: Tensor | None = None
    extra: dict = field(default_factory=dict)

    @property
    def on_grid(self) -> bool:
        """Whether ``elements`` is the element array of the ``N``-grid mesh (then the losses use strided views)."""
        e = self.elements
        return e is grid_elements(self.n, self.ref.shape[-1]) or bool(self.extra.get("grid_elements"))

    def to(self, device) -> "Batch":
        """The batch on ``device`` (the cached element array stays on the CPU; losses use strided views)."""
        dev = torch.device(device)
        if dev.type == "cpu":
            return self
        mv = lambda t: None if t is None else t.to(dev, non_blocking=True)  # noqa: E731
        extra = {k: mv(v) if isinstance(v, Tensor) else v for k, v in self.extra.items()}
        return Batch(mv(self.inputs), mv(self.ref), self.elements.to(dev), self.n, mv(self.density),
                     mv(self.mu_target), {**extra, "grid_elements": self.on_grid})


@dataclass(frozen=True)
class LossWeights:
    """Weights of the loss terms.

    Attributes
    ----------
    beltrami : float
        :math:`\\lambda_{\\mathrm{hr}}`, the paper's Beltrami regularization weight, of the Beltrami energy
        :math:`\\int|\\mu|^2` in the DEQ loss (0 gives DEM).  Not the :math:`\\lambda` of weight refinement
        (:data:`rfmap.tasks.objectives.FLIP_WEIGHT`).
    fold : float
        Weight of the fold penalty (:func:`rfmap.tasks.losses.fold_penalty`, an addition of this package, not in
        the paper); ``fold_threshold`` is its :math:`\\tau`.  The default here is not the weight every shipped
        model was trained with: each model's is in its configuration (``get_config(name).loss``,
        :mod:`rfmap.training.config`).
    area : float
        Free boundary: weight of the area constraint (:func:`rfmap.tasks.losses.area_penalty`, also an addition of
        this package).
    density_tangent : bool
        Below the 1 % floor of an element's mapped measure, continue its density along the tangent instead of
        clamping it (:func:`rfmap.tasks.losses.element_density`), so that collapsed and flipped elements keep a
        restoring gradient from the density term. The default, ``False``, clamps; the
        ``full`` presets of the U-Net density models set it, and those shipped models were trained with it (the
        FNO of ``fno-deq2d-square`` clamps; each model's metadata records its setting).
    """

    beltrami: float = 0.0
    fold: float = 10.0
    fold_threshold: float = 0.02
    area: float = 1.0
    density_tangent: bool = False


@dataclass
class MappedBatch:
    """A batch and the network's map of it, as a task's loss sees them.

    Attributes
    ----------
    batch : Batch
    mapped : Tensor, shape (B, P, d)
        The mapped vertices :math:`u = x + \\mathcal{B}(x) \\odot \\psi(x)`.
    measures : rfmap.tasks.losses.Measures
        The signed element measures before and after, shape (B, m) (strided on a grid).
    spec : TaskSpec
    """

    batch: Batch
    mapped: Tensor
    measures: L.Measures
    spec: TaskSpec


class Task:
    """A kind of map a surrogate learns; subclasses are registered with :func:`register_task`.

    Class attributes
    ----------------
    kind : str
        The registry key, stored in ``TaskSpec.kind``, ``MapResult.kind`` and the weights' metadata.
    title : str
        The kind in words, for messages.
    dims : tuple of int
        The dimensions the task supports.
    score_metric : str
        The validation's primary metric (a key of :class:`rfmap.core.metrics.MapMetrics`), lower is better.
    metric_names : tuple of str
        The entries of one validation record (:meth:`validation_record`).
    loss_terms : tuple of str
        The names of the task's own loss terms (the fold penalty and a teacher's term are common to all).
    teacher : bool
        Whether a classical teacher (:mod:`rfmap.tasks.teacher`) applies.
    equalizes : bool
        Whether the map equalizes a density: then a map is judged against doing nothing, shortened when it is no
        better, and may be polished by the flow-based solver (:mod:`rfmap.finish`).
    methods : tuple of str
        The classical solvers of :mod:`rfmap.solvers` that compute this kind of map (``rfmap solve --method``).
    reference_title : str
        The classical reference solver in words, for tables.
    complex_field : bool
        Whether the field of a map (``MapResult.field``) is complex.
    """

    kind: ClassVar[str] = ""
    title: ClassVar[str] = ""
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    score_metric: ClassVar[str] = ""
    metric_names: ClassVar[tuple[str, ...]] = ()
    loss_terms: ClassVar[tuple[str, ...]] = ()
    teacher: ClassVar[bool] = False
    equalizes: ClassVar[bool] = False
    methods: ClassVar[tuple[str, ...]] = ()
    reference_title: ClassVar[str] = ""
    complex_field: ClassVar[bool] = False

    # ------------------------------------------------------------------ encoding and input
    def n_params(self, dim: int) -> int:
        """Number of parameter channels ``c`` of the encoding in ``dim`` dimensions."""
        raise NotImplementedError

    def channels(self, params: Tensor) -> Tensor:
        """The parameter channels of the encoding, shape (B, P, c), from the parameters at the P vertices."""
        raise NotImplementedError

    def check_field(self, grid: np.ndarray, preprocess: bool = True) -> np.ndarray:
        """A user's field sampled on a grid, checked and normalised as the network expects it (``ValueError`` on
        bad input)."""
        raise NotImplementedError

    def resampled(self, grid: np.ndarray) -> np.ndarray:
        """A checked field after interpolation to another grid (e.g. unit mass restored); default unchanged."""
        return grid

    def sample_named(self, field: Any) -> Callable:
        """The function of points that samples a named field object of this kind (default the object itself)."""
        return field

    def field_on_mesh(self, grid: np.ndarray, fn: Callable | None, ref: np.ndarray, elements: np.ndarray,
                      grid_n: int | None) -> np.ndarray:
        """The input field on an output mesh, as a map's ``MapResult.field``: from the exact evaluator ``fn``
        when there is one, else interpolated from the checked ``grid`` (``grid_n``: the mesh is the ``N``-grid)."""
        raise NotImplementedError

    def result_kind(self) -> ResultKind:
        """What a map's ``MapResult.field`` holds: a vertex density when the task equalizes one."""
        return ResultKind(self.kind, vertex_density=self.equalizes, complex_field=self.complex_field)

    def hard_field(self, rng: np.random.Generator, n: int, dim: int) -> tuple[np.ndarray, dict]:
        """A field on the ``N``-grid drawn to be hard for a surrogate (:mod:`rfmap.fields.hard`) and the keywords
        of ``Surrogate.map`` to map it with."""
        raise ValueError(f"{self.title} tasks have no hard fields")

    # ------------------------------------------------------------------ training
    def draw(self, rng: np.random.Generator, spec: TaskSpec, n: int, options: SampleOptions,
             teach: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """One random training sample: ``(points (N**d, d), params (N**d, ...), target or None)``; ``teach``:
        draw the teacher's map as the target (``NaN`` rows where it has none)."""
        raise NotImplementedError

    def batch(self, spec: TaskSpec, inputs: Tensor, ref: Tensor, params: Tensor, n: int,
              targets: np.ndarray | None) -> Batch:
        """The :class:`~rfmap.tasks.base.Batch` of drawn samples (``params`` as tensors, ``targets`` a teacher's maps or
        ``None``)."""
        raise NotImplementedError

    def loss(self, mb: MappedBatch, weights: LossWeights) -> tuple[Tensor, dict[str, Tensor]]:
        """The task's own loss terms of a mapped batch: ``(weighted total, {term: value})``."""
        raise NotImplementedError

    # ------------------------------------------------------------------ maps
    def refine_objective(self, ref: Tensor, psi: Tensor, elements: Tensor, field: np.ndarray, boundary: str,
                         grid_n: int | None) -> Callable[[np.ndarray], float]:
        r"""The weight refinement's objective :math:`\mathcal{J}(\alpha)` (paper Sec. 4.3)."""
        raise NotImplementedError

    def metric_inputs(self, field: np.ndarray) -> dict:
        """The keywords ``density`` and ``mu`` of :func:`rfmap.finish.repair.dispatch.repair_map` for a map of ``field``."""
        return {"density": None, "mu": None}

    def reference(self, grid: np.ndarray, boundary: str | None = None):
        """The classical reference solver's map (:class:`rfmap.core.result.MapResult`, the first of ``methods``)
        of a user's field on the ``N``-grid's vertices."""
        if not self.methods:
            raise ValueError(f"{self.title} tasks have no classical solver")
        return self.solve(self.solver_input(grid), grid.shape[0], self.methods[0], boundary)

    def solve(self, values: np.ndarray, n: int, method: str, boundary: str | None, progress: bool = False):
        """A classical map (``method`` one of ``methods``) on the ``N``-grid of the solver's input ``values``
        (:meth:`solver_input`, :meth:`solver_sample`), as ``rfmap solve`` computes it; ``boundary`` ``None``: the
        task's default."""
        raise ValueError(f"{self.title} tasks have no classical solver")

    def solver_input(self, grid: np.ndarray) -> np.ndarray:
        """A user's field on the ``N``-grid's vertices checked and prepared for :meth:`solve` (``ValueError``
        otherwise)."""
        return self.check_field(grid)

    def solver_sample(self, field: Any, n: int) -> np.ndarray:
        """The solver's input of a named field of this kind on the ``N``-grid."""
        return self.solver_input(np.asarray(self.sample_named(field)(grid_points(n, field.dim))).reshape(
            (n,) * field.dim))

    def reference_of(self, field: Callable, n: int, dim: int, boundary: str):
        """The classical reference map on the ``N``-grid of a field given as a function of points (a held-out
        field, :class:`rfmap.tasks.heldout.ValidationField`), for a model with ``boundary``."""
        raise ValueError(f"{self.title} tasks have no classical solver")

    def training_fields_text(self, config: dict) -> str:
        """The random training fields of a stored training configuration (``meta["config"]``) in words."""
        return "random fields"

    def test_fields(self, dim: int) -> tuple[str, ...]:
        """The paper's test fields of this kind in ``dim`` dimensions (reported after training, never used to select
        a model); none by default."""
        return ()

    def test_record(self, result, name: str) -> dict:
        """The metrics of a map of the paper's test field ``name``."""
        raise NotImplementedError

    # ------------------------------------------------------------------ validation
    def validation_fields(self, dim: int, count: int, stream: str, low_frequency: bool = False) -> list:
        """The fixed held-out fields (``ValidationField``) of the task."""
        raise NotImplementedError

    def validation_record(self, result, vf) -> tuple[dict, float, float]:
        """``(record, value, baseline)`` of one validation map: the metrics named by ``metric_names``, the
        value of ``score_metric``, and that of doing nothing (the identity map)."""
        raise NotImplementedError


def grad_magnitude(values: np.ndarray, n: int, dim: int) -> np.ndarray:
    """:math:`|\nabla v|` of values on the ``N``-grid by central differences, flattened (N**d,): where the
    Sobol jitter of the vertices concentrates them."""
    g = np.gradient(values.reshape((n,) * dim))
    return np.sqrt(sum(gi**2 for gi in g)).reshape(-1)


@lru_cache(maxsize=64)
def grid_elements(n: int, dim: int) -> Tensor:
    """Elements of the ``N``-grid mesh as a LongTensor (cached)."""
    return torch.as_tensor(grid_mesh(n, dim).elements)


def encode(points: Tensor, params: Tensor, spec: TaskSpec, n: int) -> Tensor:
    r"""Stack coordinates and parameter channels into the network input.

    Parameters
    ----------
    points : Tensor, shape (B, N**d, d)
        Vertex positions in grid order (regular or jittered).
    params : Tensor, shape (B, N**d, ...)
        The task's parameters at the vertices (a unit-mass density, a complex Beltrami coefficient, ...).
    n : int
        Grid side ``N``.

    Returns
    -------
    Tensor, shape (B, d + c, N, ..., N)
    """
    B, P, d = points.shape
    if P != n**d:
        raise ValueError(f"{P} points do not form an N={n} grid in {d}D")
    ch = spec.task.channels(params)
    x = torch.cat([points, ch.to(points.dtype)], -1)  # (B, P, d+c)
    return x.transpose(1, 2).reshape(B, d + spec.n_params, *([n] * d)).contiguous()


def draw_samples(spec: TaskSpec, *, seed: int, step: int, indices, n: int, options: SampleOptions | None = None,
                 **kw):
    """The raw arrays of training samples ``indices`` of step ``step`` on an ``N``-grid (numpy only, so that a
    worker process can draw them and send them to the training process); the task draws each sample
    (:meth:`Task.draw`) as ``options`` say (:class:`SampleOptions`, whose fields may be given as keywords:
    ``jitter``, ``density_cfg``, ``beltrami_cfg``, ``beltrami_source``, ``teacher``).

    Sample ``i`` of step ``t`` is generated from ``np.random.default_rng([seed, t, i])`` only, so a batch split
    across processes (data-parallel training) or drawn by worker processes reproduces the single-process batch
    exactly.

    With an active ``teacher`` (tasks with ``Task.teacher``, :mod:`rfmap.tasks.teacher`), the first
    ``teacher_indices(len(indices), teacher.share)`` samples also get the classical map of their field as a target.

    Returns
    -------
    points : ndarray, shape (B, N**d, d), float64
        The vertices of each sample's grid.
    params : ndarray, shape (B, N**d, ...)
        The field of each sample at its vertices, e.g. the unit-mass density (float64) or the Beltrami coefficient
        (complex128).
    targets : ndarray, shape (B, N**d, d), float64
        Only with an active ``teacher``: the teacher's map at the sample's vertices, NaN for samples without a
        target (beyond the share, or the solver failed).
    """
    task = spec.task
    options = replace(options or SampleOptions(), **kw)
    indices = list(indices)
    if options.teaching and not task.teacher:
        raise ValueError(f"a classical teacher does not apply to {task.title} tasks")
    n_teach = teacher_indices(len(indices), options.teacher.share) if options.teaching else 0
    pts_l, par_l, tgt_l = [], [], []
    for k, i in enumerate(indices):
        rng = np.random.default_rng([seed, step, int(i)])
        pts, par, tgt = task.draw(rng, spec, n, options, k < n_teach)
        pts_l.append(pts)
        par_l.append(par)
        tgt_l.append(tgt)
    if options.teaching:
        return np.stack(pts_l), np.stack(par_l), np.stack(tgt_l)
    return np.stack(pts_l), np.stack(par_l)


def make_batch(spec: TaskSpec, points: np.ndarray, params: np.ndarray, n: int,
               targets: np.ndarray | None = None) -> Batch:
    """Tensors of a training batch from the arrays of :func:`draw_samples` (float32 / complex64); ``targets``
    (a teacher's maps, NaN rows for samples without one) become ``extra["target"]`` and ``extra["target_mask"]``."""
    ref = torch.as_tensor(points, dtype=torch.float32)
    par = torch.as_tensor(params)
    par = par.to(torch.complex64) if par.is_complex() else par.float()
    inputs = encode(ref, par, spec, n)
    return spec.task.batch(spec, inputs, ref, par, n, targets)


def teacher_extra(points: np.ndarray, targets: np.ndarray | None) -> dict:
    """``extra`` entries of a batch with a teacher's maps: ``target`` (the sample's own points where it has none)
    and ``target_mask``."""
    if targets is None:
        return {}
    mask = np.isfinite(targets).all(axis=(1, 2))
    return {"target": torch.as_tensor(np.where(mask[:, None, None], targets, points), dtype=torch.float32),
            "target_mask": torch.as_tensor(mask)}


def sample_batch(spec: TaskSpec, *, seed: int, step: int, indices, n: int, options: SampleOptions | None = None,
                 **kw) -> Batch:
    """Draw the training samples ``indices`` of step ``step`` on an ``N``-grid (:func:`draw_samples` then
    :func:`make_batch`; no teacher)."""
    pts, par = draw_samples(spec, seed=seed, step=step, indices=indices, n=n, options=options, **kw)[:2]
    return make_batch(spec, pts, par, n)


def task_loss(spec: TaskSpec, batch: Batch, psi: Tensor, weights: LossWeights,
              teacher_weight: float = 0.0) -> tuple[Tensor, dict]:
    """Total loss and its parts for network output ``psi`` of shape ``(B, d, *S)``: the task's own terms
    (:meth:`Task.loss`), the fold penalty, and with ``teacher_weight`` > 0 the supervised term
    :func:`rfmap.tasks.teacher.teacher_loss` where the batch carries targets."""
    B, d = psi.shape[:2]
    disp = psi.reshape(B, d, -1).transpose(1, 2)
    mapped = apply_displacement(batch.ref, disp, spec.boundary)
    if batch.on_grid:  # the elements are those of the N-grid mesh: strided fast path
        pre = L.Measures(grid_signed_measures(batch.ref, batch.n), grid_signed_measures(mapped, batch.n))
    else:
        pre = L.Measures(signed_measures(batch.ref, batch.elements), signed_measures(mapped, batch.elements))
    total, parts = spec.task.loss(MappedBatch(batch, mapped, pre, spec), weights)
    if weights.fold:
        parts["fold"] = L.fold_penalty(batch.ref, mapped, batch.elements, weights.fold_threshold, pre=pre)
        total = total + weights.fold * parts["fold"]
    if teacher_weight and "target" in batch.extra:
        parts["teacher"] = teacher_loss(mapped, batch.extra["target"], batch.ref, batch.extra["target_mask"],
                                        batch.n)
        total = total + teacher_weight * parts["teacher"]
    return total, {k: float(v.detach()) for k, v in parts.items()}


def batch_loss_terms(model, spec: TaskSpec, batch: Batch, weights: LossWeights) -> tuple[float, dict, Tensor, dict]:
    r"""A network's loss on a batch as training computes it, with the terms element by element, without gradients.

    Parameters
    ----------
    model : torch.nn.Module or None
        The displacement network (``Surrogate.model``): ``batch.inputs`` to :math:`\psi` of shape ``(B, d, *S)``.
        ``None``: the identity map (:math:`\psi = 0`), the reference a trained network's terms are read against.

    Returns
    -------
    total : float
        :func:`task_loss` of the network's maps.
    parts : dict
        Its terms (batch means).
    mapped : Tensor, shape (B, P, d)
        The mapped vertices :math:`u = x + \mathcal{B}(x) \odot \psi(x)`.
    terms : dict
        :func:`rfmap.tasks.losses.loss_integrands` of the maps (fold threshold of ``weights``).
    """
    with torch.no_grad():
        if model is None:  # the identity map: zero displacement on the batch's grid
            grid = batch.inputs.shape[2:]
            psi = torch.zeros(batch.inputs.shape[0], len(grid), *grid, dtype=batch.ref.dtype)
        else:
            psi = model(batch.inputs)
        total, parts = task_loss(spec, batch, psi, weights)
        mapped = apply_displacement(batch.ref, psi.flatten(2).transpose(1, 2), spec.boundary)
        terms = L.loss_integrands(batch.ref, mapped, batch.elements, density=batch.density,
                                  mu_target=batch.mu_target, fold_threshold=weights.fold_threshold)
    return float(total), parts, mapped, terms
