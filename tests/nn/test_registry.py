"""The table of network constructors: every architecture is built by name, an unknown one is named in the error."""
import pytest

from rfmap.nn.registry import ARCHS, NETWORKS, build_model


def test_every_architecture_is_a_constructor_in_the_table():
    assert ARCHS == tuple(NETWORKS) == ("unet", "fno")


def test_an_unknown_architecture_lists_the_known_names():
    with pytest.raises(ValueError, match=r"unknown model architecture 'mlp'; expected one of \('unet', 'fno'\)"):
        build_model({"arch": "mlp", "dim": 2, "n_params": 1})


def test_a_description_missing_an_argument_names_it():
    with pytest.raises(ValueError, match="lacks 'depth'"):
        build_model({"arch": "unet", "dim": 2, "n_params": 1, "base": 4})
