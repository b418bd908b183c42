"""``rfmap cartogram``: GeoJSON regions resized by a value (:func:`rfmap.cartogram.resize.cartogram`), a CSV template
(``--make-csv``), values joined from a CSV (``--data``), a time series (``--series``, ``--gif``) and figures
(``--png``, ``--svg``).  Exit status 0: within tolerance, every region valid and no overlaps; 1: not so (the GeoJSON
is written all the same, flagged); 2: bad input (one line, nothing written).
"""
from __future__ import annotations

import os
import sys

from ..core.wording import counted
from .base import CLIError, solver_name

__all__ = ["add_cartogram_parser", "cmd_cartogram", "cartogram_options"]


def _cartogram_outputs(args) -> list[str]:
    """The files ``rfmap cartogram`` will write, checked before any work: suffixes and existing folders."""
    if args.make_csv:
        outs = [args.make_csv]
    elif args.out is None:
        raise CLIError("--out is required (or --make-csv to write a CSV template)")
    else:
        outs = [args.out]
    for opt, suffix in (("png", (".png",)), ("svg", (".svg",)), ("gif", (".gif", ".mp4")), ("html", (".html",))):
        path = getattr(args, opt)
        if path and not path.lower().endswith(suffix):
            raise CLIError(f"--{opt} must name a {' or '.join(suffix)} file, got {path!r}")
        if path and not args.make_csv:
            outs.append(path)
    if args.html and not args.make_csv:
        import importlib.util

        if importlib.util.find_spec("plotly") is None:
            raise CLIError("--html needs plotly: pip install 'rfmap[geo]'")
    if args.projected and args.lonlat:
        raise CLIError("--projected and --lonlat exclude each other")
    if args.max_passes < 1:
        raise CLIError(f"--max-passes must be at least 1, got {args.max_passes}")
    if (args.color or args.label) and not args.data and not (args.png or args.svg or args.html):
        raise CLIError("--color and --label are for the figures: add --png, --svg or --html")
    for path in outs:
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise CLIError(f"cannot write {path}: no folder {folder}")
    return outs


def _cartogram_input(args):
    """The regions of ``rfmap cartogram``: the GeoJSON as it is, or with ``--data`` joined to it
    (:func:`rfmap.cartogram.data.join_values`); the join's report lines are printed."""
    if not args.data:
        if args.id:
            raise CLIError("--id needs --data (or --make-csv)")
        return args.input
    from ..cartogram.data import join_values, read_csv_table, read_csv_values

    if not args.id:
        raise CLIError("--data needs --id COLUMN (the CSV column that holds the regions' ids)")
    extra_cols = list(dict.fromkeys(c for c in (args.color, args.label, args.inset) if c))
    table = read_csv_table(args.data, args.id, extra_cols)
    extra = {c: {rid: row[c] for rid, row in table.items()} for c in extra_cols}
    collection = args.input
    for k, col in enumerate(args.series or [args.value]):
        join = join_values(collection, read_csv_values(args.data, args.id, col), key=args.id_property or args.id,
                           value=col, missing=args.missing, extra=extra, projection=args.projection)
        collection = join.collection
        if k == 0:
            for line in join.report():
                print(line)
    return collection


def cmd_cartogram(args) -> int:
    """Exit 0 for a cartogram within tolerance with valid, disjoint regions; 1 for one that is not (written all the
    same, its ``"rfmap"`` status ``"failed"``: :meth:`rfmap.cartogram.resize.Cartogram.problems`); 2 for bad input."""
    _cartogram_outputs(args)
    if args.make_csv:
        from ..cartogram.data import write_csv_template

        key, value = args.id_property or args.id or "id", args.value or "value"
        n = write_csv_template(args.input, args.make_csv, key=key, value=value)
        print(f"wrote {args.make_csv}: {n} regions, their {key!r} and an empty {value!r} column")
        return 0
    if (args.value is None) == (args.series is None):
        raise CLIError("give one of --value (a cartogram) and --series (a cartogram per value, animated)")
    if args.gif and not args.series:
        raise CLIError("--gif needs --series")
    from ..cartogram.resize import cartogram

    options = cartogram_options(args)
    if args.inset and args.series:
        raise CLIError("--inset draws one cartogram: it does not go with --series")
    collection = _cartogram_input(args)
    if args.series:
        return _cartogram_series(args, collection, options)
    if args.inset:
        return _cartogram_insets(args, collection, options)
    try:
        carto = cartogram(collection, args.value, options)
    except ImportError as e:  # pyproj (or plotly) missing: a setup problem, told in one line
        raise CLIError(str(e)) from e
    carto.save(args.out)
    _cartogram_figures(args, carto)
    _cartogram_page(args, [carto])
    names = [carto.input_features[i].get("id", f"#{i}") for i in carto.floored]
    _print_report(f"wrote {args.out}: {counted(len(carto.input_features), 'region')} by {args.value!r}",
                  f"{carto.method}, N = {carto.n}: {counted(carto.info['iterations'], 'pass')}, {carto.time:.2f} s",
                  carto.metrics())
    far = carto.info.get("beyond_domain", [])
    if far:
        print(f"written in the projection's plane ({carto.frame.projection.definition}; the GeoJSON's \"crs\" "
              f"member): {counted(len(far), 'region')} left the longitude/latitude domain (use --lonlat to force "
              "it)")
    if names:
        print(f"zero values floored in {counted(len(names), 'region')}: {_listed(names)}")
    cut = carto.info.get("overlaps_cut", [])
    if cut:
        label = [carto.input_features[i].get("id", f"#{i}") for pair in cut for i in pair]
        print(f"sliver overlaps cut in {counted(len(cut), 'pair of neighbours')} pressed together: "
              f"{_listed([f'{a} / {b}' for a, b in zip(label[::2], label[1::2])], LISTED_CUTS)}")
    return _report_problems(carto.problems())


def cartogram_options(args):
    """The :class:`rfmap.cartogram.options.CartogramOptions` of ``rfmap cartogram``'s arguments, built once and passed
    whole to the cartogram, the series or the insets."""
    from ..cartogram.options import CartogramOptions

    return CartogramOptions(method=args.method, n=args.n, tol=args.tol, max_iterations=args.max_passes,
                            projection=args.projection, model=args.model, points=args.points, timeout=args.timeout,
                            output="projected" if args.projected else "input" if args.lonlat else "auto")


def _print_report(head: str, run: str, metrics) -> None:
    """The report of a written cartogram: what was written, then, indented, one line for the run (method, raster,
    passes, time), one for the area errors and one for the topology
    (:meth:`rfmap.cartogram.metrics.CartogramMetrics.report_lines`)."""
    print(head)
    for line in (run, *metrics.report_lines()):
        print(f"  {line}")


def _report_problems(problems: list[str]) -> int:
    """Each problem of a cartogram on its own line of stderr; the exit status (1 when there is any)."""
    for p in problems:
        print(f"rfmap cartogram: failed: {p}", file=sys.stderr)
    return 1 if problems else 0


#: how many names a line of the command's report lists before it counts the rest
LISTED = 10
LISTED_CUTS = " (the output's \"rfmap\" member, \"overlaps_cut\", lists them all)"


def _listed(names: list, where: str = "") -> str:
    """The first :data:`LISTED` names, comma-separated, and how many more there are (and ``where`` to read them)."""
    shown = ", ".join(map(str, names[:LISTED]))
    return shown + (f" and {len(names) - LISTED} more{where}" if len(names) > LISTED else "")


def _cartogram_series(args, collection, options) -> int:
    """``--series``: a cartogram per value, each warm-started from the previous
    (:func:`rfmap.cartogram.series.cartogram_series`); ``--out`` holds the last, ``--gif`` the animation."""
    from ..cartogram.methods import METHODS, get_method
    from ..cartogram.series import cartogram_series, save_animation

    if not get_method(options.method).classical:
        classical = " or ".join(name for name, m in METHODS.items() if m.classical)
        raise CLIError(f"--series runs the classical methods ({classical})")
    if args.projected or args.lonlat:
        raise CLIError("--series writes every frame in the projection's plane: --projected and --lonlat do not apply")
    try:
        series = cartogram_series(collection, args.series, options)
    except ImportError as e:
        raise CLIError(str(e)) from e
    series.frames[-1].carto.save(args.out)
    if args.gif:
        import matplotlib

        matplotlib.use("Agg")
        save_animation(series, args.gif)
    _cartogram_page(args, [f.carto for f in series.frames], [f.key for f in series.frames])
    for f in series.frames:
        print(f"{f.key}: {counted(f.passes, 'pass')}, {f.seconds:.2f} s, largest area error {f.max_error:.4f}")
    also = [p for p in (args.gif, args.html) if p]
    print(f"wrote {args.out} (the last frame, in the projection's plane)" + (f" and {', '.join(also)}" if also else ""))
    return _report_problems(series.problems())


def _cartogram_insets(args, collection, options) -> int:
    """``--inset COLUMN``: every inset a cartogram of its own, placed beside the main map on one scale
    (:func:`rfmap.cartogram.insets.cartogram_insets`); written in the placed frames."""
    from ..cartogram.insets import cartogram_insets

    if args.projected or args.lonlat:
        raise CLIError("--inset writes the insets' placed frames: --projected and --lonlat do not apply")
    try:
        carto = cartogram_insets(collection, args.value, args.inset, options)
    except ImportError as e:
        raise CLIError(str(e)) from e
    carto.save(args.out)
    _cartogram_figures(args, carto)
    _cartogram_page(args, [carto])
    sides = ", ".join(f"{side} {idx.size}" for side, idx in carto.groups.items())
    _print_report(f"wrote {args.out}: {counted(len(carto.input_features), 'region')} by {args.value!r} in "
                  f"{counted(len(carto.groups), 'inset')} ({sides})",
                  f"{carto.method}, N = {carto.n}: {carto.time:.2f} s", carto.metrics())
    return _report_problems(carto.problems())


def _cartogram_page(args, cartos: list, keys: list | None = None) -> None:
    """``--html``: an interactive page (:mod:`rfmap.cartogram.html`), a slider through the frames of a series;
    hover labels from ``--label``, colours from ``--color``."""
    if not args.html:
        return
    from ..cartogram.html import HtmlOptions, page_figure, write_page

    props = [f.get("properties") or {} for f in cartos[0].features]
    labels = [p.get(args.label) for p in props] if args.label else None
    colors = None
    if args.color:
        from matplotlib.colors import to_hex

        from ..viz.cartograms import region_colours

        colors = [to_hex(c) for c in region_colours([p.get(args.color) for p in props])[0]]
    opts = HtmlOptions(title=args.value, labels=labels, colors=colors)
    write_page(page_figure(cartos, keys or [args.value], opts), args.html)
    if not args.series:
        print(f"wrote {args.html}: an interactive page (hover a region for its value and area error)")


def _cartogram_figures(args, carto) -> None:
    """``--png`` / ``--svg``: the map and its cartogram side by side (:func:`rfmap.viz.cartogram_figure`)."""
    if not (args.png or args.svg):
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..viz.cartograms import cartogram_figure

    props = [f.get("properties") or {} for f in carto.features]
    colors = [p.get(args.color) for p in props] if args.color else None
    labels = [p.get(args.label) for p in props] if args.label else None
    for path in (args.png, args.svg):
        if path:
            fig = cartogram_figure(carto, colors=colors, labels=labels, title=args.value, path=path)
            plt.close(fig)

#: ``--n``'s help: cells, where ``rfmap solve`` and ``rfmap map`` count points
N_HELP = ("cells per side N of the density raster, as cartogram-cpp's -n (default {n}); the maps run on N + 1 points "
          "per side, the count that rfmap solve and rfmap map --n take")
#: the help of ``--inset``, which names cartogram-cpp first on the command line's page
INSET_HELP = ("the column (or, without --data, the property) naming each region's inset, as the 'Inset' column of "
              "cartogram-cpp (the C++ program of the flow-based method, Gastner, Seguy & More 2018, "
              "github.com/mgastner/cartogram-cpp): C or empty (the main map), L, R, T or B (left, right, top, bottom "
              "of it); each inset is a cartogram in its own frame, put on the main map's scale beside it")


def add_cartogram_parser(sub) -> None:
    """Add ``rfmap cartogram`` to the sub-command parsers ``sub``."""
    from ..cartogram.methods import METHODS
    from ..cartogram.options import CartogramOptions
    from ..cartogram.projection import PROJECTIONS

    default = CartogramOptions()  # every default of the command is the API's

    s = sub.add_parser("cartogram",
                       help="resize GeoJSON regions by a value (a flow-based cartogram by default; diffusion, "
                            "surrogate or hybrid)",
                       description="Resize GeoJSON regions by a value. Longitude/latitude are projected to an "
                                   "equal-area plane first (Lambert azimuthal equal-area centred on the map; Equal "
                                   "Earth for a map wider than 180 degrees of longitude). Exit status 0: within "
                                   "tolerance, every region valid and no overlaps; 1: not so (the GeoJSON is written "
                                   "all the same, its \"rfmap\" member's status \"failed\", and each problem is "
                                   "printed); 2: bad input (one line, nothing written).")
    s.add_argument("input", help="GeoJSON FeatureCollection of Polygon / MultiPolygon features")
    s.add_argument("--value", default=None,
                   help="the feature property holding each region's value (with --data: the CSV column)")
    s.add_argument("--series", nargs="+", default=None, metavar="VALUE",
                   help="instead of --value: a cartogram per value in turn (e.g. one per year), each from the previous "
                        "one, by flow or diffusion only; --out writes the last, --gif the animation")
    s.add_argument("--gif", default=None, help="with --series: write the frames as an animation (.gif, or .mp4)")
    d = s.add_argument_group("values from a CSV table")
    d.add_argument("--data", default=None, metavar="FILE.csv",
                   help="read the values from this CSV, joined to the regions by --id (exactly, else with accents "
                        "and case ignored where that finds one partner); the regions without a row, the rows "
                        "without a region, the pairs joined ignoring accents and case and the ids with several "
                        "such partners are listed, one line each")
    d.add_argument("--id", default=None, metavar="COLUMN",
                   help="the CSV column of the regions' ids, matched to the GeoJSON property of the same name "
                        "(or the feature's id for 'id')")
    d.add_argument("--id-property", default=None, metavar="NAME",
                   help="the GeoJSON property to match --id against, where its name differs")
    d.add_argument("--missing", choices=["mean", "drop", "error"], default="mean",
                   help="a region without a row: given the mean density of the others (default, as cartogram "
                        "programs do), dropped, or an error")
    d.add_argument("--color", default=None, metavar="COLUMN",
                   help="colour the figures by this column (colours, or categories); default: neighbours differ")
    d.add_argument("--label", default=None, metavar="COLUMN",
                   help="label the regions of the figures (and the --html page's hover) by this column")
    d.add_argument("--inset", default=None, metavar="COLUMN",
                   help=INSET_HELP)
    d.add_argument("--make-csv", default=None, metavar="OUT.csv",
                   help="only write a CSV template: one row per region with its --id (default: the feature id) and "
                        "an empty --value column")
    s.add_argument("--method", choices=tuple(METHODS), type=solver_name, default=default.method,
                   help="classical flow-based method (default, the fastest), classical diffusion (also 'dem'), "
                        "neural surrogate, or the surrogate polished by the flow")
    s.add_argument("--n", type=int, default=default.n, help=N_HELP.format(n=default.n))
    s.add_argument("--tol", type=float, default=default.tol,
                   help=f"repeat passes until the largest relative area error is at most this (default {default.tol})")
    s.add_argument("--max-passes", type=int, default=default.max_iterations,
                   help=f"at most this many passes (default {default.max_iterations})")
    s.add_argument("--timeout", type=float, default=None, metavar="SECONDS",
                   help="start no further pass after this many seconds; the best pass so far is written, and the "
                        "command exits 1 unless it is within the tolerance")
    s.add_argument("--points", type=int, default=None, metavar="COUNT",
                   help="simplify (shared borders kept) or densify the region outlines to about this many "
                        "vertices, the detail kept; the flow still splits edges to grid cells")
    s.add_argument("--projection", choices=PROJECTIONS, default=default.projection,
                   help="the plane of the cartogram: auto (default: equal-area for longitude/latitude, none for "
                        "planar coordinates), equal-area, equirectangular or none")
    s.add_argument("--projected", action="store_true",
                   help="write the cartogram in the projection's plane (metres) instead of the input's coordinates "
                        "(by default the plane is chosen only when a region left the longitude/latitude domain, "
                        "and the output says so)")
    s.add_argument("--lonlat", action="store_true",
                   help="write longitude/latitude even when a region left their domain (it is then drawn at the "
                        "domain's edge, and the command exits 1)")
    s.add_argument("--model", default=None, help="surrogate for --method surrogate/hybrid (default deq2d-square)")
    s.add_argument("--out", default=None, help="output GeoJSON (required unless --make-csv)")
    s.add_argument("--png", default=None,
                   help="also draw the input and the cartogram side by side, with an area legend (.png)")
    s.add_argument("--svg", default=None, help="the same figure as SVG (.svg)")
    s.add_argument("--html", default=None, metavar="OUT.html",
                   help="also write a self-contained interactive page (plotly, in the 'geo' extra): hover a region "
                        "for its name (or --label), value and area error; with --series, a slider and a play button "
                        "step through the frames")
    s.set_defaults(func=cmd_cartogram)
