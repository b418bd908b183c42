"""Plotting: one matplotlib style for the 2D figures, PyVista (off screen) for the 3D ones, VTK export.

One module per kind of figure: :mod:`~rfmap.viz.figures` (the style and where figures are saved),
:mod:`~rfmap.viz.meshes` (2D maps), :mod:`~rfmap.viz.volumes` (3D maps), :mod:`~rfmap.viz.architecture` (the
network), :mod:`~rfmap.viz.training` (batches, loss terms, learning curves), :mod:`~rfmap.viz.cartograms` and
:mod:`~rfmap.viz.studies` (the studies' tables and reports).  Every name is importable from :mod:`rfmap.viz`,
with :func:`rfmap.core.result.to_pyvista` and :func:`rfmap.core.result.setup_pyvista`.
"""
from __future__ import annotations

from ..core.result import setup_pyvista, to_pyvista
from .architecture import architecture_diagram
from .cartograms import area_error_histograms, cartogram_figure, cartogram_panels, plot_regions
from .figures import STYLE, figures_dir, repository_root, save_figure, style
from .meshes import beltrami_figure, element_rho, extreme_figure, map_rows_figure, plot_beltrami_row, plot_density, \
    plot_map_row, plot_mesh, plot_mu, plot_slice_outline, population_figure, vertex_error_panels
from .studies import displacement_demand_figure, shorten_curve, table_lines, time_accuracy_figure
from .training import LOSS_TERMS, learning_curves, plot_batch, plot_loss_terms, training_curves, validation_vs_time
from .volumes import CAMERA_3D, render_lattice, render_volume, volume_rows

__all__ = ["STYLE", "style", "repository_root", "figures_dir", "save_figure", "plot_mesh", "plot_density", "plot_mu",
           "plot_map_row", "to_pyvista", "render_volume", "element_rho", "setup_pyvista", "architecture_diagram",
           "population_figure", "volume_rows", "render_lattice", "plot_batch", "plot_loss_terms", "training_curves",
           "learning_curves", "CAMERA_3D", "LOSS_TERMS", "plot_regions", "cartogram_figure", "cartogram_panels",
           "area_error_histograms", "time_accuracy_figure", "validation_vs_time", "table_lines", "plot_slice_outline",
           "displacement_demand_figure", "vertex_error_panels", "shorten_curve", "plot_beltrami_row",
           "beltrami_figure", "map_rows_figure", "extreme_figure"]
