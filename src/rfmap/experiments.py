"""The paper's experiments under their historical path: every name lives in the paper layer, :mod:`rfmap.paper`.

The table formatter and glue in :mod:`rfmap.paper.tables`, the paper's tables in :mod:`rfmap.paper.reproduce`, the
studies on unseen fields in :mod:`rfmap.paper.generalization`, the training recipes in :mod:`rfmap.paper.recipes`,
the benchmarks' shared code in :mod:`rfmap.paper.benchmarks` and the flow studies in :mod:`rfmap.paper.flow_studies`.
``FLOW_SETTINGS`` here is :data:`rfmap.paper.flow_studies.CONVERGENCE_SETTINGS` (the cartograms' flow settings are
:data:`rfmap.cartogram.FLOW_SETTINGS`).
"""
from __future__ import annotations

from .paper.benchmarks import WARM_MODELS, benchmark_fields, summarize, time_to_accuracy
from .paper.flow_studies import (CONVERGENCE_SETTINGS, flow_convergence, residual_floor, sea_blend_study,
                                 warm_start_residuals)
from .paper.generalization import displacement_demand, distortion_table, generalization_table
from .paper.recipes import recipe_table, training_fields_text
from .paper.reproduce import (SYM, SYM_REF, beltrami_resolution_table, beltrami_table, exact_beltrami_result,
                              population_summary, population_table, reproduce, resolution_table)
from .paper.tables import COLUMN_TITLES, DIGITS, MAX_COLUMNS, Table, format_value, glue_all, paper_table  # noqa: F401

#: :data:`rfmap.paper.flow_studies.CONVERGENCE_SETTINGS` under its former name
FLOW_SETTINGS = CONVERGENCE_SETTINGS

__all__ = ["paper_table", "Table", "beltrami_table", "beltrami_resolution_table", "population_table",
           "resolution_table", "reproduce", "exact_beltrami_result", "population_summary", "glue_all",
           "COLUMN_TITLES", "format_value", "DIGITS", "generalization_table", "WARM_MODELS", "benchmark_fields",
           "time_to_accuracy", "summarize", "residual_floor", "flow_convergence", "FLOW_SETTINGS",
           "warm_start_residuals", "sea_blend_study",
           "displacement_demand", "distortion_table", "recipe_table", "training_fields_text", "SYM", "SYM_REF"]
