"""Held-out fields: the seeded random streams that training never draws (the fields themselves are the tasks').

Training sample ``i`` of step ``t`` is drawn from ``np.random.default_rng([seed, t, i])`` (a three-word seed);
held-out field ``j`` of a stream comes from ``np.random.default_rng([VALIDATION_SEED + stream, j])`` (a two-word
seed), a different random stream for every ``seed``, ``t`` and ``i``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["VALIDATION_SEED", "STREAMS", "ValidationField", "held_out_rng"]

#: First word of every validation seed (training seeds have three words, so the streams never coincide).
VALIDATION_SEED = 20_250_917

#: The streams of held-out fields: 0 validates during training (and chooses the weights that are kept), 1 draws the
#: unseen random fields on which the book reports its results (the studies of :mod:`rfmap.paper`), used for nothing
#: else (the glossary's *report stream*).
STREAMS = {"validation": 0, "report": 1}


@dataclass(frozen=True)
class ValidationField:
    """One held-out field: a label, the raw field on points (P, d), and where known the exact map."""

    label: str
    field: Callable[[np.ndarray], np.ndarray]
    exact: Callable[[np.ndarray], np.ndarray] | None = None


def held_out_rng(j: int, stream: str) -> np.random.Generator:
    """The generator of held-out field ``j`` of ``stream`` (:data:`STREAMS`)."""
    if stream not in STREAMS:
        raise ValueError(f"unknown stream {stream!r}; expected one of {tuple(STREAMS)}")
    return np.random.default_rng([VALIDATION_SEED + STREAMS[stream], j])
