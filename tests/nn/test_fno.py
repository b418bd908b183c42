"""The FNO alternative (neuraloperator's FNO behind the U-Net's interface) and the side-by-side comparison helpers.

Invariants: the untrained FNO is the identity map (zero displacement) on any grid, its description rebuilds it, its
complex spectral weights survive a safetensors round trip bit for bit, and training, ``--init`` checks and the
comparison tables work with it exactly as with the U-Net.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from rfmap.paper import compare
from rfmap.training.config import ModelConfig, get_config
from rfmap.paper.tables import Table
from rfmap.nn import FNONet, MultiResUNet, build_model, fno_available, from_tensor_state, tensor_state
from rfmap.surrogate import Surrogate
from rfmap.tasks import TaskSpec

pytestmark = pytest.mark.skipif(not fno_available(), reason="neuraloperator is not installed")

SQUARE = TaskSpec("density", 2, "square")


def tiny_fno(seed: int = 0, perturb: bool = True) -> Surrogate:
    torch.manual_seed(seed)
    net = FNONet(2, 1, modes=4, width=8, layers=2, padding=0.25)
    if perturb:  # a non-zero head, so that the map is not the identity
        with torch.no_grad():
            for p in net.net.projection.fcs[-1].parameters():
                p.normal_(0, 0.02)
    return Surrogate(net, SQUARE, {"name": "tiny-fno", "n_range": [17, 25]})


@pytest.mark.parametrize("n", [4, 9, 17, 40])
def test_untrained_fno_is_identity_on_any_grid(n):
    net = FNONet(2, 1, modes=6, width=8, layers=2)
    out = net(torch.randn(2, 3, n, n))
    assert out.shape == (2, 2, n, n)
    assert torch.count_nonzero(out) == 0


def test_fno_3d_shapes():
    net = FNONet(3, 1, modes=3, width=4, layers=1)
    assert net(torch.randn(1, 4, 7, 8, 9)).shape == (1, 3, 7, 8, 9)


@pytest.mark.parametrize("kw, match", [({"dim": 4}, "dim"), ({"modes": 0}, "modes"), ({"padding": 1.0}, "padding")])
def test_fno_rejects_bad_arguments(kw, match):
    with pytest.raises(ValueError, match=match):
        FNONet(**{"dim": 2, "n_params": 1, **kw})


def test_fno_rejects_bad_input():
    net = FNONet(2, 1, modes=4, width=4, layers=1)
    with pytest.raises(ValueError, match="channels"):
        net(torch.randn(1, 2, 9, 9))
    with pytest.raises(ValueError, match="too small"):
        net(torch.randn(1, 3, 3, 3))
    with pytest.raises(ValueError, match="shape"):
        net(torch.randn(3, 9, 9))


def test_build_model_rebuilds_both_architectures():
    for model in (FNONet(2, 1, modes=4, width=8, layers=2), MultiResUNet(2, 1, 4, 2)):
        again = build_model(model.kwargs())
        assert type(again) is type(model) and again.kwargs() == model.kwargs()
    # metadata written before the architecture choice existed has no "arch": a U-Net
    assert isinstance(build_model({"dim": 2, "n_params": 1, "base": 4, "depth": 2}), MultiResUNet)
    with pytest.raises(ValueError, match="architecture"):
        build_model({"arch": "transformer", "dim": 2, "n_params": 1})
    with pytest.raises(ValueError, match="lacks"):
        build_model({"arch": "fno", "dim": 2, "n_params": 1})


def test_model_config_kwargs_match_the_built_model():
    for mc in (ModelConfig(), ModelConfig(arch="fno", modes=5, width=6, layers=2, padding=0.1)):
        kw = mc.kwargs(2, 1)
        assert build_model(kw).kwargs() == kw
    with pytest.raises(ValueError, match="architecture"):
        ModelConfig(arch="mlp").kwargs(2, 1)


def test_complex_weights_roundtrip_through_real_views():
    net = tiny_fno().model
    state = tensor_state(net)
    assert all(not v.is_complex() for v in state.values())
    assert any(v.shape[-1] == 2 for v in state.values())
    back = from_tensor_state(net, state)
    own = net.state_dict()
    for k, v in back.items():
        assert torch.equal(v, own[k])


def test_fno_surrogate_save_load_is_exact(tmp_path):
    sur = tiny_fno()
    sur.save(tmp_path / "fno.safetensors")
    again = Surrogate.load(tmp_path / "fno.safetensors")
    assert again.model.kwargs() == sur.model.kwargs()
    a, b = sur.map("sin-cos", 21, repair=False), again.map("sin-cos", 21, repair=False)
    np.testing.assert_array_equal(a.mapped_points, b.mapped_points)
    assert np.abs(a.mapped_points - a.ref_points).max() > 1e-6  # the perturbed head moves points


def test_fno_trains_and_init_checks_the_architecture(tmp_path):
    from rfmap.training import train

    cfg = get_config("fno-deq2d-square", "ci").with_overrides(steps=4, val_every=2, ckpt_every=2)
    sur = train(cfg, tmp_path / "fno", progress=False)
    assert sur.model.kwargs()["arch"] == "fno" and sur.meta["steps"] == 4
    # continuing from it works; continuing an FNO config from U-Net weights is refused clearly
    again = train(cfg.with_overrides(steps=2), tmp_path / "fno2", init=str(tmp_path / "fno" / "fno-deq2d-square.safetensors"),
                  progress=False)
    assert again.meta["lineage"][-1]["steps"] == 4
    unet = train(get_config("deq2d-square", "ci").with_overrides(steps=2, val_every=2), tmp_path / "unet",
                 progress=False)
    del unet
    with pytest.raises(ValueError, match="architecture"):
        train(cfg, tmp_path / "bad", init=str(tmp_path / "unet" / "deq2d-square.safetensors"), progress=False)


def test_comparison_tables_on_two_tiny_models():
    surs = {"A": tiny_fno(0), "B": tiny_fno(1)}
    paper = compare.paper_fields_table(surs, n=17, fields=["sin-cos", "ring"], refine=False)
    assert [m for _, m, _ in paper.rows] == ["A", "B", "A", "B"]
    assert all(v["flips_repaired"] == 0 for _, _, v in paper.rows)
    res = compare.resolution_table(surs, ns=(17, 33))
    assert {m for _, m, _ in res.rows} == {"A (work)", "A (native)", "B (work)", "B (native)"}
    assert res.value("33", "A (native)", "work_n") == 33 and res.value("33", "A (work)", "work_n") == 25
    pts = compare.points_table(surs, n=9)
    assert {c for c, _, _ in pts.rows} == {"jittered", "scattered"}
    assert compare.parameter_count(surs["A"].model) == sum(
        p.numel() * (2 if p.is_complex() else 1) for p in surs["A"].model.parameters())


def test_comparison_refuses_different_tasks():
    other = Surrogate(MultiResUNet(2, 1, 4, 2), TaskSpec("density", 2, "free"), {"name": "free"})
    with pytest.raises(ValueError, match="different tasks"):
        compare.paper_fields_table({"A": tiny_fno(), "B": other})
    with pytest.raises(ValueError, match="at least one"):
        compare.model_table({})


def test_wins_counts_the_best_method_per_case():
    t = Table("t", "t", ["x"])
    for case, a, b in [("1", 0.1, 0.2), ("2", 0.3, 0.3), ("3", 0.5, 0.4)]:
        t.add(case, "a", {"x": a})
        t.add(case, "b", {"x": b})
    assert compare.wins(t, "x") == {"a": 2, "b": 2}
    assert compare.wins(t, "x", lower=False) == {"a": 2, "b": 2}
    t.add("4", "a", {"x": 1.0})
    t.add("4", "b", {"x": 2.0})
    assert compare.wins(t, "x") == {"a": 3, "b": 2}


def test_speed_against_flow_times_every_model_and_the_flow_solver():
    from rfmap.solvers import solve_dem
    from rfmap.fields import sample_density

    surs = {"A": tiny_fno(0), "B": tiny_fno(1)}
    out = compare.speed_against_flow(surs, n=17, repeats=2)
    assert list(out) == ["A", "B", "flow solver"]
    assert all(v["time"] > 0 for v in out.values())
    flow = solve_dem(sample_density("multi-freq", 17), method="flow").metrics().std_rho_map
    assert out["flow solver"]["std_rho_map"] == pytest.approx(flow, rel=1e-12)
    from rfmap.finish import quiet_quality

    with quiet_quality():
        plain = surs["A"].map("multi-freq", 17, repair=False).metrics().std_rho_map
    assert out["A"]["std_rho_map"] == pytest.approx(plain, rel=1e-6)
    with pytest.raises(ValueError, match="repeats"):
        compare.speed_against_flow(surs, n=17, repeats=0)
