r"""The density task: a density-equalizing map (DEM, DEQ) of the unit square or cube (paper Sec. 5.2).

* encoding (:math:`c = 1` parameter channel): the channel is :math:`\log p` of the unit-mass density, a discretisation-consistent
  normalisation (mass :math:`\int p = 1` on every grid).  This differs from the paper, whose Sec. 4.1 stacks the
  field itself, :math:`[x, p(x)]`: a density-equalizing map depends on :math:`p` only through its ratios, which
  :math:`\log p` turns into differences, and :math:`\log p` keeps a density that spans orders of magnitude (a
  narrow peak over a low floor) in a range of order one;
* training fields: random densities (:class:`rfmap.fields.random.RandomDensity`) at Sobol-jittered vertices, with a
  classical teacher's map as an optional target (:mod:`rfmap.tasks.teacher`);
* loss: the density mismatch :math:`L(\tilde\rho - 1)`, with :math:`\lambda_{\mathrm{hr}} \int |\mu|^2` for DEQ
  in 2D (the paper's Beltrami regularization weight); two further terms are this package's additions, not in the
  paper: the fold penalty (:func:`rfmap.tasks.losses.fold_penalty`, added to every task's loss by
  :func:`rfmap.tasks.base.task_loss`) and, on a free boundary, the area constraint
  (:func:`rfmap.tasks.losses.area_penalty`);
* refinement objective: :math:`\mathrm{Std}(\tilde\rho_{\text{map}}) + \lambda\,\#\text{flipped}/m`, with
  :math:`\lambda` the weight of the flipped-element fraction
  (:func:`rfmap.tasks.objectives.density_objective`);
* validation: Std(ρ̃_map) on four families of held-out densities, relative to the field's own Std(ρ̃_orig);
* reference solver: the diffusion method (:func:`rfmap.solvers.solve_dem`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
from torch import Tensor

from .. import solvers
from ..core.geometry import grid_element_mean
from ..core.inputs import check_density, preprocess_density, unit_mass
from ..core.mesh import grid_points, grid_vertex_weights, interpolate, jittered_points, vertex_weights
from ..fields.hard import hard_density
from ..fields.paper import TEST_FIELDS
from ..fields.random import RandomDensity, RandomDensityConfig
from . import losses as L
from .base import Batch, LossWeights, MappedBatch, SampleOptions, Task, TaskSpec, grad_magnitude, grid_elements, \
    register_task, teacher_extra
from .heldout import ValidationField, held_out_rng
from .objectives import FLIP_WEIGHT, density_objective
from .teacher import teacher_map, teacher_targets

__all__ = ["DensityTask", "DENSITY_KINDS", "density_validation_field"]

#: The families of held-out densities, taken in turn.
DENSITY_KINDS = ("smooth", "steps", "peak", "ramp")


@register_task
class DensityTask(Task):
    """Density-equalizing maps (DEM; DEQ with a Beltrami-energy weight): vertex densities in, a map whose mapped
    element densities are equal out."""

    kind = "density"
    title = "density"
    dims = (2, 3)
    score_metric = "std_rho_map"
    metric_names = ("std_rho_map", "n_flipped", "min_jacobian")
    loss_terms = ("density", "mu2", "area")
    teacher = True
    equalizes = True
    methods = ("diffusion", "dem", "flow")
    reference_title = "diffusion DEM"

    def n_params(self, dim: int) -> int:
        return 1

    def channels(self, params: Tensor) -> Tensor:
        return torch.log(params).unsqueeze(-1)

    def check_field(self, grid: np.ndarray, preprocess: bool = True) -> np.ndarray:
        if np.iscomplexobj(grid):
            raise ValueError("a density model needs a real density field, got complex values")
        return preprocess_density(grid) if preprocess else unit_mass(check_density(grid))

    def resampled(self, grid: np.ndarray) -> np.ndarray:
        """A checked density after interpolation to another grid, scaled to unit mass again."""
        return unit_mass(check_density(grid))

    def field_on_mesh(self, grid: np.ndarray, fn, ref: np.ndarray, elements: np.ndarray,
                      grid_n: int | None) -> np.ndarray:
        """Unit-mass vertex densities (P,) on the output mesh: from the exact evaluator ``fn`` when there is one,
        else interpolated from the input ``grid`` (``grid_n``: the output mesh is the ``N``-grid)."""
        w = grid_vertex_weights(grid_n, ref.shape[1]) if grid_n else vertex_weights(ref, elements)
        if fn is not None:
            return preprocess_density(np.asarray(fn(ref), dtype=np.float64), weights=w)
        src = torch.as_tensor(grid)[None, None]
        return unit_mass(interpolate(src, torch.as_tensor(ref))[0, :, 0].numpy(), w)

    def hard_field(self, rng, n: int, dim: int):
        """A hard positive density (:func:`rfmap.fields.hard.hard_density`), mapped with ``preprocess=False`` so
        that its near-zero regions survive."""
        return hard_density(rng, n, dim), {"preprocess": False}

    # ------------------------------------------------------------------ training
    def draw(self, rng, spec: TaskSpec, n: int, options: SampleOptions, teach: bool):
        """A random density (``options.density``) at jittered vertices; with ``teach`` the teacher's map."""
        dim = spec.dim
        fld = RandomDensity(rng, options.density_cfg or RandomDensityConfig.for_dim(dim))
        grid_vals = fld.on_grid(n)
        if options.jitter > 0:
            pts = jittered_points(n, dim, rng, grad_magnitude=grad_magnitude(grid_vals, n, dim),
                                  strength=options.jitter)
            w = vertex_weights(pts, grid_elements(n, dim).numpy())
            p = preprocess_density(fld(pts), weights=w)
        else:
            pts = grid_points(n, dim)
            p = preprocess_density(grid_vals.reshape((n,) * dim)).reshape(-1)
        target = None
        if options.teaching:
            mapped = teacher_map(grid_vals.reshape((n,) * dim), spec.boundary, options.teacher.method) \
                if teach else None
            target = np.full_like(pts, np.nan) if mapped is None else teacher_targets(pts, n, mapped)
        return pts, p, target

    def batch(self, spec: TaskSpec, inputs: Tensor, ref: Tensor, params: Tensor, n: int, targets) -> Batch:
        return Batch(inputs, ref, grid_elements(n, spec.dim), n, density=params,
                     extra=teacher_extra(ref.numpy(), targets))

    def loss(self, mb: MappedBatch, weights: LossWeights):
        b, mapped, pre = mb.batch, mb.mapped, mb.measures
        if b.on_grid:
            pre = replace(pre, density=grid_element_mean(b.density, b.n, b.ref.shape[-1]))
        parts = {"density": L.density_loss(b.ref, mapped, b.elements, b.density, pre=pre,
                                           tangent=weights.density_tangent)}
        total = parts["density"]
        if weights.beltrami and mb.spec.dim == 2:
            parts["mu2"] = L.beltrami_energy(b.ref, mapped, b.elements)
            total = total + weights.beltrami * parts["mu2"]
        if mb.spec.boundary == "free" and weights.area:
            parts["area"] = L.area_penalty(b.ref, mapped, b.elements, pre=mb.measures)
            total = total + weights.area * parts["area"]
        return total, parts

    # ------------------------------------------------------------------ maps
    def refine_objective(self, ref, psi, elements, field, boundary, grid_n):
        return density_objective(ref, psi, elements, field, boundary, FLIP_WEIGHT, grid_n=grid_n)

    def metric_inputs(self, field: np.ndarray) -> dict:
        return {"density": field, "mu": None}

    def solver_input(self, grid: np.ndarray) -> np.ndarray:
        """A real density, preprocessed as ``rfmap map`` does (minimum shifted to 0.1, unit mass)."""
        if np.iscomplexobj(grid):
            raise ValueError("a density solver needs a real density, got complex values")
        return preprocess_density(grid)

    def solver_sample(self, field, n: int) -> np.ndarray:
        return field.sample(n)

    def solve(self, values: np.ndarray, n: int, method: str, boundary: str | None, progress: bool = False):
        return solvers.solve_dem(values, method=method, boundary=boundary or "square", progress=progress)

    def reference_of(self, field, n: int, dim: int, boundary: str):
        """The diffusion DEM of the preprocessed density on a square or, for a free model, a free boundary."""
        dens = preprocess_density(field(grid_points(n, dim)).reshape((n,) * dim))
        return solvers.solve_dem(dens, boundary="free" if boundary == "free" else "square")

    def training_fields_text(self, config: dict) -> str:
        """The paper's smooth modes (in every field), then the share of fields that add each other feature: box
        steps, patches, vertex noise and, where drawn, narrow peaks, steep ramps and single hard ramps or peaks."""
        dens = config.get("density_field") or {}
        default = RandomDensityConfig()
        extra = [f"box steps {100 * dens.get('p_step', default.p_step):.0f} %",
                 f"patches {100 * dens.get('p_patch', default.p_patch):.0f} %"]
        if dens.get("p_noise", default.p_noise):
            extra.append(f"noise {100 * dens.get('p_noise', default.p_noise):.0f} %")
        if dens.get("p_peak"):
            extra.append(f"peaks {100 * dens['p_peak']:.0f} %")
        if dens.get("p_ramp"):
            scale = dens.get("ramp_scale", 1.0)
            extra.append(f"ramps {100 * dens['p_ramp']:.0f} %" + (f" (height ×{scale:g})" if scale != 1.0 else ""))
        if dens.get("p_hard"):
            extra.append(f"single hard ramps or peaks {100 * dens['p_hard']:.0f} %")
        return "modes (every field)" + "".join(f", {e}" for e in extra)

    def test_fields(self, dim: int) -> tuple[str, ...]:
        """The paper's test densities in ``dim`` dimensions (reported after training, never used to select a model)."""
        return TEST_FIELDS[self.kind, dim]

    def test_record(self, result, name: str) -> dict:
        m = result.metrics()
        return {"std_rho_map": m.std_rho_map, "n_flipped": m.n_flipped, "min_jacobian": m.min_jacobian}

    # ------------------------------------------------------------------ validation
    def validation_fields(self, dim: int, count: int, stream: str, low_frequency: bool = False) -> list:
        if low_frequency:
            raise ValueError("low_frequency applies to Beltrami validation maps only")
        return [density_validation_field(j, DENSITY_KINDS[j % len(DENSITY_KINDS)], dim, stream)
                for j in range(count)]

    def validation_record(self, result, vf: ValidationField):
        m = result.metrics()
        rec = {"std_rho_map": m.std_rho_map, "n_flipped": m.n_flipped, "min_jacobian": m.min_jacobian}
        return rec, m.std_rho_map, m.std_rho_orig


def density_validation_field(j: int, kind: str, dim: int, stream: str = "validation") -> ValidationField:
    """Held-out density ``j`` of family ``kind`` (:data:`DENSITY_KINDS`): ``smooth`` (a random training-style
    density without sharp parts), ``steps`` (box steps and high-frequency patches), ``peak`` (a narrow Gaussian peak
    of height 1-8 over a gently tilted background) or ``ramp`` (a steep tanh ramp of height 1-4 across a random
    direction)."""
    rng = held_out_rng(j, stream)
    base = RandomDensityConfig.for_dim(dim)
    if kind == "smooth":
        f = RandomDensity(rng, replace(base, p_step=0.0, p_patch=0.0, p_noise=0.0))
    elif kind == "steps":
        f = RandomDensity(rng, replace(base, p_step=1.0, p_patch=1.0, p_noise=0.0))
    elif kind == "peak":
        c = rng.uniform(0.2, 0.8, dim)
        width = rng.uniform(0.03, 0.08)
        height = float(np.exp(rng.uniform(np.log(1.0), np.log(8.0))))
        tilt = rng.uniform(-0.3, 0.3, dim)

        def f(x, c=c, w=width, h=height, tilt=tilt):
            x = np.asarray(x, dtype=np.float64)
            return 1.0 + (x - 0.5) @ tilt + h * np.exp(-((x - c) ** 2).sum(-1) / (2 * w**2))
    elif kind == "ramp":
        normal = rng.normal(size=dim)
        normal /= np.linalg.norm(normal)
        offset = float(normal @ rng.uniform(0.3, 0.7, dim))
        width = rng.uniform(0.01, 0.05)
        contrast = rng.uniform(2.0, 5.0)

        def f(x, nrm=normal, o=offset, w=width, k=contrast):
            x = np.asarray(x, dtype=np.float64)
            return 1.0 + 0.5 * (k - 1.0) * (1.0 + np.tanh((x @ nrm - o) / w))
    else:
        raise ValueError(f"unknown validation kind {kind!r}; expected one of {DENSITY_KINDS}")
    return ValidationField(f"{kind}-{j}", f)
