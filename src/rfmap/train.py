r"""Data-free training of a surrogate (paper Sec. 5), single-process or data-parallel, on the CPU or a GPU.

``rfmap train --config NAME [--preset ci|full|paper] [--device auto|cpu|cuda] [--init MODEL|FILE] [--resume]``
(also ``python -m rfmap.train``) trains the named configuration of :mod:`rfmap.config`.  Every step draws a fresh
batch of random fields (sample ``i`` of step ``t`` is seeded by ``(seed, t, i)``) on a random grid size in
``n_range``, with Sobol-jittered vertices.  With ``workers >= 1`` the batches are drawn ahead of the step by
worker processes; the batches, hence the weights, are the same for any number of workers.

Data-parallel: ``torchrun --nproc_per_node=K -m rfmap.train --config NAME ...`` runs K processes (gloo on CPU,
NCCL on GPU); rank ``r`` draws samples ``r*B .. (r+1)*B - 1`` of each step, so K processes with batch ``B`` train
the same model as one process with batch ``K*B``.

Validation and the choice of the shipped checkpoint use the held-out random fields of :mod:`rfmap.validation`
(seeds training never draws); the paper's test fields are evaluated once at the end as a report.

3D networks train in the ``channels_last_3d`` memory format (:func:`memory_format`): the same model and the same
arithmetic up to float rounding, but oneDNN's 3D convolutions, their backward passes above all, run about 1.5x faster
(measured: one ``dem3d-cube`` step at batch 2, N = 48, 626 -> 430 ms on two threads).  2D networks keep the
contiguous format, which is as fast there.

``--ema DECAY`` keeps an exponential moving average of the weights (:class:`WeightAverage`); validation, the choice of
the shipped checkpoint and the shipped file then use the averaged weights, which bounce less between checkpoints than
the weights as trained.

``--init`` starts from shipped or saved weights with a fresh optimiser and schedule (a warm restart); the
metadata keeps the lineage (parent name and SHA-256, cumulative steps and wall time).

Outputs in ``--out`` (default ``runs/NAME``): ``log.jsonl`` (one JSON object per logged step and per
validation), ``checkpoint.pt`` (model, optimiser, scheduler, step; loaded with ``weights_only=True`` onto any
device), and the final ``NAME.safetensors`` + ``NAME.json`` (metadata: config, command, steps, wall time,
validation metrics, lineage, training history).
"""
from __future__ import annotations

import argparse
import contextlib
import copy
import hashlib
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ._version import __version__
from .config import PRESETS, TrainConfig, config_names, get_config
from .device import resolve_device
from .nn.registry import build_model
from .paper_fields import BELTRAMI_MAPS, TEST_FIELDS
from .surrogate import Surrogate, models, quiet_quality
from .tasks import TaskSpec, draw_samples, make_batch, task_loss
from .validation import evaluate, family_table, score

__all__ = ["train", "validate", "report_paper_fields", "resolve_device", "load_init", "main", "PAPER_FIELDS",
           "TrainState", "WeightAverage", "memory_format"]

#: the paper's test fields per (kind, dim): evaluated as a report at the end of training, never for selection
PAPER_FIELDS = TEST_FIELDS


# ---------------------------------------------------------------------------------------------------- devices
def memory_format(dim: int) -> torch.memory_format:
    """Memory format of a ``dim``-dimensional network and its inputs during training: ``channels_last_3d`` in 3D
    (oneDNN's Conv3d forward and backward are faster there), ``contiguous_format`` in 2D."""
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


def step_size_n(cfg: TrainConfig, step: int) -> int:
    """Training grid side of step ``step`` (uniform in ``n_range``, the same on every rank)."""
    lo, hi = cfg.n_range
    return int(np.random.default_rng([cfg.seed, step, 2**31]).integers(lo, hi + 1))


# ---------------------------------------------------------------------------------------------------- batches
def draw_step(cfg: TrainConfig, step: int, rank: int = 0) -> tuple[int, np.ndarray, np.ndarray, np.ndarray | None]:
    """The raw arrays of rank ``rank``'s share of step ``step``: ``(n, points, params, targets)`` (a pure function of
    the configuration, the step and the rank); ``targets`` are the teacher's maps (:mod:`rfmap.teacher`, NaN where
    a sample has none), ``None`` without a teacher."""
    n = step_size_n(cfg, step)
    drawn = draw_samples(cfg.task, seed=cfg.seed, step=step, indices=range(rank * cfg.batch, (rank + 1) * cfg.batch),
                         n=n, jitter=cfg.jitter, density_cfg=cfg.density_field, beltrami_cfg=cfg.beltrami_field,
                         beltrami_source=cfg.beltrami_source, teacher=cfg.teacher)
    return (n, *drawn) if len(drawn) == 3 else (n, *drawn, None)


class _ThreadLoader:
    """Draws the batches of the coming steps in a background thread (numpy releases the GIL in its array
    kernels), so that field synthesis overlaps with the network step."""

    def __init__(self, cfg: TrainConfig, rank: int, start: int, stop: int, depth: int = 2):
        import queue
        import threading

        self.q: "queue.Queue" = queue.Queue(maxsize=depth)
        self._stop = threading.Event()

        def work():
            for step in range(start, stop):
                if self._stop.is_set():
                    return
                try:
                    item = (step, draw_step(cfg, step, rank), None)
                except BaseException as e:  # surface errors in the training loop
                    item = (step, None, e)
                while not self._stop.is_set():
                    try:
                        self.q.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if item[2] is not None:
                    return

        self.thread = threading.Thread(target=work, daemon=True)
        self.thread.start()

    def get(self, step: int):
        got, arrays, err = self.q.get()
        if err is not None:
            raise err
        assert got == step, (got, step)
        return arrays

    def close(self):
        self._stop.set()
        self.thread.join(timeout=5)


def _worker_main(cfg: TrainConfig, rank: int, steps: range, q, stop) -> None:  # pragma: no cover - subprocess
    import queue

    torch.set_num_threads(1)
    try:  # yield the cores to the training threads: synthesis fills their gaps instead of stalling them
        os.nice(10)
    except (AttributeError, OSError):
        pass
    parent = os.getppid()

    def put(item) -> bool:  # False once training has stopped or its process is gone (killed: no clean close)
        while not stop.is_set() and os.getppid() == parent:
            try:
                q.put(item, timeout=1.0)
                return True
            except queue.Full:
                continue
        return False

    delivered = True
    try:
        for step in steps:
            if stop.is_set() or not put((step, draw_step(cfg, step, rank), None)):
                delivered = False
                break
    except BaseException as e:  # noqa: BLE001 - reported to the training process
        delivered = put((None, None, f"{type(e).__name__}: {e}"))
    if not delivered:
        # training stopped or its process is gone: batches still buffered must not hold the exit (a multiprocessing
        # queue waits at exit until its feeder thread has written them to the pipe, i.e. forever once nobody reads;
        # a killed training run left its workers running as orphans)
        q.cancel_join_thread()


_BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def single_blas_thread_env():
    """Environment for starting batch workers: one BLAS/OpenMP thread each (restored on exit).

    numpy's OpenBLAS otherwise starts a thread per core, and their busy-waiting after every matrix product of the
    field synthesis takes cycles from the training threads: dem3d-cube at 2 threads, batch 2, N = 48, one worker,
    measured 519-540 ms per step with the default threads against 444-455 ms with one.
    """
    saved = {k: os.environ.get(k) for k in _BLAS_THREAD_VARS}
    os.environ.update({k: "1" for k in _BLAS_THREAD_VARS})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _ProcessLoader:
    """Draws the batches in ``workers`` separate processes (step ``t`` by worker ``t mod workers``), off the
    training process's interpreter lock; the arrays arrive in step order.  The workers run at a lower scheduling
    priority (``nice`` 10), so that on a machine whose cores the training threads fill, synthesis takes the gaps
    rather than preempting a thread the others wait for (beltrami2d at 2 threads: 210 -> 185 ms per step)."""

    def __init__(self, cfg: TrainConfig, rank: int, start: int, stop: int, workers: int, depth: int = 2):
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.workers = workers
        self.start = start
        self._stop = ctx.Event()
        self.queues = [ctx.Queue(maxsize=depth) for _ in range(workers)]
        self.procs = [ctx.Process(target=_worker_main, args=(cfg, rank, range(start + w, stop, workers), q,
                                                             self._stop), daemon=True)
                      for w, q in enumerate(self.queues)]
        with single_blas_thread_env():  # read by numpy's BLAS when a worker imports it
            for p in self.procs:
                p.start()

    def get(self, step: int):
        import queue

        q = self.queues[(step - self.start) % self.workers]
        while True:
            try:
                got, arrays, err = q.get(timeout=5.0)
                break
            except queue.Empty:
                if not all(p.is_alive() for p in self.procs):
                    raise RuntimeError("a batch worker process died; rerun with --workers 0 to see its error")
        if err is not None:
            raise RuntimeError(f"batch worker failed: {err}")
        assert got == step, (got, step)
        return arrays

    def close(self):
        self._stop.set()
        for q in self.queues:  # unblock workers waiting on a full queue
            try:
                while not q.empty():
                    q.get_nowait()
            except Exception:  # noqa: BLE001 - best effort while shutting down
                pass
        for p in self.procs:
            p.join(timeout=2)
            if p.is_alive():
                p.terminate()


def _loader(cfg: TrainConfig, rank: int, start: int, stop: int):
    if cfg.workers > 0 and stop - start > 2 * cfg.workers:
        return _ProcessLoader(cfg, rank, start, stop, cfg.workers)
    return _ThreadLoader(cfg, rank, start, stop)


# ------------------------------------------------------------------------------------------------- validation
def validate(sur: Surrogate, cfg: TrainConfig) -> dict:
    """Metrics on the held-out random fields (:func:`rfmap.validation.evaluate`) at ``cfg.val_ns``."""
    return evaluate(sur, cfg.val_ns, cfg.val_count, repair=cfg.val_repair)


@quiet_quality()
def report_paper_fields(sur: Surrogate, n: int, fields: list[str] | None = None) -> dict:
    """Metrics on the paper's test fields at grid side ``n`` (a report; never used to select a model)."""
    fields = fields or PAPER_FIELDS[(sur.spec.kind, sur.spec.dim)]
    out: dict = {}
    vals = []
    for name in fields:
        r = sur.map(name, n, **({"repair": False} if _has_repair(sur) else {}))
        if sur.spec.kind == "beltrami":
            m = r.metrics(exact_points=BELTRAMI_MAPS[name](r.ref_points), mu_ref=r.field)
            vals.append({"mean_dd": m.mean_dd, "mean_dmu": m.mean_dmu, "n_flipped": m.n_flipped,
                         "min_jacobian": m.min_jacobian})
        else:
            m = r.metrics()
            vals.append({"std_rho_map": m.std_rho_map, "n_flipped": m.n_flipped, "min_jacobian": m.min_jacobian})
        out[name] = vals[-1]
    summary = {}
    for k in vals[0]:
        arr = [v[k] for v in vals]
        summary[k] = int(sum(arr)) if k == "n_flipped" else (min(arr) if k == "min_jacobian" else float(np.mean(arr)))
    out["mean"] = summary
    return out


def _has_repair(sur) -> bool:
    import inspect

    return "repair" in inspect.signature(sur.map).parameters


def machine(device: torch.device) -> dict:
    """What the run was trained on (recorded in the metadata, so the book can say it)."""
    import platform

    info = {"cpu_count": os.cpu_count(), "platform": platform.platform(terse=True), "torch": torch.__version__}
    if device.type == "cuda":
        info["gpu"] = torch.cuda.get_device_name(device)
    return info


# ---------------------------------------------------------------------------------------------------- lineage
def sha256(path) -> str:
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
        from .surrogate import WEIGHTS_DIR

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
    if parent.model.kwargs() != want:
        raise ValueError(f"--init {source!r} has architecture {parent.model.kwargs()}, config {cfg.name!r} "
                         f"expects {want}")
    meta = parent.meta
    record = {"name": meta.get("name", path.stem), "file": path.name, "sha256": sha256(path),
              "preset": meta.get("preset"), "command": meta.get("command"), "steps": int(meta.get("steps", 0)),
              "wall_time": float(meta.get("wall_time", 0.0)),
              "cumulative_steps": int(meta.get("cumulative_steps", meta.get("steps", 0))),
              "cumulative_wall_time": float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0)))}
    if meta.get("resumed"):
        record["resumed"] = list(meta["resumed"])
    return parent, record


# ------------------------------------------------------------------------------------------- weight averaging
class WeightAverage:
    r"""An exponential moving average of a model's parameters (Polyak averaging).

    After the ``t``-th optimiser step (``t = 1, 2, ...`` from the start of the run)

    .. math:: \bar w \leftarrow \bar w + (1 - \beta_t)(w - \bar w), \qquad
              \beta_t = \min\!\left(\beta, \frac{1 + t}{10 + t}\right),

    the usual warm-up of the decay, so that the average soon forgets the starting weights.  With ``beta = 0.999``
    it spans about the last thousand steps.  Buffers (none in the shipped networks, which normalise by groups) are
    taken from the model as they are.

    Parameters
    ----------
    model : torch.nn.Module
        The model being trained (not a DistributedDataParallel wrapper).
    decay : float
        ``beta`` in ``(0, 1)``.
    """

    def __init__(self, model: torch.nn.Module, decay: float):
        if not 0.0 < decay < 1.0:
            raise ValueError(f"the weight-average decay must lie in (0, 1), got {decay}")
        self.decay = float(decay)
        self.names = [n for n, _ in model.named_parameters()]
        self.params = [p for _, p in model.named_parameters()]
        self.shadow = [p.detach().clone() for p in self.params]
        self.updates = 0

    @torch.no_grad()
    def update(self) -> None:
        """Fold the model's current parameters into the average (call after every optimiser step)."""
        self.updates += 1
        beta = min(self.decay, (1.0 + self.updates) / (10.0 + self.updates))
        torch._foreach_lerp_(self.shadow, [p.detach() for p in self.params], 1.0 - beta)

    def averaged_state(self, model: torch.nn.Module) -> dict:
        """``model.state_dict()`` with the averaged parameters in place of the trained ones (detached copies)."""
        state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        for name, avg in zip(self.names, self.shadow):
            state[name] = avg.detach().clone()
        return state

    def state_dict(self) -> dict:
        return {"updates": self.updates, "shadow": {n: t.detach().cpu() for n, t in zip(self.names, self.shadow)}}

    def load_state_dict(self, state: dict) -> None:
        self.updates = int(state["updates"])
        for name, t in zip(self.names, self.shadow):
            t.copy_(state["shadow"][name])


# ------------------------------------------------------------------------------------------------------ state
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
    if cfg.threads:  # on CUDA too: validation, refinement and the paper-field report run on a CPU copy, and two
        # runs sharing a 16-core GPU machine with torch's default threads each spent 150-180 s per 3D validation
        # (7 s on a 2-core CPU with 2 threads): the threads of the two processes and their batch workers competed
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    spec = cfg.task
    lineage: list = []
    model = build_model(cfg.model.kwargs(spec.dim, spec.n_params))
    if init:
        parent, record = load_init(init, cfg)
        model.load_state_dict(parent.model.state_dict())
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
            # the best state is compared with later ones by the current rule (rfmap.validation.score)
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


def train(cfg: TrainConfig, out_dir=None, *, resume: bool = False, init: str | None = None,
          device: str | torch.device | None = "cpu", progress: bool = True, log_every: int = 10,
          command: str | None = None, finish: bool = False) -> Surrogate:
    """Train ``cfg``; returns the trained :class:`Surrogate` (also written to ``out_dir``).

    Parameters
    ----------
    resume : bool
        Continue from ``out_dir/checkpoint.pt`` (model, optimiser, schedule, step and elapsed time).
    init : str, optional
        Start from a shipped model's weights or a ``.safetensors`` file (fresh optimiser and schedule).
    device : str or torch.device
        ``'cpu'`` (default), ``'cuda'`` or ``'auto'``; on CUDA the network runs under bf16 autocast.
    command : str, optional
        The command line that started the run (recorded in the metadata).
    finish : bool
        With ``resume``: train no further, but end the run from its checkpoint as if its budget were spent (final
        validation, the choice of the best validated state, the paper-field report and the weight file), e.g. after
        the run was stopped early.
    """
    dev = device if isinstance(device, torch.device) else resolve_device(device)
    out = Path(out_dir or Path("runs") / cfg.name)
    if finish and not (resume and (out / "checkpoint.pt").exists()):
        raise ValueError(f"--finish ends a run from its checkpoint: give --resume and an --out with checkpoint.pt "
                         f"(none in {out})")
    rank, _ = _dist_info()
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    st = _build_state(cfg, out, dev, resume, init, command)
    st.t_start = time.perf_counter() - st.elapsed0
    bar = None
    if progress and st.rank == 0:
        from tqdm.auto import tqdm

        bar = tqdm(total=cfg.steps, initial=st.step, desc=f"train {cfg.name}", unit="step", dynamic_ncols=True)
    try:
        if init is not None and not resume and not finish and st.rank == 0 and cfg.select_best and cfg.val_every:
            _validate_and_keep(st, bar)  # the parent competes: a run that improves on nothing ships its parent
        if not finish:  # --finish: no further step, straight to the end of the run
            loader = _loader(cfg, st.rank, st.step, cfg.steps)
            try:
                _loop(st, loader, bar, log_every)
            finally:
                loader.close()
    finally:
        if bar is not None:
            bar.close()
    return _finish(st)


def _train_step(st: TrainState, n: int, pts: np.ndarray, par: np.ndarray,
                targets: np.ndarray | None = None) -> tuple[float, dict, float]:
    cfg = st.cfg
    batch = make_batch(cfg.task, pts, par, n, targets).to(st.device)
    batch.inputs = batch.inputs.contiguous(memory_format=memory_format(cfg.task.dim))
    st.model.train()
    if st.device.type == "cuda":
        with torch.autocast("cuda", dtype=torch.bfloat16):
            psi = st.net(batch.inputs)
        psi = psi.float()
    else:
        psi = st.net(batch.inputs)
    loss, parts = task_loss(cfg.task, batch, psi, cfg.loss, cfg.teacher.weight if cfg.teacher.active else 0.0)
    st.opt.zero_grad(set_to_none=True)
    loss.backward()
    gnorm = float(torch.nn.utils.clip_grad_norm_(st.model.parameters(), cfg.clip))
    st.opt.step()
    st.sched.step()
    if st.avg is not None:
        st.avg.update()
    return float(loss.detach()), parts, gnorm


def _validate_and_keep(st: TrainState, bar) -> dict:
    v = validate(st.cpu_surrogate(), st.cfg)
    st.log({"step": st.step, "validation": v, "elapsed": round(st.elapsed(), 2)})
    s = score(v["mean"])
    if st.best is None or s < tuple(st.best["score"]):
        state = st.model.state_dict() if st.avg is None else st.avg.averaged_state(st.model)
        st.best = {"step": st.step, "score": list(s), "summary": v["mean"],
                   "state": {k: t.detach().cpu().clone() for k, t in state.items() if isinstance(t, torch.Tensor)}}
    if bar is not None:
        m = v["mean"]
        fam = family_table(m)
        bar.write(f"step {st.step}: validation {fam}" if fam else f"step {st.step}: validation {m}")
    return v


def _loop(st: TrainState, loader, bar, log_every: int) -> None:
    cfg = st.cfg
    if cfg.time_limit > 0 and st.elapsed0 > cfg.time_limit:
        return  # resumed after its time limit: nothing left to train (elapsed0 comes from the checkpoint, so every
        # rank of a data-parallel run decides alike; the clock inside the loop is agreed on by all_reduce)
    while st.step < cfg.steps:
        n, pts, par, targets = loader.get(st.step)
        lv, parts, gnorm = _train_step(st, n, pts, par, targets)
        st.step += 1
        st.ema = lv if st.ema is None else 0.95 * st.ema + 0.05 * lv
        elapsed = st.elapsed()
        if bar is not None:
            bar.update(1)
            bar.set_postfix(loss=f"{st.ema:.3g}", n=n)
        if st.step % log_every == 0 or st.step == cfg.steps:
            st.log({"step": st.step, "n": n, "loss": lv, **parts, "grad_norm": gnorm,
                    "lr": st.opt.param_groups[0]["lr"], "elapsed": round(elapsed, 2)})
        stop = cfg.time_limit > 0 and elapsed > cfg.time_limit
        if st.world > 1:
            flag = torch.tensor([float(stop)], device=st.device if st.device.type == "cuda" else "cpu")
            torch.distributed.all_reduce(flag)
            stop = bool(flag.item() > 0)
        if st.rank == 0 and cfg.val_every and st.step % cfg.val_every == 0 and st.step < cfg.steps and not stop:
            _validate_and_keep(st, bar)
        if st.step % cfg.ckpt_every == 0 or stop or st.step == cfg.steps:
            st.checkpoint()
        if cfg.snapshot_every and st.rank == 0 and (st.step % cfg.snapshot_every == 0 or stop
                                                    or st.step == cfg.steps):
            st.snapshot()
        if stop:
            if bar is not None:
                bar.write(f"time limit of {cfg.time_limit:.0f} s reached at step {st.step}")
            break


def _finish(st: TrainState) -> Surrogate:
    """Final validation, the choice of the shipped weights (the best validated state), the paper-field report,
    and the weight file."""
    cfg = st.cfg
    if st.rank != 0:
        return st.cpu_surrogate()
    if st.avg is not None:  # from here on the model holds the averaged weights (the checkpoint keeps both)
        st.model.load_state_dict(st.avg.averaged_state(st.model))
        st.avg = None
    if not cfg.val_every:  # no validation here (a run on a lent accelerator): rfmap validate scores its snapshots
        sur = st.cpu_surrogate()
        sur.meta["selected_step"] = st.step
        sur.meta["history"] = history(st.out / "log.jsonl")
        sur.save(st.out / f"{cfg.name}.safetensors")
        return sur
    last = validate(st.cpu_surrogate(), cfg)
    selected = st.step
    if cfg.select_best and st.best is not None and tuple(st.best["score"]) < score(last["mean"]):
        st.model.load_state_dict({k: v.to(st.device) for k, v in st.best["state"].items()})
        selected = st.best["step"]
        final = validate(st.cpu_surrogate(), cfg)
    else:
        final = last
    st.log({"step": st.step, "validation": final, "elapsed": round(st.elapsed(), 2), "final": True,
            "selected_step": selected})
    sur = st.cpu_surrogate()
    report = report_paper_fields(sur, cfg.val_n)
    st.log({"step": st.step, "paper_fields_report": report})
    sur = st.cpu_surrogate(final)
    sur.meta["selected_step"] = selected
    sur.meta["paper_fields_report"] = report
    sur.meta["history"] = history(st.out / "log.jsonl")
    sur.meta["history"]["validation_set"] = (f"{cfg.val_count} held-out random fields at N = "
                                             f"{', '.join(str(n) for n in cfg.val_ns)}")
    sur.save(st.out / f"{cfg.name}.safetensors")
    return sur


def history(log_path, points: int = 200) -> dict:
    """A compact training history from ``log.jsonl``: up to ``points`` (step, loss, elapsed) triples of a running
    mean of the loss, and the mean validation metrics over steps and wall time (stored in the weight metadata for
    the book's plots)."""
    steps, losses, times, val = [], [], [], []
    with open(log_path) as f:
        for line in f:
            rec = json.loads(line)
            if "validation" in rec:
                val.append({"step": rec["step"], "elapsed": rec.get("elapsed"), **rec["validation"]["mean"]})
            elif "loss" in rec:
                steps.append(rec["step"])
                losses.append(rec["loss"])
                times.append(rec.get("elapsed"))
    if losses:
        w = max(1, len(losses) // points)
        sm = np.convolve(losses, np.ones(w) / w, mode="valid")[::w]
        steps = steps[w - 1::w][: len(sm)]
        times = times[w - 1::w][: len(sm)]
        losses = [float(x) for x in sm]
    return {"step": steps, "loss": losses, "elapsed": times, "validation": val}


# -------------------------------------------------------------------------------------------------------- CLI
def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    p = parser or argparse.ArgumentParser(prog="rfmap train", description="Train a surrogate from a named config.")
    p.add_argument("--config", required=True, help=f"one of: {', '.join(config_names())}")
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
    p.add_argument("--device", default="cpu", help="auto, cpu (default) or cuda; CUDA trains under bf16 autocast")
    p.add_argument("--steps", type=int, default=None, help="override the number of steps")
    p.add_argument("--batch", type=int, default=None, help="override the per-process batch size")
    p.add_argument("--time-limit", type=float, default=None, help="override the wall-time limit (s; 0: none)")
    p.add_argument("--lr", type=float, default=None,
                   help="override the peak learning rate (e.g. lower for a gentle warm restart with --init)")
    p.add_argument("--ema", type=float, default=None, metavar="DECAY",
                   help="keep an exponential moving average of the weights with this decay (e.g. 0.999); validation, "
                        "checkpoint choice and the shipped file use it (0: off, the default)")
    p.add_argument("--threads", type=int, default=None,
                   help="torch CPU threads per process (also with --device cuda: validation runs on a CPU copy)")
    p.add_argument("--workers", type=int, default=None, help="batch-drawing worker processes (0: a thread)")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--teacher", default=None, metavar="flow|diffusion|none",
                   help="density configs: a classical solver's map of a share of each batch's fields as a supervised "
                        "target beside the data-free losses (rfmap.teacher; default: the config's, none)")
    p.add_argument("--teacher-share", type=float, default=None, help="share of each batch with a target (0, 1]")
    p.add_argument("--teacher-weight", type=float, default=None, help="weight of the teacher's displacement loss")
    p.add_argument("--base", type=int, default=None, help="override the U-Net's base width (channels)")
    p.add_argument("--depth", type=int, default=None, help="override the U-Net's number of levels")
    p.add_argument("--snapshot-every", type=int, default=None, metavar="K",
                   help="write the weights every K steps to OUT/snapshots/ (self-contained files for rfmap validate)")
    p.add_argument("--no-validate", action="store_true",
                   help="no validation during or after the run (e.g. on an accelerator); score the snapshots "
                        "afterwards with rfmap validate")
    p.add_argument("--no-progress", action="store_true")
    return p


def run(args) -> Surrogate:
    cfg = get_config(args.config, args.preset)
    over = {k: v for k, v in {"steps": args.steps, "batch": args.batch, "time_limit": args.time_limit,
                              "threads": args.threads, "seed": args.seed, "workers": args.workers,
                              "lr": args.lr, "ema": args.ema}.items()
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

    from .teacher import TeacherConfig

    over: dict = {}
    t = {k: v for k, v in {"method": getattr(args, "teacher", None), "share": getattr(args, "teacher_share", None),
                           "weight": getattr(args, "teacher_weight", None)}.items() if v is not None}
    if t:
        over["teacher"] = TeacherConfig(**{**cfg.teacher.__dict__, **t})
        if over["teacher"].active and cfg.task.kind != "density":
            raise ValueError(f"--teacher: config {cfg.name!r} maps a Beltrami coefficient; a classical teacher "
                             "applies to density configs only")
    m = {k: v for k, v in {"base": getattr(args, "base", None), "depth": getattr(args, "depth", None)}.items()
         if v is not None}
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


def _command_line(args) -> str:
    parts = ["rfmap train", f"--config {args.config}"]
    if args.preset:
        parts.append(f"--preset {args.preset}")
    for flag, val in [("--steps", args.steps), ("--batch", args.batch), ("--time-limit", args.time_limit),
                      ("--threads", args.threads), ("--workers", args.workers), ("--seed", args.seed),
                      ("--lr", args.lr), ("--ema", args.ema), ("--init", args.init),
                      ("--teacher", getattr(args, "teacher", None)),
                      ("--teacher-share", getattr(args, "teacher_share", None)),
                      ("--teacher-weight", getattr(args, "teacher_weight", None)),
                      ("--base", getattr(args, "base", None)), ("--depth", getattr(args, "depth", None)),
                      ("--snapshot-every", getattr(args, "snapshot_every", None))]:
        if val is not None:
            parts.append(f"{flag} {val:g}" if isinstance(val, float) else f"{flag} {val}")
    if args.device and args.device != "cpu":
        parts.append(f"--device {args.device}")
    if getattr(args, "no_validate", False):
        parts.append("--no-validate")
    if args.resume:
        parts.append("--resume")
    if args.finish:
        parts.append("--finish")
    return " ".join(parts)


def main(argv=None) -> int:
    """``python -m rfmap.train`` (same options as ``rfmap train``); returns the exit status (2 on bad input)."""
    args = build_parser().parse_args(argv)
    try:
        run(args)
    except ValueError as e:
        print(f"rfmap train: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
