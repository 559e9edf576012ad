"""Random everyday shapes for the engine tier: seeded CSG models with holes, pockets, bosses, slopes.

The corpus of ``everyday`` holds shapes chosen by hand; these are drawn at random (a seed gives the
same model and settings on every machine) from the features everyday prints combine: a block, a
cylinder or a rounded slab as the body; bosses standing on it or overhanging it; vertical holes
through it or blind from the top or the bottom, some narrower than Cura's infill line spacing;
horizontal holes (bridges and overhangs); a closed cavity; a slope cut off a corner; slots of 1-2 mm.
Each model comes with Cura settings drawn from the options people change (walls, pattern, skin
count and pattern, infill before walls, density).  They are checked as the corpus is
(``everyday.process_and_check``).

    python3 -m tests.engine.random_shapes --seeds 0-59 --out /tmp/random-shapes
    python3 -m tests.engine.random_shapes --seeds 0-11 --render docs/images   # random-shapes.png
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np
from manifold3d import Manifold

from .everyday import MODELS, SEGMENTS, EverydayCase, above_ground, block, cylinder

PATTERNS = ("grid", "triangles", "cubic", "gyroid", "lines", "trihexagon", "zigzag", "quarter_cubic")
SKIN_PATTERNS = ("lines", "concentric", "zigzag")
DENSITIES = (10, 15, 20, 30, 40)


def _body(rng: np.random.Generator) -> tuple[Manifold, float, float, float]:
    """The body: (solid, half width x, half width y, height), mm."""
    kind = rng.integers(3)
    sx, sy = rng.uniform(18, 48, 2)
    height = float(rng.uniform(5, 18))
    if kind == 0:
        solid = block(sx, sy, height)
    elif kind == 1:
        solid = cylinder(sx, height)
        sy = sx
    else:  # a slab with rounded corners: the hull of four cylinders
        r = float(rng.uniform(2, min(sx, sy) / 3))
        corners = [cylinder(2 * r, height, x=cx * (sx / 2 - r), y=cy * (sy / 2 - r))
                   for cx in (-1, 1) for cy in (-1, 1)]
        solid = Manifold.batch_hull(corners)
    return solid.rotate((0.0, 0.0, float(rng.uniform(0, 90)))), sx / 2, sy / 2, height


def random_model(seed: int) -> Manifold:
    """A random everyday solid (seeded), standing on z = 0, centred near X/Y = 0, mm."""
    rng = np.random.default_rng(seed)
    solid, hx, hy, height = _body(rng)
    reach = 0.8 * min(hx, hy)

    def spot():
        return rng.uniform(-reach, reach, 2)

    for _ in range(rng.integers(0, 3)):  # bosses: on top, or overhanging a side
        x, y = spot()
        tall = float(rng.uniform(3, 12))
        if rng.random() < 0.5:
            boss = cylinder(float(rng.uniform(4, 14)), tall, x=x, y=y, z=height)
        else:
            boss = block(*rng.uniform(3, 16, 2), tall, x=x, y=y, z=height).rotate((0.0, 0.0, float(rng.uniform(0, 90))))
        if rng.random() < 0.3:  # a shelf sticking out at mid height (overhang)
            boss = block(float(rng.uniform(8, 20)), float(rng.uniform(4, 10)), float(rng.uniform(2, 4)),
                         x=x + hx * 0.8, y=y, z=float(rng.uniform(2, height)))
        solid = solid + boss
    top = height + 12.0
    for _ in range(rng.integers(1, 5)):  # vertical holes: through, blind from the top or from the bottom
        x, y = spot()
        width = float(rng.choice([rng.uniform(1.0, 3.0), rng.uniform(3.0, 12.0)]))
        how = rng.integers(3)
        depth = float(rng.uniform(1.5, 0.8 * height))
        z, length = ((-1.0, top + 2.0), (height - depth, top), (-1.0, depth + 1.0))[how]
        if rng.random() < 0.5:
            cut = cylinder(width, length, x=x, y=y, z=z, segments=32)
        else:
            cut = block(width, float(rng.uniform(width, 3 * width)), length, x=x, y=y, z=z)
            cut = cut.rotate((0.0, 0.0, float(rng.uniform(0, 90))))
        solid = solid - cut
    if rng.random() < 0.5:  # a horizontal hole: bridges over it, overhangs round it
        d = float(rng.uniform(3, min(10.0, 0.7 * height)))
        z = float(rng.uniform(d / 2 + 1.0, max(d / 2 + 1.5, height - d / 2 - 1.0)))
        tube = Manifold.cylinder(4 * max(hx, hy), d / 2, d / 2, 32).rotate((90.0, 0.0, 0.0))
        solid = solid - tube.translate((float(spot()[0]), 2 * max(hx, hy), z)).rotate((0.0, 0.0, float(rng.uniform(0, 180))))
    if rng.random() < 0.3:  # a closed cavity
        r = float(rng.uniform(2, max(2.0, min(6.0, height / 3))))  # (a low body: a 2 mm cavity)
        x, y = spot() * 0.5
        solid = solid - Manifold.sphere(r, SEGMENTS).translate((x, y, height / 2))
    if rng.random() < 0.4:  # a slope cut off one side: keep n . p <= c, n tilted by `tilt` from vertical
        tilt, turn = math.radians(float(rng.uniform(20, 60))), float(rng.uniform(0, 2 * math.pi))
        normal = np.array([math.sin(tilt) * math.cos(turn), math.sin(tilt) * math.sin(turn), math.cos(tilt)])
        edge = float(rng.uniform(0.3, 0.9)) * min(hx, hy) * math.sin(tilt) + float(rng.uniform(0.4, 0.9)) * height * math.cos(tilt)
        solid = solid.trim_by_plane(tuple(-normal), -edge)
    if rng.random() < 0.3:  # a slot 1-2 mm wide (narrower than the infill's line spacing)
        x, y = spot()
        slot = block(float(rng.uniform(1.0, 2.0)), float(rng.uniform(8, 2 * reach)), top + 2.0, x=x, y=y, z=-1.0)
        solid = solid - slot.rotate((0.0, 0.0, float(rng.uniform(0, 180))))
    solid = above_ground(solid)
    # the largest piece only: a cut may leave a chip standing alone
    pieces = sorted(solid.decompose(), key=lambda m: -m.volume())
    return pieces[0] if pieces else solid


def random_settings(seed: int) -> tuple[dict, int]:
    """Cura settings (over the engine tier's defaults) and the density (%) drawn for `seed`."""
    rng = np.random.default_rng(10_000 + seed)
    settings = {
        "wall_line_count": int(rng.integers(1, 5)),
        "infill_pattern": str(rng.choice(PATTERNS)),
        "top_bottom_pattern": str(rng.choice(SKIN_PATTERNS)),
        "skin_outline_count": int(rng.integers(0, 2)),
        "infill_before_walls": bool(rng.random() < 0.5),
    }
    if rng.random() < 0.3:
        settings["top_layers"] = settings["bottom_layers"] = int(rng.integers(2, 7))
    return settings, int(rng.choice(DENSITIES))


def random_case(seed: int) -> tuple[EverydayCase, int]:
    """The everyday case of `seed` (its model registered in ``everyday.MODELS``) and its density."""
    name = f"random_{seed}"
    MODELS.setdefault(name, lambda seed=seed: random_model(seed))
    settings, density = random_settings(seed)
    return EverydayCase(name, ((name, (0.0, 0.0)),), settings, f"random shape {seed}"), density


def _seeds(text: str) -> list[int]:
    seeds = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds.extend(range(int(lo), int(hi or lo) + 1))
    return seeds


def sliced_or_none(cache, case: EverydayCase, density: float, engine: str, unsliced: list, seed: int):
    """`cache.get(case, density, engine)`, or None (and `seed` added to `unsliced`, a line printed) when
    CuraEngine cannot slice it: CuraEngine 5.0 fails an assertion in its combing on a few models (random
    shape 47, random regions 20), which is not the pass's to judge."""
    from DelaunayInfill.curaengine import CuraEngineError

    try:
        return cache.get(case, density, engine)
    except CuraEngineError as exc:
        unsliced.append(seed)
        print(f"{case.name}: CuraEngine {engine} cannot slice it: {str(exc).splitlines()[0][:200]}", flush=True)
        return None


def summary(failed: list, unsliced: list) -> int:
    """Print the run's last lines; the exit status (1: a seed failed)."""
    if unsliced:
        print(f"not sliced (CuraEngine failed): {unsliced}")
    print(f"failed: {failed}" if failed else "all passed")
    return 1 if failed else 0


def main(argv=None) -> int:
    from .everyday import REPORT_HEADER, EverydaySliceCache, process_and_check, report_row

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="0-19", help="seeds, e.g. 0-59 or 3,7,11 (default 0-19)")
    parser.add_argument("--engine", default="4.13", help="CuraEngine version (default 4.13)")
    parser.add_argument("--out", help="folder for the slices")
    parser.add_argument("--render", metavar="DIR", help="draw the seeds' models into DIR/random-shapes.png and stop")
    args = parser.parse_args(argv)
    if args.render:
        from .everyday import render

        names = [random_case(seed)[0].name for seed in _seeds(args.seeds)]
        print(render(args.render, names=names, file_name="random-shapes.png"))
        return 0
    if not args.out:
        parser.error("--out is required to slice")
    cache = EverydaySliceCache(args.out)
    print(REPORT_HEADER, flush=True)
    failed, unsliced = [], []
    for seed in _seeds(args.seeds):
        case, density = random_case(seed)
        done = sliced_or_none(cache, case, density, args.engine, unsliced, seed)
        if done is None:
            continue
        _, report, result = process_and_check(done)
        print(report_row(done, report, result), case.settings, flush=True)
        if not result.ok:
            failed.append(seed)
            print(result.report(), flush=True)
    return summary(failed, unsliced)


if __name__ == "__main__":
    sys.exit(main())
