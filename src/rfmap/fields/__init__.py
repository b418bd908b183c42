"""The input fields of :mod:`rfmap` in one namespace: every name below can be imported from ``rfmap.fields``, and
each is documented with the module that defines it.

* :mod:`rfmap.fields.paper` -- the paper's test densities and Beltrami test maps (``DENSITIES``, ``BELTRAMI_MAPS``,
  ``TEST_FIELDS``, ``PAPER_N``, ``RECT_PEAK_BOX``, ``DensityField``, ``BeltramiMap``, ``field_names``,
  ``get_field``, ``sample_density``, ``sample_mu``);
* :mod:`rfmap.fields.random` -- random training fields (``RandomDensity``, ``RandomDensityConfig``,
  ``random_density``, ``RandomMap``, ``random_boundary_map``, ``RandomBeltrami``, ``RandomBeltramiConfig``,
  ``random_beltrami``);
* :mod:`rfmap.fields.hard` -- hard fields that make a network's raw map fold (sharp peaks, near-zero regions,
  steep ramps; each task draws its own kind, :doc:`Repair and shortening </book/api/repair>`);
* :mod:`rfmap.core.inputs` -- checking and normalising input fields (``check_density``, ``check_mu``, ``unit_mass``,
  ``preprocess_density``).
"""
from __future__ import annotations

from ..core.inputs import check_density, check_mu, preprocess_density, unit_mass
from .paper import (BELTRAMI_MAPS, DENSITIES, PAPER_N, RECT_PEAK_BOX, TEST_FIELDS, BeltramiMap, DensityField,
                    field_names, get_field, sample_density, sample_mu)
from .random import (RandomBeltrami, RandomBeltramiConfig, RandomDensity, RandomDensityConfig, RandomMap,
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
]
