"""The rows of :func:`rfmap.paper.benchmarks.compare_methods` name the grid each surrogate map's network ran on."""
from rfmap.fields.paper import sample_density
from rfmap.paper.benchmarks import compare_methods
from rfmap.surrogate import Surrogate


def test_surrogate_rows_record_the_working_grid_of_the_map_they_measured():
    """Below the training range the network runs on the clipped working grid, and both surrogate rows say so;
    the default row's Std is that of the same plain call made directly."""
    sur = Surrogate.pretrained("dem2d-square")
    n = 17
    assert sur.work_n(n) != n  # the case worth checking: a working grid other than the requested one
    dens = sample_density("sin-cos", n)
    rows = {r["method"]: r for r in compare_methods(dens, sur, methods=("surrogate", "surrogate+refine"))}
    direct = sur.map(dens, n, preprocess=False)
    assert rows["surrogate"]["work_n"] == rows["surrogate+refine"]["work_n"] == sur.work_n(n)
    assert rows["surrogate"]["work_n"] == direct.info["work_n"]
    assert rows["surrogate"]["std_rho_map"] == direct.metrics().std_rho_map
