"""The stages composed: what happens to a computed map before it is delivered, for network and classical maps."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from .polish import GUARD, polish_tolerance
from ..core.result import MapResult
from .draft import Draft
from .stages import judge, polish, refine, repair, shorten

__all__ = ["MapOptions", "finish", "finish_map"]


@dataclass(frozen=True)
class MapOptions:
    """How a field is mapped, listed once: the keywords of :meth:`rfmap.Surrogate.map` (and ``map_batch``), the
    options of ``rfmap map``, and of :func:`finish` / :func:`finish_map` for classical maps (which read the
    finishing stages' fields: ``refine``, ``refine_bounds``, ``repair``, ``polish``, ``guard``).

    Attributes
    ----------
    refine : bool
        Weight refinement of the map's displacement (paper Sec. 4.3; :func:`rfmap.finish.stages.refine`).  A
        network's map is refined as it is predicted (every working grid that :func:`rfmap.finish.stages.regrid`
        tries is), not by :func:`finish`.
    refine_bounds : (float, float), optional
        Search interval of every component of the stretching vector (default :data:`rfmap.finish.refine.REFINE`).
    repair : bool
        Make the map fold-free (:func:`rfmap.finish.stages.repair`), and shorten a density map that is still no
        more equal than its input (:func:`rfmap.finish.stages.shorten`).  ``False`` returns the raw map.
    polish : bool or float
        Finish a density map of a grid with the flow-based solver (:func:`rfmap.finish.stages.polish`); a number
        is the tolerance on Std(rho~_map).  A polished map is not judged or shortened: the flow equalizes it.
    guard : bool
        With ``polish``: keep the better of the warm and the cold flow (:data:`rfmap.finish.polish.GUARD`).
    work_n : int, optional
        A network's working grid side (default :meth:`rfmap.Surrogate.work_n`; then, in 3D and without ``polish``,
        a folded map is first tried on coarser working grids).  Given explicitly, it is used as given.
    native : bool
        Run the network on the requested grid itself (``work_n = n``, no coarser working grid tried): the paper's
        method.  Excludes ``work_n``.
    alpha : sequence of d floats, optional
        A fixed stretching vector of a network's map (ignored with ``refine``).
    preprocess : bool
        Apply the paper's density preprocessing (shift to minimum 0.1, unit mass) to raw values; with ``False`` a
        positive density is only scaled to unit mass.
    symmetrize : bool or str
        Average a network's displacement over symmetries of the square or cube (:mod:`rfmap.nn.symmetry`).
    """

    refine: bool = False
    refine_bounds: tuple[float, float] | None = None
    repair: bool = True
    polish: bool | float = False
    guard: bool = GUARD
    work_n: int | None = None
    native: bool = False
    alpha: Sequence[float] | None = None
    preprocess: bool = True
    symmetrize: bool | str = False

    def __post_init__(self):
        if self.polish is not False:
            polish_tolerance(self.polish)  # a bad value is an error before any work

    @property
    def tol(self) -> float | None:
        """The polish's tolerance on Std(rho~_map) (``None``: the solver's default)."""
        return polish_tolerance(self.polish) if self.polish is not False else None


def finish(draft: Draft, options: MapOptions = MapOptions()) -> Draft:
    """The stages after the map is computed: refine, repair, then polish, or for a density map judge and shorten.

    A density map of a grid without ``polish`` is judged (:func:`rfmap.finish.stages.judge`); with ``repair`` a density
    map of a grid or a network's map of query points is shortened when it is no more equal than its input.
    """
    if options.polish is not False and (not draft.task.equalizes or draft.grid_n is None):
        raise ValueError("polish finishes density maps on the output grid; it does not apply to "
                         f"{draft.kind} maps or to query points")
    if options.refine:
        draft = refine(draft, options.refine_bounds)
    if options.repair:
        draft = repair(draft, cold_polish=options.polish is not False)
    if options.polish is not False:
        return polish(draft, options.tol, options.guard)
    if draft.task.equalizes:
        if draft.grid_n is not None:
            draft = judge(draft)
        if options.repair and (draft.grid_n is not None or draft.prediction is not None):
            draft = shorten(draft)
    return draft


def finish_map(result: MapResult, options: MapOptions = MapOptions(), *, boundary: str | None = None,
               n: int | None = None) -> MapResult:
    """Finish a computed map, e.g. a classical solver's (:mod:`rfmap.solvers`), with the stages of :func:`finish`.

    Parameters
    ----------
    result : MapResult
    options : MapOptions
    boundary : {"fixed", "square", "free"}, optional
        The map's boundary condition (default ``result.info["boundary"]``, which the solvers record).
    n : int, optional
        The grid side when the mesh is :func:`rfmap.core.mesh.grid_mesh` ``(N, d)`` (default: recognised).

    Returns
    -------
    MapResult
        ``info``: the solver's own extras and the stages' reports (:class:`rfmap.finish.report.InfoView`; the typed
        report is ``info.report``).
    """
    return finish(Draft.of(result, boundary, n), options).deliver()
