"""Tests of :mod:`rfmap.finish`: each stage alone, on hand-built and classical maps; the composition on a classical
map keeps the solver's extras; the typed report and its read-only view ``MapResult.info``."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from rfmap.finish import Draft, FinishOptions, InfoView, MapReport, NetworkReport, RegridReport, finish_map
from rfmap.finish.stages import judge, regrid, repair, shorten
from rfmap.core.mesh import grid_mesh
from rfmap.nn import MultiResUNet
from rfmap.fields.paper import sample_density
from rfmap.core.result import MapResult
from rfmap.solvers import solve_dem
from rfmap.surrogate import Surrogate
from rfmap.tasks import TaskSpec


def pushed(n: int, shift) -> np.ndarray:
    """The identity of the 2D ``n``-grid with its centre vertex pushed by ``shift`` (folds the triangles around it)."""
    p = grid_mesh(n, 2).points.copy()
    p[np.ravel_multi_index((n // 2, n // 2), (n, n))] += shift
    return p


def grid_draft(points, field, kind="density", report=MapReport(), seconds=0.0) -> Draft:
    n = round(len(points) ** 0.5)
    mesh = grid_mesh(n, 2)
    res = MapResult(mesh.points, points, mesh.elements, field, kind=kind, time=seconds)
    return Draft(res, report, "square", n)


@pytest.fixture(scope="module")
def dem():
    return solve_dem(sample_density("sin-cos", 17))


def test_info_is_a_read_only_view_of_the_typed_report():
    torch.manual_seed(0)
    sur = Surrogate(MultiResUNet(2, 1, base=4, depth=2), TaskSpec("density", 2, "square"), {"name": "tiny"})
    res = sur.map("sin-cos", 21, refine=True)
    info = res.info
    assert isinstance(info, InfoView) and isinstance(info.report, MapReport)
    assert dict(info) == info.report.flat() and info == info.report.flat()
    assert list(info) == ["work_n", "network_time", "symmetrize", "refine_objective_start", "refine_objective",
                          "refine_evaluations", "alpha", "repair", "quality"]
    assert info["work_n"] == info.report.network.work_n == 21 and info["symmetrize"] is None
    assert info["alpha"] == info.report.alpha and info["refine_objective"] == info.report.refine.objective
    assert info.get("polish") is None and "regrid" not in info and "shorten" not in info
    with pytest.raises(TypeError):
        info["alpha"] = [1.0, 1.0]
    with pytest.raises(TypeError):  # the keywords of Surrogate.map, no others
        sur.map_batch(["sin-cos"], 21, refin=True)


def test_a_classical_map_keeps_its_extras_and_gains_the_reports(dem):
    out = finish_map(dem)
    assert out.info["method"] == "diffusion" and out.info["iterations"] == dem.info["iterations"]
    assert out.info["repair"]["needed"] is False and "shorten" not in out.info and "work_n" not in out.info
    q, m = out.info["quality"], dem.metrics()
    assert not q["worse"] and q["std_rho_map"] == pytest.approx(m.std_rho_map, rel=1e-5)
    np.testing.assert_array_equal(out.mapped_points, dem.mapped_points)
    assert out.time >= dem.time


def test_refinement_of_a_classical_map_stretches_its_displacement(dem):
    """A diffusion map whose displacement was stretched by 1.6 is brought back by alpha of about 1 / 1.6."""
    over = replace(dem, mapped_points=dem.ref_points + 1.6 * dem.displacement)
    out = finish_map(over, FinishOptions(refine=True, repair=False))
    assert out.info["refine_objective"] <= out.info["refine_objective_start"]
    np.testing.assert_allclose(out.info["alpha"], 1 / 1.6, atol=0.02)  # measured 0.007
    np.testing.assert_allclose(out.displacement, np.array(out.info["alpha"]) * over.displacement, atol=1e-12)
    assert out.metrics().std_rho_map < over.metrics().std_rho_map


def test_polish_of_a_classical_map(dem):
    out = finish_map(dem, FinishOptions(polish=True))
    p = out.info["polish"]
    assert p["start"] in ("warm", "cold") and "smooth_passes" not in p and "quality" not in out.info
    assert out.metrics().n_flipped == 0 and out.info["method"] == "diffusion"
    with pytest.raises(ValueError, match="polish must be"):
        FinishOptions(polish=-1.0)


def test_repair_judge_and_shorten_one_by_one():
    """A folded map of a uniform density: repaired fold-free, judged less equal than no map, shortened back to the
    identity; each stage adds its report and its seconds."""
    n = 17
    draft = grid_draft(pushed(n, (0.12, 0.07)), np.ones(n * n), seconds=1.0)
    assert Draft.of(draft.result, "square").grid_n == n and draft.folded() > 0
    fixed = repair(draft)
    assert fixed.folded() == 0 and fixed.report.repair["needed"] and fixed.result.time > 1.0
    judged = judge(fixed)
    assert judged.report.quality["worse"] and judged.report.shorten is None
    short = shorten(judged)
    assert short.report.shorten["scale"] == 0.0 and short.report.quality["shortened_from"] > 1e-3
    np.testing.assert_allclose(short.result.mapped_points, draft.result.ref_points, atol=0)
    assert short.result.time >= judged.result.time >= fixed.result.time
    assert repair(draft, cold_polish=True).report.repair["skipped"]  # a cold polish follows: left folded


def test_regrid_takes_the_first_fold_free_working_grid():
    n = 9
    identity = grid_mesh(n, 2).points
    folded = pushed(n, (0.3, 0.0))
    mu = np.zeros(len(grid_mesh(n, 2).elements), complex)  # a Beltrami map: every fold-free map is taken

    def draft(points, w, seconds):
        return grid_draft(points, mu, "beltrami", MapReport(network=NetworkReport(w, seconds)), seconds)

    tried = []

    def remap(w):
        tried.append(w)
        return draft(folded if w == 7 else identity, w, 0.25)

    out = regrid(draft(folded, n, 1.0), remap, [7, 5, 3])
    assert tried == [7, 5] and out.report.regrid == RegridReport(n, [7, 5], 5, out.report.regrid.time)
    assert out.report.network == NetworkReport(5, 1.25) and out.result.time >= 1.0
    np.testing.assert_array_equal(out.result.mapped_points, identity)
    good = draft(identity, n, 1.0)
    assert regrid(good, remap, [7]) is good and tried == [7, 5]  # a fold-free map is left alone
    none = regrid(draft(folded, n, 1.0), lambda w: draft(folded, w, 0.25), [7])
    assert none.report.regrid.work_n is None and none.report.network == NetworkReport(n, 1.0)
    assert none.report.flat()["regrid"] == {"from": n, "tried": [7], "work_n": None, "time": none.report.regrid.time}


def test_map_options_are_the_predictions_and_the_finishing_stages():
    """``MapOptions`` (the keywords of ``Surrogate.map``) is the surrogate's ``PredictOptions`` and the stages'
    ``FinishOptions``, each field owned by one; the stages receive their own part; the polish is refused for maps it
    cannot finish by one check, whichever path asks."""
    from dataclasses import fields

    from rfmap.surrogate import MapOptions, PredictOptions
    from rfmap.tasks import get_task

    own = {f.name for f in fields(FinishOptions)}
    assert own.isdisjoint(f.name for f in fields(PredictOptions))
    assert {f.name for f in fields(MapOptions)} == own | {f.name for f in fields(PredictOptions)}
    o = MapOptions(refine=True, polish=0.01, work_n=33, symmetrize=True)
    assert o.finishing == FinishOptions(refine=True, polish=0.01) and type(o.finishing) is FinishOptions
    assert o.working_side(65, lambda n: 17) == 33 and not o.default_grid
    assert MapOptions().working_side(65, lambda n: 17) == 17 and MapOptions().default_grid
    assert MapOptions(native=True).working_side(65, lambda n: 17) == 65
    with pytest.raises(ValueError, match="contradicts"):
        MapOptions(native=True, work_n=33).working_side(65, lambda n: 17)
    with pytest.raises(ValueError, match="polish must be"):
        MapOptions(polish=-1.0)
    with pytest.raises(ValueError, match="does not apply to beltrami maps"):
        FinishOptions(polish=True).check(get_task("beltrami"), True)
    with pytest.raises(ValueError, match="or to query points"):
        FinishOptions(polish=True).check(get_task("density"), False)
    FinishOptions(polish=True).check(get_task("density"), True)
    FinishOptions().check(get_task("beltrami"), False)
