"""The learning-rate schedule of a training run (:func:`rfmap.training.state._scheduler`): exact rates of the linear
warm-up and of the cosine that follows it."""
from __future__ import annotations

import math

import pytest
import torch

from rfmap.training.config import get_config
from rfmap.training.state import _scheduler

LR, LR_MIN, WARMUP, STEPS = 1e-3, 1e-5, 4, 20


def rates(n_steps: int, warmup: int = WARMUP) -> list[float]:
    """The rate of each of the first ``n_steps`` optimiser steps under the cosine schedule."""
    cfg = get_config("deq2d-square", "ci").with_overrides(lr=LR, lr_min=LR_MIN, warmup=warmup, steps=STEPS,
                                                           schedule="cosine", time_limit=0.0)
    opt = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=cfg.lr)
    sched = _scheduler(opt, cfg)
    out = []
    for _ in range(n_steps):
        out.append(opt.param_groups[0]["lr"])
        opt.step()
        sched.step()
    return out


def test_the_warm_up_starts_at_one_step_of_the_rate_and_reaches_the_peak_at_its_last_step():
    """Step k < W runs at lr (k + 1) / W: step 0 at lr / W (never at 0, a step that would be wasted), step W - 1 at
    the peak lr; then the cosine starts from the peak (step W at lr) and ends at lr_min (step STEPS)."""
    r = rates(STEPS + 1)
    assert r[0] == pytest.approx(LR / WARMUP, rel=1e-12) and r[0] > 0
    assert r[WARMUP - 1] == pytest.approx(LR, rel=1e-12)
    assert r[:WARMUP] == pytest.approx([LR * (k + 1) / WARMUP for k in range(WARMUP)], rel=1e-12)
    assert r[WARMUP] == pytest.approx(LR, rel=1e-12)
    mid = (WARMUP + STEPS) // 2  # half-way through the cosine: the mean of lr and lr_min
    t = (mid - WARMUP) / (STEPS - WARMUP)
    assert r[mid] == pytest.approx(LR_MIN + (LR - LR_MIN) * 0.5 * (1 + math.cos(math.pi * t)), rel=1e-12)
    assert r[STEPS] == pytest.approx(LR_MIN, rel=1e-12)


def test_without_a_warm_up_the_first_step_runs_at_the_peak_rate():
    assert rates(1, warmup=0)[0] == pytest.approx(LR, rel=1e-12)


def test_learning_rates_are_the_rates_a_run_steps_with():
    """rfmap.training.learning_rates gives the rate of every step: the cosine above, and the paper's printed step
    decay of the 2D density models (halved every step_size steps)."""
    from rfmap.training import learning_rates

    cfg = get_config("deq2d-square", "ci").with_overrides(lr=LR, lr_min=LR_MIN, warmup=WARMUP, steps=STEPS,
                                                           schedule="cosine", time_limit=0.0)
    assert learning_rates(cfg, STEPS + 1) == pytest.approx(rates(STEPS + 1), rel=1e-12)
    paper = get_config("deq2d-square", "paper")
    r = learning_rates(paper, 2 * paper.step_size + 1)
    assert r[0] == r[paper.step_size - 1] == pytest.approx(paper.lr, rel=1e-12)
    assert r[paper.step_size] == pytest.approx(paper.lr * paper.gamma, rel=1e-12)
    assert r[2 * paper.step_size] == pytest.approx(paper.lr * paper.gamma**2, rel=1e-12)


def test_a_run_stopped_by_its_time_limit_reaches_the_floor_at_its_last_step():
    """learning_rates(cfg, stopped_at=K): a time-limited cosine run that stopped at step K follows the elapsed time,
    read as K equal steps: it warms up as by the step count, then falls towards lr_min by step K, well before its step
    budget; without a time limit there is no such run."""
    from rfmap.training import learning_rates

    cfg = get_config("deq2d-square", "ci").with_overrides(lr=LR, lr_min=LR_MIN, warmup=WARMUP, steps=STEPS,
                                                           schedule="cosine", time_limit=60.0)
    k = STEPS // 2
    r = learning_rates(cfg, stopped_at=k)
    assert len(r) == k
    assert r[:WARMUP] == pytest.approx(rates(WARMUP), rel=1e-12)
    # the last step runs at (k - 1) / k of the time limit, close to the floor
    t = (k - 1) / k
    assert r[-1] == pytest.approx(LR_MIN + (LR - LR_MIN) * 0.5 * (1 + math.cos(math.pi * t)), rel=1e-12)
    assert r[-1] < learning_rates(cfg)[k - 1]
    with pytest.raises(ValueError, match="time limit"):
        learning_rates(cfg.with_overrides(time_limit=0.0), stopped_at=k)


def test_the_first_run_of_a_shipped_chain_is_drawn_as_it_ran():
    """run_learning_rates: the first run of the shipped deq2d-square chain stopped on its time limit before its
    step budget (its record says so), so its rates end at the steps it took, near the floor of its cosine."""
    from rfmap import Surrogate
    from rfmap.training.lineage import run_settings
    from rfmap.training.state import run_learning_rates

    meta = Surrogate.pretrained("deq2d-square").meta
    full = get_config("deq2d-square", "full")
    first = run_settings(meta, vars(full))[0]
    r, stopped = run_learning_rates(meta, full)
    assert stopped == (first["steps"] < first["step budget"])
    assert len(r) == first["steps"]
    if stopped:
        assert r[-1] < 0.01 * max(r)
