r"""Accuracy bounds on the shipped models (``rfmap.surrogate.models()``): a retrain that maps the paper's test fields
worse than the bound below fails.

Every model maps the paper's test fields (and ``multi-freq``) at ``ci`` sizes, 2D N = 33 and 3D N = 17, twice: the
raw network map (``repair=False``) and the delivered map (the defaults: fold repair, then the shortening of a map that
is no more equal than the input).  Both must be fold-free and within the model's bound:

* density models: :math:`\mathrm{Std}(\tilde\rho_{map}) \le` ``MARGIN`` x (the ratio below) x
  :math:`\mathrm{Std}(\tilde\rho_{orig})`, per field (the identity map has ratio 1);
* ``beltrami2d``: mean vertex distance to the exact map :math:`|\Delta d|` and mean :math:`|\Delta\mu|` at most
  ``MARGIN`` x the values below, per test map (the identity map: :math:`|\Delta d|` 0.0465, 0.0205, 0.0210, 0.0215
  and :math:`|\Delta\mu|` 0.168, 0.108, 0.091, 0.109 on T1-T4).

The tables hold the values measured on the shipped weights (raw and delivered maps agree on every test field today:
nothing folds and nothing is shortened), one dict per model.  A model retrained and shipped replaces its dict with
its own measured values (``python tests/test_accuracy.py`` prints them) when they are no worse; the margin is not
widened.
"""
from __future__ import annotations

import pytest

from rfmap.fields.paper import BELTRAMI_MAPS, TEST_FIELDS
from rfmap.surrogate import Surrogate, models, quiet_quality

#: How much worse than measured a shipped model may map a test field before the test fails.
MARGIN = 1.4
N = {2: 33, 3: 17}

#: Std(rho~_map) / Std(rho~_orig) of each density model's raw map, per field (2D N = 33, 3D N = 17).
DENSITY_RATIO = {
    "dem2d-square": {"sin-cos": 0.155, "exp-log": 0.165, "rect-peak": 0.160, "ring": 0.140, "multi-freq": 0.193},
    "deq2d-square": {"sin-cos": 0.159, "exp-log": 0.178, "rect-peak": 0.160, "ring": 0.097, "multi-freq": 0.194},
    "deq2d-square-native": {"sin-cos": 0.231, "exp-log": 0.274, "rect-peak": 0.221, "ring": 0.118,
                            "multi-freq": 0.275},
    "deq2d-free": {"sin-cos": 0.139, "exp-log": 0.174, "rect-peak": 0.145, "ring": 0.158, "multi-freq": 0.192},
    "fno-deq2d-square": {"sin-cos": 0.468, "exp-log": 0.529, "rect-peak": 0.437, "ring": 0.454,
                         "multi-freq": 0.542},
    "dem3d-cube": {"sin-cos-3d": 0.244, "shell-3d": 0.296, "octant-3d": 0.270, "prism-peak-3d": 0.484,
                   "multi-freq-3d": 0.261},
    "dem3d-cube-native": {"sin-cos-3d": 0.237, "shell-3d": 0.313, "octant-3d": 0.259, "prism-peak-3d": 0.470,
                          "multi-freq-3d": 0.257},
    "dem3d-free": {"sin-cos-3d": 0.166, "shell-3d": 0.189, "octant-3d": 0.206, "prism-peak-3d": 0.567,
                   "multi-freq-3d": 0.184},
}
#: (mean |Δd|, mean |Δμ|) of the Beltrami model's raw map of each test map at N = 33.
BELTRAMI_ERROR = {
    "beltrami2d": {"T1": (0.00297, 0.0131), "T2": (0.00126, 0.0122), "T3": (0.00065, 0.0068),
                   "T4": (0.00053, 0.0073)},
}


def measure(sur: Surrogate, field: str, repair: bool) -> tuple[int, float, float]:
    """``(folded elements, first measure, second measure)`` of one map: Std ratio and Std(rho~_map) for a density
    model, mean |Δd| and mean |Δμ| for a Beltrami model."""
    n = N[sur.spec.dim]
    with quiet_quality():  # a poor map is what the assertion reports
        res = sur.map(field, n, repair=repair)
    if sur.spec.kind == "density":
        m = res.metrics()
        return m.n_flipped, m.std_rho_map / m.std_rho_orig, m.std_rho_map
    m = res.metrics(exact_points=BELTRAMI_MAPS[field](res.ref_points), mu_ref=res.field)
    return m.n_flipped, m.mean_dd, m.mean_dmu


def test_every_shipped_model_has_bounds():
    assert sorted({**DENSITY_RATIO, **BELTRAMI_ERROR}) == models()


@pytest.mark.parametrize("repair", [False, True], ids=["raw", "delivered"])
@pytest.mark.parametrize("name", sorted(DENSITY_RATIO))
def test_density_model_accuracy(name, repair):
    """Std(rho~_map) <= MARGIN x the measured ratio x Std(rho~_orig) on every field, and no folded element."""
    sur = Surrogate.pretrained(name)
    worse = []
    for field, ratio in DENSITY_RATIO[name].items():
        flipped, got, _ = measure(sur, field, repair)
        if flipped or not got <= MARGIN * ratio:
            worse.append(f"{field}: ratio {got:.4f} (bound {MARGIN * ratio:.4f}, measured {ratio}), {flipped} folded")
    assert not worse, f"{name} ({'delivered' if repair else 'raw'} maps): " + "; ".join(worse)


@pytest.mark.parametrize("repair", [False, True], ids=["raw", "delivered"])
@pytest.mark.parametrize("name", sorted(BELTRAMI_ERROR))
def test_beltrami_model_accuracy(name, repair):
    """mean |Δd| and mean |Δμ| <= MARGIN x measured on every test map, and no folded element."""
    sur = Surrogate.pretrained(name)
    worse = []
    for field, (dd, dmu) in BELTRAMI_ERROR[name].items():
        flipped, got_dd, got_dmu = measure(sur, field, repair)
        if flipped or not (got_dd <= MARGIN * dd and got_dmu <= MARGIN * dmu):
            worse.append(f"{field}: |Δd| {got_dd:.5f} (bound {MARGIN * dd:.5f}), |Δμ| {got_dmu:.4f} "
                         f"(bound {MARGIN * dmu:.4f}), {flipped} folded")
    assert not worse, f"{name} ({'delivered' if repair else 'raw'} maps): " + "; ".join(worse)


def test_the_bounds_reject_the_identity_map():
    """The bounds are far from what no map at all scores: the identity (ratio 1; the |Δd| of T1-T4 above) fails
    every one of them."""
    identity_dd = {"T1": 0.0465, "T2": 0.0205, "T3": 0.0210, "T4": 0.0215}
    assert all(MARGIN * r < 0.8 for table in DENSITY_RATIO.values() for r in table.values())
    assert all(MARGIN * dd < 0.2 * identity_dd[f] for table in BELTRAMI_ERROR.values()
               for f, (dd, _) in table.items())


if __name__ == "__main__":  # print the measured values of the shipped weights, for the tables above
    for name in models():
        sur = Surrogate.pretrained(name)
        fields = BELTRAMI_ERROR.get(name) or DENSITY_RATIO.get(name) or TEST_FIELDS[sur.spec.kind, sur.spec.dim]
        for repair in (False, True):
            values = {f: measure(sur, f, repair) for f in fields}
            print(name, "delivered" if repair else "raw",
                  {f: tuple(float(f"{x:.3g}") for x in v) for f, v in values.items()})
