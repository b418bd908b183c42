r"""The training loop: steps on fresh random batches, validation and the choice of the shipped weights.  The
steps follow the paper's training settings (Sec. 5.1 and 5.2: epochs, optimiser, learning-rate schedule, gradient
clipping); the validation, the weight average and the choice of the kept weights are this project's own.  This loop
runs one training run; the weights of each shipped model come from a chain of runs, each started from the weights of
the one before (``rfmap train --init``), which ``rfmap models --lineage`` lists and the book's page *Reproducing the
results* gives as commands.

Validation and the choice of the shipped checkpoint use the held-out random fields of :mod:`rfmap.training.validation` (seeds
training never draws); the paper's test fields are evaluated once at the end as a report
(:func:`report_paper_fields`).  With ``cfg.ema`` > 0 (:class:`~rfmap.training.averaging.WeightAverage`) validation,
the choice and the shipped file use the averaged weights.

Outputs in ``out_dir`` (default ``runs/NAME``): ``log.jsonl`` (one JSON object per logged step and per validation),
``checkpoint.pt`` and the final ``NAME.safetensors`` + ``NAME.json`` (metadata: config, command, steps, wall time,
validation metrics, lineage, training history, :func:`history`).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from .config import TrainConfig
from ..core.device import autocast, check_precision, resolve_device
from ..finish import quiet_quality
from ..surrogate import Surrogate
from ..tasks import make_batch, task_loss
from .validation import evaluate, family_table, score
from .data import _loader
from .state import TrainState, _build_state, _dist_info, memory_format

__all__ = ["train", "RunOptions", "validate", "report_paper_fields", "history"]


def validate(sur: Surrogate, cfg: TrainConfig) -> dict:
    """Metrics on the held-out random fields (:func:`rfmap.training.validation.evaluate`) at ``cfg.val_ns``."""
    return evaluate(sur, cfg.val_ns, cfg.val_count, repair=cfg.val_repair, native=cfg.val_native)


@quiet_quality()
def report_paper_fields(sur: Surrogate, n: int, fields: list[str] | None = None) -> dict:
    """Metrics on the paper's test fields at grid side ``n`` (a report; never used to select a model): the task's
    test fields (:meth:`rfmap.tasks.base.Task.test_fields`) and records (:meth:`rfmap.tasks.base.Task.test_record`); empty
    for a task without test fields."""
    task = sur.spec.task
    fields = fields or task.test_fields(sur.spec.dim)
    out: dict = {}
    vals = []
    for name in fields:
        vals.append(task.test_record(sur.map(name, n, repair=False), name))
        out[name] = vals[-1]
    if not vals:
        return out
    summary = {}
    for k in vals[0]:
        arr = [v[k] for v in vals]
        summary[k] = int(sum(arr)) if k == "n_flipped" else (min(arr) if k == "min_jacobian" else float(np.mean(arr)))
    out["mean"] = summary
    return out


@dataclass(frozen=True)
class RunOptions:
    """How a training run starts, where it runs and what it reports (:func:`train`).

    Attributes
    ----------
    resume : bool
        Continue from ``out_dir/checkpoint.pt`` (model, optimiser, schedule, step and elapsed time).
    init : str, optional
        Start from a shipped model's weights or a ``.safetensors`` file (fresh optimiser and schedule).
    device : str or torch.device
        ``'cpu'`` (default, as for ``rfmap train --device``: a run uses a GPU only when asked to, unlike
        :func:`~rfmap.core.device.resolve_device`, whose default is ``'auto'``), ``'cuda'`` or ``'auto'``; the
        network's arithmetic is ``cfg.precision``.
    command : str, optional
        The command line that started the run (recorded in the metadata).
    finish : bool
        With ``resume``: train no further, but end the run from its checkpoint as if its budget were spent (final
        validation, the choice of the best validated state, the paper-field report and the weight file), e.g. after
        the run was stopped early.
    progress : bool
        A progress bar (rank 0).
    log_every : int
        Steps between the loss records of ``log.jsonl``.
    """

    resume: bool = False
    init: str | None = None
    device: str | torch.device | None = "cpu"
    progress: bool = True
    log_every: int = 10
    command: str | None = None
    finish: bool = False


def train(cfg: TrainConfig, out_dir=None, options: RunOptions | None = None, **kw) -> Surrogate:
    """Train ``cfg``; returns the trained :class:`rfmap.Surrogate` (also written to ``out_dir``, default ``runs/NAME``).
    ``options`` (:class:`RunOptions`) say how the run starts and reports; its fields may be given as keywords
    (``train(cfg, out, init="deq2d-square", progress=False)``)."""
    opts = replace(options or RunOptions(), **kw)
    resume, init, device, finish = opts.resume, opts.init, opts.device, opts.finish
    progress, log_every, command = opts.progress, opts.log_every, opts.command
    dev = device if isinstance(device, torch.device) else resolve_device(device)
    cfg = cfg.with_overrides(precision=check_precision(cfg.precision, dev))  # "BF16" is "bf16"
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
    with autocast(cfg.precision, st.device):
        psi = st.net(batch.inputs)
    psi = psi.float()
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
    if not cfg.val_every:  # no validation here (a run on a GPU): rfmap validate scores its snapshots
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
        # the last state's validation stays in the log (its learning curve), then the shipped state's
        st.log({"step": st.step, "validation": last, "elapsed": round(st.elapsed(), 2), "last": True})
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
    the book's plots).  A run that ended before its first log record (no ``log.jsonl``) has an empty history."""
    steps, losses, times, val = [], [], [], []
    if not Path(log_path).exists():
        return {"step": [], "loss": [], "elapsed": [], "validation": []}
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
