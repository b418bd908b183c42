r"""Studies of the flow-based solver: its free boundary's sea, where the classical solvers' residual comes from,
whether its gap to the diffusion solver is a convergence error, and where a flow started from a network's map ends.

With a free boundary the domain floats in a larger box filled with a *sea* of (nearly) mean density; the domain's
outline, where the density jumps from the domain's to the sea's, is the *coast*.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..core.inputs import preprocess_density
from ..core.mesh import grid_mesh, grid_points
from ..core.metrics import residual_scales, rotational_share
from ..fields.paper import sample_density
from ..solvers import solve_dem
from ..solvers.flow import solve_flow
from ..training.validation import validation_fields
from ..core.wording import format_sig
from .benchmarks import CaseTable, benchmark_fields
from .tables import format_value

__all__ = ["sea_blend_study", "SEA_TOL", "residual_floor", "CONVERGENCE_SETTINGS", "flow_convergence",
           "warm_start_residuals", "floor_table", "convergence_table", "rotation_table", "sea_table", "warm_table"]

#: A flow "ends higher" than another on a field when its final Std(ρ̃_map) is more than this factor above.
SEA_TOL = 1.05


def sea_blend_study(dim: int = 2, n: int = 256, *, count: int = 8, blend: float = 0.25) -> list[dict[str, Any]]:
    r"""The free boundary's flow with the diffusion solver's sea and with a blended one, beside the diffusion solver.

    On ``count`` unseen random fields (the report stream of :func:`rfmap.training.validation.validation_fields`: smooth,
    steps, peak and ramp in turn, preprocessed) the diffusion solver and the flow-based solver run with
    ``boundary="free"``; the flow three times (``rfmap.solvers.flow.solve_flow``): with the sea that jumps to its
    level at the coast (the diffusion solver's) and only blurred retries after a stall (``stall_blend=0``); as by
    default (that sea, but a stalled first pass redone with the sea blended over ``STALL_BLEND``); and with the sea
    blended over ``blend`` from the start (``sea_blend=blend``).

    Returns
    -------
    list of dict
        One row per field: ``field``, ``kind``, ``std_diffusion``, ``ratio_abrupt``, ``ratio_default`` and
        ``ratio_blended`` (the flows' final Std(ρ̃_map) over the diffusion solver's), ``stalled`` (whether the
        abrupt sea's first pass stalled), ``fallback`` (whether the default flow redid it with a blended sea),
        ``shift`` (the largest distance between the blended and the abrupt flows' mapped vertices, in grid
        spacings: how far the blend moves the map, its coastline included), ``time_default`` (the default flow's
        time over the diffusion solver's) and ``n_flipped`` (all flows together).
    """
    pts = grid_points(n, dim)
    rows = []
    for vf in validation_fields("density", dim, count, stream="report"):
        dens = preprocess_density(np.asarray(vf.field(pts)).reshape((n,) * dim))
        diffusion = solve_dem(dens, boundary="free")
        s_d = diffusion.metrics().std_rho_map
        abrupt = solve_flow(dens, boundary="free", stall_blend=0.0)
        default = solve_flow(dens, boundary="free")
        blended = solve_flow(dens, boundary="free", sea_blend=blend)
        ma, md, mb = abrupt.metrics(), default.metrics(), blended.metrics()
        rows.append({"field": vf.label, "kind": vf.label.rsplit("-", 1)[0], "std_diffusion": s_d,
                     "ratio_abrupt": ma.std_rho_map / s_d, "ratio_default": md.std_rho_map / s_d,
                     "ratio_blended": mb.std_rho_map / s_d, "stalled": bool(abrupt.info["stall_blurs"]),
                     "fallback": bool(default.info["sea_fallback"]),
                     "shift": float(np.abs(blended.mapped_points - abrupt.mapped_points).max() * (n - 1)),
                     "time_default": default.time / diffusion.time,
                     "n_flipped": int(ma.n_flipped + md.n_flipped + mb.n_flipped)})
    return rows


def residual_floor(density_name: str = "sin-cos", ns=(64, 128, 256), boundary: str = "square") -> list[dict[str, Any]]:
    r"""Where the classical solvers' final :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` comes from, per grid side.

    For every ``N`` the paper's test density ``density_name`` is mapped by the diffusion solver, by the flow-based
    solver, and by one more flow pass started from the flow's map (``solve_flow(start=...)``, the residual density
    located exactly on the raster).  Each result is split by :func:`rfmap.core.metrics.residual_scales` into the
    residual's smooth part (what a further flow can act on) and its element-scale part.

    Returns
    -------
    list of dict
        One row per ``N`` and method (``"diffusion"``, ``"flow"``, ``"flow + second pass"``): ``n``, ``method``,
        ``std`` (= Std(ρ̃_map)), ``smooth``, ``element_fraction``, ``time`` (s; the second pass alone) and
        ``n_flipped``.  The second pass's own map is reported, even where it is worse than its start.
    """
    rows = []
    for n in ns:
        dens = sample_density(density_name, int(n))
        diff = solve_dem(dens, boundary=boundary)
        flow = solve_flow(dens, boundary=boundary)
        again = solve_flow(dens, boundary=boundary, start=flow.mapped_points, keep_best=False)
        for method, res in (("diffusion", diff), ("flow", flow), ("flow + second pass", again)):
            sc = residual_scales(res.ref_points, res.mapped_points, res.elements, res.field)
            rows.append({"n": int(n), "method": method, "std": sc["std"], "smooth": sc["smooth"],
                         "element_fraction": sc["element_fraction"], "time": res.time,
                         "n_flipped": res.metrics().n_flipped})
    return rows


#: The flow settings that :func:`flow_convergence` compares: the default, the step tolerance ``rtol`` set to 0.02
#: and to 0.005 (the defaults, ``rfmap.solvers.flow.RTOL``, are 0.2 in 2D and 0.4 in 3D), and the density raster
#: twice as fine (``refine=4``).
#:
#: :meta hide-value:
CONVERGENCE_SETTINGS = ({}, {"rtol": 0.02}, {"rtol": 0.005}, {"refine": 4})


def flow_convergence(dim: int = 2, n: int = 256, boundary: str = "square", *, random: int = 2,
                     settings=CONVERGENCE_SETTINGS) -> list[dict[str, Any]]:
    r"""Whether the flow-based solver's gap to the diffusion solver is a convergence error.

    On the paper's test densities and a number ``random`` of unseen random fields
    (:func:`~rfmap.paper.benchmarks.benchmark_fields`) the diffusion solver runs once and the flow-based solver once
    per entry of ``settings`` (keyword arguments of ``rfmap.solvers.flow.solve_flow``: a tighter step tolerance
    ``rtol``, a finer density raster ``refine``). If the flow's final :math:`\mathrm{Std}(\tilde\rho_{\text{map}})`
    were above diffusion's because its time integration or its raster were too coarse, tightening them would close
    the gap; if it stays, the two solvers end at different maps, each converged.

    Returns
    -------
    list of dict
        One row per field and flow setting: ``field``, ``setting`` (a label such as ``"rtol=0.02"``,
        ``"default"``), ``std_ratio`` and ``time_ratio`` (flow over diffusion, same field, same process),
        ``steps``, ``n_flipped``, and the diffusion solver's ``std_diffusion`` and ``time_diffusion`` (s).  With
        ``boundary="square"`` also ``rotation`` and ``rotation_diffusion``: the share of the flow's and of the
        diffusion solver's displacement that is not a gradient (:func:`rfmap.core.metrics.rotational_share`; ``None``
        for a free boundary, whose walls move).
    """
    def rotation(res):
        return rotational_share(res.ref_points, res.mapped_points) if boundary == "square" else None

    rows = []
    for label, dens in benchmark_fields(dim, n, random=random):
        diff = solve_dem(dens, boundary=boundary)
        s_d = diff.metrics().std_rho_map
        rot_d = rotation(diff)
        for kw in settings:
            flow = solve_flow(dens, boundary=boundary, **kw)
            m = flow.metrics()
            rows.append({"field": label, "setting": ", ".join(f"{k}={v}" for k, v in kw.items()) or "default",
                         "std_ratio": m.std_rho_map / s_d, "time_ratio": flow.time / diff.time,
                         "steps": int(flow.info["steps"]), "n_flipped": int(m.n_flipped),
                         "std_diffusion": s_d, "time_diffusion": diff.time,
                         "rotation": rotation(flow), "rotation_diffusion": rot_d})
    return rows


def warm_start_residuals(sur, density_name: str = "sin-cos", ns=(51, 128, 256)) -> list[dict[str, Any]]:
    r"""Why a flow started from a given map ends where it does: five maps of the test density per grid side.

    * ``"cold flow"``: ``solve_flow`` from the identity, the density sampled as its P1 interpolant;
    * ``"flow from the identity, warm-start route"``: the same start, but through the *warm-start route*, the
      path of a flow started from a given map (the hybrid's), which rasterizes the residual density of the starting
      map (here the input density's element means;
      ``rfmap.solvers.residual.vertex_residual``);
    * ``"network"``: the surrogate's map ``sur.map(density_name, N)``;
    * ``"flow from the network"``: one flow pass from the network's map, ``NaN`` where it stalls;
    * ``"polish"``: ``sur.map(density_name, N, polish=True, guard=False)``, whose flow starts from the map of the
      network's smoothed displacement (``rfmap.finish.polish.smooth_displacement``, and above the working grid
      ``rfmap.finish.polish.smooth_grid_displacement`` on the output grid), ``NaN`` where it starts cold.

    The two identity rows differ only in how the density reaches the raster, so their ratio is the cost of the
    warm-start route itself; the network row's element-scale share (:func:`rfmap.core.metrics.residual_scales`) is the
    part of its residual that no flow can act on, and the last row shows how much of it the smoothing removes.
    ``sur`` must be a 2D or 3D density surrogate with a square boundary.

    Returns
    -------
    list of dict
        One row per ``N`` and map: ``n``, ``method``, ``std``, ``smooth``, ``element_fraction``, ``time`` (s).
    """
    if not sur.spec.task.equalizes or sur.spec.boundary != "square":
        raise ValueError(f"warm_start_residuals needs a density surrogate with a square boundary, got {sur.spec}")
    rows = []
    for n in ns:
        n = int(n)
        dens = sample_density(density_name, n)
        ref = grid_mesh(n, sur.spec.dim).points
        cold = solve_flow(dens)
        ident = solve_flow(dens, start=ref, stall_blurs=())
        net = sur.map(density_name, n)
        try:
            warm = solve_flow(dens, start=net.mapped_points, stall_blurs=())
        except RuntimeError:
            warm = None
        pol = sur.map(density_name, n, polish=True, guard=False)
        if pol.info["polish"]["start"] != "warm":
            pol = None
        for method, res in (("cold flow", cold), ("flow from the identity, warm-start route", ident),
                            ("network", net), ("flow from the network", warm), ("polish", pol)):
            if res is None:
                rows.append({"n": n, "method": method, "std": float("nan"), "smooth": float("nan"),
                             "element_fraction": float("nan"), "time": float("nan")})
                continue
            sc = residual_scales(res.ref_points, res.mapped_points, res.elements, res.field)
            rows.append({"n": n, "method": method, "std": sc["std"], "smooth": sc["smooth"],
                         "element_fraction": sc["element_fraction"], "time": float(res.time)})
    return rows


def _table(title: str, head: list[str], rows: list[list[str]]) -> CaseTable:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return CaseTable(title, "\n".join(lines))


def floor_table(rows: list[dict[str, Any]]) -> CaseTable:
    """The rows of :func:`residual_floor` as a table: per grid side and method the final Std(ρ̃_map), its smooth
    part, the element-scale share of its variance, the time and the folded elements (small numbers as powers of
    ten)."""
    return _table("Where the last residual sits",
                  ["N", "method", "Std ρ̃ map", "smooth part", "element-scale share", "time", "folded"],
                  [[str(r["n"]), r["method"], format_sig(r["std"], 4), format_sig(r["smooth"], 3),
                    f"{100 * r['element_fraction']:.1f} %", format_value(r["time"], "time"), str(r["n_flipped"])]
                   for r in rows])


def _settings(rows: list[dict[str, Any]]) -> tuple[list[str], list[str], dict]:
    settings = list(dict.fromkeys(r["setting"] for r in rows))
    fields = list(dict.fromkeys(r["field"] for r in rows))
    return settings, fields, {(r["field"], r["setting"]): r for r in rows}


def convergence_table(rows: list[dict[str, Any]]) -> CaseTable:
    """The rows of :func:`flow_convergence` as a table: one row per field, one column per setting, each cell the
    flow's final Std(ρ̃_map) and time, both over the diffusion solver's on the same field."""
    settings, fields, cv = _settings(rows)
    return _table("Is the flow converged? Std and time over the diffusion solver's",
                  ["field"] + [f"{s}: Std / time" for s in settings],
                  [[f] + [f"{cv[f, s]['std_ratio']:.3g} / {cv[f, s]['time_ratio']:.2g}" for s in settings]
                   for f in fields])


def rotation_table(rows: list[dict[str, Any]]) -> CaseTable:
    """The default-setting rows of :func:`flow_convergence` as a table: per field the flow's Std over the diffusion
    solver's, the rotational share of each solver's displacement, and the ratio of the two shares."""
    _, fields, cv = _settings(rows)
    out = []
    for f in fields:
        r = cv[f, "default"]
        out.append([f, f"{r['std_ratio']:.3g}", format_sig(r["rotation_diffusion"], 3), format_sig(r["rotation"], 3),
                    f"{r['rotation'] / r['rotation_diffusion']:.3g}"])
    return _table("How the two maps differ",
                  ["field", "Std: flow / diffusion", "rotational share: diffusion", "flow", "flow / diffusion"], out)


def sea_table(rows: list[dict[str, Any]]) -> CaseTable:
    """The rows of :func:`sea_blend_study` as a table: per field the three flows' final Std(ρ̃_map) over the
    diffusion solver's, whether the abrupt sea stalled, the default flow's time over the diffusion solver's (a stalled
    attempt included) and the shift of the blended flow's map in grid spacings."""
    return _table("A dense coast: the flows' Std over the diffusion solver's",
                  ["field", "abrupt sea, blurred retries", "default", "blended sea", "abrupt sea stalled",
                   "default's time / diffusion's", "shift (spacings)"],
                  [[r["field"], f"{r['ratio_abrupt']:.3g}", f"{r['ratio_default']:.3g}", f"{r['ratio_blended']:.3g}",
                    "yes" if r["stalled"] else "no", f"{r['time_default']:.2g}", f"{r['shift']:.3g}"] for r in rows])


def warm_table(rows: list[dict[str, Any]]) -> CaseTable:
    """The rows of :func:`warm_start_residuals` as a table: per grid side and map the final Std(ρ̃_map), its
    smooth part, the element-scale share of its variance and the time."""
    return _table("Why the warm start stops short",
                  ["N", "map", "Std ρ̃ map", "smooth part", "element-scale share", "time"],
                  [[str(r["n"]), r["method"], format_sig(r["std"], 4), format_sig(r["smooth"], 3),
                    f"{100 * r['element_fraction']:.1f} %", format_value(r["time"], "time")] for r in rows])
