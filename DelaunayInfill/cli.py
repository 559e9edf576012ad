"""``delaunay-infill``: process Cura G-code, preview a layer, run the demo.

Subcommands: ``process``, ``preview``, ``demo``; plus ``figures`` (lead) and
``package`` / ``install-cura`` (packaging) when those modules are present.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time

__all__ = ["main", "build_parser"]

EXIT_OK, EXIT_ERROR, EXIT_REFUSED = 0, 1, 2


def _percent(text: str) -> float:
    try:
        value = float(text.strip().rstrip("%"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a percentage: {text!r}") from None
    if not (0 < value <= 100):
        raise argparse.ArgumentTypeError(f"a density must be in (0, 100] %, got {value:g}")
    return value / 100.0


def _flow(text: str) -> float:
    try:
        value = float(text.strip().rstrip("%"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a percentage: {text!r}") from None
    if not (10 <= value <= 300):
        raise argparse.ArgumentTypeError(f"--flow is the extrusion relative to Cura's infill, 10 to 300 %, got {value:g}")
    return value / 100.0


def _steps(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if not 0 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"--relax takes 0 to 1000 steps, got {value}")
    return value


def output_problem(path: str) -> str | None:
    """Why `path` cannot be written as an output file (None: it can), in the CLI's words."""
    if os.path.isdir(path) or path.endswith(os.sep):
        return f"{path} is a folder: give a file name (e.g. {os.path.join(path, 'out.gcode')})"
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        return f"the folder {folder} does not exist"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"cannot write into {folder} (no permission)"
    if os.path.exists(path) and not os.access(path, os.W_OK):
        return f"cannot overwrite {path} (no permission)"
    return None


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {value:g}")
    return value


def _named_percent(text: str) -> tuple[str, float]:
    name, sep, pct = text.rpartition(":")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME:PCT, got {text!r}")
    return name, _percent(pct)


def _offset(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y[,Z] in mm, got {text!r}") from None
    if len(values) not in (2, 3):
        raise argparse.ArgumentTypeError(f"expected X,Y[,Z] in mm, got {text!r}")
    return values


def _window(text: str) -> tuple[float, float, float, float]:
    try:
        x0, y0, x1, y1 = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X0,Y0,X1,Y1 in mm, got {text!r}") from None
    if not (x1 > x0 and y1 > y0):
        raise argparse.ArgumentTypeError(f"the window needs X1 > X0 and Y1 > Y0, got {text!r}")
    return x0, y0, x1, y1


class Progress:
    """Progress of a long run on stderr: a bar on a terminal, plain periodic lines elsewhere.

    Nothing shows for a run shorter than `after` seconds.  On a terminal one line is redrawn
    (``\\r``) at most every 0.2 s; in a log (not a terminal) a plain line is written every
    `every` seconds, so logs get no carriage returns.
    """

    BAR = 30  # characters

    def __init__(self, label: str, enabled: bool, stream=None, clock=time.perf_counter,
                 after: float | None = None, every: float = 10.0):
        self.label = label
        self.enabled = enabled
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        env_after = os.environ.get("DELAUNAY_INFILL_PROGRESS_AFTER")
        self.after = after if after is not None else float(env_after) if env_after else 2.0
        self.every = every
        self.start = clock()
        self.shown = False
        self.finished = False
        self.last = -1e9

    def __call__(self, fraction: float) -> None:
        if not self.enabled:
            return
        now = self.clock()
        elapsed = now - self.start
        if elapsed < self.after or (now - self.last < (0.2 if self.tty else self.every) and fraction < 1.0):
            return
        if fraction >= 1.0 and self.finished:
            return  # 100 % once
        self.finished = fraction >= 1.0
        self.last = now
        self.shown = True
        fraction = min(max(fraction, 0.0), 1.0)
        eta = elapsed / fraction - elapsed if fraction > 0 else 0.0
        timing = f"{elapsed:.0f} s, about {eta:.0f} s left" if fraction < 1.0 else f"{elapsed:.0f} s"
        if self.tty:
            filled = int(round(fraction * self.BAR))
            bar = "#" * filled + "." * (self.BAR - filled)
            self.stream.write(f"\r{self.label} [{bar}] {fraction * 100:3.0f} %  {timing}   ")
        else:
            self.stream.write(f"{self.label}: {fraction * 100:.0f} % ({timing})\n")
        self.stream.flush()

    def done(self) -> None:
        if self.shown and self.tty:
            self.stream.write("\n")
            self.stream.flush()
        self.shown = False


# --------------------------------------------------------------------------- process
def modifier_regions(specs: list[str], offset) -> list:
    """`--modifier FILE.stl:PCT` values as density regions (ValueError in the CLI's words)."""
    from .gcode import Region

    regions = []
    for spec in specs:
        path, pct = _named_percent(spec)
        if not os.path.isfile(path):
            raise ValueError(f"modifier STL not found: {path}")
        regions.append(Region.from_stl(path, pct, offset=offset))
    return regions


def painted_region(spec: str, offset):
    """A ``--paint MODEL.stl:FACES.json:PCT:DEPTH`` value as a density region (ValueError in the CLI's words)."""
    from .painting import PaintedRegion

    parts = spec.rsplit(":", 3)
    if len(parts) != 4 or not all(parts):
        raise ValueError(f"--paint: expected MODEL.stl:FACES.json:PCT:DEPTH, got {spec!r}")
    stl, faces, pct, depth = parts
    try:
        density = _percent(pct)
    except argparse.ArgumentTypeError as exc:
        raise ValueError(f"--paint: {exc}") from None
    try:
        depth_mm = float(depth)
    except ValueError:
        raise ValueError(f"--paint: the depth must be a number of mm, got {depth!r}") from None
    if not (0.0 < depth_mm < float("inf")):
        raise ValueError(f"--paint: the depth must be a positive number of mm, got {depth!r}")
    for path in (stl, faces):
        if not os.path.isfile(path):
            raise ValueError(f"--paint: no such file: {path}")
    try:
        return PaintedRegion.from_files(stl, faces, density, depth_mm, offset=offset)
    except OSError as exc:
        raise ValueError(f"--paint: cannot read {exc.filename or faces}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise ValueError(f"--paint: {exc}") from None


def _cmd_process(args) -> int:
    from .gcode import GCodeError, MeshSettings, ProcessSettings, process_file

    if args.output is None and not args.in_place:
        print("error: give -o OUT.gcode, or --in-place to replace the input", file=sys.stderr)
        return EXIT_REFUSED
    if args.output is not None and args.in_place:
        print("error: -o and --in-place exclude each other", file=sys.stderr)
        return EXIT_REFUSED
    if not os.path.isfile(args.input):
        print(f"error: no such file: {args.input}", file=sys.stderr)
        return EXIT_REFUSED
    if args.output is not None and os.path.abspath(args.output) == os.path.abspath(args.input):
        print("error: the output is the input: give --in-place to replace it, or another -o", file=sys.stderr)
        return EXIT_REFUSED
    problem = output_problem(args.output or args.input)
    if problem:
        print(f"error: {problem}; nothing was written", file=sys.stderr)
        return EXIT_REFUSED
    try:
        settings = ProcessSettings(
            density=args.density,
            line_width=args.line_width,
            seed=args.seed,
            layout=args.layout,
            flow=args.flow if args.flow is not None else 1.0,
            speed=args.speed,
            relax=args.relax,
            combing=not args.no_combing,
            meshes={name: MeshSettings(density=pct) for name, pct in args.mesh},
        )
        settings.validate()
        offset = args.modifier_offset or (0.0, 0.0, 0.0)
        regions = modifier_regions(args.modifier, offset)
        # --paint (issue 14): painted faces' depth-neighbourhood inside the model, placed like --modifier STLs
        regions += [painted_region(spec, offset) for spec in args.paint]
    except (ValueError, argparse.ArgumentTypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    if args.density is not None and args.density < 0.01:
        print(f"warning: --density {args.density * 100:g} is {args.density * 100:g} %; did you mean "
              f"{args.density * 10000:g} %?", file=sys.stderr)
    progress = Progress(f"processing {os.path.basename(args.input)}", enabled=not args.quiet)
    # --in-place --verify: the result goes next to the input first, is checked against it, then replaces it
    target = args.output
    if args.in_place and args.verify:
        target = os.path.join(os.path.dirname(os.path.abspath(args.input)),
                              f".{os.path.basename(args.input)}.delaunay-verify.gcode")
    try:
        clock = None
        if args.stages:
            from .gcode.stages import StageClock

            clock = StageClock()
        report = process_file(args.input, target, settings, regions=regions, in_place=args.in_place and target is None,
                              progress=progress, write_unchanged=False, keep_going=args.keep_going, stages=clock)
    except GCodeError as exc:
        progress.done()
        print(f"error: {args.input}: {exc}; nothing was written", file=sys.stderr)
        return EXIT_REFUSED
    except (ValueError, FileNotFoundError, OSError) as exc:
        progress.done()
        print(f"error: {getattr(exc, 'strerror', None) or exc}; nothing was written", file=sys.stderr)
        return EXIT_REFUSED
    progress.done()
    if report.already_processed:
        print(f"{args.input} was already processed by DelaunayInfill (marker in its header): nothing to do, nothing written")
        return EXIT_OK
    out = args.input if args.in_place else args.output
    if not args.quiet:
        print(report.format_table())
    if clock is not None:  # asked for: shown even with -q
        print("\nwhere the time went (--stages):")
        print(clock.table(report.layers_processed))
    for warning in _hints(report, args):
        print(f"warning: {warning}", file=sys.stderr)
    if report.failed_layers and not args.keep_going:
        if args.quiet:
            print(f"error: {len(report.failed_layers)} layer(s) could not be processed "
                  f"({'; '.join(report.failure_messages[:3])})", file=sys.stderr)
        print("error: nothing was written (--keep-going writes the file with Cura's infill in those layers)",
              file=sys.stderr)
        return EXIT_ERROR
    if not report.written:
        print("nothing was changed, so nothing was written", file=sys.stderr)
        return EXIT_ERROR
    if args.verify:
        from .gcode.verify import verify_files

        check = verify_files(args.input, target if args.in_place else out, flow=settings.flow)
        print(check.summary())
        for problem in check.problems:
            print(f"  - {problem}")
        if not check.ok:
            if args.in_place:
                os.unlink(target)
                print(f"error: {args.input} was left as it was", file=sys.stderr)
            return EXIT_ERROR
        if args.in_place:
            os.replace(target, args.input)
    if not args.quiet:
        print(f"wrote {out}")
    return EXIT_OK


def _hints(report, args) -> list[str]:
    """What the user should know of a run that did less than asked, with what to do."""
    hints = []
    if args.modifier or args.paint:
        for region in report.regions:
            if region.name.startswith(("base", "mesh ")):
                continue
            if not region.area_mm2 > 0:
                hints.append(f"the region {region.name} touches no infill: is it placed in G-code coordinates? "
                             "--modifier-offset 110,110 moves an STL to the centre of a 220 mm bed, where "
                             "CuraEngine puts a model's origin")
    known = set(report.meshes)
    for name, _ in args.mesh:
        if name not in known and os.path.basename(name) not in {os.path.basename(m) for m in known}:
            shown = ", ".join(sorted(known)) or "none"
            hints.append(f"--mesh {name}: no such ;MESH: in the file (its meshes: {shown})")
    if args.line_width is not None and report.line_width_found and not (
            0.67 <= args.line_width / report.line_width_found <= 1.5):
        hints.append(f"--line-width {args.line_width:g} mm is far from the file's own {report.line_width_found:.2g} mm "
                     "(its walls): the infill will extrude that much more or less per line")
    if report.layers_total and not report.infill_before_mm:
        hints.append("the file has no infill (;TYPE:FILL) to replace: was it sliced with 0 % infill? Slice it "
                     "with some infill density; Delaunay infill replaces Cura's")
    return hints


# --------------------------------------------------------------------------- preview
def _cmd_preview(args) -> int:
    from .gcode.preview import MATPLOTLIB_MISSING, render_layer

    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print(f"error: {MATPLOTLIB_MISSING}", file=sys.stderr)
        return EXIT_REFUSED
    for path in [args.input, args.before] if args.before else [args.input]:
        if not os.path.isfile(path):
            print(f"error: no such file: {path}", file=sys.stderr)
            return EXIT_REFUSED
    out = args.output or f"{os.path.splitext(os.path.basename(args.input))[0]}_layer{args.layer}.png"
    problem = output_problem(out)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_REFUSED
    try:
        regions = modifier_regions(args.modifier, args.modifier_offset or (0.0, 0.0, 0.0))
    except (ValueError, argparse.ArgumentTypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    try:
        render_layer(args.input, args.layer, out, before=args.before, occurrence=args.occurrence, window=args.window,
                     regions=regions)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    print(f"wrote {out}")
    return EXIT_OK


# --------------------------------------------------------------------------- demo
def _cmd_demo(args) -> int:
    from .gcode.demo import run_demo

    if args.reslice:
        from .curaengine import CuraEngineError, find_curaengine

        try:
            find_curaengine()
        except CuraEngineError as exc:
            print(f"error: --reslice needs CuraEngine: {exc}", file=sys.stderr)
            return EXIT_REFUSED
    return run_demo(args.output, reslice=args.reslice)


# --------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="delaunay-infill",
        description="Replace Cura's sparse infill with Delaunay-triangulated variable-density infill.",
    )
    from . import __version__

    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "process",
        help="replace the infill of a Cura G-code file",
        description="Replace Cura's ;TYPE:FILL with Delaunay infill. Settings not given are inferred "
        "from the G-code (line width, flow, speed, retraction, Cura's own density).",
    )
    p.add_argument("input", metavar="IN.gcode")
    p.add_argument("-o", "--output", metavar="OUT.gcode", help="output file (written atomically)")
    p.add_argument("--in-place", action="store_true", help="replace IN.gcode (atomically)")
    p.add_argument("--density", type=_percent, metavar="PCT", help="base infill density in %% (default: Cura's)")
    p.add_argument("--line-width", type=_positive, metavar="MM", help="infill line width (default: from the walls)")
    p.add_argument("--modifier", action="append", default=[], metavar="FILE.stl:PCT",
                   help="a density region from an STL (G-code coordinates, see --modifier-offset); repeatable; "
                   "PCT 0: no infill there (a Cura 0 %% infill mesh leaves no trace in the G-code: give it so)")
    p.add_argument("--modifier-offset", type=_offset, metavar="X,Y[,Z]",
                   help="shift modifier STLs into G-code coordinates (e.g. 110,110 for a model that CuraEngine "
                   "centred on a 220 mm bed; Z: a raft's lift, raft thickness + air gap - layer 0 Z overlap)")
    p.add_argument("--paint", action="append", default=[], metavar="MODEL.stl:FACES.json:PCT:DEPTH",
                   help="a density region painted on a model: the part of MODEL.stl within DEPTH mm of the "
                   "triangles FACES.json lists ({\"faces\": [i, ...]}, 0-based, in the STL's order); placed as "
                   "--modifier-offset places modifier STLs; repeatable")
    p.add_argument("--mesh", action="append", default=[], type=_named_percent, metavar="NAME:PCT",
                   help="density of a ;MESH: in the G-code (a Cura infill_mesh modifier, or a model); repeatable")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--layout", choices=("seamless", "paper"), default="seamless",
                   help="seamless: one triangulation across regions (default); paper: one per convex part")
    p.add_argument("--flow", type=_flow, metavar="PCT", help="extrusion relative to Cura's infill, 10-300 (default 100)")
    p.add_argument("--speed", type=_positive, metavar="MM_S", help="infill speed (default: Cura's)")
    p.add_argument("--relax", type=_steps, default=0, help="relaxation steps (default 0)")
    p.add_argument("--no-combing", action="store_true",
                   help="retract on a travel that leaves the part instead of going round inside it")
    p.add_argument("--verify", action="store_true", help="check the output against the input afterwards "
                   "(with --in-place: before it replaces the input)")
    p.add_argument("--keep-going", action="store_true",
                   help="write the output even when some layers fail (they keep Cura's infill)")
    p.add_argument("--stages", action="store_true",
                   help="print where the time went: parse, areas, patterns, routes, emit, estimate, ...")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress line or summary")
    p.set_defaults(func=_cmd_process)

    p = sub.add_parser("preview", help="top view of one layer as PNG, coloured by line type",
                       description="Draw one layer (walls, skin, infill, travel) into a PNG. Needs matplotlib.")
    p.add_argument("input", metavar="FILE.gcode")
    p.add_argument("--layer", type=int, required=True, metavar="N", help="the ;LAYER: number")
    p.add_argument("-o", "--output", metavar="layer.png")
    p.add_argument("--before", metavar="ORIGINAL.gcode", help="draw this file's layer beside it for comparison")
    p.add_argument("--occurrence", type=int, default=0, help="which layer N when numbers repeat (one-at-a-time)")
    p.add_argument("--window", type=_window, metavar="X0,Y0,X1,Y1", help="zoom to this part of the bed (mm)")
    p.add_argument("--modifier", action="append", default=[], metavar="FILE.stl:PCT",
                   help="draw this density region's outline at the layer (as given to process); repeatable")
    p.add_argument("--modifier-offset", type=_offset, metavar="X,Y[,Z]",
                   help="shift modifier STLs into G-code coordinates, as for process")
    p.set_defaults(func=_cmd_preview)

    p = sub.add_parser("demo", help="run the bundled demo (star with the paper's Figure 10 densities, H-bracket)",
                       description="Process bundled CuraEngine G-code; write G-code, layer PNGs and a summary.")
    p.add_argument("-o", "--output", default="delaunay-demo", help="output folder (default ./delaunay-demo)")
    p.add_argument("--reslice", action="store_true", help="slice the bundled STLs with CuraEngine first")
    p.set_defaults(func=_cmd_demo)

    for module in (".figures_cli", ".packaging"):
        try:
            mod = importlib.import_module(module, __package__)
        except ImportError:
            continue
        register = getattr(mod, "register_cli", None)
        if register is not None:
            register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
