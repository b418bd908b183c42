"""rfmap: resolution-free neural surrogates for geometric parameterization and mapping.

Quick start::

    from rfmap.fields import sample_density
    from rfmap.solvers import solve_dem
    from rfmap import Surrogate, models

    # the classical diffusion DEM
    res = solve_dem(sample_density("sin-cos", 51))
    print(res.metrics())
    # a shipped neural surrogate on the same density
    sur = Surrogate.pretrained("deq2d-square")
    print(sur.map("sin-cos", 51).metrics())

The neural names (:class:`Surrogate`, :func:`models`, :func:`load_or_train`) are imported on first use, so that the
classical paths (``rfmap cartogram``, :mod:`rfmap.cartogram.resize`) run without loading PyTorch.
"""
from ._version import __version__

__all__ = ["Surrogate", "models", "load_or_train", "__version__"]

#: where each lazily imported name lives
_LAZY = {"Surrogate": "surrogate", "models": "surrogate", "load_or_train": "pretrained"}


def __getattr__(name: str):
    """``rfmap.Surrogate``, ``rfmap.models``, ``rfmap.load_or_train``: imported on first access (PEP 562)."""
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
