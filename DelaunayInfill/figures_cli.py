"""``delaunay-infill figures``: the command line of `figures` (light: numpy, shapely and the pattern
engine load only when the command runs, so ``delaunay-infill --help`` stays quick)."""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["register_cli"]


def register_cli(subparsers) -> None:
    """Add ``figures`` to the ``delaunay-infill`` command line."""
    p = subparsers.add_parser(
        "figures", help="redraw the paper's Figures 2 and 10 with measured densities",
        description="Redraw the paper's Figure 2 (10, 40, 80 %% on a square) and Figure 10 (the star's six "
        "regions, both layouts) with the densities measured, and print the calibration tables as markdown.")
    p.add_argument("-o", "--out", default="figures", help="output folder, made when missing (default ./figures)")
    p.add_argument("--table", default=None, help="markdown tables file (default OUT/figures.md)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the patterns (default 0)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        print(f"error: {out} is a file: give a folder with -o", file=sys.stderr)
        return 2
    table = Path(args.table) if args.table else out / "figures.md"
    if not table.parent.is_dir() and table.parent != out:
        print(f"error: the folder {table.parent} does not exist", file=sys.stderr)
        return 2
    from .figures import write_figures

    try:
        text = write_figures(out, seed=args.seed, table=table)
    except OSError as exc:
        print(f"error: cannot write into {out}: {exc.strerror}", file=sys.stderr)
        return 2
    sys.stdout.write(text)
    for name in (out / "figure2.png", out / "figure10.png", table):
        print(f"wrote {name}", file=sys.stderr)
    return 0
