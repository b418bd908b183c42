"""The diffusion map's heat field skips only the cosine modes that have decayed below double precision's round-off."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

try:  # the heat field of rfmap.solvers.diffusion.solve_dem, under either of its names
    from rfmap.solvers.heatfield import HeatField as Field
except ImportError:
    from rfmap.solvers.diffusion import CosineDiffusion as Field


@pytest.mark.parametrize("d,m", [(2, 33), (3, 17)])
def test_the_heat_field_drops_only_modes_decayed_below_1e_17(d, m):
    r"""The modes that the field's ``fields(t)`` skips have decayed by a per-axis factor
    :math:`e^{-\pi^2 k^2 t} < 10^{-17}`, so the density and its gradient equal the sum over every mode to 1e-14 of
    their scale, at early and late times; a cut at a decay of 2 % would be off by about 1e-3."""
    rng = np.random.default_rng(5)
    field = Field(np.exp(0.5 * rng.normal(size=(m,) * d)))
    full = copy.copy(field)
    full.n_modes = lambda t: m  # every mode kept
    axes = tuple(range(1, d + 1))
    for t in (2e-4, 2e-3, 2e-2):
        kk = field.n_modes(t)
        assert kk == m or math.exp(-math.pi**2 * kk**2 * t) < 1e-17
        got, want = np.asarray(field.fields(t)), np.asarray(full.fields(t))
        assert np.all(np.abs(got - want).max(axis=axes) <= 1e-14 * np.abs(want).max(axis=axes)), t
