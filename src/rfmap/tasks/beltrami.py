r"""The Beltrami task: the quasi-conformal map of the unit square with a prescribed Beltrami coefficient (paper
Sec. 5.1).

* encoding (:math:`c = 2` parameter channels): the channels are :math:`\mathrm{Re}\,\mu` and :math:`\mathrm{Im}\,\mu` at the vertices;
* training fields: the exact coefficient of a random boundary-fixing map (:class:`rfmap.fields.random.RandomMap`),
  or a random coefficient (:class:`rfmap.fields.random.RandomBeltrami`), at Sobol-jittered vertices;
* loss: :math:`\int_\Omega |\mu(u) - \mu_{\text{in}}|^2` (:func:`rfmap.tasks.losses.beltrami_loss`), and the fold
  penalty that :func:`rfmap.tasks.base.task_loss` adds to every task (this package's addition, not in the paper);
* refinement objective: :math:`\mathrm{mean}|\mu(u_\alpha) - \mu_{\text{in}}| + \lambda\,\#\text{flipped}/m`
  (:func:`rfmap.tasks.objectives.beltrami_objective`);
* validation: the mean vertex distance to the exact map of held-out random maps, at sup-norm levels of
  :math:`|\mu|` spread over [0.1, 0.85] (a low-frequency set of 1-4 slow modes serves reports only);
* reference solver: the Linear Beltrami Solver (:func:`rfmap.solvers.solve_lbs`).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from .. import solvers
from ..core.inputs import check_mu
from ..core.mesh import element_centroids, grid_mesh, grid_points, interpolate, jittered_points, square_triangles
from ..fields.hard import hard_beltrami
from ..fields.paper import BELTRAMI_MAPS, TEST_FIELDS, sample_mu
from ..fields.random import RandomBeltrami, RandomBeltramiConfig, RandomMap
from . import losses as L
from .base import Batch, LossWeights, MappedBatch, SampleOptions, Task, TaskSpec, grad_magnitude, grid_elements, \
    register_task
from .heldout import ValidationField, held_out_rng
from .objectives import FLIP_WEIGHT, beltrami_objective

__all__ = ["BeltramiTask", "beltrami_validation_field"]

#: Side of the grid on which the jitter's density of a random map is probed.
PROBE_N = 33


@register_task
class BeltramiTask(Task):
    """Reconstruction of a map from its Beltrami coefficient :math:`\\mu` (2D, identity on the boundary)."""

    kind = "beltrami"
    title = "Beltrami"
    dims = (2,)
    score_metric = "mean_dd"
    metric_names = ("mean_dd", "n_flipped", "min_jacobian")
    loss_terms = ("beltrami",)
    methods = ("lbs",)
    reference_title = "LBS"
    complex_field = True

    def n_params(self, dim: int) -> int:
        return 2

    def channels(self, params: Tensor) -> Tensor:
        return torch.stack([params.real, params.imag], -1)

    def check_field(self, grid: np.ndarray, preprocess: bool = True) -> np.ndarray:
        if not np.iscomplexobj(grid):
            grid = grid.astype(np.complex128)
        return check_mu(grid, name="Beltrami coefficient")

    def sample_named(self, field):
        """The coefficient function ``field.mu`` of a named test map (:class:`rfmap.fields.paper.BeltramiMap`)."""
        return field.mu

    def field_on_mesh(self, grid: np.ndarray, fn, ref: np.ndarray, elements: np.ndarray,
                      grid_n: int | None) -> np.ndarray:
        """:math:`\\mu` per element (m,) at the centroids: from the exact evaluator ``fn`` when there is one, else
        interpolated from the input ``grid``."""
        cen = element_centroids(ref, elements)
        if fn is not None:
            return np.asarray(fn(cen))
        v = interpolate(torch.as_tensor(np.stack([grid.real, grid.imag]))[None], torch.as_tensor(cen))[0].numpy()
        return v[:, 0] + 1j * v[:, 1]

    def hard_field(self, rng, n: int, dim: int):
        """A hard coefficient at the vertices (:func:`rfmap.fields.hard.hard_beltrami`)."""
        return hard_beltrami(rng, n), {}

    # ------------------------------------------------------------------ training
    def draw(self, rng, spec: TaskSpec, n: int, options: SampleOptions, teach: bool):
        """The coefficient of a random map (``options.beltrami_source == 'map'``) or a random coefficient."""
        cfg = options.beltrami_cfg or RandomBeltramiConfig()
        from_map = options.beltrami_source == "map"
        gen = RandomMap(rng, cfg) if from_map else RandomBeltrami(rng, cfg)
        if options.jitter > 0:
            probe = grid_mesh(PROBE_N, 2).points
            g = grad_magnitude(np.abs(gen.mu_grid(PROBE_N) if from_map else gen(probe)), PROBE_N, 2)
            g_n = interpolate(g.reshape(1, 1, PROBE_N, PROBE_N), grid_points(n, 2))[0, :, 0]
            pts = jittered_points(n, 2, rng, grad_magnitude=g_n, strength=options.jitter)
            mu = gen.mu(pts) if from_map else gen(pts)
        else:
            pts = grid_points(n, 2)
            mu = gen.mu_grid(n) if from_map else gen(pts)
        return pts, mu, None

    def batch(self, spec: TaskSpec, inputs: Tensor, ref: Tensor, params: Tensor, n: int, targets) -> Batch:
        elements = grid_elements(n, spec.dim)
        return Batch(inputs, ref, elements, n, mu_target=params[:, elements].mean(-1))

    def loss(self, mb: MappedBatch, weights: LossWeights):
        b = mb.batch
        parts = {"beltrami": L.beltrami_loss(b.ref, mb.mapped, b.elements, b.mu_target)}
        return parts["beltrami"], parts

    # ------------------------------------------------------------------ maps
    def refine_objective(self, ref, psi, elements, field, boundary, grid_n):
        return beltrami_objective(ref, psi, elements, field, boundary, FLIP_WEIGHT)

    def metric_inputs(self, field: np.ndarray) -> dict:
        return {"density": None, "mu": field}

    def solver_input(self, grid: np.ndarray) -> np.ndarray:
        r""":math:`\mu` per triangle from a 2D coefficient on the grid's vertices: the mean of the three vertex
        values on every triangle (the P1 interpolant's mean, so :math:`|\mu| < 1` stays)."""
        if grid.ndim != 2:
            raise ValueError(f"method lbs needs a 2D Beltrami coefficient, shape (N, N); got shape {grid.shape}")
        return check_mu(grid, name="the Beltrami coefficient").reshape(-1)[square_triangles(grid.shape[0])].mean(1)

    def solver_sample(self, field, n: int) -> np.ndarray:
        return sample_mu(field.name, n)

    def solve(self, values: np.ndarray, n: int, method: str, boundary: str | None, progress: bool = False):
        return solvers.solve_lbs(values, n, boundary="fixed" if boundary in (None, "fixed") else boundary)

    def reference_of(self, field, n: int, dim: int, boundary: str):
        """The Linear Beltrami Solver's map of the coefficient ``field`` (identity on the boundary)."""
        return solvers.solve_lbs(field, n)

    def training_fields_text(self, config: dict) -> str:
        """The coefficients of random boundary-fixing maps, with the share of low-frequency maps (a few slow modes)
        where drawn."""
        low = (config.get("beltrami_field") or {}).get("low", 0.0)
        return "coefficients of random maps that fix the boundary" + (
            f"; {100 * low:.0f} % of them low-frequency (a few slow modes)" if low else "")

    def test_fields(self, dim: int) -> tuple[str, ...]:
        """The paper's test maps T1-T4 in 2D (reported after training, never used to select a model)."""
        return TEST_FIELDS[self.kind, dim]

    def test_record(self, result, name: str) -> dict:
        m = result.metrics(exact_points=BELTRAMI_MAPS[name](result.ref_points), mu_ref=result.field)
        return {"mean_dd": m.mean_dd, "mean_dmu": m.mean_dmu, "n_flipped": m.n_flipped,
                "min_jacobian": m.min_jacobian}

    # ------------------------------------------------------------------ validation
    def validation_fields(self, dim: int, count: int, stream: str, low_frequency: bool = False) -> list:
        return [beltrami_validation_field(j, count, stream, low_frequency) for j in range(count)]

    def validation_record(self, result, vf: ValidationField):
        exact = vf.exact(result.ref_points)
        m = result.metrics(exact_points=exact)
        rec = {"mean_dd": m.mean_dd, "n_flipped": m.n_flipped, "min_jacobian": m.min_jacobian}
        return rec, m.mean_dd, float(np.linalg.norm(result.ref_points - exact, axis=1).mean())


def beltrami_validation_field(j: int, count: int, stream: str = "validation", low: bool = False) -> ValidationField:
    """Held-out map ``j`` of ``count``: a random boundary-fixing map whose :math:`\\|\\mu\\|_\\infty` is
    ``0.1 + 0.75 j / (count - 1)``, with its exact image; ``low``: 1-4 slow modes (labels ``low-map-j``)."""
    rng = held_out_rng(j, stream)
    level = 0.1 + 0.75 * j / max(1, count - 1)
    m = RandomMap(rng, RandomBeltramiConfig(sup=(level, level), low=1.0 if low else 0.0))
    return ValidationField(f"{'low-' if low else ''}map-{j}", m.mu, exact=m)
