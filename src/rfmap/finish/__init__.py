r"""Finishing a computed map: the stages between a network's (or a classical solver's) map and the one returned.

A map is predicted (:meth:`rfmap.Surrogate.map`: field, displacement, map of the output mesh) or solved
(:mod:`rfmap.solvers`); then a sequence of stages, in this order, each a function from a :class:`.Draft` (the map
and the report of what was done to it) to the next, finishes it:

* :func:`~rfmap.finish.stages.refine` -- weight refinement of the stretching vector (paper Sec. 4.3);
* :func:`~rfmap.finish.stages.regrid` -- in 3D, a folded network map tried on coarser working grids, each map
  refined too when refinement is on;
* :func:`~rfmap.finish.stages.repair` -- the map made fold-free;
* :func:`~rfmap.finish.stages.polish` -- a density map finished by the flow-based solver;
* :func:`~rfmap.finish.stages.judge` -- whether a density map is more equal than its input, i.e. lowers
  Std(ρ̃) (:mod:`~rfmap.finish.quality`);
* :func:`~rfmap.finish.stages.shorten` -- if not, shortened towards the identity until it is.

:func:`~rfmap.finish.pipeline.finish` composes them as :meth:`rfmap.Surrogate.map` does, with :class:`.FinishOptions`;
:func:`.finish_map` applies them to a classical map.  The report is typed (:class:`.MapReport`) and the returned map's
``info`` is its read-only view as a dictionary (:class:`.InfoView`).  Maps of query points
go back to their working grid (:mod:`~rfmap.finish.query`).

The stages are the functions of the module :mod:`rfmap.finish.stages`; each calls the module that does its work:
:mod:`~rfmap.finish.refine` (the search for :math:`\alpha`), :mod:`~rfmap.finish.repair` (one strategy per module),
:mod:`~rfmap.finish.polish` (the flow-based solver from the network's map) and :mod:`~rfmap.finish.shorten`.
Modules: :mod:`~rfmap.finish.report`, :mod:`~rfmap.finish.draft`, :mod:`~rfmap.finish.stages`,
:mod:`~rfmap.finish.query`, :mod:`~rfmap.finish.quality`, :mod:`~rfmap.finish.pipeline`.
"""
from __future__ import annotations

from .draft import Draft, Prediction, WorkingGridMap, displacement_at
from .pipeline import FinishOptions, finish, finish_map
from .quality import GAIN_RTOL, QUALITY_MARGIN, PoorMapWarning, density_quality, poor_map_message, quality_message, \
    quiet_quality
from .report import InfoView, MapReport, NetworkReport, RefineReport, RegridReport

__all__ = ["Draft", "Prediction", "WorkingGridMap", "displacement_at", "FinishOptions", "finish", "finish_map",
           "QUALITY_MARGIN", "GAIN_RTOL", "PoorMapWarning", "density_quality", "poor_map_message", "quality_message",
           "quiet_quality", "InfoView", "MapReport", "NetworkReport", "RefineReport", "RegridReport"]
