"""Plotting: one matplotlib style for the 2D figures, PyVista (off screen) for the 3D ones, VTK export.

One module per kind of figure: :mod:`~rfmap.viz.figures` (the style and where figures are saved),
:mod:`~rfmap.viz.meshes` (2D maps), :mod:`~rfmap.viz.volumes` (3D maps), :mod:`~rfmap.viz.diffusion` (the
figures of the diffusion chapter), :mod:`~rfmap.viz.architecture` (the
network), :mod:`~rfmap.viz.training` (batches, loss terms, learning curves), :mod:`~rfmap.viz.cartograms` and
:mod:`~rfmap.viz.studies` (the studies' tables and reports).  Every name is importable from :mod:`rfmap.viz`,
with :func:`rfmap.core.result.to_pyvista` and :func:`rfmap.core.result.setup_pyvista`.

The names are imported on first access (PEP 562), each from its own module, so that drawing a cartogram
(:mod:`rfmap.viz.cartograms`, torch-free) does not load the modules of the 3D figures and the map results, which
need PyTorch.
"""
from __future__ import annotations

import importlib

#: the module (relative to this package) of each exported name
_HOME = {
    "..core.result": ("setup_pyvista", "to_pyvista"),
    ".architecture": ("architecture_diagram", "displacement_grids_figure", "encoding_figure"),
    ".cartograms": ("area_error_histograms", "cartogram_figure", "cartogram_panels", "plot_regions"),
    ".diffusion": ("boundaries_figure", "dem_steps_figure", "grid_convergence_figure", "overview_figure",
                   "solve_cost_figure", "volume_panels_figure"),
    ".figures": ("STYLE", "colorbar", "figures_dir", "frameless", "repository_root", "save_figure", "style"),
    ".meshes": ("beltrami_case_figure", "beltrami_figure", "element_rho", "extreme_figure", "folded_maps_figure",
                "grid_line_step", "grid_lines_drawn", "map_rows_figure", "query_points_figure",
                "plot_beltrami_row", "jitter_figure", "plot_density", "plot_map_row", "plot_mesh", "plot_mu",
                "plot_slice_outline",
                "population_figure", "random_fields_figure", "vertex_error_panels"),
    ".studies": ("displacement_demand_figure", "resolution_panels", "shorten_curve", "table_lines",
                 "time_accuracy_figure"),
    ".training": ("LOSS_TERMS", "learning_curves", "loss_terms_figure", "plot_batch", "plot_learning_rates",
                  "plot_loss_terms", "training_curves", "validation_vs_time"),
    ".volumes": ("CAMERA_3D", "render_lattice", "render_volume", "volume_rows"),
}
_MODULE_OF = {name: module for module, names in _HOME.items() for name in names}

__all__ = sorted(_MODULE_OF)


def __getattr__(name: str):
    """An exported name, imported from its module on first access."""
    if name not in _MODULE_OF:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_MODULE_OF[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
