"""The diffusion flow's shared pieces (rfmap.solvers.heatflow) and its two integrators (rfmap.solvers.bs32 and
rfmap.solvers.heun) against exact answers."""
import math

import numpy as np
import pytest

from rfmap.solvers.bs32 import BS32Options, bs32_flow
from rfmap.solvers.heatflow import INTEGRATORS, SLOWEST_RATE, Settling, blur_start, diffuse
from rfmap.solvers.heun import HeunOptions, Stalled, heun_flow


class _Decay:
    """v(t, y) = -y: every point decays as exp(-t) towards the origin."""

    def velocity_at(self, t, y):
        return -y


def _identity(p):
    return p


@pytest.mark.parametrize("options", [BS32Options(1e-6, first_step=1e-3, t_end=1.0),
                                     HeunOptions(1e-6, first_step=1e-3)])
def test_both_integrators_follow_an_exact_flow(options):
    """From y0 to t = 1 (no settling): y0 exp(-1), to the step tolerance, and the time reached is 1."""
    y0 = np.array([[1.0, 0.5], [-0.25, 2.0]])
    y, info = INTEGRATORS[type(options)](lambda t, y: -y, y0.copy(), _identity, options)
    assert abs(info["t_end"] - 1.0) < 1e-12 and info["steps"] > 5
    assert np.abs(y - y0 * math.exp(-1.0)).max() < 1e-4


def test_the_flow_stops_once_settled_and_reports_its_speed():
    """For v = -y the displacement to come is |y|; the rule stops when |v|/pi^2 <= tol, at t = log(|y0|/(tol pi^2))
    (for |y0| = 1), and the evaluations are counted."""
    tol = 1e-3
    y0 = np.array([[1.0, 0.0]])
    settling = Settling(tol)
    y, info = diffuse(_Decay(), y0, _identity, BS32Options(1e-7, first_step=1e-3), settling)
    assert info["residual_velocity"] == settling.speed <= tol * SLOWEST_RATE
    assert abs(info["t_end"] - math.log(1.0 / (tol * SLOWEST_RATE))) < 0.05
    assert info["evaluations"] == 1 + 3 * (info["steps"] + info["rejected"])  # FSAL: three per step
    assert abs(settling.remaining(info["t_end"]) - info["t_end"]) < 1e-12  # nothing left to come


def test_a_flow_that_keeps_folding_stops_at_its_last_fold_free_state():
    """Bogacki--Shampine steps stop after ``fold_stop`` fold rejections, where they were."""
    y0 = np.array([[1.0, 0.0]])
    y, info = bs32_flow(lambda t, y: -y, y0.copy(), _identity, BS32Options(1e-3, first_step=0.1, t0=0.5,
                                                                            fold_stop=7), lambda p: True)
    assert info["fold_stop"] == 0.5 and info["fold_rejections"] == 7 and info["steps"] == 0
    np.testing.assert_array_equal(y, y0)
    # the Heun pairs shorten the step instead, until it stalls
    with pytest.raises(Stalled, match="fell below"):
        heun_flow(lambda t, y: -y, y0.copy(), _identity, HeunOptions(1e-3, stall_dt=1e-3), lambda p: p[0, 0] < 0.9)


def test_a_blurred_start_is_the_heat_kernels_time():
    """Diffusion for t blurs by a Gaussian of variance 2t: sigma spacings of an n-grid at t = (sigma h)^2 / 2."""
    assert blur_start(0.0, 17) == 0.0
    assert blur_start(2.0, 17) == pytest.approx(0.5 * (2.0 / 16) ** 2, rel=1e-15)
