r"""Trained surrogates: weights on disk, and inference at any resolution or at arbitrary query points.

Weights are stored as ``NAME.safetensors`` (tensors only; loading never unpickles) next to ``NAME.json`` with the
metadata: model constructor arguments, task, boundary, preset, the full training configuration, rfmap version,
steps, wall time and final validation metrics.

Inference (paper Secs. 4.1–4.3): the input field is sampled on a working grid whose side lies in the range the model
was trained on, encoded as :math:`[x, p(x)]` with :math:`p` in its task's encoding (a density as :math:`\log p`,
where the paper writes :math:`p`; :mod:`rfmap.tasks.density`), and mapped to a displacement :math:`\psi` on that
grid; :math:`\psi` is interpolated (bi/trilinearly) to the requested points :math:`x_q`, which may form any grid or
an unstructured cloud, and :math:`u(x_q) = x_q + \mathcal{B}(x_q) \odot (\alpha \odot \psi(x_q))`. That is the
prediction; :meth:`~rfmap.Surrogate.map` then finishes the map with the stages of :mod:`rfmap.finish` (refine,
regrid, repair, polish, judge, shorten), which also report what they did (``MapResult.info``).
"""
from __future__ import annotations

import json
import os
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from ._version import __version__
from .core.inputs import is_uniform
from .core.mesh import check_n, grid_mesh, grid_points, interpolate, triangulate
from .core.device import resolve_device
from .finish import Draft, FinishOptions, InfoView, MapReport, NetworkReport, Prediction, displacement_at, finish, \
    poor_map_message
from .finish.stages import refine, regrid
from .finish.quality import GAIN_RTOL, QUALITY_MARGIN, PoorMapWarning, density_quality, quality_message, quiet_quality
from .nn.model import MultiResUNet, apply_displacement
from .nn.registry import build_model, from_tensor_state, tensor_state
from .fields.paper import PAPER_N, BeltramiMap, DensityField, get_field
from .core.result import MapResult
from .nn.symmetry import resolve_symmetry, symmetrized_displacement
from .tasks import TaskSpec, encode

__all__ = ["Surrogate", "models", "MapOptions", "PredictOptions", "PoorMapWarning", "QUALITY_MARGIN", "GAIN_RTOL",
           "quiet_quality", "density_quality", "quality_message", "WEIGHTS_DIR", "REGRID_DIMS", "REGRID_STEP"]

#: Dimensions in which a folded network map of a grid (with ``repair``, the default working grid and no query points)
#: is first evaluated again on coarser working grids, :data:`REGRID_STEP` sides apart down to the bottom of the
#: training range, taking the first map that is fold-free and more equal than the input (``info["regrid"]``); only
#: when none is does the repair run on the default grid's map.  The 3D repair guarantees a fold-free map, not a good
#: one, while the 2D repair (from the truncated Beltrami coefficient) does better than coarser grids; the numbers are
#: on the book's page *Design decisions*.  An explicit ``work_n`` is used as given, and with ``polish`` a folded map
#: starts the flow cold at once.
REGRID_DIMS = (3,)
#: The step, in grid sides, between the coarser working grids that a folded map is tried on (:data:`REGRID_DIMS`).
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


@dataclass(frozen=True)
class PredictOptions:
    """How a network predicts a map: on which working grid (the grid rule), from which input, with which stretching
    and symmetry.  The surrogate's own part of :class:`~rfmap.surrogate.MapOptions`.

    Attributes
    ----------
    work_n : int, optional
        A network's working grid side (default :meth:`~rfmap.Surrogate.work_n`; then, in 3D and without ``polish``, a
        folded map is first tried on coarser working grids).  Given explicitly, it is used as given.
    native : bool
        Run the network on the requested grid itself (``work_n = n``, no coarser working grid tried), as the paper
        does (with refinement and without repair, :term:`the paper's method`, see :class:`MapOptions`).  Excludes
        ``work_n``.
    alpha : sequence of d floats, optional
        A fixed stretching vector of a network's map (ignored with ``refine``).
    preprocess : bool
        Apply the density preprocessing to raw values: shift to minimum 0.1 (the paper says only "positive"; 0.1 is
        an inference from its Std(ρ̃_orig), see :mod:`rfmap.core.inputs`), then unit mass; with ``False`` a positive
        density is only scaled to unit mass.
    symmetrize : bool or str
        Average a network's displacement over symmetries of the square or cube (:mod:`rfmap.nn.symmetry`).
    """

    work_n: int | None = None
    native: bool = False
    alpha: Sequence[float] | None = None
    preprocess: bool = True
    symmetrize: bool | str = False

    def working_side(self, n: int, default: Callable[[int], int]) -> int:
        """The grid rule: the network's grid side for an output of side ``n``, ``n`` itself with ``native``, else
        ``work_n`` as given, else ``default(n)`` (:meth:`~rfmap.Surrogate.work_n`)."""
        if self.native:
            if self.work_n is not None and int(self.work_n) != int(n):
                raise ValueError(f"native runs the network on the requested grid N={n}; work_n={self.work_n} "
                                 "contradicts it")
            return int(n)
        return int(self.work_n or default(n))

    @property
    def default_grid(self) -> bool:
        """Whether the working grid is the default one (no ``work_n``, not ``native``): only then may a folded map
        be tried on coarser grids."""
        return self.work_n is None and not self.native


@dataclass(frozen=True)
class MapOptions(FinishOptions, PredictOptions):
    """How a field is mapped by a network, listed once: the keywords of :meth:`~rfmap.Surrogate.map` (and ``map_batch``)
    and the options of ``rfmap map``.  It combines the prediction's options (:class:`PredictOptions`: the grid rule,
    the input, the stretching, the symmetry) and the finishing stages' (:class:`rfmap.finish.pipeline.FinishOptions`:
    ``refine``, ``refine_bounds``, ``repair``, ``polish``, ``guard``); :attr:`finishing` returns the latter, which are
    all that the stages receive.

    With ``native=True``, ``refine=True`` and ``repair=False`` (every other option at its default) a map is computed
    by :term:`the paper's method`."""

    @property
    def finishing(self) -> FinishOptions:
        """The finishing stages' options."""
        return FinishOptions(**{name: getattr(self, name) for name in FinishOptions.__dataclass_fields__})


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
        The network that predicts the displacement.
    spec : TaskSpec
        What the network computes: the task, the dimension and the boundary.
    meta : dict, optional
        Metadata (see :mod:`rfmap.surrogate`); ``n_range`` gives the training resolutions.
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
        bit) without the Python overhead of the module calls; the saving is a fixed time per evaluation, so it
        matters most for small grids.  Tracing a new shape costs a one-off compilation (traces are kept, also while
        tracing is off, until :meth:`to` moves the network), so it pays for many maps of one size (a batch of
        fields, an animation, a benchmark), not for one.
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
        Raises ``FileNotFoundError`` when the weights or their metadata are missing, and ``ValueError`` naming the
        file when either is corrupt or the weights do not fit the model the metadata describe."""
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
            return self._checked(lin.reshape((n,) * d), None, preprocess), n
        if callable(field):
            fn = self.spec.task.sample_named(field) if isinstance(field, (DensityField, BeltramiMap)) else field
            n = check_n(n or PAPER_N[d])
            vals = np.asarray(fn(grid_points(n, d)))
            return self._checked(vals.reshape((n,) * d), fn, preprocess), n
        arr = np.asarray(field)
        if arr.ndim != d or len(set(arr.shape)) != 1:
            raise ValueError(f"a {d}D model needs a field sampled on an N^{d} grid, got an array of shape "
                             f"{arr.shape}")
        check_n(arr.shape[0])
        return self._checked(arr, None, preprocess), int(n or arr.shape[0])

    def _checked(self, grid: np.ndarray, fn, preprocess: bool) -> _Input:
        """The field on a grid as the task checks and normalises it (:meth:`rfmap.tasks.base.Task.check_field`)."""
        return _Input(self.spec.task.check_field(grid, preprocess), fn, preprocess)

    def _work_grid(self, inp: _Input, n_work: int) -> np.ndarray:
        g = inp.grid
        if g.shape[0] == n_work:
            return g
        d = self.spec.dim
        if inp.fn is not None:  # sample the field itself on the working grid rather than resampling samples
            vals = np.asarray(inp.fn(grid_points(n_work, d))).reshape((n_work,) * d)
            return self._checked(vals, inp.fn, inp.preprocess).grid
        src = torch.as_tensor(np.stack([g.real, g.imag]) if np.iscomplexobj(g) else g[None])[None]
        out = interpolate(src.double(), torch.as_tensor(grid_points(n_work, d)))[0].numpy()
        if np.iscomplexobj(g):
            return (out[:, 0] + 1j * out[:, 1]).reshape((n_work,) * d)
        return self.spec.task.resampled(out[:, 0].reshape((n_work,) * d))

    # ------------------------------------------------------------------ inference
    def _symmetry(self, symmetrize) -> str | None:
        """The symmetry group of a ``symmetrize`` argument (:mod:`rfmap.nn.symmetry`)."""
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
            (:func:`rfmap.nn.symmetry.symmetrized_displacement`; ``True`` the dimension's
            :data:`rfmap.nn.symmetry.DEFAULT_SYMMETRY`, or a group of :data:`rfmap.nn.symmetry.SYMMETRY_GROUPS`), one
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

    def map(self, field, n: int | None = None, points=None, options: MapOptions | None = None, **kw) -> MapResult:
        """Map one field: the network's map of the requested grid (or query points), by default made fold-free.

        The options that matter most (keywords, or fields of ``options``):

        * ``refine=True``: choose the stretching vector :math:`\\alpha` after inference (the paper's Sec. 4.3);
        * ``repair=False``: return the network's map as it is, even folded (the default repairs folds and never
          returns a density map with a higher Std(ρ̃) than its input, see :mod:`rfmap.finish.quality`);
        * ``native=True``: run the network on the requested grid itself, as the paper does.  With ``native=True``,
          ``refine=True`` and ``repair=False`` (every other option at its default) a map is
          :term:`the paper's method`;
        * ``polish=True``: finish a density map with the flow-based solver, for accuracy beyond the network's.

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
        options : MapOptions, optional
            The options below (default ``MapOptions()``, see :class:`.MapOptions`); ``**kw`` replaces its fields:
        refine : bool
            Apply weight refinement (paper Sec. 4.3) before returning.
        work_n : int, optional
            Working grid side of the network (default :meth:`work_n`; then, in 3D and without ``polish``, a folded
            map is first tried on coarser working grids, :data:`.REGRID_DIMS`).  Given explicitly, it is used as
            given.
        native : bool
            Run the network on the requested grid itself (``work_n = n``, no coarser working grid tried), as the
            paper does.  Excludes ``work_n``.
        alpha : sequence of d floats, optional
            A fixed stretching vector (ignored when ``refine``).
        preprocess : bool
            Apply the density preprocessing to raw values: shift to minimum 0.1 (the paper says only
            "positive"; 0.1 is an inference from its Std(ρ̃_orig), see :mod:`rfmap.core.inputs`), then unit
            mass; with ``False`` a positive density is only scaled to unit mass.
        refine_bounds : (float, float), optional
            Search interval of every component of :math:`\\alpha` (default :data:`rfmap.finish.refine.REFINE`).
        repair : bool
            Make the returned map fold-free (after any refinement; :func:`rfmap.finish.repair.dispatch.repair_map`),
            and shorten a density map that still does not lower Std(ρ̃) below the input's towards the identity, to
            the fold-free map of lowest Std(ρ̃) between the two (:func:`rfmap.finish.shorten.shorten_map`, ``info["shorten"]``).
            With query ``points``, the map of the working grid is repaired and judged, and the points follow it, so
            that grid and points deliver one map.  ``False`` skips both: with the other options at their defaults
            it returns the raw network map (with ``refine``, a refined one).
        polish : bool or float
            Density maps on the output grid: finish the (refined) network map with the flow-based solver, started
            from the network's map smoothed (the warm start) where that is fold-free, else from the identity (the
            cold start); a number is the tolerance on Std(ρ̃_map).  A folded network map is not repaired first.
            ``time`` then covers both stages; ``info["polish"]`` records them (details:
            :func:`rfmap.finish.polish.polish_map`).
        guard : bool
            With ``polish``: after a warm start also run the cold one and keep the better map, so that the result
            is never worse than the flow-based solver alone.
        symmetrize : bool or str
            Average the network's displacement over symmetries of the square or cube, before everything else
            (:mod:`rfmap.nn.symmetry`: ``True`` for :data:`rfmap.nn.symmetry.DEFAULT_SYMMETRY`, 8 evaluations in 2D
            and 3 in 3D, or a group name); ``info["symmetrize"]`` records the group.

        Returns
        -------
        MapResult
            The map; its ``info`` reports what each stage did (a read-only view of the typed report
            :class:`rfmap.finish.report.MapReport`, ``info.report``).  It holds ``alpha``, ``work_n`` (the working
            grid of the returned map), ``network_time`` and ``symmetrize``; with refinement the objective before and
            after; when coarser working grids were tried, ``info["regrid"]``; with ``repair``, ``info["repair"]``
            (:func:`rfmap.finish.repair.dispatch.repair_map`); with ``polish``, ``info["polish"]``.  A density map of
            the output grid without ``polish`` also carries ``info["quality"]`` (:func:`.density_quality`).

        Warns
        -----
        PoorMapWarning
            When a density map does not lower Std(ρ̃) by the fraction :data:`.GAIN_RTOL` (a field unlike the
            training fields), or was shortened so as not to raise it; it names the numbers and the remedies (``refine``, ``polish``;
            :func:`.quiet_quality` silences it).

        Notes
        -----
        A uniform density (a constant, e.g. all zeros, after preprocessing: :func:`rfmap.core.inputs.is_uniform`)
        is equal already: its map is the identity, exactly, computed by no stage, and ``info`` holds only
        ``uniform = True``.
        """
        opts = replace(options or MapOptions(), **kw)
        group = self._symmetry(opts.symmetrize)
        inp, n = self._resolve(field, n, opts.preprocess)
        return self._map_one(inp, n, points, opts, group)

    def map_batch(self, fields: Sequence, n: int | None = None, points=None, options: MapOptions | None = None,
                  **kw) -> list[MapResult]:
        """Map several fields with one batched network evaluation (same ``n`` for all); ``options`` and ``kw`` as in
        :meth:`map`."""
        opts = replace(options or MapOptions(), **kw)
        group = self._symmetry(opts.symmetrize)
        inps = [self._resolve(f, n, opts.preprocess) for f in fields]
        ns = {k for _, k in inps}
        if len(ns) != 1:
            raise ValueError(f"map_batch needs one output size, got {sorted(ns)}")
        n_out = ns.pop()
        nw = opts.working_side(n_out, self.work_n)
        t0 = time.perf_counter()
        grids = np.stack([self._work_grid(i, nw) for i, _ in inps])
        psi = self.displacement(grids, group) if group else self.displacement(grids)
        dt = (time.perf_counter() - t0) / len(inps)
        return [self._map_one(i, n_out, points, opts, group, (psi[k:k + 1], grids[k], dt))
                for k, (i, _) in enumerate(inps)]

    def _map_one(self, inp: _Input, n: int, points, opts: MapOptions, group: str | None, given=None) -> MapResult:
        """Predict, then finish: the network's map of the output mesh (:meth:`_predict`, refined when asked), tried
        on coarser working grids when it folds (:func:`rfmap.finish.stages.regrid`, :data:`REGRID_DIMS`), then the stages
        of :func:`rfmap.finish.pipeline.finish`; a :class:`.PoorMapWarning` when the returned density map is poor.
        ``given``: the network's output on the default working grid from a batched evaluation (:meth:`_predict`)."""
        # the network's map is refined as it is predicted (every working grid tried is), not by the finishing stages
        stages = replace(opts.finishing, refine=False)
        stages.check(self.spec.task, points is None)
        nw = opts.working_side(n, self.work_n)
        if nw < self.model.min_size:
            raise ValueError(f"working grid N={nw} is smaller than this model accepts ({self.model.min_size})")
        ref, elements = self._output_mesh(n, points)
        grid_n = n if points is None else None
        mesh = MapResult(ref_points=ref, mapped_points=ref, elements=elements, kind=self.spec.kind,
                         field=self._field_on(inp, ref, elements, grid_n))
        if self.spec.task.equalizes and is_uniform(inp.grid) and (inp.fn is None or is_uniform(mesh.field)):
            # a uniform density is equal already: its map is the identity, exactly, and nothing is computed (a
            # density function is asked at the output vertices too; a grid's interpolant is uniform to round-off)
            return replace(mesh, mapped_points=ref.copy(), info=InfoView(MapReport(), {"uniform": True}))

        def predict(w: int, given=None) -> Draft:
            draft = self._predict(inp, mesh, grid_n, w, opts.alpha, group, given)
            return refine(draft, opts.refine_bounds) if opts.refine else draft

        draft = predict(nw, given)
        if stages.repair and opts.default_grid and stages.polish is False and self.spec.dim in REGRID_DIMS:
            draft = regrid(draft, predict, self._regrid_sides(nw))
        draft = finish(draft, stages)
        message = poor_map_message(draft.report)
        if message is not None:
            warnings.warn(message, PoorMapWarning, stacklevel=3)
        return draft.deliver()

    def _predict(self, inp: _Input, mesh: MapResult, grid_n: int | None, w: int, alpha, group: str | None,
                 given=None) -> Draft:
        r"""The network's map of the output ``mesh`` from working grid ``w``: :math:`\psi` on the working grid,
        resampled at the output vertices (read off when the output is that grid, ``grid_n``), and
        :math:`u = x + \mathcal{B}(x) \odot (\alpha \odot \psi(x))` with the given ``alpha`` (ones by default).
        ``given``: ``(psi, input on the working grid, seconds)`` of a batched evaluation, instead of evaluating."""
        t0 = time.perf_counter()
        if given is None:
            grid = self._work_grid(inp, w)
            psi = self.displacement(grid[None], group) if group else self.displacement(grid[None])
            t_net = time.perf_counter() - t0
        else:
            psi, grid, t_net = given
        t1 = time.perf_counter()
        ref = mesh.ref_points
        psi_out = displacement_at(psi, ref, grid_n if grid_n == w else None)
        a = np.ones(self.spec.dim) if alpha is None else np.asarray(alpha, dtype=np.float64)
        mapped = apply_displacement(torch.as_tensor(ref, dtype=torch.float64), psi_out, self.spec.boundary,
                                    None if alpha is None else torch.as_tensor(a)).numpy()
        result = replace(mesh, mapped_points=mapped, time=t_net + time.perf_counter() - t1)
        report = MapReport(network=NetworkReport(w, t_net, group), alpha=a.tolist())
        return Draft(result, report, self.spec.boundary, grid_n, Prediction(psi, psi_out, grid))

    def _regrid_sides(self, nw: int) -> list[int]:
        """The coarser working grids tried on a folded map: ``nw - REGRID_STEP``, ``nw - 2 REGRID_STEP``, ...
        down to the bottom of the training range (and the model's smallest grid)."""
        lo = max(int(self.n_range[0]), self.model.min_size)
        sides = list(range(nw - REGRID_STEP, lo - 1, -REGRID_STEP))
        if nw > lo and (not sides or sides[-1] != lo):
            sides.append(lo)
        return sides

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

    def _field_on(self, inp: _Input, ref: np.ndarray, elements: np.ndarray, grid_n: int | None = None) -> np.ndarray:
        r"""The input field on the output mesh (:meth:`rfmap.tasks.base.Task.field_on_mesh`: unit-mass vertex densities
        (P,), or :math:`\mu` per element (m,) at the centroids, ...); from the exact evaluator when there is one,
        else interpolated from the input grid.  ``grid_n``: the output mesh is the ``N``-grid."""
        return self.spec.task.field_on_mesh(inp.grid, inp.fn, ref, elements, grid_n)
