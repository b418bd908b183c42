r"""Typed training configurations with named ``ci`` and ``full`` presets.

``RFMAP_SCALE`` (``ci`` or ``full``, default ``full``) chooses the preset wherever none is named.  ``ci`` presets
train tiny models for a few steps (seconds on a laptop CPU, used by the tests and by the notebooks under CI);
``full`` presets are the ones that produced the shipped weights; ``paper`` presets are the paper's hyperparameters
as printed (for a GPU: ``rfmap train --config NAME --preset paper --device cuda``), with the paper's "epoch" read as
one optimisation step on a freshly drawn batch (the paper draws a new training grid every epoch).  ``RFMAP_SCALE``
only switches between ``ci`` and ``full``.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field, replace

from ..fields import RandomBeltramiConfig, RandomDensityConfig
from ..tasks import LossWeights, TaskSpec
from ..tasks.teacher import TeacherConfig

__all__ = ["TrainConfig", "ModelConfig", "CONFIGS", "PRESETS", "get_config", "config_names", "scale"]

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

    Optimiser defaults follow the paper: AdamW, gradient clipping at 1.0, a random training resolution per step,
    Sobol-jittered sampling.  ``schedule`` is ``'cosine'`` (linear warm-up then cosine decay), ``'step'``
    (decay by ``gamma`` every ``step_size`` steps) or ``'restarts'`` (cosine annealing with warm restarts,
    ``T0``, ``T_mult``).  ``ema`` > 0 keeps an exponential moving average of the weights (Polyak averaging,
    :class:`rfmap.training.averaging.WeightAverage`) with that decay; validation, the checkpoint choice and the shipped file then
    use the averaged weights (0, the default: the weights as trained).  ``teacher`` (density tasks,
    :class:`rfmap.tasks.teacher.TeacherConfig`): a classical solver's map of a share of each batch's fields as a supervised
    target beside the data-free losses (default: none, data-free as in the paper).  ``snapshot_every`` > 0 writes the
    weights every that many steps to ``OUT/snapshots/`` (single self-contained files, scored afterwards by
    ``rfmap validate``).  ``val_repair``: score the held-out maps as
    ``Surrogate.map`` delivers them (a folded network map regridded or repaired; :func:`rfmap.training.validation.evaluate`)
    instead of the raw network output; ``val_native``: run the network on the validation grid itself
    (``Surrogate.map(..., native=True)``) instead of a working grid inside ``n_range``.  A run started with
    ``init`` validates its parent at step 0, so that the parent competes with every checkpoint.

    Training grid sides: ``n_sampling`` ``'uniform'`` (every side in ``n_range`` equally often) or ``'log'``
    (log-uniform: every octave of sizes equally often, a curriculum across the sizes the paper tests) or
    ``'mixed'`` (half the steps log-uniform, half uniform on the small sides ``[lo, 3 lo]``).
    ``batch_points`` > 0 sets each step's batch to about that many grid points,
    :math:`B(N) = \mathrm{clip}(\mathrm{round}(P / N^d), 1, \mathtt{batch})`, so that a step costs about the same
    at every size (0: always ``batch``).  ``grow`` (with ``init``): the parent network is widened to ``model.base``
    channels by a function-preserving growth (:func:`rfmap.nn.grow.grow_unet`) before training.

    ``precision``: ``'fp32'`` or ``'bf16'`` (:data:`rfmap.core.device.PRECISIONS`): with ``'bf16'`` the network's
    forward and backward pass run under bfloat16 autocast (CUDA, or a CPU with AVX512-BF16/AMX); the losses, the
    Jacobians, the fold penalty, the optimiser's state and validation stay in float32.
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


def _presets(name, task, description, ci: dict, full: dict, paper: dict, paper_note: str,
             **common) -> dict[str, TrainConfig]:
    base = TrainConfig(name=name, task=task, description=description, **common)
    # the paper's runs: no wall-time limit, every thread of the machine, one batch worker
    paper = {"time_limit": 0.0, "threads": 0, "workers": 1, "val_every": 1000, "ckpt_every": 500,
             **{k: full[k] for k in ("val_sizes", "val_count", "val_repair") if k in full}, **paper}
    return {"ci": replace(base, preset="ci", **ci), "full": replace(base, preset="full", **full),
            "paper": replace(base, preset="paper", description=f"{description} Paper preset: {paper_note}",
                             **paper)}


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

CONFIGS: dict[str, dict[str, TrainConfig]] = {
    **{
        "beltrami2d": _presets(
            "beltrami2d", TaskSpec("beltrami", 2, "fixed"),
            # the low-frequency share since 69,526 steps: before, such maps had three times the default maps' error
            "Reconstruction of a boundary-fixing 2D map from its Beltrami coefficient; loss ||mu(u) - mu_in||^2 on "
            "the coefficients of random boundary-fixing maps, 30 % of them low-frequency (1-4 modes); no solver "
            "data." + _N48_NOTE,
            _CI, dict(steps=6000, batch=4, time_limit=3000.0, val_every=500, threads=1, workers=1, n_range=(48, 96),
                      **_VAL2),
            dict(steps=250000, batch=8, lr=1e-3, schedule="step", step_size=25000, gamma=0.5, warmup=0,
                 n_range=(64, 96), clip=1.0),
            "250,000 epochs with step decay, N in [64, 96], clip 1.0, as printed; the paper gives neither the "
            "learning rate nor the decay, so lr 1e-3 (that of the full preset) halved every 25,000 steps (ten "
            "halvings) is used, with batch 8; an epoch is one step on a freshly drawn batch.",
            beltrami_field=RandomBeltramiConfig(sup=(0.05, 0.6), low=0.3), loss=LossWeights(fold=1.0),
        ),
    },
    **{
        name: _presets(
            name, TaskSpec("density", 2, boundary), desc, _CI,
            dict(steps=steps, batch=4, time_limit=limit, val_every=500, threads=2, workers=1, **_VAL2),
            _PAPER_2D, _NOTE_2D,
            loss=LossWeights(beltrami=lam, **fold), lr=5e-4, warmup=300, density_field=fields,
        )
        for name, boundary, lam, steps, limit, fields, fold, desc in [
            ("deq2d-square", "square", 0.1, 6000, 3000.0, _HARD2, _FOLD_HARD,
             "2D density-equalizing quasi-conformal map (DEQ: density loss + 0.1 Beltrami energy), square boundary; "
             + _HARD_NOTE + _N48_NOTE),
            ("deq2d-free", "free", 0.1, 2500, 2700.0, _HARD2, _FOLD_HARD,
             "2D DEQ map, free boundary; " + _HARD_NOTE + _N48_NOTE),
            ("dem2d-square", "square", 0.0, 2500, 2700.0, _HARD2, _FOLD_HARD,
             "2D density-equalizing map (density loss only), square boundary; " + _HARD_NOTE + _N48_NOTE),
        ]
    },
    **{
        name: _presets(
            name, TaskSpec("density", 3, boundary), desc, _CI3,
            dict(steps=3000, batch=2, time_limit=3300.0, val_every=500, ckpt_every=100, threads=2, workers=1,
                 **_VAL3),
            dict(steps=4000, batch=2, lr=2e-4, schedule="restarts", T0=600, T_mult=2, lr_min=2e-6, clip=1.0),
            "4,000 epochs, AdamW lr 2e-4, betas (0.9, 0.995), weight decay 5e-5, cosine warm restarts T0 = 600, "
            "T_mult = 2, min lr 2e-6, N in [32, 48], clip 1.0, as printed; an epoch is one step on a freshly drawn "
            "batch of 2 (the paper gives no batch size).",
            model=ModelConfig(base=8, depth=2), n_range=(32, 48), jitter=0.0, lr=5e-4, weight_decay=5e-5,
            betas=(0.9, 0.995), schedule="cosine", warmup=200, lr_min=2e-6, val_n=24, density_field=fields,
            loss=LossWeights(**fold),
        )
        for name, boundary, fields, fold, desc in [
            ("dem3d-cube", "square", _HARD3, _FOLD_HARD,
             # the paper trains 4000 epochs with warm restarts at lr 2e-4 on a GPU; under an hour on a CPU one
             # cosine cycle at lr 5e-4 gets further
             "3D density-equalizing map, cube boundary (density loss on tetrahedra, fold penalty); one cosine cycle "
             "at lr 5e-4. " + _HARD3_NOTE),
            # fold penalty 100 until 23,366 steps: with it every steep held-out ramp at N = 48 folded
            ("dem3d-free", "free", _HARD3, _FOLD_HARD3, "3D density-equalizing map, free boundary (density loss, "
             "volume constraint, fold penalty); same schedule and fields as dem3d-cube, fold penalty 1000 from "
             "det J < 0.02."),
        ]
    },
}

for _name in ("deq2d-square", "deq2d-free", "dem2d-square"):
    CONFIGS[_name]["full"] = replace(CONFIGS[_name]["full"], n_range=(48, 96))

#: the FNO comparison: deq2d-square's task, losses, fields, schedule and wall-time budget as they were when the FNO
#: was trained (the U-Net has since moved on to _HARD2 fields and N from 48), with neuraloperator's
#: FNO in place of the U-Net (16 modes, width 24, 4 layers, 12.5 % padding: about the U-Net's parameter count and
#: step time; book: Design decisions)
CONFIGS["fno-deq2d-square"] = {
    preset: replace(
        # the loss of deq2d-square when the FNO was trained (fold penalty of weight 10 from det J < 0.02)
        cfg, name="fno-deq2d-square", lr=1e-3, loss=LossWeights(beltrami=0.1), density_field=_SHARP2,
        n_range=(64, 96) if preset == "full" else cfg.n_range,
        model=ModelConfig(arch="fno", modes=4, width=8, layers=2) if preset == "ci" else
        ModelConfig(arch="fno", modes=16, width=24, layers=4, padding=0.125),
        description="Fourier neural operator (FNO: 16 modes per axis, width 24, 4 layers, 12.5 % padding) for "
                    "deq2d-square's task (2D DEQ map, square boundary), trained as deq2d-square was then (densities "
                    "with narrow peaks and steep ramps) at lr 1e-3." +
                    (f" Paper preset: {_NOTE_2D}" if preset == "paper" else ""))
    for preset, cfg in CONFIGS["deq2d-square"].items()
}


def _across_sizes(parent: str, name: str, full: dict, ci_range: tuple[int, int], what: str) -> dict:
    """The presets of ``parent`` trained from its weights across grid sides (log-uniform), to run natively (the
    network on the requested grid): ``full`` overrides the full preset, the ``ci`` preset draws sides from
    ``ci_range``, the paper preset the full preset's sides; ``what`` opens each description."""
    out = {}
    for preset, cfg in CONFIGS[parent].items():
        over = {"full": {**full, "threads": 1, "workers": 0},
                "ci": dict(n_range=ci_range, n_sampling="log", val_native=True)}.get(
                    preset, dict(n_range=full["n_range"], n_sampling="log"))
        paper = " " + cfg.description[cfg.description.index("Paper preset"):] if preset == "paper" else ""
        out[preset] = replace(cfg, name=name, **over, description=what + paper)
    return out


#: deq2d-square trained across the sizes the paper tests, to run natively at every side from 32 to 256: log-uniform
#: sides (every octave a third of the steps) at about the same cost per step (batch_points), validated natively at
#: both ends of the range, from deq2d-square's weights (the lineage)
CONFIGS["deq2d-square-native"] = _across_sizes(
    "deq2d-square", "deq2d-square-native",
    dict(n_range=(32, 256), n_sampling="log", batch_points=20736, batch=16, val_sizes=(32, 51, 128, 256),
         val_native=True, lr=1e-4, ema=0.999, warmup=0, steps=40000, time_limit=7200.0), (17, 33),
    "deq2d-square's task, losses and fields, trained from its weights across grid sides 32-256 (log-uniform, about "
    "20,736 grid points a batch) and validated natively at 32, 51, 128 and 256: it runs natively at every side the "
    "paper tests.")
#: dem3d-cube trained across the 3D grid sides the paper tests (24-64), so that its resolution rows run natively: the
#: same log-uniform sides at about the cost of two 40^3 grids per step, validated natively at both ends
CONFIGS["dem3d-cube-native"] = _across_sizes(
    "dem3d-cube", "dem3d-cube-native",
    dict(n_range=(24, 64), n_sampling="log", batch_points=128000, batch=2, val_sizes=(32, 64), val_count=8,
         val_native=True, val_every=1000, lr=1e-4, ema=0.999, warmup=0, steps=40000, time_limit=8400.0), (9, 17),
    "dem3d-cube's task, losses and fields, trained from its weights across grid sides 24-64 (log-uniform, about "
    "128,000 grid points a step) and validated natively at 32 and 64: it runs natively at every side the paper "
    "tests.")


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
