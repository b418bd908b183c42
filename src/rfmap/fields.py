"""The input fields of :mod:`rfmap`, gathered in one namespace.

The concepts live in their own modules; this module re-exports their public names:

* :mod:`rfmap.inputs` -- checking and normalising input fields (``check_density``, ``check_mu``, ``unit_mass``,
  ``preprocess_density``);
* :mod:`rfmap.paper_fields` -- the paper's test densities and Beltrami test maps (``DENSITIES``, ``BELTRAMI_MAPS``,
  ``TEST_FIELDS``, ``PAPER_N``, ``sample_density``, ``sample_mu``, ...);
* :mod:`rfmap.random_fields` -- random training fields (``RandomDensity``, ``RandomBeltrami``, ``RandomMap``, ...);
* :mod:`rfmap.mesh` -- vertex quadrature weights and Sobol-jittered grid vertices (``vertex_weights``,
  ``jittered_points``).
"""
from __future__ import annotations

from .inputs import check_density, check_mu, preprocess_density, unit_mass
from .mesh import jittered_points, vertex_weights
from .paper_fields import (BELTRAMI_MAPS, DENSITIES, PAPER_N, RECT_PEAK_BOX, TEST_FIELDS, BeltramiMap, DensityField,
                           field_names, get_field, sample_density, sample_mu)
from .random_fields import (RandomBeltrami, RandomBeltramiConfig, RandomDensity, RandomDensityConfig, RandomMap,
                            random_beltrami, random_boundary_map, random_density)

__all__ = [
    "DensityField",
    "BeltramiMap",
    "DENSITIES",
    "BELTRAMI_MAPS",
    "RECT_PEAK_BOX",
    "TEST_FIELDS",
    "PAPER_N",
    "field_names",
    "get_field",
    "check_density",
    "check_mu",
    "unit_mass",
    "vertex_weights",
    "preprocess_density",
    "sample_density",
    "sample_mu",
    "RandomDensity",
    "RandomDensityConfig",
    "random_density",
    "RandomMap",
    "RandomBeltramiConfig",
    "random_boundary_map",
    "RandomBeltrami",
    "random_beltrami",
    "jittered_points",
]
