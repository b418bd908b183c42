"""Classical reference solvers.

* :func:`solve_lbs` -- Linear Beltrami Solver (Lui et al. 2013): the quasi-conformal map of the unit square with a
  prescribed Beltrami coefficient.
* :func:`solve_dem` -- density-equalizing map of the unit square or cube: it picks the method, the diffusion method
  (Gastner & Newman 2004, :func:`~rfmap.solvers.diffusion.solve_diffusion`, which this package also exports) or,
  with ``method="flow"``, the flow-based method (Gastner, Seguy & More 2018, :func:`solve_flow`).

All return a :class:`rfmap.core.result.MapResult`; :data:`SOLVERS` / :func:`get_solver` look them up by name: ``"lbs"``,
``"diffusion"`` and ``"flow"`` (``"dem"`` is accepted as another name of ``"diffusion"``, :data:`ALIASES`).

The solvers (which run on torch) are imported the first time they are used, so that importing this package, e.g.
for :data:`ALIASES` or the torch-free cartogram flow (:mod:`rfmap.solvers.cartoflow`), does not load PyTorch.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from ..core.result import MapResult

__all__ = ["SOLVERS", "DEM_METHODS", "ALIASES", "get_solver", "solve_lbs", "solve_dem", "solve_diffusion",
           "solve_flow", "FlowOptions", "DiffusionOptions"]

#: Density-equalizing methods of :func:`solve_dem`.
DEM_METHODS = ("diffusion", "flow")
#: Other names of solvers: ``"dem"`` (the diffusion DEM) is ``"diffusion"``.
ALIASES = {"dem": "diffusion"}


def solve_dem(density, *, method: str = "diffusion", **kwargs) -> MapResult:
    """Density-equalizing map of the unit square or cube by the diffusion or the flow-based method.

    Parameters
    ----------
    density : ndarray, shape (N, N) or (N, N, N)
    method : {"diffusion", "flow"}
        ``"diffusion"`` (also ``"dem"``): :func:`~rfmap.solvers.diffusion.solve_diffusion` (Gastner & Newman
        2004); ``"flow"``: :func:`solve_flow` (Gastner, Seguy & More 2018), usually the faster of the two
        (chapter 11 of the book, *Fast classical maps and neural warm starts*, times both on its fields and
        grids).
    **kwargs
        Options of the chosen solver (``boundary``, ``progress``, ...).

    Returns
    -------
    MapResult
    """
    method = ALIASES.get(method, method)
    if method in DEM_METHODS:
        return get_solver(method)(density, **kwargs)
    raise ValueError(f"unknown density-equalizing method {method!r}; choose one of {DEM_METHODS}")


def __getattr__(name: str):
    """The solvers, their options (:class:`FlowOptions`, :class:`DiffusionOptions`) and :data:`SOLVERS` (the registry of the classical solvers by name),
    imported on first access."""
    if name == "solve_lbs":
        from .lbs import solve_lbs as value
    elif name == "solve_diffusion":
        from .diffusion import solve_diffusion as value
    elif name == "DiffusionOptions":
        from .diffusion import DiffusionOptions as value
    elif name in ("solve_flow", "FlowOptions"):
        from . import flow

        value = getattr(flow, name)
    elif name == "SOLVERS":
        value = {"lbs": __getattr__("solve_lbs"), "diffusion": __getattr__("solve_diffusion"),
                 "flow": __getattr__("solve_flow")}
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def get_solver(name: str) -> Callable[..., MapResult]:
    """Look up a solver by name (``"lbs"``, ``"diffusion"`` or ``"flow"``, or a name of :data:`ALIASES`);
    ``ValueError`` naming the known solvers otherwise."""
    solvers = __getattr__("SOLVERS") if "SOLVERS" not in globals() else globals()["SOLVERS"]
    if not isinstance(name, str) or ALIASES.get(name, name) not in solvers:
        raise ValueError(f"unknown solver {name!r}; known solvers: {', '.join(sorted(solvers))}")
    return solvers[ALIASES.get(name, name)]
