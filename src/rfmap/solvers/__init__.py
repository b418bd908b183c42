"""Classical reference solvers.

* :func:`solve_lbs` -- Linear Beltrami Solver (Lui et al. 2013): the quasi-conformal map of the unit square with a
  prescribed Beltrami coefficient.
* :func:`solve_dem` -- density-equalizing map of the unit square or cube: the diffusion method (Gastner & Newman
  2004, ``rfmap.solvers.diffusion``) or, with ``method="flow"``, the flow-based method (Gastner, Seguy & More
  2018, :func:`solve_flow`).

All return a :class:`rfmap.result.MapResult`; :data:`SOLVERS` / :func:`get_solver` look them up by name: ``"lbs"``,
``"diffusion"`` and ``"flow"`` (``"dem"`` is accepted as another name of ``"diffusion"``, :data:`ALIASES`).
"""
from __future__ import annotations

from typing import Callable

from ..result import MapResult
from .diffusion import solve_dem as solve_diffusion
from .flow import FlowOptions, solve_flow
from .lbs import solve_lbs

__all__ = ["SOLVERS", "DEM_METHODS", "ALIASES", "get_solver", "solve_lbs", "solve_dem", "solve_diffusion",
           "solve_flow", "FlowOptions"]

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
        ``"diffusion"`` (also ``"dem"``): ``rfmap.solvers.diffusion.solve_dem`` (Gastner & Newman 2004); ``"flow"``:
        ``rfmap.solvers.flow.solve_flow`` (Gastner, Seguy & More 2018), usually several times faster.
    **kwargs
        Options of the chosen solver (``boundary``, ``progress``, ...).

    Returns
    -------
    MapResult
    """
    method = ALIASES.get(method, method)
    if method == "diffusion":
        return solve_diffusion(density, **kwargs)
    if method == "flow":
        return solve_flow(density, **kwargs)
    raise ValueError(f"unknown density-equalizing method {method!r}; choose one of {DEM_METHODS}")


#: Registry of the classical solvers by name.
SOLVERS: dict[str, Callable[..., MapResult]] = {"lbs": solve_lbs, "diffusion": solve_diffusion, "flow": solve_flow}


def get_solver(name: str) -> Callable[..., MapResult]:
    """Look up a solver by name (``"lbs"``, ``"diffusion"`` or ``"flow"``, or a name of :data:`ALIASES`);
    ``ValueError`` naming the known solvers otherwise."""
    if not isinstance(name, str) or ALIASES.get(name, name) not in SOLVERS:
        raise ValueError(f"unknown solver {name!r}; known solvers: {', '.join(sorted(SOLVERS))}")
    return SOLVERS[ALIASES.get(name, name)]
