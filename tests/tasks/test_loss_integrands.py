"""rfmap.tasks.losses.loss_integrands: the loss terms element by element integrate to the losses of training."""
import pytest
import torch

from rfmap.tasks import losses as L
from rfmap.nn.model import apply_displacement
from rfmap.tasks import LossWeights, TaskSpec, sample_batch, task_loss


def _mapped(batch, spec, scale=0.3, seed=0):
    g = torch.Generator().manual_seed(seed)
    disp = scale * torch.randn(batch.ref.shape, generator=g, dtype=batch.ref.dtype)
    return apply_displacement(batch.ref, disp, spec.boundary)


@pytest.mark.parametrize("spec", [TaskSpec("density", 2, "square"), TaskSpec("density", 2, "free"),
                                  TaskSpec("density", 3, "square"), TaskSpec("beltrami", 2, "fixed")])
def test_integrands_integrate_to_the_losses(spec):
    batch = sample_batch(spec, seed=0, step=0, indices=range(2), n=9)
    mapped = _mapped(batch, spec)
    t = L.loss_integrands(batch.ref, mapped, batch.elements, density=batch.density, mu_target=batch.mu_target,
                          fold_threshold=0.05)
    w = t["weight"]
    assert float(t["fold"].max()) > 0  # the random displacement folds some elements
    args = (batch.ref, mapped, batch.elements)
    expect = {"fold": L.fold_penalty(*args, 0.05), "area": L.area_penalty(*args)}
    if spec.kind == "density":
        expect["density"] = L.density_loss(*args, batch.density)
    else:
        expect["beltrami"] = L.beltrami_loss(*args, batch.mu_target)
    if spec.dim == 2:
        expect["mu2"] = L.beltrami_energy(*args)
    else:
        assert "mu2" not in t
    for key, value in expect.items():
        got = t[key].mean() if key == "area" else L.weighted_mean(t[key], w)
        assert float(got) == pytest.approx(float(value), rel=1e-5, abs=1e-9), key


def test_integrands_match_the_parts_of_task_loss():
    spec = TaskSpec("density", 2, "free")
    batch = sample_batch(spec, seed=3, step=1, indices=range(3), n=11)
    psi = 0.1 * torch.randn(3, 2, 11, 11, generator=torch.Generator().manual_seed(1))
    weights = LossWeights(beltrami=0.1, fold=10.0, fold_threshold=0.02, area=1.0)
    _, parts = task_loss(spec, batch, psi, weights)
    mapped = apply_displacement(batch.ref, psi.flatten(2).transpose(1, 2), spec.boundary)
    t = L.loss_integrands(batch.ref, mapped, batch.elements, density=batch.density,
                          fold_threshold=weights.fold_threshold)
    for key in ("density", "mu2", "fold"):
        assert float(L.weighted_mean(t[key], t["weight"])) == pytest.approx(parts[key], rel=1e-4, abs=1e-9), key
    assert float(t["area"].mean()) == pytest.approx(parts["area"], rel=1e-4, abs=1e-12)


def test_batch_loss_terms_of_an_untrained_network_are_those_of_the_identity():
    """rfmap.tasks.batch_loss_terms: an untrained network (zero head) maps every vertex to itself; its loss is the
    density mismatch of the input alone, and the integrands give the same number."""
    from rfmap.nn.model import MultiResUNet
    from rfmap.tasks import batch_loss_terms

    spec = TaskSpec("density", 2, "square")
    batch = sample_batch(spec, seed=0, step=0, indices=range(2), n=9)
    weights = LossWeights(beltrami=0.1)
    total, parts, mapped, terms = batch_loss_terms(MultiResUNet(base=4, depth=2), spec, batch, weights)
    assert torch.equal(mapped, batch.ref)
    assert parts["fold"] == 0 and parts["mu2"] == pytest.approx(0, abs=1e-12)
    assert total == pytest.approx(parts["density"], rel=1e-6)
    assert float(L.weighted_mean(terms["density"], terms["weight"])) == pytest.approx(parts["density"], rel=1e-5)


@pytest.mark.parametrize("spec", [TaskSpec("density", 2, "free"), TaskSpec("beltrami", 2, "fixed")])
def test_batch_loss_terms_without_a_model_are_those_of_the_identity(spec):
    """model=None gives the identity map's terms, those of an untrained (zero-head) network: a Beltrami batch keeps
    its whole mu mismatch, |mu_in|^2, and nothing is folded."""
    from rfmap.nn.model import MultiResUNet
    from rfmap.tasks import batch_loss_terms

    batch = sample_batch(spec, seed=2, step=0, indices=range(2), n=9)
    weights = LossWeights(beltrami=0.1, fold=1.0, area=1.0)
    total, parts, mapped, _ = batch_loss_terms(None, spec, batch, weights)
    net = MultiResUNet(n_params=batch.inputs.shape[1] - 2, base=4, depth=2)
    net_total, net_parts, _, _ = batch_loss_terms(net, spec, batch, weights)
    assert torch.equal(mapped, batch.ref)
    assert total == pytest.approx(net_total, rel=1e-6)
    assert parts.keys() == net_parts.keys() and parts["fold"] == 0
    if spec.kind == "beltrami":
        assert parts["beltrami"] > 0
