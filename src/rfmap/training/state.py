r"""The state of a training run: model, optimiser, schedule, step, clock, best validated weights and lineage.

:class:`TrainState` is everything the loop reads and updates; :func:`rfmap.training.loop.train` builds it for a fresh,
warm-started (``--init``) or resumed (``--resume``) run.  A warm start keeps the lineage of the weights it starts from
(parent name and SHA-256, cumulative steps and wall time, :func:`load_init`); a checkpoint (``checkpoint.pt``: model,
optimiser, scheduler, step, loaded with ``weights_only=True`` onto any device) holds the state of an interrupted run.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import torch

from .._version import __version__
from ..nn.grow import check_growth, grow_unet
from ..nn.registry import build_model
from ..surrogate import Surrogate, WEIGHTS_DIR, models
from ..tasks import TaskSpec
from .averaging import WeightAverage
from .config import TrainConfig
from .lineage import run_settings
from .validation import score

__all__ = ["TrainState", "memory_format", "machine", "sha256", "load_init", "learning_rates", "run_learning_rates"]


def memory_format(dim: int) -> torch.memory_format:
    """Memory format of a ``dim``-dimensional network and its inputs during training: ``channels_last_3d`` in 3D
    (oneDNN's Conv3d forward and backward are faster there; the same arithmetic up to float rounding),
    ``contiguous_format`` in 2D."""
    return torch.channels_last_3d if dim == 3 else torch.contiguous_format


def _dist_info() -> tuple[int, int]:
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        return torch.distributed.get_rank(), torch.distributed.get_world_size()
    return 0, 1


def _scheduler(opt, cfg: TrainConfig, clock: Callable[[], float] | None = None):
    """The learning-rate schedule of ``cfg``.

    ``cosine``: linear warm-up, then a cosine from ``lr`` to ``lr_min``.  With a wall-time limit and a ``clock``
    (seconds trained so far), the cosine follows whichever of the step count and the elapsed time is further
    along, so that the learning rate reaches ``lr_min`` when the budget ends even if fewer steps fit than
    ``steps``; such runs depend on the machine's speed and are not bit-reproducible (runs without a time limit
    are).  Data-parallel runs follow the step count only, so that every rank uses the same rate."""
    if cfg.schedule == "cosine":
        def f(step):
            if step < cfg.warmup:
                return (step + 1) / max(1, cfg.warmup)
            t = (step - cfg.warmup) / max(1, cfg.steps - cfg.warmup)
            if clock is not None and cfg.time_limit > 0:
                t = max(t, clock() / cfg.time_limit)
            return cfg.lr_min / cfg.lr + (1 - cfg.lr_min / cfg.lr) * 0.5 * (1 + math.cos(math.pi * min(t, 1.0)))
        return torch.optim.lr_scheduler.LambdaLR(opt, f)
    if cfg.schedule == "step":
        return torch.optim.lr_scheduler.StepLR(opt, cfg.step_size, cfg.gamma)
    if cfg.schedule == "restarts":
        return torch.optim.lr_scheduler.CosineAnnealingWarmRestarts(opt, cfg.T0, cfg.T_mult, eta_min=cfg.lr_min)
    raise ValueError(f"unknown schedule {cfg.schedule!r}; expected cosine, step or restarts")


def learning_rates(cfg: TrainConfig, steps: int | None = None, *, stopped_at: int | None = None) -> list[float]:
    """The learning rate of each of the first ``steps`` optimiser steps (default ``cfg.steps``) of a run of ``cfg``
    (its ``schedule``) that is not stopped by a wall-time limit (``--time-limit``): the rates by the step count
    alone.  A time-limited run with the ``cosine`` schedule stretches the same cosine over the elapsed time, so it
    may reach ``lr_min`` in fewer steps; the ``step`` and ``restarts`` schedules follow the step count in every
    run.

    ``stopped_at``: the step at which such a run reached its time limit.  The rates are then those of its steps up
    to that one (``steps`` is ignored), with its clock read as if every step took the same time (step ``k`` at
    ``k / stopped_at`` of ``cfg.time_limit``), since a run's record keeps its total time, not each step's.

    >>> from rfmap.training.config import get_config
    >>> cfg = get_config("deq2d-square", "full")
    >>> rates = learning_rates(cfg, stopped_at=cfg.steps // 2)
    >>> len(rates), rates[-1] < learning_rates(cfg)[cfg.steps // 2]
    (3000, True)
    """
    if stopped_at is not None and cfg.time_limit <= 0:
        raise ValueError("stopped_at needs a run with a time limit (cfg.time_limit > 0)")
    opt = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=cfg.lr)
    done = [0]
    clock = None if stopped_at is None else (lambda: done[0] / max(1, stopped_at) * cfg.time_limit)
    sched = _scheduler(opt, cfg, clock)
    rates = []
    for _ in range(stopped_at if stopped_at is not None else cfg.steps if steps is None else steps):
        rates.append(opt.param_groups[0]["lr"])
        opt.step()
        done[0] += 1
        sched.step()
    return rates


def run_learning_rates(meta: dict, preset: TrainConfig, run: int = 1) -> tuple[list[float], bool]:
    """The learning rate of every step that run ``run`` of the chain behind a weight file took, and whether its
    time limit stopped it before its step budget.

    ``meta`` is the weights' metadata (``Surrogate.meta``), ``preset`` the configuration the chain started
    from (its ``full`` preset); the run's step budget, time limit and peak rate are those its command set
    (:func:`rfmap.training.lineage.run_settings`).  A run that its time limit stopped followed the clock: its rates
    are :func:`learning_rates` with ``stopped_at``, which reads its steps as taking equal time."""
    rec = run_settings(meta, vars(preset))[run - 1]
    cfg = preset.with_overrides(steps=rec["step budget"], lr=rec["peak lr"],
                                time_limit=60.0 * rec["time limit (min)"])
    stopped = rec["steps"] < rec["step budget"] and cfg.time_limit > 0
    if stopped:
        return learning_rates(cfg, stopped_at=rec["steps"]), True
    return learning_rates(cfg, rec["steps"]), False


def machine(device: torch.device) -> dict:
    """What the run was trained on (recorded in the metadata, so the book can say it)."""
    import platform

    info = {"cpu_count": os.cpu_count(), "platform": platform.platform(terse=True), "torch": torch.__version__}
    if device.type == "cuda":
        info["gpu"] = torch.cuda.get_device_name(device)
    return info


def sha256(path) -> str:
    """Hex SHA-256 of the file at ``path`` (the lineage record of a parent's weights)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def load_init(source: str, cfg: TrainConfig) -> tuple[Surrogate, dict]:
    """The weights to start from (a shipped model's name or a ``.safetensors`` path) and their lineage record.

    Raises ``ValueError`` when they were trained for another task, dimension or boundary, or with another
    architecture than ``cfg.model``."""
    if source in models():
        path = WEIGHTS_DIR / f"{source}.safetensors"
    else:
        path = Path(source)
        if path.suffix != ".safetensors":
            path = path.with_suffix(".safetensors")
        if not path.exists():
            raise ValueError(f"--init {source!r}: neither a shipped model ({', '.join(models())}) nor a weight file")
    try:
        parent = Surrogate.load(path)
    except FileNotFoundError as e:
        raise ValueError(f"--init {source!r}: {e}") from e
    if parent.spec != cfg.task:
        raise ValueError(f"--init {source!r} was trained for {parent.spec}, but config {cfg.name!r} is {cfg.task}")
    want = cfg.model.kwargs(cfg.task.dim, cfg.task.n_params)
    have = parent.model.kwargs()
    if cfg.grow:
        same = {k: v for k, v in have.items() if k != "base"} == {k: v for k, v in want.items() if k != "base"}
        if not same:
            raise ValueError(f"--grow: --init {source!r} has architecture {have}; growth only widens it to "
                             f"{want}")
        try:
            check_growth(parent.model, int(want["base"]))
        except ValueError as e:
            raise ValueError(f"--grow: --init {source!r}: {e}") from e
    elif have != want:
        raise ValueError(f"--init {source!r} has architecture {have}, config {cfg.name!r} expects {want}")
    meta = parent.meta
    record = {"name": meta.get("name", path.stem), "file": path.name, "sha256": sha256(path),
              "preset": meta.get("preset"), "command": meta.get("command"), "steps": int(meta.get("steps", 0)),
              "wall_time": float(meta.get("wall_time", 0.0)),
              "cumulative_steps": int(meta.get("cumulative_steps", meta.get("steps", 0))),
              "cumulative_wall_time": float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0)))}
    if meta.get("resumed"):
        record["resumed"] = list(meta["resumed"])
    if meta.get("selected_step") is not None:  # the step whose weights the parent kept (0: its own parent's)
        record["selected_step"] = int(meta["selected_step"])
    if cfg.grow:
        record["grown"] = {"from": have, "to": want, "method": "rfmap.nn.grow.grow_unet", "seed": cfg.seed}
    return parent, record


@dataclass
class TrainState:
    """Everything the training loop reads and updates."""

    cfg: TrainConfig
    model: torch.nn.Module
    net: torch.nn.Module  # the model, or its DistributedDataParallel wrapper
    opt: torch.optim.Optimizer
    sched: object
    out: Path
    device: torch.device
    rank: int = 0
    world: int = 1
    step: int = 0
    elapsed0: float = 0.0  # training time of earlier sessions (--resume)
    lineage: list = field(default_factory=list)
    command: str | None = None  # the command line that started the run (kept across --resume)
    resumed: list = field(default_factory=list)  # the command lines that continued it after interruptions
    best: dict | None = None  # {"step", "score", "summary", "state"}
    ema: float | None = None  # running mean of the loss (progress bar)
    avg: WeightAverage | None = None  # the averaged weights (cfg.ema > 0)
    t_start: float = 0.0

    @property
    def spec(self) -> TaskSpec:
        return self.cfg.task

    def elapsed(self) -> float:
        return time.perf_counter() - self.t_start

    def log(self, rec: dict) -> None:
        if self.rank == 0:
            with open(self.out / "log.jsonl", "a") as f:
                f.write(json.dumps(rec) + "\n")

    def checkpoint(self) -> None:
        if self.rank != 0:
            return
        tmp = self.out / "checkpoint.pt.part"
        torch.save({"model": self.model.state_dict(), "opt": self.opt.state_dict(), "sched": self.sched.state_dict(),
                    "step": self.step, "elapsed": self.elapsed(), "lineage": json.dumps(self.lineage),
                    "command": self.command or "", "resumed": json.dumps(self.resumed),
                    "best": None if self.best is None else {k: json.dumps(v) for k, v in self.best.items()
                                                            if k != "state"},
                    "best_state": None if self.best is None else self.best["state"],
                    "average": None if self.avg is None else self.avg.state_dict(),
                    "config": json.dumps(self.cfg.to_dict(), sort_keys=True)}, tmp)
        os.replace(tmp, self.out / "checkpoint.pt")

    def snapshot(self) -> Path:
        """Write the current (averaged) weights with their metadata as one self-contained file,
        ``OUT/snapshots/NAME-stepSSSSSSS.safetensors`` (``rfmap validate`` scores such files afterwards)."""
        sur = self.cpu_surrogate()
        sur.meta["snapshot_step"] = self.step
        path, _ = sur.save(self.out / "snapshots" / f"{self.cfg.name}-step{self.step:07d}.safetensors", embed=True)
        return path

    def cpu_surrogate(self, final: dict | None = None) -> Surrogate:
        """A CPU copy of the current model (its averaged weights when ``cfg.ema`` > 0) with its metadata (used for
        validation and for the shipped file)."""
        cfg = self.cfg
        model = copy.deepcopy(self.model)
        if self.avg is not None:
            model.load_state_dict(self.avg.averaged_state(self.model))
        model = model.float().cpu().to(memory_format=torch.contiguous_format).eval()
        elapsed = self.elapsed()
        parent = self.lineage[-1] if self.lineage else {"cumulative_steps": 0, "cumulative_wall_time": 0.0}
        meta = {"name": cfg.name, "preset": cfg.preset, "n_range": list(cfg.n_range), "config": cfg.to_dict(),
                "rfmap_version": __version__, "steps": self.step, "wall_time": round(elapsed, 1),
                "cumulative_steps": int(parent["cumulative_steps"]) + self.step,
                "cumulative_wall_time": round(float(parent["cumulative_wall_time"]) + elapsed, 1),
                "lineage": self.lineage, "device": str(self.device), "threads": torch.get_num_threads(),
                "machine": machine(self.device),
                "world_size": self.world, "global_batch": cfg.batch * self.world, "description": cfg.description}
        if self.command:
            meta["command"] = self.command
        if self.resumed:
            meta["resumed"] = list(self.resumed)
        if final is not None:
            meta["final_metrics"] = final
        return Surrogate(model, cfg.task, meta)


def _build_state(cfg: TrainConfig, out: Path, device: torch.device, resume: bool, init: str | None,
                 command: str | None) -> TrainState:
    rank, world = _dist_info()
    if cfg.threads:  # on CUDA too: validation runs on a CPU copy, whose default threads would oversubscribe a machine
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    spec = cfg.task
    lineage: list = []
    if cfg.grow and not init and not resume:
        raise ValueError("--grow widens the network of --init; give the parent with --init")
    model = build_model(cfg.model.kwargs(spec.dim, spec.n_params))
    if init:
        parent, record = load_init(init, cfg)
        source = grow_unet(parent.model, cfg.model.base, seed=cfg.seed) if cfg.grow else parent.model
        model.load_state_dict(source.state_dict())
        lineage = list(parent.meta.get("lineage", [])) + [record]
    model = model.to(device, memory_format=memory_format(spec.dim))
    net = model
    if world > 1:
        net = torch.nn.parallel.DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda"
                                                        else None)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, betas=cfg.betas)
    st = TrainState(cfg, model, net, opt, None, out, device, rank, world, lineage=lineage, command=command)
    if cfg.ema:
        st.avg = WeightAverage(model, cfg.ema)
    # time-aware cosine in a single process only (ranks must agree on the learning rate)
    clock = (lambda: st.elapsed() if st.t_start else 0.0) if world == 1 else None
    st.sched = sched = _scheduler(opt, cfg, clock=clock)
    ckpt = out / "checkpoint.pt"
    if resume and ckpt.exists():
        state = torch.load(ckpt, weights_only=True, map_location=device)
        if state.get("config") != json.dumps(cfg.to_dict(), sort_keys=True):
            raise ValueError(f"checkpoint {ckpt} was written by a different configuration; remove it or use "
                             "another --out")
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["opt"])
        sched.load_state_dict(state["sched"])
        st.step, st.elapsed0 = int(state["step"]), float(state["elapsed"])
        if st.avg is not None and state.get("average"):
            st.avg.load_state_dict(state["average"])
        st.lineage = json.loads(state.get("lineage", "[]"))
        # the metadata keeps the command that started the run (the one to repeat it) and lists the resumptions
        st.resumed = json.loads(state.get("resumed", "[]")) + ([command] if command else [])
        st.command = state.get("command") or _started_as(command, st.lineage)
        if state.get("best"):
            st.best = {k: json.loads(v) for k, v in state["best"].items()}
            st.best["state"] = state["best_state"]
            # the best state is compared with later ones by the current rule (rfmap.training.validation.score)
            st.best["score"] = list(score(st.best["summary"]))
    elif rank == 0 and (out / "log.jsonl").exists():
        (out / "log.jsonl").unlink()
    return st


def _started_as(command: str | None, lineage: list) -> str | None:
    """The starting command of a run resumed from a checkpoint that predates stored commands.

    A resumed run repeats its starting options (the configuration must match), so the starting command is the
    resuming one without ``--resume``, with ``--init PARENT`` where the run had a parent (its lineage record).
    """
    if not command:
        return command
    words = [w for w in command.split() if w not in ("--resume", "--finish")]
    if lineage and "--init" not in words:
        words += ["--init", str(lineage[-1]["name"])]
    return " ".join(words)
