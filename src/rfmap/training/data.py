r"""Batches of random fields for training: the grid side and samples of a step, and the loaders that draw them ahead.

Every step draws a fresh batch of random fields (sample ``i`` of step ``t`` is seeded by ``(seed, t, i)``) on a
random grid size in ``n_range``, with Sobol-jittered vertices.  With ``workers >= 1`` the batches are drawn ahead of
the step by worker processes, otherwise by a thread; the batches, hence the weights, are
the same for any number of workers.  Rank ``r`` of a data-parallel run draws samples ``r*B .. (r+1)*B - 1``.
"""
from __future__ import annotations

import contextlib
import os

import numpy as np
import torch

from .config import TrainConfig
from ..tasks import draw_samples

__all__ = ["step_size_n", "step_batch", "draw_step", "single_blas_thread_env"]


def step_size_n(cfg: TrainConfig, step: int) -> int:
    r"""Training grid side of step ``step``, the same on every rank: uniform in ``n_range``, or with
    ``n_sampling='log'`` log-uniform, :math:`N = \lfloor \exp U(\log lo, \log(hi + 1)) \rfloor`, or with
    ``'mixed'`` log-uniform on half the steps and uniform on :math:`[lo, \min(hi, 3\,lo)]` on the other half
    (the small sides, where most of the paper's fields are tested, stay frequent)."""
    lo, hi = cfg.n_range
    rng = np.random.default_rng([cfg.seed, step, 2**31])
    mode = cfg.n_sampling
    if mode == "mixed":
        mode = "log" if rng.uniform() < 0.5 else "uniform"
        if mode == "uniform":
            hi = min(hi, 3 * lo)
    if mode == "log":
        return int(min(hi, np.floor(np.exp(rng.uniform(np.log(lo), np.log(hi + 1))))))
    return int(rng.integers(lo, hi + 1))


def step_batch(cfg: TrainConfig, n: int) -> int:
    r"""Per-rank batch of a step on the ``N``-grid: ``batch``, or with ``batch_points`` > 0
    :math:`\mathrm{clip}(\mathrm{round}(P / N^d), 1, \mathtt{batch})` (about the same cost at every size)."""
    if cfg.batch_points <= 0:
        return cfg.batch
    return int(np.clip(round(cfg.batch_points / n ** cfg.task.dim), 1, cfg.batch))


def draw_step(cfg: TrainConfig, step: int, rank: int = 0) -> tuple[int, np.ndarray, np.ndarray, np.ndarray | None]:
    """The raw arrays of rank ``rank``'s share of step ``step``: ``(n, points, params, targets)`` (a pure function of
    the configuration, the step and the rank); ``targets`` are the teacher's maps (:mod:`rfmap.tasks.teacher`, NaN where
    a sample has none), ``None`` without a teacher."""
    n = step_size_n(cfg, step)
    b = step_batch(cfg, n)
    drawn = draw_samples(cfg.task, seed=cfg.seed, step=step, indices=range(rank * b, (rank + 1) * b),
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

    numpy's OpenBLAS otherwise starts a thread per core, whose busy-waiting takes cycles from the training threads.
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
    rather than preempting a thread the others wait for."""

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
