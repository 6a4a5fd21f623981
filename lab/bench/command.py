"""``python -m lab bench``: run a reconstruction method over benchmark shapes, print a table.

One row per domain × condition; each row's full result (per-shape metrics, timings, memory) is
written as JSON to ``--out`` (``<method>_<domain>_<condition>.json``). ``--table`` runs every
radius mode of ``ours`` instead and prints Table I (rows fixed, best fixed, curvature, learned,
and a reference method's row, Open3D Poisson by default; per domain CD-L1 ×10², F1@0.005,
F1@0.01, NC, double-layered share and area ratio), one table per condition; a mode the engine has
not built yet is reported as 'not available'.

Examples::

    python -m lab bench --method poisson --domain all --condition clean --count 20
    python -m lab bench --method ours --radius-mode fixed --domain cars --condition noisy
    python -m lab bench --table --condition clean --count 20
    python -m lab bench --method ours --domain rooms --condition noisy --count 30 --resume
    python -m lab bench --method poisson --report     # table of the JSON files in --out
    python -m lab bench --table --report --condition clean   # Table I from those files
"""

import sys

from engine.settings import DEVICES, RADIUS_MODES

CONDITION_NAMES = ("clean", "sparse", "noisy", "outliers")
DOMAIN_NAMES = ("cars", "garments", "rooms")  # "all"; "real" (REAL_SHAPES) only by name
TABLE_MODES = RADIUS_MODES
REFERENCE_LABEL = "{method} (reference)"
BEST_FIXED_LABEL = "best fixed"
# The single ball radius with the lowest held-out UDF error per domain over the learned mode's
# range (engine/weights/SELECTOR_CARD.md, "best fixed"): Table I's row of a fixed radius tuned
# to the domain, beside the default 0.018.
BEST_FIXED_RADII = {"cars": 0.030, "garments": 0.036, "rooms": 0.043}


def add_arguments(parser) -> None:
    """Register the command's arguments on an ``argparse`` parser."""
    parser.add_argument("--method", default="ours",
                        help="poisson, ours, nearest-udf, truth-udf (our mesher on the GT's "
                             "exact distances: the mesher's floor), or ground-truth (the GT "
                             "itself: the metrics' sampling floor) (default ours)")
    parser.add_argument("--radius-mode", default="fixed", choices=RADIUS_MODES,
                        help="radius mode of ours (default fixed)")
    parser.add_argument("--radius", type=float, default=None,
                        help="ball radius of ours in fixed mode, unit frame (default: the "
                             "engine's, 0.018); results are then named ours-r<radius>")
    parser.add_argument("--fill-gaps", action="store_true",
                        help="ours fills the gaps of sparse scans wider than the ball radius "
                             "(the engine's --fill-gaps, on by default there; here off unless "
                             "given, so that Table I's names stay); results are then named "
                             "...-gaps")
    parser.add_argument("--domain", default="all", choices=DOMAIN_NAMES + ("real", "all"),
                        help="a domain of test shapes, all three, or real: the real meshes of "
                             "lab.bench.dataset.REAL_SHAPES, sampled like the objects")
    parser.add_argument("--condition", default="all", choices=CONDITION_NAMES + ("all",))
    parser.add_argument("--count", type=int, default=20, help="test shapes per domain (default 20)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="shapes run at once, one process each with one thread (default 1; "
                             "on a many-core GPU machine, e.g. 12)")
    parser.add_argument("--samples", type=int, default=100_000,
                        help="metric samples per mesh (default 100000)")
    parser.add_argument("--sample-seed", type=int, default=0,
                        help="seed of the metric's surface samples; the shapes and their inputs "
                             "have fixed seeds of their own (default 0)")
    parser.add_argument("--resolution", type=int, default=256,
                        help="grid resolution of ours (default 256)")
    parser.add_argument("--device", default="auto", choices=DEVICES,
                        help="device of ours (default auto)")
    parser.add_argument("--out", default="bench_results",
                        help="folder for the JSON results (default bench_results)")
    parser.add_argument("--table", action="store_true",
                        help="run each radius mode of ours and print Table I")
    parser.add_argument("--reference", default="poisson",
                        help="with --table: the method whose row is printed under the radius "
                             "modes, run on the same shapes (default poisson; none for no row)")
    parser.add_argument("--report", action="store_true",
                        help="run nothing: print the table (with --table, Table I) of the JSON "
                             "results already in --out")
    parser.add_argument("--resume", action="store_true",
                        help="keep the shapes already scored in --out's JSON for the same method, "
                             "domain, condition, samples and sample seed; run only the missing "
                             "ones (extends a run to a larger --count, or finishes an interrupted "
                             "one)")
    parser.add_argument("--meshes", default=None,
                        help="a folder where each predicted mesh is saved (one .npz per shape), "
                             "for --rescore")
    parser.add_argument("--fields", default=None,
                        help="ours: a folder where each shape's distance field is kept; a later "
                             "run with the same input, settings and field code (the engine "
                             "outside engine/meshing) meshes the kept field instead of computing "
                             "it, so a mesher change is measured at the mesher's cost (those "
                             "shapes' seconds and memory are left out of the means)")
    parser.add_argument("--rescore", action="store_true",
                        help="run nothing: score again, under today's protocol, every result in "
                             "--out of the selected domains and conditions from the meshes its "
                             "run saved in --meshes, and rewrite its JSON (times kept)")
    parser.add_argument("--quiet", action="store_true", help="no per-shape progress on stderr")


def _selected(value: str, names):
    return list(names) if value == "all" else [value]


def _progress(quiet: bool):
    if quiet:
        return None

    def report(fraction: float, message: str) -> None:
        print(f"[{fraction * 100:5.1f}%] {message}", file=sys.stderr, flush=True)

    return report


def _factory(args, name: str, radius_mode: str, radius=None):
    """A picklable callable that builds the method (in this process or in a worker); ``radius``
    (fixed mode) overrides ``--radius``."""
    import functools

    from .methods import make_method

    options = {}
    if name in ("ours", "nearest-udf", "truth-udf"):
        options = {"resolution": args.resolution, "device": args.device}
        if name == "ours":
            options["radius_mode"] = radius_mode
            radius = args.radius if radius is None else radius
            if radius is not None:
                options["radius"] = radius
            options["fill_gaps"] = bool(args.fill_gaps)
            if args.fields:
                options["fields"] = args.fields
    return functools.partial(make_method, name, **options)


def run(args) -> int:
    """Run the benchmark(s), print the markdown table(s), write the JSON files."""
    from engine.errors import InputError

    from .harness import format_table, ground_truth, run_benchmark, write_json
    from .methods import METHODS, MethodUnavailable

    if args.count < 1:
        raise InputError("--count must be at least 1")
    if args.jobs < 1:
        raise InputError("--jobs must be at least 1")
    if args.method not in METHODS and args.method != "ground-truth":
        raise InputError(f"unknown method {args.method!r}; known: {', '.join(METHODS)}")
    domains = _selected(args.domain, DOMAIN_NAMES)
    conditions = _selected(args.condition, CONDITION_NAMES)
    progress = _progress(args.quiet)

    if args.table and args.reference != "none" and args.reference not in METHODS:
        raise InputError(f"unknown --reference {args.reference!r}; known: "
                         f"{', '.join(METHODS)}, none")
    if args.rescore:
        return _rescore(args, domains, conditions, progress)
    if args.table:
        return _run_table(args, domains, conditions, progress)
    if args.report:
        return _report(args, domains, conditions)

    oracle = args.method == "ground-truth"
    try:
        factory = None if oracle else _factory(args, args.method, args.radius_mode)
        method = ground_truth if oracle else factory()
    except MethodUnavailable as error:
        print(f"{args.method}: not available: {error}", file=sys.stderr)
        return 1
    name = "ground-truth" if oracle else method.__name__
    given_truth = oracle or getattr(method, "needs_ground_truth", False)
    results = []
    for condition in conditions:
        for domain in domains:
            result = run_benchmark(method, domain, condition, args.count, seed=args.sample_seed,
                                   samples=args.samples, progress=progress, name=name,
                                   pass_ground_truth=given_truth, jobs=1 if oracle else args.jobs,
                                   method_factory=factory, meshes=args.meshes,
                                   earlier=_earlier(args, name, domain, condition))
            path = write_json(result, args.out)
            print(f"wrote {path}", file=sys.stderr)
            results.append(result)
    print(format_table(results))
    return 0


def _rescore(args, domains, conditions, progress) -> int:
    """Score the results in ``--out`` of the selected domains and conditions again from the
    meshes saved in ``--meshes``; rewrite their JSON."""
    import glob
    import os

    from engine.errors import InputError

    from .harness import read_json, rescore, write_json

    if not args.meshes:
        raise InputError("--rescore needs --meshes, the folder the runs saved their meshes in")
    done = 0
    for path in sorted(glob.glob(os.path.join(args.out, "*.json"))):
        result = read_json(path)
        if result.get("domain") not in domains or result.get("condition") not in conditions:
            continue
        try:
            result = rescore(result, args.meshes, progress=progress)
        except FileNotFoundError as error:
            print(f"not rescored: {path}: {error}", file=sys.stderr)
            continue
        print(f"rescored {write_json(result, args.out)}", file=sys.stderr)
        done += 1
    return 0 if done else 1


def _earlier(args, name: str, domain: str, condition: str):
    """With ``--resume``, the result already in ``--out`` for this row (None when there is none)."""
    import os

    from .harness import read_json, result_filename

    path = os.path.join(args.out, result_filename(
        {"method": name, "domain": domain, "condition": condition}))
    if not args.resume or not os.path.exists(path):
        return None
    return read_json(path)


def _report(args, domains, conditions) -> int:
    """Print the table of the results in ``--out`` for the selected method, domains, conditions
    (each on its first ``--count`` shapes)."""
    import os

    from .harness import first_shapes, format_table, read_json
    from .methods import ours_name

    name = (ours_name(args.radius_mode, args.radius, args.fill_gaps) if args.method == "ours"
            else args.method)
    results, missing = [], []
    for condition in conditions:
        for domain in domains:
            path = os.path.join(args.out, f"{name}_{domain}_{condition}.json")
            if os.path.exists(path):
                result = read_json(path)  # its first --count shapes (all, if it has fewer)
                results.append(first_shapes(result, args.count) or result)
            else:
                missing.append(path)
    print(format_table(results))
    for path in missing:
        print(f"missing: {path}", file=sys.stderr)
    return 0 if results else 1


def _load_result(args, method: str, domain: str, condition: str):
    """A result written earlier to ``--out``, cut to its first ``--count`` shapes; None when
    missing or shorter."""
    import os

    from .harness import first_shapes, read_json

    path = os.path.join(args.out, f"{method}_{domain}_{condition}.json")
    if not os.path.exists(path):
        return None
    return first_shapes(read_json(path), args.count)


def _table_rows(args, domains):
    """Table I's rows: (label, method name, radius mode, radius per domain or None) for the
    default fixed radius, the best fixed radius of each domain (``BEST_FIXED_RADII``), the other
    radius modes of ``ours``, then the reference method's row (``--reference``) unless it is
    ``none``."""
    rows = [(mode, "ours", mode, None) for mode in TABLE_MODES]
    rows.insert(1, (BEST_FIXED_LABEL, "ours", "fixed",
                    {d: BEST_FIXED_RADII[d] for d in domains}))
    if args.reference != "none":
        rows.append((REFERENCE_LABEL.format(method=args.reference), args.reference, None, None))
    return rows


def _run_table(args, domains, conditions, progress) -> int:
    """Table I: one row per radius mode of ``ours`` (and the reference method), columns per
    domain. With ``--report`` the table is assembled from the JSON results already in ``--out``
    (runs done one at a time); the best fixed row only where ``--out`` holds some of its
    results."""
    import os

    from .harness import first_shapes, run_benchmark, write_json
    from .methods import MethodUnavailable, ours_name

    for condition in conditions:
        cells = {}
        for label, method_name, mode, radii in _table_rows(args, domains):
            def name(domain):
                if method_name != "ours":
                    return method_name
                return ours_name(mode, radii[domain] if radii else None, args.fill_gaps)

            if args.report:
                if radii and not any(os.path.exists(os.path.join(
                        args.out, f"{name(d)}_{d}_{condition}.json")) for d in domains):
                    continue  # results from before the best fixed row: no such row to report
                found = {d: _load_result(args, name(d), d, condition) for d in domains}
                missing = [d for d, r in found.items() if r is None]
                cells[label] = (f"not run ({', '.join(missing)}: no result with {args.count} "
                                f"shapes in {args.out})" if missing else found)
                continue
            cells[label] = {}
            for domain in domains:
                factory = _factory(args, method_name, mode, radii[domain] if radii else None)
                try:
                    method = factory()
                except MethodUnavailable as error:
                    cells[label] = f"not available ({error})"
                    break
                result = run_benchmark(method, domain, condition, args.count, seed=args.sample_seed,
                                       samples=args.samples, progress=progress, jobs=args.jobs,
                                       method_factory=factory, meshes=args.meshes,
                                       earlier=_earlier(args, method.__name__, domain,
                                                        condition))
                print(f"wrote {write_json(result, args.out)}", file=sys.stderr)
                cells[label][domain] = first_shapes(result, args.count)  # --resume may keep more
        print(format_table_one(cells, domains, condition, args.count, args.samples))
        print()
    return 0


def format_table_one(cells: dict, domains, condition: str, count: int, samples: int) -> str:
    """Table I as markdown: rows = radius modes, per domain 4 metric columns, then the
    double-layered share of the predicted area beside the ground truth's own (its thin parts) and
    the area ratio prediction / ground truth (in brackets: with the truth's close sheets counted
    once). In each metric column the best value as printed (lowest CD, highest F-score and NC)
    is bold, in every row that reaches it, unless all rows print the same value.

    Parameters
    ----------
    cells : dict mode -> (dict domain -> run_benchmark result) or a 'not available' string
    domains : the domains, in column order
    condition, count, samples : stated in the caption
    """
    from .harness import _area, _fmt

    keys = (("cd_l1_x100", 3), ("f1_0.005", 3), ("f1_0.01", 3), ("nc", 3))
    head = "| radius mode | " + " | ".join(
        f"{d} CD-L1 ×10² | {d} F1@0.005 | {d} F1@0.01 | {d} NC | {d} double % (GT %) "
        f"| {d} area ratio" for d in domains) + " | s/shape |"
    rule = "|---|" + "---|" * (6 * len(domains) + 1)
    lines = [f"Table I ({condition}, {count} shapes per domain, {samples} samples per mesh)",
             "", head, rule]
    scored = [cell for cell in cells.values() if not isinstance(cell, str)]
    best = {}
    for domain in domains:
        for key, digits in keys:
            printed = {_fmt(cell[domain]["summary"][key], digits) for cell in scored}
            numbers = [float(text) for text in printed if text not in ("–", "inf")]
            if len(printed) > 1 and numbers:
                best[domain, key] = _fmt(min(numbers) if key == "cd_l1_x100" else max(numbers),
                                         digits)
    for mode, cell in cells.items():
        if isinstance(cell, str):
            lines.append(f"| {mode} | " + " | ".join([cell] + ["–"] * (6 * len(domains)))
                         + " |")
            continue
        values = []
        seconds = [cell[d]["summary"]["seconds"] for d in domains]
        for domain in domains:
            summary = cell[domain]["summary"]
            failed = summary["empty"]
            for key, digits in keys:
                text = _fmt(summary[key], digits)
                if best.get((domain, key)) == text:
                    text = f"**{text}**"
                if key == "cd_l1_x100" and failed:
                    text += f" ({failed} failed)"
                values.append(text)
            values += [_double_layer(summary), _area(summary)]
        values.append(_fmt(sum(seconds) / len(seconds), 1))
        lines.append(f"| {mode} | " + " | ".join(values) + " |")
    return "\n".join(lines)


def _double_layer(summary: dict) -> str:
    """``double % (GT %)`` within one spacing; ``–`` for results scored without it."""
    if summary.get("double_layer") is None:
        return "–"
    return f"{100 * summary['double_layer']:.1f} ({100 * summary['gt_double_layer']:.1f})"
