"""``rfmap train`` (also ``python -m rfmap.training``): the command line of training.

``rfmap train --config NAME [--preset ci|full|paper] [--device auto|cpu|cuda] [--init MODEL|FILE] [--resume]`` trains
the named configuration of :mod:`rfmap.training.config`.  Data-parallel: ``torchrun --nproc_per_node=K -m rfmap.training --config
NAME ...`` runs K processes (gloo on CPU, NCCL on GPU); K processes with batch ``B`` train the same model as one
process with batch ``K*B``.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import torch

from .config import PRESETS, TrainConfig, config_names, get_config
from ..core.device import check_precision, resolve_device
from ..surrogate import Surrogate
from .loop import train
from .state import load_init

__all__ = ["build_parser", "run", "main"]


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """The arguments of ``rfmap train`` (:doc:`/book/api/cli`), added to ``parser`` or to a new parser."""
    p = parser or argparse.ArgumentParser(prog="rfmap train", description="Train a surrogate from a named config.")
    p.add_argument("--config", required=True,
                   help=f"one of: {', '.join(config_names())} (rfmap models lists the shipped models; "
                        "ablation-lambda-* are the Beltrami-weight ablations of chapter 08, unet-fno-budget the "
                        "U-Net trained at the FNO's budget in chapter 12)")
    p.add_argument("--preset", choices=list(PRESETS), default=None,
                   help="ci (seconds), full (the shipped CPU runs) or paper (the paper's hyperparameters); "
                        "default: $RFMAP_SCALE or full")
    p.add_argument("--out", default=None, help="output directory (default runs/CONFIG)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--finish", action="store_true",
                   help="with --resume: train no further; end the run from its checkpoint (final validation, best "
                        "validated state, weight file), e.g. after stopping it early")
    p.add_argument("--init", default=None, metavar="MODEL|FILE",
                   help="start from a shipped model or a .safetensors file (fresh optimiser and schedule)")
    p.add_argument("--device", default="cpu", help="auto, cpu (default) or cuda")
    p.add_argument("--precision", default=None, metavar="fp32|bf16",
                   help="the network's arithmetic in training: fp32, or bf16 autocast (CUDA, or a CPU with "
                        "AVX512-BF16/AMX); losses and Jacobians stay in fp32 (default: the config's, fp32)")
    p.add_argument("--steps", type=int, default=None, help="override the number of steps")
    p.add_argument("--batch", type=int, default=None, help="override the per-process batch size")
    p.add_argument("--time-limit", type=float, default=None, help="override the wall-time limit (s; 0: none)")
    p.add_argument("--lr", type=float, default=None,
                   help="override the peak learning rate (e.g. lower for a gentle continued run with --init)")
    p.add_argument("--ema", type=float, default=None, metavar="DECAY",
                   help="keep an exponential moving average of the weights with this decay (e.g. 0.999); validation, "
                        "checkpoint choice and the shipped file use it (0: off, the default)")
    p.add_argument("--threads", type=int, default=None,
                   help="torch CPU threads per process (also with --device cuda: validation runs on a CPU copy)")
    p.add_argument("--workers", type=int, default=None, help="batch-drawing worker processes (0: a thread)")
    p.add_argument("--seed", type=int, default=None,
                   help="seed of the initial weights (and of --grow's new channels) and of each step's grid side, "
                        "fields and sample points; the held-out validation fields do not depend on it (default: "
                        "the config's, 0)")
    p.add_argument("--teacher", default=None, metavar="flow|diffusion|none",
                   help="density configs: a classical solver's map of a share of each batch's fields as a supervised "
                        "target beside the data-free losses (rfmap.tasks.teacher; default: the config's, none)")
    p.add_argument("--teacher-share", type=float, default=None, help="share of each batch with a target (0, 1]")
    p.add_argument("--teacher-weight", type=float, default=None, help="weight of the teacher's displacement loss")
    p.add_argument("--hard-share", type=float, default=None, metavar="P",
                   help="density configs: override the share of hard training fields (a single steep ramp or narrow "
                        "peak, RandomDensityConfig.p_hard), e.g. to weigh the fields whose maps fold more")
    p.add_argument("--fold-weight", type=float, default=None, metavar="W",
                   help="override the weight of the fold penalty (LossWeights.fold), e.g. stronger against maps "
                        "that fold on steep ramps")
    p.add_argument("--base", type=int, default=None, help="override the U-Net's base width (channels)")
    p.add_argument("--depth", type=int, default=None, help="override the U-Net's number of levels")
    p.add_argument("--grow", type=int, default=None, metavar="BASE",
                   help="with --init: widen the parent U-Net to BASE channels by a function-preserving growth "
                        "(rfmap.nn.grow; a multiple of the parent's base) and train from there")
    p.add_argument("--n-range", type=int, nargs=2, default=None, metavar=("LO", "HI"),
                   help="override the training grid sides (e.g. 24 64 in 3D, 32 256 in 2D)")
    p.add_argument("--n-sampling", choices=["uniform", "log", "mixed"], default=None,
                   help="how each step's grid side is drawn from the range (log: every octave equally often; mixed: "
                        "half log, half uniform on the small sides LO..3 LO)")
    p.add_argument("--batch-points", type=int, default=None, metavar="P",
                   help="each step's batch holds about P grid points (at most --batch), so steps cost alike at "
                        "every size (0: always --batch)")
    p.add_argument("--val-sizes", type=int, nargs="+", default=None, metavar="N",
                   help="override the validation grid sides (e.g. the extremes of the range)")
    p.add_argument("--val-count", type=int, default=None, metavar="K",
                   help="override the number of held-out validation fields at each side, e.g. more for a steadier "
                        "score (density: field j is of family j mod 4, so a multiple of 4 weighs them alike; the "
                        "first K fields are the same at every K)")
    p.add_argument("--val-native", action="store_true",
                   help="validate with the network on each validation grid itself (Surrogate.map(native=True))")
    p.add_argument("--snapshot-every", type=int, default=None, metavar="K",
                   help="write the weights every K steps to OUT/snapshots/ (self-contained files for rfmap validate)")
    p.add_argument("--no-validate", action="store_true",
                   help="no validation during or after the run (e.g. on an accelerator); score the snapshots "
                        "afterwards with rfmap validate")
    p.add_argument("--no-progress", action="store_true", help="print no progress bar")
    return p


def run(args) -> Surrogate:
    """Train as the parsed arguments ``args`` of :func:`build_parser` say; returns the trained surrogate."""
    cfg = get_config(args.config, args.preset)
    over = {k: v for k, v in {"steps": args.steps, "batch": args.batch, "time_limit": args.time_limit,
                              "threads": args.threads, "seed": args.seed, "workers": args.workers,
                              "lr": args.lr, "ema": args.ema,
                              "precision": getattr(args, "precision", None)}.items()
            if v is not None}
    for k in ("steps", "batch"):
        if k in over and over[k] < 1:
            raise ValueError(f"--{k} must be at least 1, got {over[k]}")
    if over.get("workers", 0) < 0 or over.get("threads", 0) < 0:
        raise ValueError("--workers and --threads must not be negative")
    if "lr" in over and not (math.isfinite(over["lr"]) and over["lr"] > 0):
        raise ValueError(f"--lr must be a positive number, got {over['lr']}")
    if "ema" in over and not (math.isfinite(over["ema"]) and 0.0 <= over["ema"] < 1.0):
        raise ValueError(f"--ema must lie in [0, 1), got {over['ema']}")
    cfg = cfg.with_overrides(**over, **_structured_overrides(cfg, args))
    device = resolve_device(args.device)
    cfg = cfg.with_overrides(precision=check_precision(cfg.precision, device))
    if args.init and args.resume:
        raise ValueError("--init and --resume exclude each other (a resumed run keeps its own lineage)")
    if args.init:
        load_init(args.init, cfg)  # validate before any output is written
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if device.type == "cuda" else "gloo"
        if device.type == "cuda":
            torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
            device = torch.device("cuda", torch.cuda.current_device())
        torch.distributed.init_process_group(backend)
    try:
        return train(cfg, args.out, resume=args.resume, init=args.init, device=device,
                     progress=not args.no_progress, command=_command_line(args), finish=args.finish)
    finally:
        if world > 1 and torch.distributed.is_initialized():
            torch.distributed.destroy_process_group()


def _structured_overrides(cfg: TrainConfig, args) -> dict:
    """Overrides of the nested options (teacher, model) and of validation from the command line; ``ValueError``
    on values out of range."""
    from dataclasses import replace as _replace

    from ..tasks.teacher import TeacherConfig

    over: dict = {}
    t = {k: v for k, v in {"method": getattr(args, "teacher", None), "share": getattr(args, "teacher_share", None),
                           "weight": getattr(args, "teacher_weight", None)}.items() if v is not None}
    if t:
        over["teacher"] = TeacherConfig(**{**cfg.teacher.__dict__, **t})
        if over["teacher"].active and not cfg.task.task.teacher:
            raise ValueError(f"--teacher: config {cfg.name!r} maps a {cfg.task.task.title} field; a classical "
                             "teacher applies to density configs only")
    over.update(_size_overrides(args))
    hard = getattr(args, "hard_share", None)
    if hard is not None:
        if cfg.density_field is None:
            raise ValueError(f"--hard-share: config {cfg.name!r} draws no density fields")
        if not (math.isfinite(hard) and 0.0 <= hard <= 1.0):
            raise ValueError(f"--hard-share must lie in [0, 1], got {hard}")
        over["density_field"] = _replace(cfg.density_field, p_hard=hard)
    fold = getattr(args, "fold_weight", None)
    if fold is not None:
        if not (math.isfinite(fold) and fold >= 0.0):
            raise ValueError(f"--fold-weight must be finite and non-negative, got {fold}")
        over["loss"] = _replace(cfg.loss, fold=fold)
    grow = getattr(args, "grow", None)
    if grow is not None:
        if not getattr(args, "init", None):
            raise ValueError("--grow widens the network of --init; give the parent with --init")
        if getattr(args, "base", None) is not None and args.base != grow:
            raise ValueError(f"--grow {grow} and --base {args.base} disagree")
        over["grow"] = True
    m = {k: v for k, v in {"base": grow if grow is not None else getattr(args, "base", None),
                           "depth": getattr(args, "depth", None)}.items() if v is not None}
    if m:
        if cfg.model.arch != "unet":
            raise ValueError("--base and --depth apply to U-Net configs")
        if any(v < 1 for v in m.values()):
            raise ValueError(f"--base and --depth must be at least 1, got {m}")
        over["model"] = _replace(cfg.model, **m)
    every = getattr(args, "snapshot_every", None)
    if every is not None:
        if every < 0:
            raise ValueError(f"--snapshot-every must not be negative, got {every}")
        over["snapshot_every"] = every
    if getattr(args, "no_validate", False):
        over.update(val_every=0, select_best=False)
    return over


def _size_overrides(args) -> dict:
    """The training and validation grid sides of the command line (``--n-range``, ``--n-sampling``,
    ``--batch-points``, ``--val-sizes``, ``--val-count``, ``--val-native``); ``ValueError`` on values out of
    range."""
    over: dict = {}
    rng = getattr(args, "n_range", None)
    if rng is not None:
        lo, hi = rng
        if not 3 <= lo <= hi:
            raise ValueError(f"--n-range must be LO HI with 3 <= LO <= HI, got {lo} {hi}")
        over["n_range"] = (lo, hi)
    if getattr(args, "n_sampling", None):
        over["n_sampling"] = args.n_sampling
    bp = getattr(args, "batch_points", None)
    if bp is not None:
        if bp < 0:
            raise ValueError(f"--batch-points must not be negative, got {bp}")
        over["batch_points"] = bp
    vs = getattr(args, "val_sizes", None)
    if vs:
        if min(vs) < 3:
            raise ValueError(f"--val-sizes must be at least 3, got {min(vs)}")
        over["val_sizes"] = tuple(vs)
    vc = getattr(args, "val_count", None)
    if vc is not None:
        if vc < 1:
            raise ValueError(f"--val-count must be at least 1, got {vc}")
        over["val_count"] = vc
    if getattr(args, "val_native", False):
        over["val_native"] = True
    return over


def _command_line(args) -> str:
    parts = ["rfmap train", f"--config {args.config}"]
    if args.preset:
        parts.append(f"--preset {args.preset}")
    for flag, val in [("--steps", args.steps), ("--batch", args.batch), ("--time-limit", args.time_limit),
                      ("--threads", args.threads), ("--workers", args.workers), ("--seed", args.seed),
                      ("--lr", args.lr), ("--ema", args.ema), ("--init", args.init),
                      ("--precision", getattr(args, "precision", None)),
                      ("--teacher", getattr(args, "teacher", None)),
                      ("--teacher-share", getattr(args, "teacher_share", None)),
                      ("--teacher-weight", getattr(args, "teacher_weight", None)),
                      ("--hard-share", getattr(args, "hard_share", None)),
                      ("--fold-weight", getattr(args, "fold_weight", None)),
                      ("--base", getattr(args, "base", None)), ("--depth", getattr(args, "depth", None)),
                      ("--grow", getattr(args, "grow", None)),
                      ("--n-range", " ".join(map(str, args.n_range)) if getattr(args, "n_range", None) else None),
                      ("--n-sampling", getattr(args, "n_sampling", None)),
                      ("--batch-points", getattr(args, "batch_points", None)),
                      ("--val-sizes", " ".join(map(str, args.val_sizes)) if getattr(args, "val_sizes", None)
                       else None),
                      ("--val-count", getattr(args, "val_count", None)),
                      ("--snapshot-every", getattr(args, "snapshot_every", None))]:
        if val is not None:
            parts.append(f"{flag} {val:g}" if isinstance(val, float) else f"{flag} {val}")
    if args.device and args.device != "cpu":
        parts.append(f"--device {args.device}")
    if getattr(args, "val_native", False):
        parts.append("--val-native")
    if getattr(args, "no_validate", False):
        parts.append("--no-validate")
    if args.resume:
        parts.append("--resume")
    if args.finish:
        parts.append("--finish")
    return " ".join(parts)


def main(argv=None) -> int:
    """``python -m rfmap.training`` (same options as ``rfmap train``); returns the exit status (2 on bad input)."""
    args = build_parser().parse_args(argv)
    try:
        run(args)
    except ValueError as e:
        print(f"rfmap train: error: {e}", file=sys.stderr)
        return 2
    return 0
