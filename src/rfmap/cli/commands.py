"""The ``rfmap`` command line.

Subcommands: ``solve`` (classical solvers), ``metrics``, ``map`` (neural surrogates), ``train`` (its parser is
:mod:`rfmap.training.cli`), ``models``, ``reproduce`` (the paper's tables), ``validate`` (score saved weights on the
validation stream), ``cartogram`` (GeoJSON regions resized by a value).  Errors in the input print one line and exit
with status 2; no partial output file is left behind.  A cartogram that misses its tolerance or has an invalid or
overlapping region is written, flagged, and exits with status 1.  A solver's other name (``--method dem`` for
``diffusion``, :data:`rfmap.solvers.ALIASES`) is accepted wherever a method is named.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from ..core.wording import counted
from .base import CLIError, solver_name

__all__ = ["main", "entry", "build_parser", "CLIError"]


def _load_npy(path: str) -> np.ndarray:
    """An array from a ``.npy`` file (no pickles); a :class:`CLIError` if it cannot be read."""
    try:
        return np.load(path, allow_pickle=False)
    except Exception as e:  # noqa: BLE001
        raise CLIError(f"cannot read {path}: {e}") from e


def _grid_field_file(args) -> tuple[np.ndarray, int]:
    """``rfmap solve --field-file``: the array, sampled on an ``N^d`` grid, and ``N`` (``--n`` may only repeat it)."""
    from ..core.mesh import check_n

    arr = _load_npy(args.field_file)
    if arr.ndim not in (2, 3) or len(set(arr.shape)) != 1:
        raise CLIError(f"--field-file must hold a field sampled on an N^d grid, shape (N, N) or (N, N, N); "
                       f"got shape {arr.shape}")
    n = check_n(arr.shape[0])
    if args.n is not None and args.n != n:
        raise CLIError(f"--n {args.n} does not match the grid side {n} of {args.field_file}")
    return arr, n


def cmd_solve(args) -> int:
    from ..fields.paper import field_names, get_field
    from ..tasks import get_task, kinds

    # the task whose classical solver the method is: it checks and prepares the field and solves
    task = next((get_task(k) for k in kinds() if args.method in get_task(k).methods), None)
    if task is None:
        known = ", ".join(m for k in kinds() for m in get_task(k).methods)
        raise CLIError(f"unknown method {args.method!r}; the solvers of the registered kinds are {known}")
    if args.field_file:
        arr, n = _grid_field_file(args)
        values = task.solver_input(arr)  # a density as rfmap map preprocesses it, mu per triangle, ...
    else:
        if args.n is None:
            raise CLIError("--n is required with --field (with --field-file the array's side gives N)")
        f, n = get_field(args.field), args.n
        if f.kind != task.kind:
            raise CLIError(f"method {args.method} needs a {task.title} field ({', '.join(field_names(task.kind))}), "
                           f"got {args.field!r}")
        values = task.solver_sample(f, n)
    res = task.solve(values, n, args.method, args.boundary, progress=not args.quiet)
    res.save(args.out)
    if not args.quiet:
        print(f"wrote {args.out}: {res.metrics()}")
    return 0


def cmd_metrics(args) -> int:
    from ..fields.paper import BELTRAMI_MAPS, sample_mu
    from ..core.result import load_result

    res = load_result(args.file)
    m = res.metrics()
    if args.exact:
        f = BELTRAMI_MAPS.get(args.exact)
        if f is None:
            raise CLIError(f"--exact must name a Beltrami test map ({', '.join(BELTRAMI_MAPS)}), got {args.exact!r}")
        m = res.metrics(exact_points=f(res.ref_points),
                        mu_ref=sample_mu(args.exact, points=res.ref_points, elements=res.elements))
    print(m.to_json())
    return 0


def _model_meta(surrogate_cls, name: str) -> tuple[dict, str | None]:
    """A shipped model's metadata, and the extra it needs where its architecture's package is not installed (the
    FNO without ``neuraloperator``: then the metadata is read from its JSON file, the model not built)."""
    try:
        return surrogate_cls.pretrained(name).meta, None
    except ImportError:
        import json

        from ..surrogate import WEIGHTS_DIR

        meta = json.loads((WEIGHTS_DIR / f"{name}.json").read_text())
        arch = (meta.get("model") or {}).get("arch", "unet")
        if arch != "fno":
            raise
        return meta, "fno"


def _description(name: str, meta: dict) -> str:
    """What a shipped model is: its config's current description (the weights' own, written when it was trained,
    may tell a history that its lineage keeps), else the one in its metadata."""
    from ..training.config import CONFIGS

    preset = (meta.get("config") or {}).get("preset", "full")
    cfg = CONFIGS.get(name, {}).get(preset)
    return cfg.description if cfg is not None else meta.get("description", "")


def _boundary_word(task: dict) -> str:
    """A task's boundary as ``rfmap models`` prints it: ``cube`` for the walls of the 3D ``square`` condition."""
    boundary = task.get("boundary", "?")
    return "cube" if boundary == "square" and task.get("dim") == 3 else boundary


def cmd_models(args) -> int:
    from ..surrogate import Surrogate, models

    names = models()
    if not names:
        print("no pretrained models are shipped")
    width = max((len(name) for name in names), default=0)
    for name in names:
        meta, needs = _model_meta(Surrogate, name)
        t = meta.get("task", {})
        runs = list(meta.get("lineage", [])) + [meta]
        total_steps = meta.get("cumulative_steps", meta.get("steps"))
        total_wall = float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0)))
        if not args.lineage:  # the whole chain's steps and time, as --lineage's first line gives them
            print(f"{name:{width}s}  {t.get('kind', '?'):9s} {t.get('dim', '?')}D {_boundary_word(t):7s} "
                  f"{total_steps!s:>6} steps, {counted(len(runs), 'run'):>7s}, {total_wall / 60:4.0f} min  " +
                  (f"[needs rfmap[{needs}]: pip install 'rfmap[{needs}]'] " if needs else "") +
                  f"{_description(name, meta)}")
            continue
        print(f"{name}: {counted(len(runs), 'run')}, {total_steps} steps, {total_wall / 60:.0f} min")
        for k, run in enumerate(runs, 1):
            sha = run.get("sha256")
            print(f"  {k}. {run.get('command', '?')}   # {run.get('steps')} steps, "
                  f"{float(run.get('wall_time', 0.0)) / 60:.0f} min" + (f", sha256 {sha[:12]}" if sha else ""))
            for again in run.get("resumed") or []:  # continued after an interruption, or ended with --finish
                print(f"     then {again}")
            kept = run.get("selected_step")
            if kept is not None and int(kept) != int(run.get("steps") or 0):  # validation chose an earlier state
                print(f"     kept the weights of step {kept}" +
                      (" (its parent's: no validated state improved on them)" if int(kept) == 0 else
                       " (the best validated state)"))
            if run.get("grown"):  # the next run started from these weights widened (rfmap.nn.grow)
                g = run["grown"]
                print(f"     then widened from base {g['from'].get('base')} to {g['to'].get('base')} "
                      "(function-preserving growth, rfmap.nn.grow)")
    if args.lineage and names:
        print("In a chain, '--init NAME' continues from the weights the run before it wrote: pass that run's "
              "runs/NAME/NAME.safetensors to --init to repeat the chain. A run with a --time-limit stops on the clock "
              "and its schedule follows the elapsed time, so a repeat on another machine trains as long, not for the "
              "same steps; a run that was stopped and ended with '--resume --finish' lists that command under it "
              "(stop it at the same step).")
    return 0


def cmd_map(args) -> int:
    from ..core.device import resolve_device
    from ..finish import poor_map_message, quiet_quality
    from ..surrogate import Surrogate, models

    device = resolve_device(args.device)  # before any work: an unavailable device is bad input
    sur = Surrogate.pretrained(args.model, device=device) if args.model in models() else \
        Surrogate.load(args.model, device=device) if os.path.exists(args.model) else None
    if sur is None:
        raise CLIError(f"unknown model {args.model!r}: not a shipped model ({', '.join(models()) or 'none'}) "
                       "nor a weight file")
    field = _load_npy(args.field_file) if args.field_file else args.field
    points = _load_npy(args.points) if args.points else None
    polish = False if args.polish is None else (True if args.polish == "default" else args.polish)
    if args.no_guard and polish is False:
        raise CLIError("--no-guard only applies with --polish")
    with quiet_quality():  # a poor map is reported below, in one line
        res = sur.map(field, args.n, points, map_options(args, polish))
    res.save(args.out)
    if args.vtk:
        res.to_vtk(args.vtk)
    print(f"wrote {args.out}: {res.metrics()}")
    if res.info.get("uniform"):
        print("the density is uniform: its map is the identity (the network was not run)")
        return 0
    if res.info.get("symmetrize"):
        from ..nn.symmetry import symmetries

        group = res.info["symmetrize"]
        print(f"symmetrized: the network's mean over {len(symmetries(sur.spec.dim, group))} symmetries ({group})")
    if "regrid" in res.info:
        print(regrid_summary(res.info["regrid"]))
    print(repair_summary(res.info.get("repair")))
    msg = poor_map_message(res.info.report, "--refine", "--polish")
    if msg is not None:
        print(f"rfmap map: warning: {msg}", file=sys.stderr)
    if "polish" in res.info:
        p = res.info["polish"]
        st = p["stages"]
        print(f"polish: {p['start']} start{' (' + p['reason'] + ')' if p['reason'] else ''}, Std(ρ̃_map) "
              f"{st['surrogate']['std_rho_map']:.4g} -> {st['polish']['std_rho_map']:.4g}, network "
              f"{st['surrogate']['time']:.3f} s + flow {p['time']:.3f} s")
        if "cold" in st:
            print(f"guard: warm flow {st['warm']['std_rho_map']:.4g} ({st['warm']['time']:.3f} s), cold flow "
                  f"{st['cold']['std_rho_map']:.4g} ({st['cold']['time']:.3f} s); kept the {p['kept']} map")
    return 0


def map_options(args, polish) -> "MapOptions":
    """The :class:`rfmap.surrogate.MapOptions` of ``rfmap map``'s arguments (the options of every way to map a
    field)."""
    from ..surrogate import MapOptions

    return MapOptions(refine=args.refine, native=args.native, repair=not args.no_repair, polish=polish,
                      guard=not args.no_guard, symmetrize=args.symmetrize)


def regrid_summary(report: dict) -> str:
    """One line saying which coarser working grids a folded 3D map was tried on (``rfmap.surrogate.REGRID_DIMS``,
    :class:`rfmap.finish.report.RegridReport`)."""
    tried = ", ".join(str(w) for w in report["tried"])
    if report["work_n"] is None:
        return (f"working grid: {report['from']} folded, and so did {tried}; the {report['from']}-grid map is "
                f"repaired ({report['time']:.3f} s)")
    return (f"working grid: {report['from']} folded; took {report['work_n']} (tried {tried}; "
            f"{report['time']:.3f} s)")


def repair_summary(report: dict | None) -> str:
    """One line saying what :func:`rfmap.finish.repair.dispatch.repair_map` did (or that it was skipped)."""
    if report is None:
        return "repair: off (raw network output)"
    if not report["needed"]:
        return f"repair: not needed, nothing folded ({report['time'] * 1e3:.1f} ms check)"
    if report.get("skipped"):
        return (f"repair: skipped, {counted(report['n_flipped_before'], 'folded element')}; the polish starts cold "
                "from the identity")
    b, a = report["metrics_before"], report["metrics_after"]
    extra = "".join(f", {k} {b[k]:.4g} -> {a[k]:.4g}" for k in ("std_rho_map", "max_mu", "mean_dmu") if k in b)
    if "surface_crossings_before" in report:
        extra += (f", crossing boundary triangle pairs {report['surface_crossings_before']} -> "
                  f"{report['surface_crossings_after']}")
    return (f"repair: {report['method']}, {report['n_flipped_before']} folded -> {report['n_flipped_after']}, "
            f"{report['affected']} affected, min Jacobian {b['min_jacobian']:.3g} -> {a['min_jacobian']:.3g}"
            f"{extra}, {report['time']:.3f} s")


def cmd_train(args) -> int:
    from ..training.cli import run

    sur = run(args)
    print(f"trained {sur.name}: {sur.meta.get('final_metrics', {}).get('mean')}")
    return 0


def cmd_validate(args) -> int:
    from ..training.selection import score_weights, scores_table, ship_best

    if args.count is not None and args.count < 1:
        raise CLIError(f"--count must be at least 1, got {args.count}")
    sizes = tuple(args.n) if args.n else None
    if sizes and min(sizes) < 3:
        raise CLIError(f"--n must be at least 3, got {min(sizes)}")
    scored = score_weights(args.weights, count=args.count, sizes=sizes, native=True if args.native else None,
                           progress=not args.no_progress)
    print(scores_table(scored))
    if args.ship:
        w, j = ship_best(scored, args.ship, args.name)
        print(f"shipped {scored[0].path.name} as {w} (+ {j.name})")
    return 0


def cmd_reproduce(args) -> int:
    from ..paper.reproduce import reproduce

    from ..core.device import resolve_device

    device = resolve_device(args.device)  # before any work: a bad device is one line and exit 2
    for path in reproduce(args.experiment, args.out, refine=not args.no_refine, device=device,
                          symmetrize=args.symmetrize):
        print(f"wrote {path}")
    return 0


def _polish_arg(text: str):
    """``--polish [TOL]``: a positive tolerance (``argparse`` passes the constant ``"default"`` through as is)."""
    if text == "default":
        return text
    try:
        tol = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"TOL must be a positive number, got {text!r}") from None
    if not 0 < tol < float("inf"):
        raise argparse.ArgumentTypeError(f"TOL must be a positive number, got {text!r}")
    return tol


def _symmetry_arg(text: str):
    """``--symmetrize [GROUP]``: a group name of :data:`rfmap.nn.symmetry.SYMMETRY_GROUPS`."""
    from ..nn.symmetry import SYMMETRY_GROUPS

    if text not in SYMMETRY_GROUPS:
        raise argparse.ArgumentTypeError(f"GROUP must be one of {', '.join(SYMMETRY_GROUPS)}, got {text!r}")
    return text


def _add_classical(sub) -> None:
    """``rfmap solve`` and ``rfmap metrics``."""
    s = sub.add_parser("solve", help="run a classical solver (Linear Beltrami Solver, diffusion or flow DEM)")
    s.add_argument("--method", metavar="{lbs,diffusion,flow}", required=True,
                   help="lbs (Beltrami), diffusion (diffusion DEM; also 'dem') or flow (flow-based DEM, faster): "
                        "a classical solver of a registered kind of map (rfmap.tasks.kinds)")
    g = s.add_mutually_exclusive_group(required=True)
    g.add_argument("--field", help="a built-in field name")
    g.add_argument("--field-file", help=".npy array sampled on an N^d grid: a density (preprocessed as by rfmap map) "
                                        "or, for lbs, a complex Beltrami coefficient (N, N) at the vertices")
    s.add_argument("--n", type=int, default=None,
                   help="grid side N, in points per side (with --field-file: the array's side)")
    s.add_argument("--boundary", choices=["square", "free", "fixed"], default=None,
                   help="diffusion and flow: square (default) or free; lbs: fixed (default) or square")
    s.add_argument("--out", required=True, help="output .npz")
    s.add_argument("--quiet", action="store_true", help="print neither progress nor the summary line")
    s.set_defaults(func=cmd_solve)

    s = sub.add_parser("metrics", help="print the metrics of a result file as JSON")
    s.add_argument("file", help="a result file (.npz) written by rfmap solve, map or MapResult.save")
    s.add_argument("--exact", default=None, help="Beltrami test map to measure the mean vertex distance |Δd| and "
                   "the Beltrami coefficient error |Δμ| against")
    s.set_defaults(func=cmd_metrics)


def _add_map(sub) -> None:
    """``rfmap map``."""
    s = sub.add_parser("map", help="map a field with a neural surrogate",
                       description="Map a field with a neural surrogate. A density map that leaves the density less "
                                   "equal than it was is still written, with one warning line on stderr.")
    s.add_argument("--model", required=True, help="a shipped model name (rfmap models) or a .safetensors path")
    g = s.add_mutually_exclusive_group(required=True)
    g.add_argument("--field", help="a built-in field name")
    g.add_argument("--field-file", help=".npy array sampled on an N^d grid")
    s.add_argument("--n", type=int, default=None, help="output grid side N, in points per side")
    s.add_argument("--points", default=None, help=".npy array (P, d) of query points")
    s.add_argument("--refine", action="store_true", help="apply weight refinement")
    s.add_argument("--native", action="store_true",
                   help="run the network on the requested grid itself, as the paper does, not on a working grid "
                        "inside its training range; with --refine and --no-repair (and no other option) this is "
                        "the paper's method")
    s.add_argument("--no-repair", action="store_true",
                   help="return the raw network map, without removing folded elements or shortening a map that "
                        "leaves the density less equal than it was")
    s.add_argument("--polish", nargs="?", const="default", default=None, type=_polish_arg, metavar="TOL",
                   help="finish the density map with the flow-based solver (optionally to Std(ρ̃_map) <= TOL)")
    s.add_argument("--no-guard", action="store_true",
                   help="with --polish: return the map of the flow started from the network's map (warm) without "
                        "also running the flow from the identity (cold) and keeping the better one")
    s.add_argument("--symmetrize", nargs="?", const=True, default=False, type=_symmetry_arg, metavar="GROUP",
                   help="average the network over symmetries of the square or cube (default set, or "
                        "one of flips, permutations, cyclic, full); one network evaluation per symmetry")
    s.add_argument("--out", required=True, help="output .npz")
    s.add_argument("--vtk", default=None, help="also write the mapped mesh as VTK (.vtu)")
    s.add_argument("--device", default="cpu", help="where the network runs: cpu (default), cuda or auto")
    s.set_defaults(func=cmd_map)


def _add_cartogram(sub) -> None:
    """``rfmap cartogram`` (:mod:`rfmap.cli.cartogram`)."""
    from .cartogram import add_cartogram_parser

    add_cartogram_parser(sub)


def _add_reproduce(sub) -> None:
    """``rfmap reproduce``."""
    s = sub.add_parser("reproduce", help="write the paper's tables (Markdown and CSV)")
    s.add_argument("experiment", choices=["beltrami", "dem2d", "dem3d"],
                   help="which group of the paper's tables, each on the paper's grids whatever RFMAP_SCALE says: "
                        "beltrami (the model beltrami2d), dem2d (deq2d-square and deq2d-free) or dem3d (dem3d-cube "
                        "and dem3d-free), with the classical solvers run beside the networks on the CPU")
    s.add_argument("--out", default="reproduction", help="output directory (default: reproduction)")
    s.add_argument("--no-refine", action="store_true", help="skip weight refinement")
    s.add_argument("--symmetrize", nargs="?", const=True, default=False, type=_symmetry_arg, metavar="GROUP",
                   help="add the rows of the networks averaged over the domain's symmetries")
    s.add_argument("--device", default="cpu", help="where the networks run: cpu (default), cuda or auto")
    s.set_defaults(func=cmd_reproduce)


def _add_training(sub) -> None:
    """``rfmap train``, ``rfmap models`` and ``rfmap validate``."""
    from .lazy_parser import train_parser

    s = sub.add_parser("train", help="train a surrogate from a named configuration")
    train_parser(s)
    s.set_defaults(func=cmd_train)

    s = sub.add_parser("models", help="list the shipped pretrained models")
    s.add_argument("--lineage", action="store_true",
                   help="print, per model, the rfmap train commands of every run behind its weights")
    s.set_defaults(func=cmd_models)

    s = sub.add_parser("validate", help="score saved weights (e.g. training snapshots) on the validation stream")
    s.add_argument("weights", nargs="+", help=".safetensors files or folders of them (e.g. OUT/snapshots)")
    s.add_argument("--count", type=int, default=None, help="validation fields (default: the config's)")
    s.add_argument("--n", type=int, nargs="+", default=None, help="grid sides (default: the config's)")
    s.add_argument("--native", action="store_true",
                   help="run each network on the validation grids themselves (default: the config's val_native)")
    s.add_argument("--ship", default=None, metavar="DIR", help="write the best as DIR/NAME.safetensors + .json")
    s.add_argument("--name", default=None, help="file name of the shipped weights (default: the config's name)")
    s.add_argument("--no-progress", action="store_true", help="print no progress bar")
    s.set_defaults(func=cmd_validate)


#: the sub-commands, in the order of ``rfmap --help``, and the function that adds each one's parser (some add two)
COMMANDS = {"solve": _add_classical, "metrics": _add_classical, "map": _add_map, "train": _add_training,
            "models": _add_training, "validate": _add_training, "cartogram": _add_cartogram,
            "reproduce": _add_reproduce}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``rfmap`` parser: with every sub-command, or, for a ``command`` of ``COMMANDS``, with only the
    sub-commands that its function adds (building every parser's arguments costs more than a small cartogram)."""
    p = argparse.ArgumentParser(prog="rfmap", description="Resolution-free neural surrogates for geometric mapping.")
    sub = p.add_subparsers(dest="cmd", required=True)
    adders = [COMMANDS[command]] if command in COMMANDS else dict.fromkeys(COMMANDS.values())
    for add in adders:
        add(sub)
    return p


def main(argv=None) -> int:
    """Run one ``rfmap`` sub-command.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after ``rfmap`` (default: those of the process), e.g. ``["models"]``.

    Returns
    -------
    int
        The exit status: 0 on success, 1 where the sub-command says its result falls short (``rfmap cartogram``),
        2 on bad input (one line on stderr naming the problem, no partial output file left), 130 when interrupted.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv[0] if argv else None).parse_args(argv)
    out = getattr(args, "out", None)
    existed = bool(out) and os.path.isfile(out)
    try:
        return args.func(args)
    except (CLIError, ValueError, FileNotFoundError, MemoryError) as e:
        if out and not existed and os.path.isfile(out) and args.cmd in ("solve", "map", "cartogram"):
            os.remove(out)
        if isinstance(e, MemoryError):  # past the grid-size guard (rfmap.core.mesh.check_grid_memory): say so in one line
            e = f"out of memory ({e or 'allocation failed'}); use a smaller N or fewer points"
        print(f"rfmap {args.cmd}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


# the sub-commands whose process ends without the interpreter's teardown (entry): every file they write is closed
# before they return, and they register nothing to run at exit
QUICK_EXIT = ("cartogram",)

# the number of the signal SIGPIPE, sent to a process that writes to a pipe whose reader has gone
PIPE_SIGNAL = 13


def entry() -> None:
    """The ``rfmap`` program (console script and ``python -m rfmap.cli``): runs :func:`main` on the process's
    arguments and exits with its status; when the reader of its output goes first (``rfmap models | head``), it
    ends without a message, with status 141 (128 + the number of SIGPIPE), as a Unix tool does."""
    # after a sub-command of QUICK_EXIT the process exits at once (os._exit, streams flushed) instead of tearing
    # the interpreter down, which frees every module's objects one by one: on a small map that teardown takes a
    # noticeable share of the whole command
    argv = sys.argv[1:]
    try:
        code = main(argv)
        if argv[:1] and argv[0] in QUICK_EXIT:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
        sys.stdout.flush()
    except BrokenPipeError:
        # the reader of the output has gone (``rfmap models | head``): end quietly, as a Unix tool does on
        # SIGPIPE, with the status a shell reports for one (128 + 13); the output still buffered goes nowhere
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(128 + PIPE_SIGNAL)
    sys.exit(code)


if __name__ == "__main__":
    entry()
