"""The training configurations are typed presets built by keyword (rfmap.training.config.Presets)."""
from dataclasses import replace

import pytest

from rfmap.tasks import TaskSpec
from rfmap.training.config import CONFIGS, PRESETS, Presets, TrainConfig


def test_every_config_has_its_presets_under_its_name():
    for name, presets in CONFIGS.items():
        assert tuple(presets) == PRESETS
        assert all(cfg.name == name and cfg.preset == preset for preset, cfg in presets.items())


def test_presets_of_a_base_and_derived_presets():
    """The paper preset runs as the paper's runs did and validates as the full preset; a derived configuration
    changes what it names, alike or per preset, and keeps the paper's recipe in its paper description."""
    base = TrainConfig(name="x", task=TaskSpec("density", 2, "square"), description="A model.", lr=5e-4)
    p = Presets.of(base, ci=dict(steps=3), full=dict(steps=300, threads=2, val_sizes=(51,), val_count=4),
                   paper=dict(steps=9000), paper_note="as printed.")
    assert (p.ci.steps, p.full.steps, p.paper.steps) == (3, 300, 9000)
    assert (p.paper.threads, p.paper.time_limit, p.paper.val_sizes, p.paper.val_count) == (0, 0.0, (51,), 4)
    assert p.paper.description == "A model. Paper preset: as printed." and p.full.description == "A model."
    d = p.derive(name="y", description="Another.", lr=1e-3, full=dict(steps=10))
    assert [c.name for c in d.configs().values()] == ["y"] * 3 and {c.lr for c in d.configs().values()} == {1e-3}
    assert (d.ci.steps, d.full.steps, d.paper.steps) == (3, 10, 9000)
    assert d.paper.description == "Another. Paper preset: as printed." and d.ci.description == "Another."
    assert d.full == replace(p.full, name="y", description="Another.", lr=1e-3, steps=10)
    with pytest.raises(TypeError):  # a misspelt field is an error, not a silent default
        p.derive(name="z", description="", stpes=1)


def test_hard_share_overrides_the_density_fields_and_is_recorded():
    from rfmap.training.cli import _command_line, _structured_overrides, build_parser
    from rfmap.training.config import get_config

    cfg = get_config("dem3d-cube-native", "full")
    args = build_parser().parse_args(["--config", "dem3d-cube-native", "--hard-share", "0.3"])
    over = _structured_overrides(cfg, args)
    assert over["density_field"].p_hard == 0.3
    assert over["density_field"].p_ramp == cfg.density_field.p_ramp  # the rest of the mix kept
    assert "--hard-share 0.3" in _command_line(args)
    for bad in ("1.5", "-0.1", "nan"):
        args = build_parser().parse_args(["--config", "dem3d-cube-native", "--hard-share", bad])
        with pytest.raises(ValueError, match="hard-share"):
            _structured_overrides(cfg, args)
    args = build_parser().parse_args(["--config", "beltrami2d", "--hard-share", "0.3"])
    with pytest.raises(ValueError, match="no density fields"):
        _structured_overrides(get_config("beltrami2d", "full"), args)


def test_fold_weight_overrides_the_loss_and_is_recorded():
    from rfmap.training.cli import _command_line, _structured_overrides, build_parser
    from rfmap.training.config import get_config

    cfg = get_config("dem3d-cube-native", "full")
    args = build_parser().parse_args(["--config", "dem3d-cube-native", "--fold-weight", "1000"])
    over = _structured_overrides(cfg, args)
    assert over["loss"].fold == 1000.0
    assert over["loss"].fold_threshold == cfg.loss.fold_threshold  # the rest of the loss kept
    assert over["loss"].density_tangent == cfg.loss.density_tangent
    assert "--fold-weight 1000" in _command_line(args)
    for bad in ("-1", "nan", "inf"):
        args = build_parser().parse_args(["--config", "dem3d-cube-native", "--fold-weight", bad])
        with pytest.raises(ValueError, match="fold-weight"):
            _structured_overrides(cfg, args)
