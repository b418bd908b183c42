"""Tests of the ``rfmap`` command line (:mod:`rfmap.cli.commands`): the subcommands write complete results, and bad input
prints one line on stderr, exits with status 2 and leaves no output file behind.

Most tests call :func:`rfmap.cli.commands.main` in-process (starting Python costs seconds); one runs the module as a
subprocess to check the real entry point, exit status and stderr."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from rfmap.cli.commands import main
from rfmap.nn import MultiResUNet
from rfmap.core.result import load_result
from rfmap.core.wording import counted
from rfmap.surrogate import Surrogate, quiet_quality
from rfmap.tasks import TaskSpec


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    torch.manual_seed(0)
    model = MultiResUNet(2, 1, base=4, depth=2)
    with torch.no_grad():
        model.head.weight.normal_(0.0, 0.1)
    path = tmp_path_factory.mktemp("model") / "tiny.safetensors"
    Surrogate(model, TaskSpec("density", 2, "square"), {"name": "tiny", "n_range": [17, 25]}).save(path)
    return path


def run_main(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line_error(rc, err, *, match=None):
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("rfmap ") and "error:" in lines[0]
    assert "Traceback" not in err
    if match:
        assert match in lines[0], lines[0]


# ----------------------------------------------------------------------------------------------- solve / metrics


def test_solve_lbs(tmp_path, capsys):
    out = tmp_path / "x.npz"
    rc, stdout, _ = run_main(capsys, "solve", "--method", "lbs", "--field", "T1", "--n", 17, "--out", out)
    assert rc == 0 and f"wrote {out}" in stdout
    n = 17
    with np.load(out, allow_pickle=False) as z:
        assert z["ref_points"].shape == (n * n, 2)
        assert z["mapped_points"].shape == (n * n, 2)
        assert z["elements"].shape == (2 * (n - 1) ** 2, 3)
        assert z["field"].shape == (2 * (n - 1) ** 2,) and np.iscomplexobj(z["field"])
        assert str(z["kind"]) == "beltrami"
        # lbs keeps the boundary fixed by default
        ref, mapped = z["ref_points"], z["mapped_points"]
        on = ((ref == 0) | (ref == 1)).any(1)
        np.testing.assert_allclose(mapped[on], ref[on], atol=1e-12)
        assert np.abs(mapped - ref).max() > 1e-3


def test_solve_dem_and_metrics(tmp_path, capsys):
    out = tmp_path / "d.npz"
    rc, _, _ = run_main(capsys, "solve", "--method", "dem", "--field", "sin-cos", "--n", 17, "--boundary", "square",
                        "--out", out, "--quiet")
    assert rc == 0
    res = load_result(out)
    assert res.kind == "density" and res.ref_points.shape == (17 * 17, 2) and res.field.shape == (17 * 17,)
    ref, mapped = res.ref_points, res.mapped_points
    for i in range(2):
        for wall in (0.0, 1.0):
            np.testing.assert_allclose(mapped[ref[:, i] == wall, i], wall, atol=1e-9)
    rc, stdout, _ = run_main(capsys, "metrics", out)
    assert rc == 0
    m = json.loads(stdout)
    assert set(m) == {"std_rho_orig", "std_rho_map", "min_jacobian", "n_flipped", "max_mu", "mean_mu", "time"}
    assert m["std_rho_map"] < 0.5 * m["std_rho_orig"]  # the solver equalised the density
    assert m["n_flipped"] == 0


def test_metrics_of_a_beltrami_result_with_exact_map(tmp_path, capsys):
    out = tmp_path / "b.npz"
    assert run_main(capsys, "solve", "--method", "lbs", "--field", "T2", "--n", 17, "--out", out)[0] == 0
    rc, stdout, _ = run_main(capsys, "metrics", out, "--exact", "T2")
    assert rc == 0
    m = json.loads(stdout)
    assert {"min_jacobian", "n_flipped", "max_mu", "mean_mu", "mean_dd", "mean_dmu"} <= set(m)
    assert "std_rho_map" not in m
    assert m["mean_dd"] < 5e-4  # the LBS: 2.4e-4; the identity map: 0.019
    rc, _, err = run_main(capsys, "metrics", out, "--exact", "sin-cos")
    assert_one_line_error(rc, err, match="--exact")


@pytest.mark.parametrize("args,match", [
    (["--method", "lbs", "--field", "no-such-field", "--n", "17"], "unknown field"),
    (["--method", "dem", "--field", "no-such-field", "--n", "17"], "unknown field"),
    (["--method", "lbs", "--field", "T1", "--n", "2"], "N must be >= 3"),
    (["--method", "dem", "--field", "sin-cos", "--n", "2"], "N must be >= 3"),
    (["--method", "lbs", "--field", "sin-cos", "--n", "17"], "lbs needs a Beltrami"),
    (["--method", "dem", "--field", "T1", "--n", "17"], "dem needs a density"),
    (["--method", "lbs", "--field", "T1", "--n", "200000"], "too large for this machine's memory"),
    (["--method", "dem", "--field", "sin-cos-3d", "--n", "20000"], "too large for this machine's memory"),
    (["--method", "flow", "--field", "sin-cos", "--n", "200000"], "too large for this machine's memory"),
])
def test_solve_bad_input(tmp_path, capsys, args, match):
    out = tmp_path / "bad.npz"
    rc, stdout, err = run_main(capsys, "solve", *args, "--out", out, "--quiet")
    assert_one_line_error(rc, err, match=match)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no partial file either


@pytest.mark.parametrize("method", ["dem", "flow"])
def test_solve_field_file_density_is_the_named_fields_map(tmp_path, capsys, method):
    """A raw density from a .npy file is preprocessed as the named fields are, so the raw values of sin-cos give the
    same map as --field sin-cos (and N comes from the array)."""
    from rfmap.fields.paper import get_field
    from rfmap.core.result import load_result

    raw = get_field("sin-cos").sample(17, preprocess=False)
    f = tmp_path / "density.npy"
    np.save(f, raw)
    out_file, out_name = tmp_path / "file.npz", tmp_path / "name.npz"
    assert run_main(capsys, "solve", "--method", method, "--field-file", f, "--out", out_file, "--quiet")[0] == 0
    assert run_main(capsys, "solve", "--method", method, "--field", "sin-cos", "--n", 17, "--out", out_name,
                    "--quiet")[0] == 0
    a, b = load_result(out_file), load_result(out_name)
    np.testing.assert_allclose(a.mapped_points, b.mapped_points, atol=1e-9)
    assert a.metrics().std_rho_map < 0.2 * a.metrics().std_rho_orig


def test_solve_field_file_beltrami(tmp_path, capsys):
    """A complex Beltrami coefficient at the vertices (averaged over each triangle) gives T1's map closely."""
    from rfmap.core.mesh import grid_points
    from rfmap.fields.paper import BELTRAMI_MAPS

    n = 33
    mu = BELTRAMI_MAPS["T1"].mu(grid_points(n, 2)).reshape(n, n)
    f, out = tmp_path / "mu.npy", tmp_path / "qc.npz"
    np.save(f, mu)
    rc, stdout, err = run_main(capsys, "solve", "--method", "lbs", "--field-file", f, "--n", n, "--out", out)
    assert rc == 0, err
    rc, stdout, _ = run_main(capsys, "metrics", out, "--exact", "T1")
    assert rc == 0 and json.loads(stdout)["mean_dd"] < 0.01


@pytest.mark.parametrize("array,args,match", [
    (np.ones((5, 6)), ["--method", "dem"], "N^d grid"),
    (np.ones(7), ["--method", "flow"], "N^d grid"),
    (np.ones((2, 2)), ["--method", "dem"], "N must be >= 3"),
    (np.ones((9, 9)), ["--method", "dem", "--n", "17"], "does not match"),
    (np.ones((9, 9), dtype=complex), ["--method", "dem"], "real density"),
    (np.full((9, 9), np.nan), ["--method", "flow"], "NaN"),
    (np.full((9, 9), 0.5 + 0.9j), ["--method", "lbs"], "< 1"),
    (np.zeros((5, 5, 5), dtype=complex), ["--method", "lbs"], "2D Beltrami"),
])
def test_solve_field_file_bad_input(tmp_path, capsys, array, args, match):
    f = tmp_path / "field.npy"
    np.save(f, array)
    out = tmp_path / "bad.npz"
    rc, _, err = run_main(capsys, "solve", *args, "--field-file", f, "--out", out, "--quiet")
    assert_one_line_error(rc, err, match=match)
    assert not out.exists()


def test_solve_needs_n_with_a_named_field_and_a_readable_file(tmp_path, capsys):
    out = tmp_path / "bad.npz"
    rc, _, err = run_main(capsys, "solve", "--method", "dem", "--field", "sin-cos", "--out", out)
    assert_one_line_error(rc, err, match="--n is required")
    bad = tmp_path / "bad.npy"
    bad.write_bytes(b"not an array")
    rc, _, err = run_main(capsys, "solve", "--method", "dem", "--field-file", bad, "--out", out)
    assert_one_line_error(rc, err, match="cannot read")
    assert not out.exists()


def test_errors_do_not_remove_an_existing_file(tmp_path, capsys):
    out = tmp_path / "keep.npz"
    out.write_bytes(b"previous result")
    rc, _, err = run_main(capsys, "solve", "--method", "dem", "--field", "T1", "--n", "17", "--out", out)
    assert_one_line_error(rc, err)
    assert out.read_bytes() == b"previous result"


def test_metrics_of_a_bad_file(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    rc, _, err = run_main(capsys, "metrics", bad)
    assert_one_line_error(rc, err, match="cannot read")
    rc, _, err = run_main(capsys, "metrics", tmp_path / "missing.npz")
    assert_one_line_error(rc, err)


def test_entry_point_as_subprocess(tmp_path):
    """The real process: status 2, exactly one line on stderr, nothing on stdout, no output file."""
    out = tmp_path / "x.npz"
    proc = subprocess.run([sys.executable, "-m", "rfmap.cli", "solve", "--method", "lbs", "--field", "nope",
                           "--n", "17", "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown field 'nope'" in lines[0], proc.stderr
    assert not out.exists()


def test_closed_pipe_ends_quietly():
    """``rfmap models | head``: when the reader of the output has gone, the process ends without a traceback or any
    other line on stderr, with the status a shell reports for a tool ended by SIGPIPE (141)."""
    from rfmap.cli.commands import PIPE_SIGNAL

    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line is written: the write fails every time
    try:
        proc = subprocess.run([sys.executable, "-m", "rfmap.cli", "models"], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert proc.stderr == ""
    assert proc.returncode == 128 + PIPE_SIGNAL == 141


@pytest.mark.parametrize("extra, code", [([], 0), (["--max-passes", "1", "--tol", "1e-4"], 1), (["--n", "1"], 2)])
def test_cartogram_process_exits_at_once_with_its_status_and_whole_files(tmp_path, extra, code):
    """``rfmap cartogram`` ends its process without the interpreter's teardown (``rfmap.cli.commands.QUICK_EXIT``): the exit
    status, the printed lines and the written GeoJSON are those of :func:`rfmap.cli.commands.main`."""
    from rfmap.cli.commands import QUICK_EXIT

    assert "cartogram" in QUICK_EXIT
    src, out = tmp_path / "in.geojson", tmp_path / "out.geojson"
    cells = [[[i, j], [i + 1, j], [i + 1, j + 1], [i, j + 1], [i, j]] for i in range(2) for j in range(2)]
    src.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"pop": p}, "geometry": {"type": "Polygon", "coordinates": [c]}}
        for p, c in zip([1, 1, 1, 5], cells)]}))
    proc = subprocess.run([sys.executable, "-m", "rfmap.cli", "cartogram", str(src), "--value", "pop", "--n", "32",
                           "--out", str(out), *extra], capture_output=True, text=True, timeout=120)
    assert proc.returncode == code, proc.stderr
    if code == 2:
        assert proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1 and not out.exists()
        return
    report = proc.stdout.splitlines()
    assert report[0] == f"wrote {out}: 4 regions by 'pop'" and report[1].startswith("  flow, N = 32: ")
    assert report[2].startswith("  area error mean ") and report[3].startswith("  topology: ")
    status = json.loads(out.read_text())["rfmap"]
    assert status["status"] == ("ok" if code == 0 else "failed")
    assert ("rfmap cartogram: failed:" in proc.stderr) == (code == 1)


# ----------------------------------------------------------------------------------------------- models / map


def test_models(capsys):
    rc, stdout, err = run_main(capsys, "models")
    assert rc == 0 and err == ""
    from rfmap.surrogate import models

    names = models()
    if names:
        assert all(any(line.startswith(name) for line in stdout.splitlines()) for name in names)
    else:
        assert "no pretrained models" in stdout


def test_models_line_gives_the_chain_totals_and_cube(capsys):
    """A model's line gives its whole chain's steps and runs (as --lineage's first line), not its last run's, and
    calls the 3D 'square' boundary 'cube'."""
    import json

    from rfmap.surrogate import WEIGHTS_DIR, models

    rc, stdout, err = run_main(capsys, "models")
    assert rc == 0 and err == ""
    lines = {ln.split()[0]: ln for ln in stdout.splitlines() if ln.strip()}
    for name in models():
        meta = json.loads((WEIGHTS_DIR / f"{name}.json").read_text())
        runs = meta.get("lineage", []) + [meta]
        fields = lines[name].split()
        assert f"{meta.get('cumulative_steps', meta['steps'])} steps, {counted(len(runs), 'run')}," in \
            " ".join(fields)
        assert "steps=" not in lines[name]
        task = meta.get("task", {})
        if task.get("dim") == 3 and task.get("boundary") == "square":
            assert fields[3] == "cube"


def test_models_lineage_lists_every_run(capsys):
    """--lineage prints each shipped model's runs, parents first, with the commands and step counts of the
    metadata, and cumulative steps that add up."""
    import json

    from rfmap.surrogate import WEIGHTS_DIR, models

    rc, stdout, err = run_main(capsys, "models", "--lineage")
    assert rc == 0 and err == ""
    for name in models():
        meta = json.loads((WEIGHTS_DIR / f"{name}.json").read_text())
        runs = meta.get("lineage", []) + [meta]
        head = f"{name}: {counted(len(runs), 'run')}, {meta.get('cumulative_steps', meta['steps'])} steps"
        assert head in stdout
        block = stdout.split(head, 1)[1].splitlines()[1:]
        lines = [ln.strip() for ln in block if ln.startswith("  ")]  # this model's runs and their resumptions
        numbered = [ln for ln in lines if ln.split(".", 1)[0].isdigit()][:len(runs)]
        for k, (line, run) in enumerate(zip(numbered, runs), 1):
            assert line.startswith(f"{k}. {run['command']}   # {run['steps']} steps")
            # a run's resumptions (e.g. an early end with --resume --finish) follow it, then the validated state
            # it kept when that is not its last step
            after = lines[lines.index(line) + 1:]
            again = run.get("resumed") or []
            for j, cmd in enumerate(again):
                assert after[j] == f"then {cmd}"
            kept = run.get("selected_step")
            if kept is not None and int(kept) != int(run["steps"]):
                assert after[len(again)].startswith(f"kept the weights of step {kept} ")
        assert sum(int(r["steps"]) for r in runs) == meta.get("cumulative_steps", meta["steps"])


def test_map_grid(tmp_path, capsys, tiny_model):
    out = tmp_path / "y.npz"
    rc, stdout, _ = run_main(capsys, "map", "--model", tiny_model, "--field", "sin-cos", "--n", 17, "--out", out)
    assert rc == 0 and f"wrote {out}" in stdout
    res = load_result(out)
    assert res.ref_points.shape == (17 * 17, 2) and res.elements.shape == (2 * 16 * 16, 3)
    want = Surrogate.load(tiny_model).map("sin-cos", 17)
    np.testing.assert_allclose(res.mapped_points, want.mapped_points, atol=1e-12)
    assert np.abs(res.displacement).max() > 1e-4


def test_map_field_file_and_refine(tmp_path, capsys, tiny_model):
    from rfmap.fields import sample_density

    f = tmp_path / "field.npy"
    np.save(f, sample_density("ring", 21))
    out = tmp_path / "r.npz"
    rc, _, _ = run_main(capsys, "map", "--model", tiny_model, "--field-file", f, "--refine", "--out", out)
    assert rc == 0
    assert load_result(out).ref_points.shape == (21 * 21, 2)  # n defaults to the array's side


def test_map_points(tmp_path, capsys, tiny_model):
    rng = np.random.default_rng(0)
    q = np.concatenate([rng.random((50, 2)), [[0, 0], [0, 1], [1, 0], [1, 1]]])
    qf = tmp_path / "q.npy"
    np.save(qf, q)
    out = tmp_path / "p.npz"
    rc, _, _ = run_main(capsys, "map", "--model", tiny_model, "--field", "sin-cos", "--points", qf, "--out", out)
    assert rc == 0
    res = load_result(out)
    assert np.array_equal(res.ref_points, q)
    assert res.mapped_points.shape == q.shape and res.elements.shape[1] == 3
    want = Surrogate.load(tiny_model).map("sin-cos", None, points=q)
    np.testing.assert_allclose(res.mapped_points, want.mapped_points, atol=1e-12)


def test_map_bad_input(tmp_path, capsys, tiny_model):
    out = tmp_path / "m.npz"
    rc, _, err = run_main(capsys, "map", "--model", tmp_path / "none.safetensors", "--field", "sin-cos",
                          "--out", out)
    assert_one_line_error(rc, err, match="unknown model")
    rc, _, err = run_main(capsys, "map", "--model", tiny_model, "--field", "T1", "--out", out)
    assert_one_line_error(rc, err, match="beltrami field")
    outside = tmp_path / "outside.npy"
    np.save(outside, np.array([[0.5, 0.5], [1.5, 0.2], [0.1, 0.1]]))
    rc, _, err = run_main(capsys, "map", "--model", tiny_model, "--field", "sin-cos", "--points", outside,
                          "--out", out)
    assert_one_line_error(rc, err, match="unit square")
    junk = tmp_path / "junk.npy"
    junk.write_bytes(b"junk")
    rc, _, err = run_main(capsys, "map", "--model", tiny_model, "--field", "sin-cos", "--points", junk,
                          "--out", out)
    assert_one_line_error(rc, err, match="cannot read")
    rc, _, err = run_main(capsys, "map", "--model", tiny_model, "--field", "sin-cos", "--n", "300000",
                          "--out", out)
    assert_one_line_error(rc, err, match="too large for this machine's memory")
    assert not out.exists()


def test_map_polish_reports_the_guard(tmp_path, capsys):
    """``--polish`` runs the warm flow and, with the guard, the cold one too, and says which map it kept;
    ``--no-guard`` returns the warm flow's map; ``--no-guard`` without ``--polish`` is an error and writes nothing."""
    out = tmp_path / "h.npz"
    rc, stdout, _ = run_main(capsys, "map", "--model", "dem2d-square", "--field", "sin-cos", "--n", 33, "--polish",
                             "--out", out)
    assert rc == 0 and "polish: warm start" in stdout
    guard = next(ln for ln in stdout.splitlines() if ln.startswith("guard: "))
    kept = guard.rsplit("kept the ", 1)[1].split()[0]
    assert kept in ("warm", "cold")
    polished = load_result(out)
    # it reaches the flow solver's equalization (Std(rho~_map) 0.0200 against the flow's 0.0217), far below the
    # network map's (0.0699, written without --polish)
    from rfmap.fields import sample_density
    from rfmap.solvers import solve_flow

    flow = solve_flow(sample_density("sin-cos", 33)).metrics().std_rho_map
    assert polished.metrics().std_rho_map <= 1.05 * flow and polished.metrics().n_flipped == 0
    plain = tmp_path / "plain.npz"
    assert run_main(capsys, "map", "--model", "dem2d-square", "--field", "sin-cos", "--n", 33, "--out", plain)[0] == 0
    assert load_result(plain).metrics().std_rho_map > 2 * flow
    rc, stdout, _ = run_main(capsys, "map", "--model", "dem2d-square", "--field", "sin-cos", "--n", 33, "--polish",
                             "--no-guard", "--out", out)
    assert rc == 0 and "guard: " not in stdout
    if kept == "warm":  # the same warm flow, without the cold one
        np.testing.assert_allclose(load_result(out).mapped_points, polished.mapped_points, atol=1e-12)
    bad = tmp_path / "bad.npz"
    rc, _, err = run_main(capsys, "map", "--model", "dem2d-square", "--field", "sin-cos", "--no-guard", "--out", bad)
    assert_one_line_error(rc, err, match="--no-guard only applies with --polish")
    assert not bad.exists()


def scaled_model(name: str, factor: float, path):
    """A copy of shipped model ``name`` whose output is ``factor`` times the original's (the 1x1 head scaled), saved
    at ``path``."""
    sur = Surrogate.pretrained(name)
    with torch.no_grad():
        sur.model.head.weight.mul_(factor)
        sur.model.head.bias.mul_(factor)
    sur.save(path)
    return path


def test_map_refine_undoes_an_overshoot(tmp_path, capsys):
    """A network whose displacement is 1.6 times a good one: its map folds, and --refine stretches it by alpha =
    (the good network's refined alpha) / 1.6, about 1/1.6; without --refine the written map stays far less equal."""
    n, field = 33, "exp-log"
    good = Surrogate.pretrained("dem2d-square")
    want = np.array(good.map(field, n, refine=True).info["alpha"]) / 1.6  # measured (1.008, 1.070) / 1.6
    over = Surrogate.load(scaled_model("dem2d-square", 1.6, tmp_path / "over.safetensors"))
    with quiet_quality():
        raw = over.map(field, n, repair=False)
    assert raw.metrics().n_flipped > 0  # 75 folded elements
    out = tmp_path / "refined.npz"
    rc, stdout, _ = run_main(capsys, "map", "--model", tmp_path / "over.safetensors", "--field", field, "--n", n,
                             "--refine", "--out", out)
    assert rc == 0 and "repair: not needed" in stdout
    res = load_result(out)
    d, d_raw = res.displacement, raw.mapped_points - raw.ref_points
    alpha = (d * d_raw).sum(0) / (d_raw * d_raw).sum(0)
    np.testing.assert_allclose(d, alpha * d_raw, atol=1e-9)  # the written map is the stretched network map
    np.testing.assert_allclose(alpha, want, atol=0.01)  # measured within 0.002
    assert np.abs(alpha - 1 / 1.6).max() < 0.05
    plain = tmp_path / "plain.npz"
    assert run_main(capsys, "map", "--model", tmp_path / "over.safetensors", "--field", field, "--n", n,
                    "--out", plain)[0] == 0
    # Std(rho~_map): refined 0.060, plain (repaired) 0.135
    assert load_result(plain).metrics().std_rho_map > 1.5 * res.metrics().std_rho_map


def _mirror_permutations(n: int):
    """Vertex permutations of the N-grid for the reflection x -> 1 - x and the transposition (x, y) -> (y, x)."""
    from rfmap.core.mesh import grid_points

    idx = np.rint(grid_points(n, 2) * (n - 1)).astype(int)
    lookup = {tuple(k): i for i, k in enumerate(idx)}
    return (np.array([lookup[(n - 1 - a, b)] for a, b in idx]), np.array([lookup[(b, a)] for a, b in idx]))


def test_map_symmetrize_is_the_symmetrized_api_map(tmp_path, capsys):
    """--symmetrize writes Surrogate.map(symmetrize=True); on the ring density, which has the square's symmetries, that
    map commutes with them to float32 round-off while the plain network's map does not."""
    model = Path(__file__).resolve().parents[1] / "data" / "tiny-deq2d-square.safetensors"  # frozen, never retrained
    n = 17
    flip, transpose = _mirror_permutations(n)

    def asymmetry(u):
        return max(np.abs(u[flip] - np.c_[1 - u[:, 0], u[:, 1]]).max(), np.abs(u[transpose] - u[:, ::-1]).max())

    sym, plain = tmp_path / "sym.npz", tmp_path / "plain.npz"
    rc, stdout, _ = run_main(capsys, "map", "--model", model, "--field", "ring", "--n", n, "--symmetrize",
                             "--out", sym)
    assert rc == 0 and "symmetrized: the network's mean over 8 symmetries (full)" in stdout
    assert run_main(capsys, "map", "--model", model, "--field", "ring", "--n", n, "--out", plain)[0] == 0
    want = Surrogate.load(model).map("ring", n, symmetrize=True)
    np.testing.assert_allclose(load_result(sym).mapped_points, want.mapped_points, atol=1e-12)
    assert asymmetry(load_result(sym).mapped_points) < 1e-6  # measured 4.5e-9
    assert asymmetry(load_result(plain).mapped_points) > 1e-2  # measured 0.046


def test_map_no_repair_writes_the_folded_network_map(tmp_path, capsys):
    """A network that folds: --no-repair writes its raw map, folds included; without the flag the map is
    fold-free."""
    torch.manual_seed(1)
    model = MultiResUNet(2, 1, base=4, depth=2)
    with torch.no_grad():
        model.head.weight.copy_(1.5 * torch.randn(model.head.weight.shape))
    path = tmp_path / "wild.safetensors"
    Surrogate(model, TaskSpec("density", 2, "square"), {"name": "wild", "n_range": [17, 25]}).save(path)
    raw, fixed = tmp_path / "raw.npz", tmp_path / "fixed.npz"
    rc, stdout, _ = run_main(capsys, "map", "--model", path, "--field", "sin-cos", "--n", 17, "--no-repair",
                             "--out", raw)
    assert rc == 0 and "repair: off (raw network output)" in stdout
    with quiet_quality():
        want = Surrogate.load(path).map("sin-cos", 17, repair=False)
    assert load_result(raw).metrics().n_flipped == want.metrics().n_flipped > 0
    np.testing.assert_allclose(load_result(raw).mapped_points, want.mapped_points, atol=1e-12)
    rc, stdout, _ = run_main(capsys, "map", "--model", path, "--field", "sin-cos", "--n", 17, "--out", fixed)
    assert rc == 0 and load_result(fixed).metrics().n_flipped == 0


def test_map_vtk(tmp_path, capsys, tiny_model):
    pv = pytest.importorskip("pyvista")
    out, vtk = tmp_path / "v.npz", tmp_path / "v.vtu"
    rc, _, _ = run_main(capsys, "map", "--model", tiny_model, "--field", "sin-cos", "--n", 9, "--out", out,
                        "--vtk", vtk)
    assert rc == 0 and vtk.exists() and vtk.stat().st_size > 0
    grid = pv.read(str(vtk))
    assert grid.n_points == 81 and grid.n_cells == 2 * 8 * 8
    np.testing.assert_allclose(np.asarray(grid.points)[:, :2], load_result(out).mapped_points, atol=1e-6)


# ----------------------------------------------------------------------------------------------- train


def test_train(tmp_path, capsys):
    out = tmp_path / "run"
    rc, stdout, _ = run_main(capsys, "train", "--config", "deq2d-square", "--preset", "ci", "--steps", 3,
                             "--out", out, "--no-progress")
    assert rc == 0 and "trained deq2d-square" in stdout
    assert (out / "deq2d-square.safetensors").exists() and (out / "deq2d-square.json").exists()
    sur = Surrogate.load(out / "deq2d-square.safetensors")
    assert sur.meta["steps"] == 3 and sur.meta["preset"] == "ci"
    rc, _, err = run_main(capsys, "train", "--config", "no-such-config", "--preset", "ci", "--out", out)
    assert_one_line_error(rc, err, match="unknown config")


def test_an_allocation_that_fails_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch):
    """Memory that runs out past the grid-size guard (another process took it, a huge point cloud) ends the command
    with one line and status 2, and leaves no output file."""
    import rfmap.solvers as S

    def exhausted(*args, **kwargs):
        raise MemoryError("Unable to allocate 9.3 GiB for an array")

    monkeypatch.setattr(S, "solve_dem", exhausted)
    out = tmp_path / "m.npz"
    rc, _, err = run_main(capsys, "solve", "--method", "dem", "--field", "sin-cos", "--n", "17", "--out", out)
    assert_one_line_error(rc, err, match="out of memory (Unable to allocate 9.3 GiB")
    assert list(tmp_path.iterdir()) == []


def test_map_warns_in_one_line_when_the_map_undoes_equalization(tmp_path, capsys, tiny_model):
    f = tmp_path / "flat.npy"
    np.save(f, 1.0 + 1e-6 * np.linspace(0, 1, 21)[:, None] * np.ones(21))  # uniform to one part in a million
    out = tmp_path / "flat.npz"
    rc, stdout, err = run_main(capsys, "map", "--model", tiny_model, "--field-file", f, "--out", out)
    assert rc == 0 and out.exists() and f"wrote {out}" in stdout
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("rfmap map: warning: the network's map left this density less")
    assert "shortened to 0 of itself" in lines[0]  # a nearly uniform density: the identity is the best map
    assert "--refine" in lines[0] and "--polish" in lines[0] and "Warning" not in err


def test_map_of_query_points_warns_in_one_line_when_shortened(tmp_path, capsys, tiny_model):
    """Query points are judged on the working grid (rfmap.finish.query.shorten_query); the CLI's line
    then names the grid-only remedy as such."""
    from rfmap.core.mesh import grid_points

    f, pts = tmp_path / "flat.npy", tmp_path / "pts.npy"
    np.save(f, 1.0 + 1e-6 * np.linspace(0, 1, 21)[:, None] * np.ones(21))  # uniform to one part in a million
    np.save(pts, grid_points(21, 2)[::5])
    out = tmp_path / "flat.npz"
    rc, stdout, err = run_main(capsys, "map", "--model", tiny_model, "--field-file", f, "--points", pts,
                               "--out", out)
    assert rc == 0 and out.exists()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "shortened to 0 of itself" in lines[0]
    assert "--polish (the flow-based finish, on a grid only)" in lines[0]


def test_a_named_subcommand_builds_only_its_parser_and_parses_alike(capsys):
    """``rfmap cartogram ...`` builds the cartogram parser alone (the others cost more than a small cartogram), with
    the same result as the whole parser; ``rfmap --help`` and an unknown command still see every sub-command."""
    from rfmap.cli.commands import COMMANDS, build_parser

    argv = ["cartogram", "map.geojson", "--value", "pop", "--n", "128", "--method", "dem", "--projected"]
    alone, whole = build_parser("cartogram").parse_args(argv), build_parser().parse_args(argv)
    assert vars(alone) == vars(whole) and alone.method == "diffusion" and alone.n == 128
    sub = next(a for a in build_parser("cartogram")._actions if a.dest == "cmd")
    assert set(sub.choices) == {"cartogram"}
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    listed = capsys.readouterr().out
    assert all(name in listed for name in COMMANDS)
    with pytest.raises(SystemExit) as e:
        main(["no-such-command"])
    assert e.value.code == 2 and "invalid choice" in capsys.readouterr().err


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("value", [0.0, 1.0, -1.0])
def test_a_constant_density_maps_to_the_identity_without_a_warning(tmp_path, capsys, dim, value):
    """``rfmap map`` (a network that moves other fields) and ``rfmap solve`` (both methods) write the identity, bit
    for bit, for a constant field file of either dimension, say so, and print nothing on stderr."""
    torch.manual_seed(0)
    model = MultiResUNet(dim, 1, base=4, depth=2)
    with torch.no_grad():
        model.head.weight.normal_(0.0, 0.1)
    weights = tmp_path / "tiny.safetensors"
    Surrogate(model, TaskSpec("density", dim, "square"), {"name": "tiny", "n_range": [13, 17]}).save(weights)
    field = tmp_path / "flat.npy"
    np.save(field, np.full((13,) * dim, value))
    runs = [("map", "--model", weights), ("solve", "--method", "diffusion", "--quiet"),
            ("solve", "--method", "flow", "--quiet")]  # --quiet: no progress bar on stderr
    for k, run in enumerate(runs):
        out = tmp_path / f"m{k}.npz"
        rc, stdout, err = run_main(capsys, *run, "--field-file", field, "--out", out)
        assert rc == 0 and err == "", (run, err)
        res = load_result(out)
        assert np.array_equal(res.mapped_points, res.ref_points), run
        if run[0] == "map":
            assert "std_rho_map=0," in stdout and "n_flipped=0" in stdout
            assert stdout.splitlines()[1] == "the density is uniform: its map is the identity (the network was not run)"
