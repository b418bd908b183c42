r"""Trained surrogates: weights on disk, and inference at any resolution or at arbitrary query points.

Weights are stored as ``NAME.safetensors`` (tensors only; loading never unpickles) next to ``NAME.json`` with the
metadata: model constructor arguments, task, boundary, preset, the full training configuration, rfmap version,
steps, wall time and final validation metrics.

Inference (paper Secs. 4.1–4.3): the input field is sampled on a working grid whose side lies in the range the
model was trained on, encoded as :math:`[x, p(x)]`, and mapped to a displacement :math:`\psi` on that grid;
:math:`\psi` is interpolated (bi/trilinearly) to the requested points :math:`x_q`, which may form any grid or an
unstructured cloud, and :math:`u(x_q) = x_q + \mathcal{B}(x_q) \odot (\alpha \odot \psi(x_q))`.
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from ._version import __version__
from .inputs import check_density, check_mu, preprocess_density, unit_mass
from .metrics import density_std
from .mesh import check_n, element_centroids, element_measures, grid_mesh, grid_points, grid_vertex_weights, interpolate, \
    triangulate, vertex_weights
from .device import resolve_device
from .geometry import grid_element_mean, grid_signed_measures
from .hybrid import GUARD
from .nn.model import MultiResUNet, apply_displacement
from .nn.registry import build_model, from_tensor_state, tensor_state
from .paper_fields import PAPER_N, BeltramiMap, DensityField, get_field
from .refine import REFINE, RefineResult, beltrami_objective, density_objective, refine_alpha
from .repair import fold_free, repair_map
from .shorten import shorten_map
from .result import MapResult
from .solvers.flow import F32_MARGIN
from .symmetry import resolve_symmetry, symmetrized_displacement
from .tasks import TaskSpec, encode

__all__ = ["Surrogate", "models", "PoorMapWarning", "QUALITY_MARGIN", "quiet_quality", "density_quality",
           "quality_message", "WEIGHTS_DIR", "REGRID_DIMS", "REGRID_STEP"]

#: Dimensions in which a folded network map of a grid (with ``repair``, the default working grid and no query points)
#: is first evaluated again on coarser working grids, :data:`REGRID_STEP` sides apart down to the bottom of the
#: training range, taking the first map that is fold-free and more equal than the input (``info["regrid"]``); only
#: when none is does the repair run on the default grid's map.  The repair guarantees a fold-free map, not a good one:
#: it shortens the displacement around the folds until every element keeps a twentieth of its measure, and those
#: elements then carry twenty times the mean density.  On the 16 held-out validation densities of the 3D models at
#: N = 48 (``rfmap.validation``; never the test fields) all four steep ramps folded on the default 48-grid, and their
#: repaired maps were less equal than no map at all (mean Std(rho~_map) 1.65 for dem3d-cube and 2.86 for dem3d-free,
#: against 1.0 to 1.3 for the input), while the same networks mapped every ramp without a fold on a 32- to 44-grid
#: (0.53 to 0.98 and 0.32 to 0.51); the twelve fields that did not fold keep the default grid.  Over all 16 fields,
#: mean Std(rho~_map) at N = 48 went from 0.472 to 0.238 (cube) and from 0.748 to 0.137 (free), at N = 64 from 0.446
#: to 0.249 and from 0.355 to 0.137, and the mean time per map fell by two thirds (no repair).  In 2D the repair
#: rebuilds the map from its truncated Beltrami coefficient and does better: on 10 folded maps of hard densities
#: (``rfmap.stress``) of deq2d-square and deq2d-free at N = 51 to 128, coarser grids helped once (0.242 -> 0.240),
#: did much worse once (0.33 -> 1.42) and cost up to 0.7 s more, so 2D maps go straight to the repair.  An explicit
#: ``work_n`` is used as given, and with ``polish`` a folded map starts the flow cold at once, as before (a warm start
#: saves the 3D flow nothing: from the identity it needs only 7 or 8 steps at N = 48).
REGRID_DIMS = (3,)
REGRID_STEP = 4

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"


def models() -> list[str]:
    """Names of the pretrained models shipped with the package."""
    return sorted(p.stem for p in WEIGHTS_DIR.glob("*.json") if p.with_suffix(".safetensors").exists())


@dataclass
class _Input:
    grid: np.ndarray  # (N_in,)*d real density or complex mu at the vertices of the input grid
    fn: Callable | None  # exact evaluator when available (names, callables)
    preprocess: bool = True


#: :func:`density_quality` calls a map worse than the input when its Std(rho~_map) exceeds Std(rho~_orig) by more
#: than this fraction (far above the single-precision measures' error, so that the identity never counts as worse)
QUALITY_MARGIN = 1e-4


class PoorMapWarning(RuntimeWarning):
    """A density map that left the density less equal than it was (:func:`density_quality`); issued by
    :meth:`Surrogate.map` with the measured numbers and the remedies."""


@contextlib.contextmanager
def quiet_quality():
    """Silence :class:`PoorMapWarning` inside the block: for code that maps many fields and reports their metrics
    itself (tables, validation)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PoorMapWarning)
        yield


def density_quality(mapped: np.ndarray, density: np.ndarray, n: int) -> dict[str, Any]:
    r"""Whether a density map of the ``N``-grid left the density more equal than it was.

    :math:`\mathrm{Std}(\tilde\rho)` of the element densities (population over measure, normalised to mean 1; as
    :func:`rfmap.metrics.compute_metrics`) on the reference and on the mapped grid, and the smallest Jacobian
    determinant (mapped over reference measure).

    Parameters
    ----------
    mapped : ndarray, shape (N**d, d)
        The images of the grid's vertices (:func:`rfmap.mesh.grid_points` order); every reference element has
        the same measure, so the reference vertices themselves are not needed.
    density : ndarray, shape (N**d,)
        Vertex densities.
    n : int
        Grid side.

    Returns
    -------
    dict
        ``std_rho_orig``, ``std_rho_map``, ``min_jacobian`` and ``worse``: whether Std(rho~_map) exceeds
        Std(rho~_orig) by more than the fraction :data:`QUALITY_MARGIN` and 1e-5 (or the map is not finite), i.e.
        the map undid more than it did.
    """
    d = mapped.shape[1]
    if not np.isfinite(mapped).all():
        return {"std_rho_orig": float("nan"), "std_rho_map": float("nan"), "min_jacobian": float("nan"),
                "worse": True}
    # every element of the N-grid has the same reference measure; the mapped measures in single precision (a quarter
    # of the time at 3D N = 48) unless an element is too thin for it (as rfmap.solvers.flow.F32_MARGIN)
    ref_measure = 1.0 / ((n - 1) ** d * math.factorial(d))
    meas = grid_signed_measures(torch.from_numpy(np.ascontiguousarray(mapped, dtype=np.float32))[None], n)[0].double()
    if float(meas.min()) <= F32_MARGIN * ref_measure:
        meas = grid_signed_measures(torch.from_numpy(np.ascontiguousarray(mapped, dtype=np.float64))[None], n)[0]
    mean = grid_element_mean(torch.as_tensor(np.asarray(density, dtype=np.float64)).reshape(1, -1), n, d)[0]
    orig = float((mean / mean.mean()).std())  # density_std with equal measures
    new = density_std(mean * ref_measure, meas)
    return {"std_rho_orig": orig, "std_rho_map": new, "min_jacobian": float(meas.min()) / ref_measure,
            "worse": bool(not new <= orig * (1.0 + QUALITY_MARGIN) + 1e-5)}  # float32 round-off: ~1e-6


def quality_message(quality: dict[str, Any], refine: str = "refine=True", polish: str = "polish=True",
                    shorten: dict[str, Any] | None = None, *, grid_only: bool = False) -> str:
    """One line for a density map that left the density less equal than it was (:func:`density_quality`);
    ``refine`` and ``polish`` name the two remedies (the API's keywords by default, the CLI's flags there), and
    ``grid_only`` says that the second one maps a grid only (a map at query points).  With ``shorten`` (the report
    of :func:`rfmap.repair.shorten_map`) the line says that the map was shortened and what it reaches now."""
    finish = "the flow-based finish, on a grid only" if grid_only else "the flow-based finish"
    if shorten is not None:
        before = shorten["std_before"]
        return (f"the network's map left this density less equal than it was (Std(rho~_map) "
                f"{'folded' if not math.isfinite(before) else format(before, '.3g')} >= Std(rho~_orig) "
                f"{quality['std_rho_orig']:.3g}); its displacement was shortened to {shorten['scale']:.3g} of "
                f"itself (Std(rho~_map) {quality['std_rho_map']:.3g}, smallest Jacobian "
                f"{quality['min_jacobian']:.3g}): the field is probably unlike the training fields; {refine} (weight "
                f"refinement) or {polish} ({finish}) can help")
    return (f"the network's map leaves this density less equal than it was (Std(rho~_map) "
            f"{quality['std_rho_map']:.3g} > Std(rho~_orig) {quality['std_rho_orig']:.3g}, smallest Jacobian "
            f"{quality['min_jacobian']:.3g}): the field is probably unlike the training fields; {refine} (weight "
            f"refinement) or {polish} ({finish}) can help")


def _embedded_meta(path: Path) -> dict | None:
    """The metadata stored in a weight file's header by ``Surrogate.save(..., embed=True)``, else ``None``."""
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="pt") as f:
            text = (f.metadata() or {}).get("meta")
    except (SafetensorError, OSError, ValueError) as e:
        raise ValueError(f"corrupt or truncated weight file {path}: {e}") from e
    if text is None:
        return None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"corrupt metadata in the header of {path}: {e}") from e

class Surrogate:
    """A trained (or untrained) neural surrogate for one task.

    Parameters
    ----------
    model : MultiResUNet or FNONet
    spec : TaskSpec
    meta : dict, optional
        Metadata (see module docstring); ``n_range`` gives the training resolutions.
    """

    def __init__(self, model: torch.nn.Module, spec: TaskSpec, meta: dict | None = None, *, device=None):
        if model.dim != spec.dim or model.n_params != spec.n_params:
            raise ValueError(f"model (dim={model.dim}, {model.n_params} parameter channels) does not fit task "
                             f"{spec}")
        self.device = resolve_device(device or "cpu")
        self.model = model.to(self.device).eval()
        self.spec = spec
        self.meta = dict(meta or {})
        self._tracing = False
        self._traces: dict[tuple, Any] = {}

    def to(self, device) -> "Surrogate":
        """Move the network to ``device`` (``'cpu'``, ``'cuda'``, ``'auto'``); returns ``self``.  Inputs and
        outputs of :meth:`map` stay numpy arrays on the host."""
        self.device = resolve_device(device)
        self.model.to(self.device)
        self._traces.clear()
        return self

    def trace(self, enable: bool = True) -> "Surrogate":
        """Evaluate the network through TorchScript traces (``torch.jit.trace``), one per input shape; returns
        ``self``.

        A trace runs the same operations on the same parameters (shared, not copied: the outputs are equal bit for
        bit) without the Python overhead of the module calls, about 1.8 ms per evaluation of the shipped U-Nets on
        a 2-core CPU (2D N = 51: 7.0 -> 5.2 ms; 3D N = 48: 67 -> 62 ms).  Tracing a new shape costs about 0.2 s
        once (traces are kept, also while tracing is off, until :meth:`to` moves the network), so it pays for many
        maps of one size (a batch of fields, an animation, a benchmark), not for one.
        A network that cannot be traced (e.g. the FNO, whose padding looks shapes up in a dict) runs eagerly.
        """
        self._tracing = bool(enable)
        return self

    def _forward(self, x: torch.Tensor) -> torch.Tensor:
        """The network on one input batch: eager, or through the trace of its shape (:meth:`trace`)."""
        if not self._tracing:
            return self.model(x)
        key = (tuple(x.shape), x.dtype, str(x.device))
        fn = self._traces.get(key)
        if fn is None:
            try:
                with warnings.catch_warnings():  # the shape-dependent branches are what the trace freezes
                    warnings.simplefilter("ignore")
                    fn = torch.jit.trace(self.model, x, check_trace=False)
            except Exception:  # noqa: BLE001 - any network that does not trace runs eagerly
                fn = self.model
            self._traces[key] = fn
        return fn(x)

    # ------------------------------------------------------------------ io
    @classmethod
    def untrained(cls, spec: TaskSpec, *, base: int = 16, depth: int = 3, seed: int = 0, **meta) -> "Surrogate":
        torch.manual_seed(seed)
        return cls(MultiResUNet(spec.dim, spec.n_params, base, depth), spec, meta)

    @property
    def name(self) -> str:
        return self.meta.get("name", "unnamed")

    @property
    def n_range(self) -> tuple[int, int]:
        r = self.meta.get("n_range")
        return (int(r[0]), int(r[1])) if r else (self.model.min_size, 1 << 30)

    def save(self, path, *, embed: bool = False) -> tuple[Path, Path | None]:
        """Write ``path`` (``.safetensors``) and the metadata JSON beside it; with ``embed`` the metadata goes into
        the weight file's header instead (one self-contained file, e.g. a training snapshot; :meth:`load` reads
        either) and the second path is ``None``."""
        from safetensors.torch import save_file

        path = Path(path).with_suffix(".safetensors")
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {**self.meta, "model": self.model.kwargs(), "task": {"kind": self.spec.kind, "dim": self.spec.dim,
                                                                    "boundary": self.spec.boundary},
                "rfmap_version": self.meta.get("rfmap_version", __version__)}
        state = tensor_state(self.model)
        tmp = path.with_suffix(".safetensors.part")
        header = {"format": "rfmap", "name": str(meta.get("name", ""))}
        if embed:
            header["meta"] = json.dumps(meta, sort_keys=True)
        save_file(state, str(tmp), metadata=header)
        os.replace(tmp, path)
        os.chmod(path, 0o644)
        if embed:
            return path, None
        jpath = path.with_suffix(".json")
        jpath.write_text(json.dumps(meta, indent=2, sort_keys=True))
        return path, jpath

    @classmethod
    def load(cls, path, *, device=None) -> "Surrogate":
        """Load weights ``path`` (``.safetensors``, metadata ``.json`` beside it) onto ``device`` (default the CPU).
        Clear errors on bad files."""
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        path = Path(path)
        if path.suffix != ".safetensors":
            path = path.with_suffix(".safetensors")
        jpath = path.with_suffix(".json")
        if not path.exists():
            raise FileNotFoundError(f"no weight file {path}")
        meta = _embedded_meta(path) if not jpath.exists() else None
        if meta is None:
            if not jpath.exists():
                raise FileNotFoundError(f"no metadata {jpath} next to the weights")
            try:
                meta = json.loads(jpath.read_text())
            except json.JSONDecodeError as e:
                raise ValueError(f"corrupt metadata {jpath}: {e}") from e
        try:
            spec = TaskSpec(**meta["task"])
            kw = meta["model"]
            model = build_model(kw)
        except (KeyError, TypeError) as e:
            raise ValueError(f"metadata {jpath} lacks the model/task description: {e}") from e
        try:
            state = load_file(str(path))
        except (SafetensorError, OSError, ValueError) as e:
            raise ValueError(f"corrupt or truncated weight file {path}: {e}") from e
        own = {k: v for k, v in model.state_dict().items() if isinstance(v, torch.Tensor)}
        state = from_tensor_state(model, state)
        missing, extra = set(own) - set(state), set(state) - set(own)
        if missing or extra:
            raise ValueError(f"weights {path} do not match the model in {jpath.name}: missing "
                             f"{sorted(missing)[:3]}, unexpected {sorted(extra)[:3]}")
        bad = [k for k in own if own[k].shape != state[k].shape]
        if bad:
            raise ValueError(f"weights {path} do not match the model: shape mismatch for {bad[:3]}")
        model.load_state_dict(state)
        return cls(model, spec, meta, device=device)

    @classmethod
    def pretrained(cls, name: str, *, device=None) -> "Surrogate":
        """Load a model shipped with the package (see :func:`models`) onto ``device`` (default the CPU)."""
        if name not in models():
            raise ValueError(f"no pretrained model {name!r}; available: {', '.join(models()) or 'none'}")
        return cls.load(WEIGHTS_DIR / f"{name}.safetensors", device=device)

    def __repr__(self) -> str:
        return f"Surrogate({self.name!r}, {self.spec}, n_range={self.n_range})"

    # ------------------------------------------------------------------ inputs
    def _resolve(self, field, n: int | None, preprocess: bool) -> tuple[_Input, int]:
        d, kind = self.spec.dim, self.spec.kind
        if isinstance(field, str):
            field = get_field(field)
        if isinstance(field, (DensityField, BeltramiMap)):
            if field.kind != kind:
                raise ValueError(f"field {field.name!r} is a {field.kind} field but model {self.name!r} maps "
                                 f"{kind} fields")
            if field.dim != d:
                raise ValueError(f"field {field.name!r} is {field.dim}D but the model is {d}D")
        if isinstance(field, tuple) and len(field) == 2:
            pts, vals = (np.asarray(a) for a in field)
            if pts.ndim != 2 or pts.shape[1] != d or vals.shape[0] != pts.shape[0]:
                raise ValueError(f"scattered samples must be (points (P, {d}), values (P,)); got {pts.shape}, "
                                 f"{vals.shape}")
            n = check_n(n or PAPER_N[d])
            from scipy.interpolate import griddata

            g = grid_points(n, d)
            lin = griddata(pts, vals, g, method="linear")
            near = griddata(pts, vals, g, method="nearest")
            lin = np.where(np.isnan(lin), near, lin)
            return self._finish(lin.reshape((n,) * d), None, preprocess), n
        if callable(field):
            fn = field.mu if isinstance(field, BeltramiMap) else field
            n = check_n(n or PAPER_N[d])
            vals = np.asarray(fn(grid_points(n, d)))
            return self._finish(vals.reshape((n,) * d), fn, preprocess), n
        arr = np.asarray(field)
        if arr.ndim != d or len(set(arr.shape)) != 1:
            raise ValueError(f"a {d}D model needs a field sampled on an N^{d} grid, got an array of shape "
                             f"{arr.shape}")
        check_n(arr.shape[0])
        return self._finish(arr, None, preprocess), int(n or arr.shape[0])

    def _finish(self, grid: np.ndarray, fn, preprocess: bool) -> _Input:
        if self.spec.kind == "density":
            if np.iscomplexobj(grid):
                raise ValueError("a density model needs a real density field, got complex values")
            grid = self._unit_mass(grid, preprocess)
        else:
            if not np.iscomplexobj(grid) and self.spec.kind == "beltrami":
                grid = grid.astype(np.complex128)
            grid = check_mu(grid, name="Beltrami coefficient")
        return _Input(grid, fn, preprocess)

    @staticmethod
    def _unit_mass(grid, preprocess):
        return preprocess_density(grid) if preprocess else unit_mass(check_density(grid))

    def _work_grid(self, inp: _Input, n_work: int) -> np.ndarray:
        g = inp.grid
        if g.shape[0] == n_work:
            return g
        d = self.spec.dim
        if inp.fn is not None:  # sample the field itself on the working grid rather than resampling samples
            vals = np.asarray(inp.fn(grid_points(n_work, d))).reshape((n_work,) * d)
            return self._finish(vals, inp.fn, inp.preprocess).grid
        src = torch.as_tensor(np.stack([g.real, g.imag]) if np.iscomplexobj(g) else g[None])[None]
        out = interpolate(src.double(), torch.as_tensor(grid_points(n_work, d)))[0].numpy()
        if np.iscomplexobj(g):
            return (out[:, 0] + 1j * out[:, 1]).reshape((n_work,) * d)
        return self._unit_mass(out[:, 0].reshape((n_work,) * d), False)

    # ------------------------------------------------------------------ inference
    def _symmetry(self, symmetrize) -> str | None:
        """The symmetry group of a ``symmetrize`` argument (:mod:`rfmap.symmetry`)."""
        return resolve_symmetry(symmetrize, self.spec.dim)

    def work_n(self, n: int) -> int:
        """The working grid side used for an output of side ``n``: ``n`` clipped to the training range."""
        lo, hi = self.n_range
        return int(min(max(n, lo), hi))

    @torch.no_grad()
    def displacement(self, grids: np.ndarray, symmetrize: bool | str = False) -> torch.Tensor:
        r"""Network output :math:`\psi` for a batch of preprocessed fields on one regular grid.

        Parameters
        ----------
        grids : array, shape (B, N, ..., N), real density (unit mass) or complex Beltrami coefficient
        symmetrize : bool or str
            The mean of the network's output over symmetries of the square or cube
            (:func:`rfmap.symmetry.symmetrized_displacement`; ``True`` the dimension's
            :data:`rfmap.symmetry.DEFAULT_SYMMETRY`, or a group of :data:`rfmap.symmetry.SYMMETRY_GROUPS`), one
            network evaluation per symmetry.

        Returns
        -------
        Tensor, float32, shape (B, d, N, ..., N)
        """
        group = self._symmetry(symmetrize)
        if group is not None:
            return symmetrized_displacement(self.displacement, grids, group)
        g = np.asarray(grids)
        B, n, d = g.shape[0], g.shape[1], self.spec.dim
        if g.ndim != d + 1:
            raise ValueError(f"expected fields of shape (B, {', '.join(['N'] * d)}), got {g.shape}")
        pts = torch.as_tensor(grid_points(n, d), dtype=torch.float32).expand(B, -1, -1)
        par = torch.as_tensor(g.reshape(B, -1))
        par = par.to(torch.complex64) if par.is_complex() else par.float()
        x = encode(pts, par, self.spec, n).to(self.device)
        return self._forward(x).float().cpu()

    def map(self, field, n: int | None = None, points=None, *, refine: bool = False, work_n: int | None = None,
            alpha: Sequence[float] | None = None, preprocess: bool = True, refine_bounds=None,
            repair: bool = True, polish: bool | float = False, guard: bool = GUARD,
            symmetrize: bool | str = False) -> MapResult:
        """Map one field.

        Parameters
        ----------
        field : str, callable, array or (points, values)
            A built-in field name; a callable on points (P, d) (a raw density, or a complex Beltrami coefficient);
            an array sampled on an N^d grid (resampled to the working grid); or scattered samples.
        n : int, optional
            Side of the output grid (default: the input array's side, else 51 in 2D and 48 in 3D).
        points : array (P, d), optional
            Evaluate the map at these arbitrary query points instead of the output grid; the result's elements
            are a Delaunay triangulation of them.
        refine : bool
            Apply weight refinement (paper Sec. 4.3) before returning.
        work_n : int, optional
            Working grid side of the network (default :meth:`work_n`; then, in 3D and without ``polish``, a folded
            map is first tried on coarser working grids, :data:`REGRID_DIMS`).  Given explicitly, it is used as
            given.
        alpha : sequence of d floats, optional
            A fixed stretching vector (ignored when ``refine``).
        preprocess : bool
            Apply the paper's density preprocessing (shift to minimum 0.1, unit mass) to raw values; with
            ``False`` a positive density is only scaled to unit mass.
        refine_bounds : (float, float), optional
            Search interval of every component of :math:`\\alpha` (default :data:`rfmap.refine.REFINE`).
        repair : bool
            Make the returned map fold-free (:func:`rfmap.repair.repair_map`, after any refinement); with query
            ``points`` the map of the working grid is repaired first and then interpolated.  A density map of the
            output grid (without ``polish``) that is then still no more equal than the input is shortened to the
            most equal fold-free map between the identity and itself (:func:`rfmap.repair.shorten_map`;
            ``info["shorten"]``), so the delivered map never leaves the density less equal than it was.  A density
            map of query ``points`` is shortened by the scale its working grid's map would be shortened by (the
            judgement is made there; ``Surrogate._shorten_query``), so that grid and points deliver one map.
            ``False`` returns the raw network map.
        polish : bool or float
            Density maps on the output grid: finish the (refined, repaired) network map with the flow-based solver
            (``rfmap.hybrid.polish_map``), started from the map of the network's displacement smoothed on the
            working grid (``rfmap.hybrid.smooth_displacement``, ``rfmap.hybrid.smooth_passes`` passes, edges per
            ``rfmap.hybrid.SMOOTH_EDGES``, and on a finer output grid ``rfmap.hybrid.OUTPUT_PASSES`` more passes
            there; all recorded in ``info["polish"]``) where that is fold-free; a number is
            the tolerance on Std(rho~_map).  ``time`` then covers both stages.  A folded
            network map is not repaired first (``info["repair"]["skipped"]``): the polish then starts cold from the
            identity, and the repair would be thrown away.
        guard : bool
            With ``polish``: after a warm flow also run the cold flow and keep the better map
            (``rfmap.hybrid.GUARD``), so that the result is never worse than the flow-based solver alone.
        symmetrize : bool or str
            Average the network's displacement over symmetries of the square or cube
            (:mod:`rfmap.symmetry`: ``True`` for :data:`rfmap.symmetry.DEFAULT_SYMMETRY`, 8 evaluations in 2D and 3
            in 3D, or a group name), before everything else; ``info["symmetrize"]`` records the group.

        Returns
        -------
        MapResult
            ``info`` holds ``alpha``, ``work_n`` (the working grid of the returned map), with refinement the
            objective before/after, when coarser working grids were tried ``info["regrid"]`` (``from``, ``tried``,
            ``work_n``: the grid taken or ``None``, ``time``), with ``repair`` the report ``info["repair"]`` (see
            :func:`rfmap.repair.repair_map`), and with ``polish`` the report
            ``info["polish"]`` (warm or cold start and both stages' times and metrics).  A density map of the output
            grid without ``polish`` also carries ``info["quality"]`` (:func:`density_quality`), and when it leaves
            the density less equal than it was (a field unlike the training fields), or had to be shortened not to,
            a :class:`PoorMapWarning` names the numbers and the remedies (``refine``, ``polish``;
            :func:`quiet_quality` silences it).
        """
        group = self._symmetry(symmetrize)
        inp, n = self._resolve(field, n, preprocess)
        return self._map_one(inp, n, points, refine, work_n, alpha, refine_bounds, repair=repair, polish=polish,
                             guard=guard, regrid=work_n is None, symmetrize=group)

    def map_batch(self, fields: Sequence, n: int | None = None, **kw) -> list[MapResult]:
        """Map several fields with one batched network evaluation (same ``n`` for all)."""
        group = self._symmetry(kw.get("symmetrize", False))
        inps = [self._resolve(f, n, kw.get("preprocess", True)) for f in fields]
        ns = {k for _, k in inps}
        if len(ns) != 1:
            raise ValueError(f"map_batch needs one output size, got {sorted(ns)}")
        nn_ = ns.pop()
        nw = kw.get("work_n") or self.work_n(nn_)
        t0 = time.perf_counter()
        grids = np.stack([self._work_grid(i, nw) for i, _ in inps])
        psi = self.displacement(grids, group) if group else self.displacement(grids)
        dt = (time.perf_counter() - t0) / len(inps)
        return [self._map_one(i, nn_, kw.get("points"), kw.get("refine", False), nw, kw.get("alpha"),
                              kw.get("refine_bounds"), psi=psi[k:k + 1], net_time=dt,
                              repair=kw.get("repair", True), polish=kw.get("polish", False),
                              guard=kw.get("guard", GUARD), regrid=kw.get("work_n") is None, symmetrize=group)
                for k, (i, _) in enumerate(inps)]

    def _map_one(self, inp: _Input, n: int, points, refine, work_n, alpha, bounds, psi=None, net_time=None,
                 repair: bool = True, polish: bool | float = False, guard: bool = GUARD, regrid: bool = False,
                 symmetrize: str | None = None):
        """Evaluate the network on the working grid (unless ``psi`` is given), resample its displacement and the
        input field on the output mesh, apply the stretching vector (refined or given), repair folds, and polish."""
        if polish is not False:
            from .hybrid import polish_tolerance

            tol = polish_tolerance(polish)
            if self.spec.kind != "density" or points is not None:
                raise ValueError("polish finishes density maps on the output grid; it does not apply to "
                                 f"{self.spec.kind} maps or to query points")
        nw = int(work_n or self.work_n(n))
        if nw < self.model.min_size:
            raise ValueError(f"working grid N={nw} is smaller than this model accepts ({self.model.min_size})")
        ref, elements = self._output_mesh(n, points)
        ref64 = torch.as_tensor(ref, dtype=torch.float64)
        fvals = self._field_on(inp, ref, elements, n if points is None else None)

        def network_map(w: int, psi_w):
            """The network's map of the output mesh from working grid ``w`` (refined or with the given alpha)."""
            t0 = time.perf_counter()
            if psi_w is None:
                grid = self._work_grid(inp, w)[None]
                psi_w = self.displacement(grid, symmetrize) if symmetrize else self.displacement(grid)
            t_net = time.perf_counter() - t0 if (net_time is None or w != nw) else net_time
            t1 = time.perf_counter()
            psi64_w = self._displacement_at(psi_w, ref, n if points is None and n == w else None)
            extra: dict[str, Any] = {}
            a_w = np.ones(self.spec.dim) if alpha is None else np.asarray(alpha, dtype=np.float64)
            if refine:
                rr = self._refine(ref64, psi64_w, torch.as_tensor(elements), fvals, n if points is None else None,
                                  bounds)
                a_w = rr.alpha
                extra = dict(refine_objective_start=rr.objective_start, refine_objective=rr.objective,
                             refine_evaluations=rr.evaluations)
            mapped_w = apply_displacement(ref64, psi64_w, self.spec.boundary,
                                          torch.as_tensor(a_w) if (refine or alpha is not None) else None).numpy()
            return psi_w, mapped_w, a_w, extra, t_net, t_net + time.perf_counter() - t1

        psi, mapped, a, extra, t_net, t_map = network_map(nw, psi)
        info: dict[str, Any] = {"work_n": nw, "network_time": t_net, "symmetrize": symmetrize}
        if (repair and regrid and polish is False and self.spec.dim in REGRID_DIMS and points is None
                and self._flipped(mapped, n)):
            # a folded map: try the network on coarser working grids before any repair (REGRID_DIMS)
            tried, t5 = [], time.perf_counter()
            for w in self._regrid_sides(nw):
                cand = network_map(w, None)
                tried.append(w)
                if not self._flipped(cand[1], n) and self._improves(ref, cand[1], elements, fvals):
                    psi, mapped, a, extra = cand[:4]
                    info.update(work_n=w, network_time=info["network_time"] + cand[4])
                    break
            t_map += time.perf_counter() - t5
            info["regrid"] = {"from": nw, "tried": tried, "work_n": info["work_n"] if info["work_n"] != nw else None,
                              "time": time.perf_counter() - t5}
            nw = info["work_n"]
        info.update(extra)
        info["alpha"] = a.tolist()
        if repair:
            t3 = time.perf_counter()
            folded = self._flipped(mapped, n) if polish is not False else 0
            if folded:
                # the polish starts cold from the identity on a folded network map (rfmap.hybrid.polish_map), so
                # a repair, which can cost more than the whole flow, would be thrown away
                cheap = {"n_flipped": folded}
                info["repair"] = {"needed": True, "skipped": True, "method": "skipped (the polish starts cold)",
                                  "n_flipped_before": folded, "n_flipped_after": folded, "affected": 0,
                                  "time": time.perf_counter() - t3, "metrics_before": cheap,
                                  "metrics_after": dict(cheap)}
            else:
                work = self._working_grid_map(psi, a) if points is not None else None
                mapped, info["repair"] = self._repair(ref, mapped, elements, fvals, n if points is None else None,
                                                      work)
            t_map += time.perf_counter() - t3
        if polish is not False:
            from .hybrid import (OUTPUT_PASSES, SMOOTH_EDGES, polish_map, smooth_displacement,
                                 smooth_grid_displacement, smooth_passes)

            t4 = time.perf_counter()  # the flow starts from the map of the smoothed displacement (rfmap.hybrid)
            passes = smooth_passes(self.spec.dim, n, nw, self.spec.boundary)
            edges = SMOOTH_EDGES[self.spec.boundary]
            psi_s = self._displacement_at(smooth_displacement(psi, passes, edges), ref, n if n == nw else None)
            out_passes = 0 if n == nw else OUTPUT_PASSES  # the resampling's kinks, smoothed on the output grid
            if out_passes:
                psi_s = smooth_grid_displacement(psi_s, n, out_passes, edges)
            start = apply_displacement(ref64, psi_s, self.spec.boundary, torch.as_tensor(a)).numpy()
            t_map += time.perf_counter() - t4
            mapped, info["polish"] = polish_map(ref, mapped, elements, fvals, n=n, boundary=self.spec.boundary,
                                                tol=tol, stage_time=t_map, start=start, guard=guard)
            info["polish"].update(smooth_passes=passes, smooth_edges=edges, output_passes=out_passes)
            t_map += info["polish"]["time"]
        if self.spec.kind == "density" and points is not None and repair and polish is False:
            # query points: shortened as the working grid's map would be, so that the delivered map is one map
            t6 = time.perf_counter()
            mapped, short, q = self._shorten_query(inp, work, ref, mapped, elements, fvals)
            t_map += time.perf_counter() - t6
            if short is not None:
                info["shorten"] = short
                warnings.warn(quality_message(q, shorten=short, grid_only=True), PoorMapWarning,
                              stacklevel=3)
        if self.spec.kind == "density" and points is None and polish is False:
            t6 = time.perf_counter()
            info["quality"] = density_quality(mapped, fvals, n)
            q = info["quality"]
            if repair and not q["std_rho_map"] < q["std_rho_orig"]:
                # less equal than no map at all: the most equal fold-free shortened map (never worse than the
                # identity; rfmap.repair.shorten_map)
                mapped, info["shorten"] = shorten_map(ref, mapped, fvals, n, boundary=self.spec.boundary)
                info["quality"] = density_quality(mapped, fvals, n)
                info["quality"]["shortened_from"] = q["std_rho_map"]
            t_map += time.perf_counter() - t6
            if info["quality"]["worse"] or "shorten" in info:
                warnings.warn(quality_message(info["quality"], shorten=info.get("shorten")), PoorMapWarning,
                              stacklevel=3)
        return MapResult(ref_points=ref, mapped_points=mapped, elements=elements, field=fvals,
                         kind=self.spec.kind, time=t_map, info=info)

    def _regrid_sides(self, nw: int) -> list[int]:
        """The coarser working grids tried on a folded map: ``nw - REGRID_STEP``, ``nw - 2 REGRID_STEP``, ...
        down to the bottom of the training range (and the model's smallest grid)."""
        lo = max(int(self.n_range[0]), self.model.min_size)
        sides = list(range(nw - REGRID_STEP, lo - 1, -REGRID_STEP))
        if nw > lo and (not sides or sides[-1] != lo):
            sides.append(lo)
        return sides

    def _improves(self, ref, mapped, elements, fvals) -> bool:
        """Whether a fold-free map is more equal than the input: Std(rho~_map) < Std(rho~_orig) for a density map
        (always true for other tasks)."""
        if self.spec.kind != "density":
            return True
        m = MapResult(ref_points=ref, mapped_points=mapped, elements=elements, field=fvals, kind="density",
                      time=0.0).metrics()
        return bool(m.std_rho_map < m.std_rho_orig)

    def _flipped(self, mapped: np.ndarray, n: int) -> int:
        """Number of elements of the output ``N``-grid map with non-positive measure (NaN counts as folded)."""
        if not np.isfinite(mapped).all():
            return int(mapped.shape[0])
        meas = grid_signed_measures(torch.from_numpy(np.ascontiguousarray(mapped))[None], n)[0]
        return int((meas <= 0).sum())

    def _working_grid_map(self, psi, alpha) -> tuple[int, np.ndarray, np.ndarray, dict]:
        """The map of the working grid (the grid of ``psi``, with the stretching vector ``alpha``) made fold-free by
        :func:`rfmap.repair.repair_map`: ``(side, grid points, repaired map, repair report)``; what a map of query
        points is interpolated from and judged on."""
        nw, d = psi.shape[-1], self.spec.dim
        grid = grid_points(nw, d)
        u = apply_displacement(torch.as_tensor(grid), self._displacement_at(psi, grid, nw), self.spec.boundary,
                               torch.as_tensor(alpha)).numpy()
        u_rep, report = repair_map(grid, u, grid_mesh(nw, d).elements, boundary=self.spec.boundary, grid_n=nw)
        return nw, grid, u_rep, report

    def _repair(self, ref, mapped, elements, fvals, grid_n, work) -> tuple[np.ndarray, dict]:
        """:func:`rfmap.repair.repair_map` of the output map; at query points, the working-grid map is repaired
        first (``work``, :meth:`_working_grid_map`) and its displacement interpolated, then any fold left on the
        query mesh is repaired there."""
        kw = {"boundary": self.spec.boundary, "density": fvals if self.spec.kind == "density" else None,
              "mu": fvals if self.spec.kind == "beltrami" else None}
        if grid_n is not None:
            return repair_map(ref, mapped, elements, grid_n=grid_n, **kw)
        nw, grid, u_rep, grid_report = work
        d = self.spec.dim
        n_raw = int((element_measures(mapped, elements) <= 0).sum())
        if grid_report["needed"]:
            disp = torch.as_tensor((u_rep - grid).T.reshape(1, d, *([nw] * d)))
            mapped = ref + interpolate(disp, torch.as_tensor(ref))[0].numpy()
        out, report = repair_map(ref, mapped, elements, **kw)
        report.update(needed=report["needed"] or grid_report["needed"], n_flipped_before=n_raw, grid=grid_report)
        if grid_report["needed"] and report["method"] == "none":
            report["method"] = "grid " + grid_report["method"]
        return out, report

    def _shorten_query(self, inp: _Input, work, ref, mapped, elements, fvals):
        r"""Shorten a density map of query points as its working grid's map would be shortened.

        The delivered map of an output grid is shortened (:func:`rfmap.repair.shorten_map`) when it leaves the
        density no more equal than it was.  Query points have no grid to judge on, so the judgement is made on the
        working grid: its repaired map ``work`` (:meth:`_working_grid_map`) and the input density sampled there.
        When that map is shortened to :math:`u_s = x + s\,(u - x)`, the query map is shortened by the same
        :math:`s` — the two are then one map, evaluated at different points — unless that folds an element of the
        query mesh; then the scale is chosen on the query mesh itself (``report["query_mesh"]``).

        Returns
        -------
        (mapped, report or None, quality)
            ``report`` is that of :func:`rfmap.repair.shorten_map` with ``decided_on``, ``work_n``,
            ``query_mesh`` and ``quality`` (:func:`density_quality` of the working grid's delivered map, with
            ``shortened_from``), which is also returned.
        """
        nw, grid, u, _ = work
        dens = self._work_grid(inp, nw).reshape(-1)
        q = density_quality(u, dens, nw)
        if q["std_rho_map"] < q["std_rho_orig"]:
            return mapped, None, q
        u_s, report = shorten_map(grid, u, dens, nw, boundary=self.spec.boundary)
        q_after = density_quality(u_s, dens, nw)
        q_after["shortened_from"] = q["std_rho_map"]
        s = report["scale"]
        out = ref + s * (mapped - ref)
        report.update(decided_on="working grid", work_n=nw, query_mesh=False, quality=q_after)
        if s > 0.0 and not fold_free(out, elements, boundary=self.spec.boundary):
            out, mesh_report = shorten_map(ref, mapped, fvals, elements=elements, boundary=self.spec.boundary)
            report.update(query_mesh=True, scale=mesh_report["scale"], query_report=mesh_report)
        return out, report, q_after

    def _output_mesh(self, n: int, points) -> tuple[np.ndarray, np.ndarray]:
        """The output mesh: the ``N``-grid, or a Delaunay triangulation of the query points."""
        d = self.spec.dim
        if points is None:
            mesh = grid_mesh(n, d)
            return mesh.points, mesh.elements
        ref = np.asarray(points, dtype=np.float64)
        if ref.ndim != 2 or ref.shape[1] != d:
            raise ValueError(f"query points must have shape (P, {d}), got {ref.shape}")
        return triangulate(ref)

    @staticmethod
    def _displacement_at(psi: torch.Tensor, ref: np.ndarray, grid_n: int | None) -> torch.Tensor:
        r"""The displacement :math:`\psi` (1, d, *grid) at the output vertices, float64 (P, d): read off the
        working grid when the output is that grid (``grid_n``), else interpolated multilinearly."""
        if grid_n is not None:
            psi_q = psi[0].reshape(psi.shape[1], -1).T
        else:
            psi_q = interpolate(psi, torch.as_tensor(ref, dtype=torch.float32))[0]
        return psi_q.double()

    def _field_on(self, inp: _Input, ref: np.ndarray, elements: np.ndarray, grid_n: int | None = None) -> np.ndarray:
        r"""The input field on the output mesh: unit-mass vertex densities (n,), or :math:`\mu` per element (m,)
        at the centroids; from the exact evaluator when there is one, else interpolated from the input grid.
        ``grid_n``: the output mesh is the ``N``-grid (its quadrature weights are cached)."""
        if self.spec.kind == "density":
            w = grid_vertex_weights(grid_n, self.spec.dim) if grid_n else vertex_weights(ref, elements)
            if inp.fn is not None:
                return preprocess_density(np.asarray(inp.fn(ref), dtype=np.float64), weights=w)
            src = torch.as_tensor(inp.grid)[None, None]
            return unit_mass(interpolate(src, torch.as_tensor(ref))[0, :, 0].numpy(), w)
        cen = element_centroids(ref, elements)
        if inp.fn is not None:
            return np.asarray(inp.fn(cen))
        g = inp.grid
        v = interpolate(torch.as_tensor(np.stack([g.real, g.imag]))[None], torch.as_tensor(cen))[0].numpy()
        return v[:, 0] + 1j * v[:, 1]

    def _refine(self, ref64, psi64, elements, fvals, grid_n: int | None, bounds) -> RefineResult:
        """Weight refinement (paper Sec. 4.3) of the task's objective, with :data:`rfmap.refine.REFINE`."""
        if self.spec.kind == "density":
            obj = density_objective(ref64, psi64, elements, fvals, self.spec.boundary, REFINE.flip_weight,
                                    grid_n=grid_n)
        else:
            obj = beltrami_objective(ref64, psi64, elements, fvals, self.spec.boundary, REFINE.flip_weight)
        return refine_alpha(obj, self.spec.dim, bounds=bounds or REFINE.bounds, tol=REFINE.tol)
