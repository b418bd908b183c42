r"""Typed training configurations with named ``ci``, ``full`` and ``paper`` presets.

Where no preset is named, the environment variable ``RFMAP_SCALE`` chooses it: ``ci`` or ``full`` (the default).
``paper`` cannot be chosen through ``RFMAP_SCALE``; name it with ``--preset paper`` (in Python,
``get_config(name, "paper")``).

* ``ci`` presets train tiny models for a few steps, for the tests and for the notebooks under CI.
* ``full`` presets are the ones the shipped weights were trained at, over a chain of runs.  The first run of a
  chain is the preset as it stands; each later run continues from the weights before it (``--init``) with the
  preset's steps, time limit and peak learning rate (at times its seed and weight average) overridden on the
  command line.  ``rfmap train --preset full`` alone therefore repeats only the first run; every run's command is
  in the model's metadata (``rfmap models --lineage``).
* ``paper`` presets are the paper's hyperparameters as printed (for a GPU: ``rfmap train --config NAME --preset
  paper --device cuda``), with the paper's "epoch" read as one optimisation step on a freshly drawn batch (the
  paper draws a new training grid every epoch).  A configuration for which the paper has no model (the FNO and its
  U-Net partner, the variants trained across grid sides) keeps its own learning rate or grid sides in its
  ``paper`` preset; the preset's description gives the paper's recipe and then what the preset runs instead.
"""
from __future__ import annotations

import json
import os
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace

from typing import Iterator

from ..fields import RandomBeltramiConfig, RandomDensityConfig
from ..tasks import LossWeights, TaskSpec
from ..tasks.teacher import TeacherConfig

__all__ = ["TrainConfig", "ModelConfig", "Presets", "CONFIGS", "PRESETS", "get_config", "config_names", "registered_config",
           "scale"]

PRESETS = ("ci", "full", "paper")
#: how the training grid side of a step is drawn from ``n_range`` (:func:`rfmap.training.data.step_size_n`)
N_SAMPLINGS = ("uniform", "log", "mixed")
#: the presets ``RFMAP_SCALE`` may name
SCALES = ("ci", "full")


def scale() -> str:
    """The active scale from ``RFMAP_SCALE`` (``'full'`` when unset)."""
    s = os.environ.get("RFMAP_SCALE", "full").strip().lower() or "full"
    if s not in SCALES:
        raise ValueError(f"RFMAP_SCALE must be one of {SCALES}, got {s!r}")
    return s


@dataclass(frozen=True)
class ModelConfig:
    """The network: ``arch='unet'`` builds :class:`rfmap.nn.MultiResUNet` (``base``, ``depth``, ``attention``),
    ``arch='fno'`` builds :class:`rfmap.nn.FNONet` (``modes``, ``width``, ``layers``, ``padding``); ``dim`` and
    ``n_params`` come from the task."""

    base: int = 16
    depth: int = 3
    attention: bool = True
    arch: str = "unet"
    modes: int = 12
    width: int = 32
    layers: int = 4
    padding: float = 0.25

    def kwargs(self, dim: int, n_params: int) -> dict:
        """Constructor arguments of the network for a task (what the built model's ``kwargs()`` returns)."""
        if self.arch == "fno":
            return {"arch": "fno", "dim": dim, "n_params": n_params, "modes": self.modes, "width": self.width,
                    "layers": self.layers, "padding": float(self.padding)}
        if self.arch != "unet":
            raise ValueError(f"unknown model architecture {self.arch!r}; expected 'unet' or 'fno'")
        return {"dim": dim, "n_params": n_params, "base": self.base, "depth": self.depth,
                "attention": self.attention}


@dataclass(frozen=True)
class TrainConfig:
    r"""Everything that defines a training run.

    As in the paper: AdamW, gradient clipping at 1.0, a random training resolution per step, and Sobol-jittered
    sampling, each vertex moved by up to ``jitter`` grid spacings times the field's local gradient magnitude over its
    largest (:func:`rfmap.core.mesh.jittered_points`).  The defaults of the learning rate, weight decay and schedule
    below are this project's; the ``paper`` presets have the paper's.

    **Optimiser.**  ``schedule`` is ``'cosine'`` (linear warm-up then cosine decay), ``'step'`` (decay by ``gamma``
    every ``step_size`` steps) or ``'restarts'`` (cosine annealing with warm restarts, ``T0``, ``T_mult``).
    ``ema`` > 0 keeps an exponential moving average of the weights (Polyak averaging,
    :class:`rfmap.training.averaging.WeightAverage`) with that decay; validation, the checkpoint choice and the
    shipped file then use the averaged weights (0, the default: the weights as trained).

    **Data.**  Training grid sides: ``n_sampling`` ``'uniform'`` (every side in ``n_range`` equally often) or
    ``'log'`` (log-uniform: every octave of sizes equally often, a curriculum across the sizes the paper tests) or
    ``'mixed'`` (half the steps log-uniform, half uniform on the small sides ``[lo, 3 lo]``).  ``batch_points`` > 0
    sets each step's batch to about that many grid points,
    :math:`B(N) = \mathrm{clip}(\mathrm{round}(P / N^d), 1, \mathtt{batch})`, so that a step costs about the same
    at every size (0: always ``batch``).  ``teacher`` (density tasks, :class:`rfmap.tasks.teacher.TeacherConfig`): a
    classical solver's map of a share of each batch's fields as a supervised target beside the data-free losses
    (default: none, data-free as in the paper).

    **Validation.**  ``val_repair``: score the held-out maps as ``Surrogate.map`` delivers them (a folded network map
    regridded or repaired; :func:`rfmap.training.validation.evaluate`) instead of the raw network output;
    ``val_native``: run the network on the validation grid itself (``Surrogate.map(..., native=True)``) instead of a
    working grid inside ``n_range``.  A run started with ``init`` validates its parent at step 0, so that the parent
    competes with every checkpoint.

    **Run.**  ``grow`` (with ``init``): the parent network is widened to ``model.base`` channels by a
    function-preserving growth (:func:`rfmap.nn.grow.grow_unet`) before training.  ``snapshot_every`` > 0 writes the
    weights every that many steps to ``OUT/snapshots/`` (single self-contained files, scored afterwards by
    ``rfmap validate``).  ``precision``: ``'fp32'`` or ``'bf16'`` (:data:`rfmap.core.device.PRECISIONS`): with
    ``'bf16'`` the network's forward and backward pass run under bfloat16 autocast (CUDA, or a CPU with
    AVX512-BF16/AMX); the losses, the Jacobians, the fold penalty, the optimiser's state and validation stay in
    float32.

    Attributes
    ----------
    name : str
        The configuration's name.
    task : TaskSpec
        What it maps (:class:`rfmap.tasks.base.TaskSpec`).
    preset : str
        ``ci``, ``full`` or ``paper``.
    description : str
        The description recorded with the shipped file.
    model : ModelConfig
        The network: a U-Net or an FNO, and its size.
    steps : int
        Optimiser steps.
    batch : int
        Fields per step (per process in a data-parallel run); see ``batch_points``.
    n_range : tuple of int
        The training grid sides, lowest and highest ``N``.
    n_sampling : str
        How the side of each step is drawn from ``n_range`` (above).
    batch_points : int
        The batch size by grid points (above; 0: always ``batch``).
    jitter : float
        The vertices' jitter in grid spacings (above).
    grow : bool
        With ``init``: widen the parent network first (above).
    lr : float
        AdamW's peak learning rate.
    weight_decay : float
        AdamW's weight decay.
    betas : tuple of float
        AdamW's moment decays.
    clip : float
        The gradient-norm clipping threshold.
    schedule : str
        The learning-rate schedule (above).
    warmup : int
        Steps of linear warm-up.
    lr_min : float
        The floor of ``'cosine'`` and ``'restarts'``.
    step_size : int
        For ``'step'``: steps between decays.
    gamma : float
        For ``'step'``: the factor of each decay.
    T0 : int
        For ``'restarts'``: the first cycle's length in steps.
    T_mult : int
        For ``'restarts'``: the factor by which each cycle is longer than the last.
    ema : float
        Decay of the weight average (0: none; above).
    loss : LossWeights
        The weights of the loss terms (:class:`rfmap.tasks.base.LossWeights`).
    density_field : RandomDensityConfig
        The random training densities (``None``: the task's defaults).
    beltrami_field : RandomBeltramiConfig
        The random training coefficients (``None``: the task's defaults).
    beltrami_source : str
        For the Beltrami task: whether a sample is the exact coefficient of a random map (``'map'``) or a random
        coefficient (``'mu'``).
    teacher : TeacherConfig
        A classical solver's maps as targets (above).
    seed : int
        Seeds the network's initial weights and every step's fields, so a run without a time limit repeats.
    val_every : int
        Steps between validations on held-out random fields (0: none during training; ``rfmap validate`` scores
        the snapshots instead).
    val_n : int
        The validation side when ``val_sizes`` is empty, and the side of the final report on the paper's test fields.
    val_sizes : tuple of int
        The validation grid sides.
    val_count : int
        Held-out fields per side.
    val_repair : bool
        Validate the default maps (recomputed on coarser grids and repaired) instead of the raw maps (above).
    val_native : bool
        Validate with the network on each validation grid itself (above).
    select_best : bool
        Ship the best validated state (:func:`rfmap.training.validation.score`) instead of the last one.
    snapshot_every : int
        Steps between weight snapshots (above; 0: none).
    ckpt_every : int
        Steps between the checkpoints ``rfmap train --resume`` continues from.
    workers : int
        Processes that draw the batches (0: drawn in the training process).
    threads : int
        PyTorch's CPU threads (0: its default).
    time_limit : float
        Wall-time budget in seconds (0: none): training stops when it is spent, and the cosine schedule then
        follows the elapsed time where that is further along than the step count.
    precision : str
        ``'fp32'`` or ``'bf16'`` (above).
    """

    name: str
    task: TaskSpec
    preset: str = "full"
    model: ModelConfig = ModelConfig()
    steps: int = 2000
    batch: int = 8
    n_range: tuple[int, int] = (64, 96)
    n_sampling: str = "uniform"
    batch_points: int = 0
    grow: bool = False
    jitter: float = 0.2
    lr: float = 1e-3
    weight_decay: float = 1e-4
    betas: tuple[float, float] = (0.9, 0.999)
    schedule: str = "cosine"
    warmup: int = 100
    step_size: int = 200
    gamma: float = 0.5
    T0: int = 600
    T_mult: int = 2
    lr_min: float = 1e-6
    clip: float = 1.0
    ema: float = 0.0
    loss: LossWeights = LossWeights()
    density_field: RandomDensityConfig | None = None
    beltrami_field: RandomBeltramiConfig | None = None
    beltrami_source: str = "map"
    seed: int = 0
    val_every: int = 250
    val_n: int = 51
    val_sizes: tuple[int, ...] = ()
    val_count: int = 16
    val_repair: bool = False
    val_native: bool = False
    teacher: TeacherConfig = TeacherConfig()
    snapshot_every: int = 0
    select_best: bool = True
    workers: int = 0
    ckpt_every: int = 250
    threads: int = 0
    time_limit: float = 0.0
    precision: str = "fp32"
    description: str = ""

    def to_dict(self) -> dict:
        return json.loads(json.dumps(asdict(self)))

    @property
    def val_ns(self) -> tuple[int, ...]:
        """Grid sides of the validation on held-out random fields (``val_sizes``, else ``(val_n,)``)."""
        return tuple(self.val_sizes) or (self.val_n,)

    def __post_init__(self):
        if self.n_sampling not in N_SAMPLINGS:
            raise ValueError(f"n_sampling must be one of {N_SAMPLINGS}, got {self.n_sampling!r}")
        lo, hi = self.n_range
        if not 2 <= lo <= hi:
            raise ValueError(f"n_range must be (lo, hi) with 2 <= lo <= hi, got {tuple(self.n_range)}")
        if self.batch_points < 0:
            raise ValueError(f"batch_points must not be negative, got {self.batch_points}")
        if self.teacher.active and not self.task.task.teacher:
            raise ValueError(f"config {self.name!r} maps a {self.task.task.title} field: a classical teacher applies "
                             "to density configs only")

    def with_overrides(self, **kw) -> "TrainConfig":
        return replace(self, **kw)


@dataclass(frozen=True)
class Presets:
    """One configuration's ``ci``, ``full`` and ``paper`` presets, each a :class:`TrainConfig` built by keyword.

    Build them with :meth:`of` (from what the presets share and what each one changes) or :meth:`derive` (from
    another configuration's presets); :meth:`configs` is the ``{preset: TrainConfig}`` of :data:`CONFIGS`.

    Attributes
    ----------
    ci : TrainConfig
        The tiny preset of the tests.
    full : TrainConfig
        The preset of the shipped weights: the first run of each shipped chain, which later runs override on the
        command line.
    paper : TrainConfig
        The paper's recipe.
    paper_note : str
        The paper's recipe as printed, which the ``paper`` preset's description appends.
    """

    ci: TrainConfig
    full: TrainConfig
    paper: TrainConfig
    paper_note: str

    @classmethod
    def of(cls, base: TrainConfig, *, ci: dict, full: dict, paper: dict, paper_note: str) -> "Presets":
        """The presets of ``base`` (name, task, description, losses, fields and optimiser: what the three share),
        each with the fields it changes.  The ``paper`` preset runs as the paper's runs did (no wall-time limit,
        every thread of the machine, one batch worker) and validates as the ``full`` preset does."""
        shared = {"time_limit": 0.0, "threads": 0, "workers": 1, "val_every": 1000, "ckpt_every": 500,
                  **{k: full[k] for k in ("val_sizes", "val_count", "val_repair") if k in full}}
        return cls(ci=replace(base, preset="ci", **ci), full=replace(base, preset="full", **full),
                   paper=replace(base, preset="paper", description=f"{base.description} Paper preset: {paper_note}",
                                 **{**shared, **paper}),
                   paper_note=paper_note)

    def derive(self, *, name: str, description: str, ci: dict | None = None, full: dict | None = None,
               paper: dict | None = None, paper_note: str | None = None, **shared) -> "Presets":
        """Another configuration from these presets: its ``name`` and ``description`` (the ``paper`` preset's with
        ``paper_note`` appended, by default these presets' note), the fields ``shared`` by the three changed alike,
        then each preset's own."""
        def one(cfg: TrainConfig, own: dict | None, text: str) -> TrainConfig:
            return replace(cfg, name=name, description=text, **{**shared, **(own or {})})

        note = self.paper_note if paper_note is None else paper_note
        return Presets(ci=one(self.ci, ci, description), full=one(self.full, full, description),
                       paper=one(self.paper, paper, f"{description} Paper preset: {note}"), paper_note=note)

    def configs(self) -> dict[str, TrainConfig]:
        """``{"ci": ..., "full": ..., "paper": ...}``."""
        return {"ci": self.ci, "full": self.full, "paper": self.paper}


#: the ``ci`` presets: tiny networks for a few steps, 2D and 3D
_CI = dict(model=ModelConfig(base=4, depth=2), steps=20, batch=2, n_range=(17, 25), warmup=2, val_every=10,
           ckpt_every=10, val_n=17, val_count=4)
_CI3 = dict(model=ModelConfig(base=4, depth=2), steps=10, batch=1, n_range=(9, 13), warmup=2, val_every=5,
            ckpt_every=5, val_n=9, val_count=2)
#: training densities with sharp features (narrow peaks, steep ramps) besides the paper's smooth and step fields
_SHARP2 = RandomDensityConfig(dim=2, p_peak=0.15, p_ramp=0.15)
#: a third of the training fields as hard as the held-out ramps and peaks (a single steep ramp of height ratio up to
#: 51 after preprocessing, or a narrow peak, over faint modes; RandomDensityConfig.p_hard), besides the sharp
#: features of _SHARP2 (the 2D density models): without them no training field is like the held-out ramps, which
#: the models then leave as unequal as they came (book: Design decisions)
_HARD2 = RandomDensityConfig(dim=2, p_peak=0.15, p_ramp=0.15, p_hard=0.3)
#: the 3D models: half that share, which keeps the held-out smooth and step fields equal (book: Design decisions)
_HARD3 = RandomDensityConfig.for_dim(3, p_peak=0.15, p_ramp=0.15, p_hard=0.15)
#: a fold penalty that a local fold cannot hide in (the penalty is a mean over all elements; book: Design
#: decisions), and the density term keeps a restoring gradient on collapsed elements (LossWeights.density_tangent)
_FOLD_HARD = dict(fold=100.0, fold_threshold=0.02, density_tangent=True)
#: the free 3D model: a fold penalty ten times stronger again, against overshooting folds on the low-density side of
#: steep ramps (book: Design decisions; Surrogate.map handles those left on coarser working grids, REGRID_DIMS)
_FOLD_HARD3 = dict(fold=1000.0, fold_threshold=0.02, density_tangent=True)
#: the training fields and fold penalty of the 2D density models, in the words of a model description
_HARD_NOTE = ("densities with narrow peaks and steep ramps (15 % each) and single hard ramps or peaks (30 %); fold "
              "penalty 100 from det J < 0.02.")
#: the 3D density models: half the 2D share of hard fields (at 30 % the held-out smooth and step fields stayed at twice
#: the free model's Std)
_HARD3_NOTE = ("Densities with narrow peaks and steep ramps (15 % each) and single hard ramps or peaks (15 %); fold "
               "penalty 100 from det J < 0.02.")
#: the 2D full presets train at grid sides from 48 (the paper's 64), so that its 51-point test grid runs at its own size
_N48_NOTE = " Trained at N in [48, 96]."
#: validation of the 2D and 3D full presets: 16 held-out random fields at these grid sides
_VAL2 = dict(val_sizes=(51, 128), val_count=16)
#: (3D: scored on the maps as Surrogate.map delivers them, a folded map regridded or repaired; see rfmap.training.validation)
_VAL3 = dict(val_sizes=(32, 48), val_count=16, val_repair=True)
_PAPER_2D = dict(steps=12000, batch=8, lr=1e-5, weight_decay=1e-5, schedule="step", step_size=200, gamma=0.5,
                 warmup=0, n_range=(64, 96), clip=1.0)
_NOTE_2D = ("12,000 epochs, AdamW lr 1e-5, weight decay 1e-5, x0.5 every 200 epochs, N in [64, 96], clip 1.0, as "
            "printed; an epoch is one step on a freshly drawn batch (the paper draws a new grid every epoch) and "
            "the batch size, which the paper does not give, is 8.")

_PAPER_3D = dict(steps=4000, batch=2, lr=2e-4, schedule="restarts", T0=600, T_mult=2, lr_min=2e-6, clip=1.0)
_NOTE_3D = ("4,000 epochs, AdamW lr 2e-4, betas (0.9, 0.995), weight decay 5e-5, cosine warm restarts T0 = 600, "
            "T_mult = 2, min lr 2e-6, N in [32, 48], clip 1.0, as printed; an epoch is one step on a freshly drawn "
            "batch of 2 (the paper gives no batch size).")


def _density2d(name: str, boundary: str, *, beltrami: float, steps: int, time_limit: float,
               description: str) -> Presets:
    """A 2D density model (``beltrami``: the weight of the Beltrami energy beside the density loss, 0 for a DEM) on
    the hard fields and fold penalty of :data:`_HARD2` and :data:`_FOLD_HARD`; its ``full`` preset trains at N in
    [48, 96] for ``steps`` steps or ``time_limit`` seconds."""
    base = TrainConfig(name=name, task=TaskSpec("density", 2, boundary), description=description,
                       loss=LossWeights(beltrami=beltrami, **_FOLD_HARD), lr=5e-4, warmup=300, density_field=_HARD2)
    return Presets.of(base, ci=_CI, paper=_PAPER_2D, paper_note=_NOTE_2D,
                      full=dict(steps=steps, batch=4, time_limit=time_limit, val_every=500, threads=2, workers=1,
                                n_range=(48, 96), **_VAL2))


def _density3d(name: str, boundary: str, *, fold: dict, description: str) -> Presets:
    """A 3D density model on the fields of :data:`_HARD3` with the fold penalty ``fold``; one cosine cycle at lr
    5e-4 (the paper's cosine annealing with warm restarts at 2e-4 is for a GPU; under an hour on a CPU one cycle gets further)."""
    base = TrainConfig(name=name, task=TaskSpec("density", 3, boundary), description=description,
                       model=ModelConfig(base=8, depth=2), n_range=(32, 48), jitter=0.0, lr=5e-4, weight_decay=5e-5,
                       betas=(0.9, 0.995), schedule="cosine", warmup=200, lr_min=2e-6, val_n=24,
                       density_field=_HARD3, loss=LossWeights(**fold))
    return Presets.of(base, ci=_CI3, paper=_PAPER_3D, paper_note=_NOTE_3D,
                      full=dict(steps=3000, batch=2, time_limit=3300.0, val_every=500, ckpt_every=100, threads=2,
                                workers=1, **_VAL3))


def _across_sizes(parent: Presets, *, name: str, description: str, ci_range: tuple[int, int],
                  full: dict) -> Presets:
    """``parent`` trained from its weights across grid sides (log-uniform), to run natively (the network on the
    requested grid): ``full`` changes the full preset (which runs on one thread), the ``ci`` preset draws sides from
    ``ci_range`` and validates natively, the paper preset draws the full preset's sides (which its description
    says after the paper's recipe)."""
    lo, hi = full["n_range"]
    return parent.derive(name=name, description=description,
                         paper_note=f"the paper's recipe: {parent.paper_note} This preset draws N log-uniformly from "
                                    f"[{lo}, {hi}] instead, the sides this configuration is trained to run at.",
                         ci=dict(n_range=ci_range, n_sampling="log", val_native=True),
                         full={**full, "threads": 1, "workers": 0},
                         paper=dict(n_range=full["n_range"], n_sampling="log"))


# the low-frequency share since 69,526 steps: before, such maps had three times the default maps' error
_BELTRAMI2D = Presets.of(
    TrainConfig(name="beltrami2d", task=TaskSpec("beltrami", 2, "fixed"),
                description="Reconstruction of a boundary-fixing 2D map from its Beltrami coefficient; loss "
                            "||mu(u) - mu_in||^2 on the coefficients of random boundary-fixing maps, 30 % of them "
                            "low-frequency (1-4 modes); no solver data." + _N48_NOTE,
                beltrami_field=RandomBeltramiConfig(sup=(0.05, 0.6), low=0.3), loss=LossWeights(fold=1.0)),
    ci=_CI,
    full=dict(steps=6000, batch=4, time_limit=3000.0, val_every=500, threads=1, workers=1, n_range=(48, 96),
              **_VAL2),
    paper=dict(steps=250000, batch=8, lr=1e-3, schedule="step", step_size=25000, gamma=0.5, warmup=0,
               n_range=(64, 96), clip=1.0),
    paper_note="250,000 epochs with step decay, N in [64, 96], clip 1.0, as printed; the paper gives neither the "
               "learning rate nor the decay, so lr 1e-3 (that of the full preset) halved every 25,000 steps (ten "
               "halvings) is used, with batch 8; an epoch is one step on a freshly drawn batch.")
_DEQ2D_SQUARE = _density2d(
    "deq2d-square", "square", beltrami=0.1, steps=6000, time_limit=3000.0,
    description="2D density-equalizing quasi-conformal map (DEQ: density loss + 0.1 Beltrami energy), square "
                "boundary; " + _HARD_NOTE + _N48_NOTE)
_DEQ2D_FREE = _density2d("deq2d-free", "free", beltrami=0.1, steps=2500, time_limit=2700.0,
                         description="2D DEQ map, free boundary; " + _HARD_NOTE + _N48_NOTE)
_DEM2D_SQUARE = _density2d(
    "dem2d-square", "square", beltrami=0.0, steps=2500, time_limit=2700.0,
    description="2D density-equalizing map (density loss only), square boundary; " + _HARD_NOTE + _N48_NOTE)
_DEM3D_CUBE = _density3d(
    "dem3d-cube", "square", fold=_FOLD_HARD,
    description="3D density-equalizing map, cube boundary (density loss on tetrahedra, fold penalty); one cosine "
                "cycle at lr 5e-4. " + _HARD3_NOTE)
# fold penalty 100 until 23,366 steps: with it every steep held-out ramp at N = 48 folded
_DEM3D_FREE = _density3d(
    "dem3d-free", "free", fold=_FOLD_HARD3,
    description="3D density-equalizing map, free boundary (density loss, volume constraint, fold penalty); same "
                "schedule and fields as dem3d-cube, fold penalty 1000 from det J < 0.02.")
#: the FNO comparison: deq2d-square's task, losses, fields, schedule and wall-time budget as they were when the FNO
#: was trained (the U-Net has since moved on to _HARD2 fields and N from 48), with neuraloperator's
#: FNO in place of the U-Net (16 modes, width 24, 4 layers, 12.5 % padding: about the U-Net's parameter count and
#: step time; book: Design decisions); the loss of deq2d-square then (fold penalty of weight 10 from det J < 0.02)
_FNO_DEQ2D_SQUARE = _DEQ2D_SQUARE.derive(
    name="fno-deq2d-square",
    description="Fourier neural operator (FNO: 16 modes per axis, width 24, 4 layers, 12.5 % padding) for "
                "deq2d-square's task (2D DEQ map, square boundary), trained as deq2d-square was then (densities "
                "with narrow peaks and steep ramps) at lr 1e-3.",
    lr=1e-3, loss=LossWeights(beltrami=0.1), density_field=_SHARP2,
    ci=dict(model=ModelConfig(arch="fno", modes=4, width=8, layers=2)),
    full=dict(n_range=(64, 96), model=ModelConfig(arch="fno", modes=16, width=24, layers=4, padding=0.125)),
    paper=dict(model=ModelConfig(arch="fno", modes=16, width=24, layers=4, padding=0.125)),
    paper_note="the paper's recipe for deq2d-square: " + _NOTE_2D + " This preset runs lr 1e-3 instead (the paper "
               "trains no FNO; this configuration's own rate).")
#: the FNO's partner at equal budget (book chapter 12): fno-deq2d-square's task, losses, fields, schedule and steps
#: with deq2d-square's U-Net in place of the FNO, trained once from scratch (study weights, not a shipped model)
_UNET_FNO_BUDGET = _FNO_DEQ2D_SQUARE.derive(
    name="unet-fno-budget",
    description="deq2d-square's U-Net trained exactly as fno-deq2d-square (same task, losses, fields, schedule and "
                "6,000 steps): the equal-budget partner of the FNO.",
    model=ModelConfig(), ci=dict(model=_CI["model"]), full=dict(model=ModelConfig(), time_limit=0.0),
    paper=dict(model=ModelConfig()),
    paper_note="the paper's recipe for deq2d-square: " + _NOTE_2D + " This preset runs lr 1e-3 instead, as "
               "fno-deq2d-square's does (the paper trains no FNO, nor this partner of it).")
#: the Beltrami weight alone (for chapter 8's Fig. 10 study): one recipe, trained from scratch twice, once with
#: lambda_hr = 0 (a DEM) and once with lambda_hr = 0.1 (a DEQ); nothing else differs (study weights, not shipped
#: models)
_ABLATION = {lam: _density2d(
    f"ablation-lambda-{tag}", "square", beltrami=lam, steps=3000, time_limit=0.0,
    description=f"The Beltrami-weight ablation: deq2d-square's recipe (fields, fold penalty, schedule) from "
                f"scratch for 3,000 steps with lambda = {lam:g}; its partner differs only in lambda.")
    for lam, tag in ((0.0, "0"), (0.1, "0.1"))}
#: deq2d-square trained across the sizes the paper tests, to run natively at every side from 32 to 256: log-uniform
#: sides (every octave a third of the steps) at about the same cost per step (batch_points), validated natively at
#: both ends of the range, from deq2d-square's weights (the lineage)
_DEQ2D_SQUARE_NATIVE = _across_sizes(
    _DEQ2D_SQUARE, name="deq2d-square-native", ci_range=(17, 33),
    full=dict(n_range=(32, 256), n_sampling="log", batch_points=20736, batch=16, val_sizes=(32, 51, 128, 256),
              val_native=True, lr=1e-4, ema=0.999, warmup=0, steps=40000, time_limit=7200.0),
    description="deq2d-square's task, losses and fields, trained from its weights across grid sides 32-256 "
                "(log-uniform, about 20,736 grid points a batch) and validated natively at 32, 51, 128 and 256: it "
                "runs natively at every side the paper tests.")
#: dem3d-cube trained across the 3D grid sides the paper tests (24-64), so that its resolution rows run natively: the
#: same log-uniform sides at about the cost of two 40^3 grids per step, validated natively at both ends
_DEM3D_CUBE_NATIVE = _across_sizes(
    _DEM3D_CUBE, name="dem3d-cube-native", ci_range=(9, 17),
    full=dict(n_range=(24, 64), n_sampling="log", batch_points=128000, batch=2, val_sizes=(32, 64), val_count=8,
              val_native=True, val_every=1000, lr=1e-4, ema=0.999, warmup=0, steps=40000, time_limit=8400.0),
    description="dem3d-cube's task, losses and fields, trained from its weights across grid sides 24-64 "
                "(log-uniform, about 128,000 grid points a step) and validated natively at 32 and 64: it runs "
                "natively at every side the paper tests.")

#: Every training configuration by name, each a ``{preset: TrainConfig}`` (:meth:`Presets.configs`); the names are
#: those of :func:`config_names`.
CONFIGS: dict[str, dict[str, TrainConfig]] = {
    p.full.name: p.configs()
    for p in (_BELTRAMI2D, _DEQ2D_SQUARE, _DEQ2D_FREE, _DEM2D_SQUARE, _DEM3D_CUBE, _DEM3D_FREE, _FNO_DEQ2D_SQUARE,
              _DEQ2D_SQUARE_NATIVE, _DEM3D_CUBE_NATIVE, _UNET_FNO_BUDGET, *_ABLATION.values())
}


@contextmanager
def registered_config(presets: Presets) -> Iterator[str]:
    """Add ``presets`` to :data:`CONFIGS` under its name for the duration of a ``with`` block (a configuration tried
    out, or a test's), then remove it; yields the name.  ``ValueError`` if the name is taken."""
    name = presets.full.name
    if name in CONFIGS:
        raise ValueError(f"config {name!r} exists already")
    CONFIGS[name] = presets.configs()
    try:
        yield name
    finally:
        CONFIGS.pop(name, None)


def config_names() -> list[str]:
    """Names of the training configurations (each with ``ci``, ``full`` and ``paper`` presets)."""
    return list(CONFIGS)


def get_config(name: str, preset: str | None = None) -> TrainConfig:
    """The named configuration at ``preset`` (default: :func:`scale`)."""
    if name not in CONFIGS:
        raise ValueError(f"unknown config {name!r}; known configs: {', '.join(CONFIGS)}")
    preset = preset or scale()
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; expected one of {PRESETS}")
    return CONFIGS[name][preset]
