"""A model's description says what the model is, in at most 300 characters; its history lives in its lineage."""
import pytest

from rfmap.training.config import CONFIGS

MAX_DESCRIPTION = 300


@pytest.mark.parametrize("name", list(CONFIGS))
def test_every_config_description_is_short(name):
    """The ``ci`` and ``full`` presets' descriptions (``rfmap models`` prints the shipped ``full`` one); the ``paper``
    preset appends the paper's printed recipe."""
    for preset in ("ci", "full"):
        text = CONFIGS[name][preset].description
        assert text and len(text) <= MAX_DESCRIPTION, f"{name} {preset}: {len(text)} characters"


def test_rfmap_models_prints_the_configs_description(capsys):
    from rfmap.cli import main
    from rfmap.surrogate import models

    assert main(["models"]) == 0
    out = capsys.readouterr().out
    for name in models():
        if name in CONFIGS:
            assert CONFIGS[name]["full"].description in out, name
