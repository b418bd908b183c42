r"""Tasks: what a surrogate maps from, how its inputs are encoded, and how training batches are drawn.

A task couples the input field (a density, or a Beltrami coefficient), the boundary condition and the losses.
The input encoding (paper Sec. 4.1) stacks the vertex coordinates and the parameter channels,
:math:`\mathcal{U} = [x_1, \dots, x_d, p_1, \dots, p_m]`, as a ``(B, d+m, *S)`` tensor in grid order:

* density tasks (m = 1): the channel is :math:`\log p` of the unit-mass density, a discretisation-consistent
  normalisation (mass :math:`\int p = 1` on every grid);
* Beltrami tasks (m = 2): the channels are :math:`\mathrm{Re}\,\mu` and :math:`\mathrm{Im}\,\mu` at the vertices.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import torch
from torch import Tensor

from . import losses as L
from .geometry import grid_element_mean, grid_signed_measures, signed_measures
from .fields import (RandomBeltramiConfig, RandomDensity, RandomDensityConfig, RandomMap, RandomBeltrami,
                     jittered_points, preprocess_density, vertex_weights)
from .mesh import grid_mesh, grid_points, interpolate
from .nn.model import BOUNDARIES, apply_displacement
from .teacher import TeacherConfig, teacher_indices, teacher_loss, teacher_map, teacher_targets

__all__ = ["TaskSpec", "Batch", "encode", "grid_elements", "draw_samples", "make_batch", "sample_batch", "task_loss",
           "KINDS"]

KINDS = ("density", "beltrami")


@dataclass(frozen=True)
class TaskSpec:
    """What a surrogate computes.

    Attributes
    ----------
    kind : str
        ``'density'`` (DEM / DEQ) or ``'beltrami'`` (reconstruction of a map from its Beltrami coefficient).
    dim : int
        2 or 3 (Beltrami tasks are 2D).
    boundary : str
        ``'square'`` (sliding walls), ``'fixed'`` (identity on the boundary) or ``'free'``.
    """

    kind: str = "density"
    dim: int = 2
    boundary: str = "square"

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown task kind {self.kind!r}; expected one of {KINDS}")
        if self.dim not in (2, 3):
            raise ValueError(f"dimension must be 2 or 3, got {self.dim}")
        if self.kind == "beltrami" and self.dim != 2:
            raise ValueError("Beltrami tasks are two-dimensional")
        if self.boundary not in BOUNDARIES:
            raise ValueError(f"unknown boundary {self.boundary!r}; expected one of {BOUNDARIES}")

    @property
    def n_params(self) -> int:
        return 1 if self.kind == "density" else 2

    def to_dict(self) -> dict:
        return {"kind": self.kind, "dim": self.dim, "boundary": self.boundary}


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
    params : Tensor, shape (B, N**d) real (density, already unit mass) or complex (Beltrami coefficient)
    n : int
        Grid side ``N``.

    Returns
    -------
    Tensor, shape (B, d + m, N, ..., N)
    """
    B, P, d = points.shape
    if P != n**d:
        raise ValueError(f"{P} points do not form an N={n} grid in {d}D")
    if spec.kind == "density":
        ch = torch.log(params).unsqueeze(-1)
    else:
        ch = torch.stack([params.real, params.imag], -1)
    x = torch.cat([points, ch.to(points.dtype)], -1)  # (B, P, d+m)
    return x.transpose(1, 2).reshape(B, d + spec.n_params, *([n] * d)).contiguous()


@dataclass
class Batch:
    """A training batch on an ``N``-grid (possibly jittered).

    Attributes
    ----------
    inputs : Tensor, shape ``(B, d+m, *S)``
    ref : Tensor, shape (B, n, d)
    elements : LongTensor, shape (m, d+1)
    density : Tensor, shape (B, n) — density tasks
    mu_target : complex Tensor, shape (B, m) — Beltrami tasks: target per triangle
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


def _grad_magnitude(values: np.ndarray, n: int, dim: int) -> np.ndarray:
    g = np.gradient(values.reshape((n,) * dim))
    return np.sqrt(sum(gi**2 for gi in g)).reshape(-1)


def _density_sample(rng, n, dim, cfg: RandomDensityConfig, jitter: float, elements_np):
    """``(points, unit-mass density at the points, raw field on the regular grid)`` of one training sample."""
    fld = RandomDensity(rng, cfg)
    grid_vals = fld.on_grid(n)
    if jitter > 0:
        pts = jittered_points(n, dim, rng, grad_magnitude=_grad_magnitude(grid_vals, n, dim), strength=jitter)
        raw = fld(pts)
        w = vertex_weights(pts, elements_np)
        p = preprocess_density(raw, weights=w)
    else:
        pts = grid_points(n, dim)
        p = preprocess_density(grid_vals.reshape((n,) * dim)).reshape(-1)
    return pts, p, grid_vals.reshape((n,) * dim)


def _beltrami_sample(rng, n, cfg: RandomBeltramiConfig, jitter: float, source: str):
    gen = RandomMap(rng, cfg) if source == "map" else RandomBeltrami(rng, cfg)
    if jitter > 0:
        probe_n = 33
        probe = grid_mesh(probe_n, 2).points
        g = _grad_magnitude(np.abs(gen.mu_grid(probe_n) if source == "map" else gen(probe)), probe_n, 2)
        g_n = interpolate(g.reshape(1, 1, probe_n, probe_n), grid_points(n, 2))[0, :, 0]
        pts = jittered_points(n, 2, rng, grad_magnitude=g_n, strength=jitter)
        mu = gen.mu(pts) if source == "map" else gen(pts)
    else:
        pts = grid_points(n, 2)
        mu = gen.mu_grid(n) if source == "map" else gen(pts)
    return pts, mu


def draw_samples(spec: TaskSpec, *, seed: int, step: int, indices, n: int, jitter: float = 0.2,
                 density_cfg: RandomDensityConfig | None = None, beltrami_cfg: RandomBeltramiConfig | None = None,
                 beltrami_source: str = "map", teacher: TeacherConfig | None = None):
    """The raw arrays of training samples ``indices`` of step ``step`` on an ``N``-grid (numpy only, so that a
    worker process can draw them and send them to the training process).

    Sample ``i`` of step ``t`` is generated from ``np.random.default_rng([seed, t, i])`` only, so a batch split
    across processes (data-parallel training) or drawn by worker processes reproduces the single-process batch
    exactly.

    With an active ``teacher`` (density tasks, :mod:`rfmap.teacher`), the first
    ``teacher_indices(len(indices), teacher.share)`` samples also get the classical map of their field as a target.

    Returns
    -------
    points : ndarray, shape (B, N**d, d), float64
    params : ndarray, shape (B, N**d), the unit-mass density (float64) or the Beltrami coefficient (complex128)
    targets : ndarray, shape (B, N**d, d), float64 — only with an active ``teacher``: the teacher's map at the
        sample's vertices, NaN for samples without a target (beyond the share, or the solver failed)
    """
    indices = list(indices)
    el_np = grid_elements(n, spec.dim).numpy() if spec.kind == "density" and jitter > 0 else None
    teach = teacher is not None and teacher.active
    if teach and spec.kind != "density":
        raise ValueError("a classical teacher applies to density tasks only")
    n_teach = teacher_indices(len(indices), teacher.share) if teach else 0
    pts_l, par_l, tgt_l = [], [], []
    for k, i in enumerate(indices):
        rng = np.random.default_rng([seed, step, int(i)])
        if spec.kind == "density":
            cfg = density_cfg or RandomDensityConfig.for_dim(spec.dim)
            pts, par, raw_grid = _density_sample(rng, n, spec.dim, cfg, jitter, el_np)
            if teach:
                mapped = teacher_map(raw_grid, spec.boundary, teacher.method) if k < n_teach else None
                tgt_l.append(np.full_like(pts, np.nan) if mapped is None else teacher_targets(pts, n, mapped))
        else:
            pts, par = _beltrami_sample(rng, n, beltrami_cfg or RandomBeltramiConfig(), jitter, beltrami_source)
        pts_l.append(pts)
        par_l.append(par)
    if teach:
        return np.stack(pts_l), np.stack(par_l), np.stack(tgt_l)
    return np.stack(pts_l), np.stack(par_l)


def make_batch(spec: TaskSpec, points: np.ndarray, params: np.ndarray, n: int,
               targets: np.ndarray | None = None) -> Batch:
    """Tensors of a training batch from the arrays of :func:`draw_samples` (float32 / complex64); ``targets``
    (a teacher's maps, NaN rows for samples without one) become ``extra["target"]`` and ``extra["target_mask"]``."""
    elements = grid_elements(n, spec.dim)
    ref = torch.as_tensor(points, dtype=torch.float32)
    par = torch.as_tensor(params)
    par = par.to(torch.complex64) if par.is_complex() else par.float()
    inputs = encode(ref, par, spec, n)
    if spec.kind == "density":
        extra = {}
        if targets is not None:
            mask = np.isfinite(targets).all(axis=(1, 2))
            extra = {"target": torch.as_tensor(np.where(mask[:, None, None], targets, points), dtype=torch.float32),
                     "target_mask": torch.as_tensor(mask)}
        return Batch(inputs, ref, elements, n, density=par, extra=extra)
    return Batch(inputs, ref, elements, n, mu_target=par[:, elements].mean(-1))


def sample_batch(spec: TaskSpec, *, seed: int, step: int, indices, n: int, jitter: float = 0.2,
                 density_cfg: RandomDensityConfig | None = None, beltrami_cfg: RandomBeltramiConfig | None = None,
                 beltrami_source: str = "map") -> Batch:
    """Draw the training samples ``indices`` of step ``step`` on an ``N``-grid (:func:`draw_samples` then
    :func:`make_batch`)."""
    pts, par = draw_samples(spec, seed=seed, step=step, indices=indices, n=n, jitter=jitter,
                            density_cfg=density_cfg, beltrami_cfg=beltrami_cfg, beltrami_source=beltrami_source)
    return make_batch(spec, pts, par, n)


@dataclass(frozen=True)
class LossWeights:
    """Weights of the loss terms.

    Attributes
    ----------
    beltrami : float
        :math:`\\lambda` of the Beltrami energy :math:`\\int|\\mu|^2` in the DEQ loss (0 gives DEM).
    fold : float
        Weight of the fold penalty; ``fold_threshold`` is its :math:`\\tau`.
    area : float
        Free boundary: weight of the area constraint.
    density_tangent : bool
        Below the 1 % floor of an element's mapped measure, continue its density along the tangent instead of
        clamping it (:func:`rfmap.losses.element_density`), so that collapsed and flipped elements keep a
        restoring gradient from the density term. ``False`` (the clamp) is what the shipped models used.
    """

    beltrami: float = 0.0
    fold: float = 10.0
    fold_threshold: float = 0.02
    area: float = 1.0
    density_tangent: bool = False


def task_loss(spec: TaskSpec, batch: Batch, psi: Tensor, weights: LossWeights,
              teacher_weight: float = 0.0) -> tuple[Tensor, dict]:
    """Total loss and its parts for network output ``psi`` of shape ``(B, d, *S)``; ``teacher_weight`` > 0 adds
    the supervised term :func:`rfmap.teacher.teacher_loss` where the batch carries targets."""
    B, d = psi.shape[:2]
    disp = psi.reshape(B, d, -1).transpose(1, 2)
    mapped = apply_displacement(batch.ref, disp, spec.boundary)
    dim = batch.ref.shape[-1]
    if batch.on_grid:  # the elements are those of the N-grid mesh: strided fast path
        ref_meas = grid_signed_measures(batch.ref, batch.n)
        meas = grid_signed_measures(mapped, batch.n)
        elem_density = None if batch.density is None else grid_element_mean(batch.density, batch.n, dim)
    else:
        ref_meas = signed_measures(batch.ref, batch.elements)
        meas = signed_measures(mapped, batch.elements)
        elem_density = None
    mk = {"ref_meas": ref_meas, "meas": meas}
    parts: dict[str, Tensor] = {}
    if spec.kind == "beltrami":
        parts["beltrami"] = L.beltrami_loss(batch.ref, mapped, batch.elements, batch.mu_target)
        total = parts["beltrami"]
    else:
        parts["density"] = L.density_loss(batch.ref, mapped, batch.elements, batch.density, elem_density=elem_density,
                                          tangent=weights.density_tangent, **mk)
        total = parts["density"]
        if weights.beltrami and d == 2:
            parts["mu2"] = L.beltrami_energy(batch.ref, mapped, batch.elements)
            total = total + weights.beltrami * parts["mu2"]
        if spec.boundary == "free" and weights.area:
            parts["area"] = L.area_penalty(batch.ref, mapped, batch.elements, **mk)
            total = total + weights.area * parts["area"]
    if weights.fold:
        parts["fold"] = L.fold_penalty(batch.ref, mapped, batch.elements, weights.fold_threshold, **mk)
        total = total + weights.fold * parts["fold"]
    if teacher_weight and "target" in batch.extra:
        parts["teacher"] = teacher_loss(mapped, batch.extra["target"], batch.ref, batch.extra["target_mask"],
                                        batch.n)
        total = total + teacher_weight * parts["teacher"]
    return total, {k: float(v.detach()) for k, v in parts.items()}
