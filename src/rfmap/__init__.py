"""rfmap: resolution-free neural surrogates for geometric parameterization and mapping.

Quick start::

    from rfmap.fields import sample_density
    from rfmap.solvers import solve_dem
    from rfmap import Surrogate, models

    res = solve_dem(sample_density("sin-cos", 51))      # classical diffusion DEM
    print(res.metrics())
    sur = Surrogate.pretrained(models()[0])               # a shipped neural surrogate
"""
from ._version import __version__
from .pretrained import load_or_train
from .surrogate import Surrogate, models

__all__ = ["Surrogate", "models", "load_or_train", "__version__"]
