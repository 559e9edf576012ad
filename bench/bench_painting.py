"""Speed of painted sections: ``PaintedRegion.at(z)`` per layer on the everyday dome (issue 14).

The everyday corpus's dome (``tests/engine/everyday.py``, radius 20 mm, 4222 triangles, built with
manifold3d, a test dependency) with its curved face painted (4096 triangles), at depths 1-4 mm.
Every layer height from 0.3 mm up in steps of ``--step`` mm is computed ``--repeats`` times with an
empty cache; the table gives the process CPU time (not wall time: the machine may be shared) of the
fastest of them, as the mean and the largest over the heights, in ms per layer.

    .venvs/current/bin/python bench/bench_painting.py [--step 1.0] [--repeats 3] [--depths 1,2,3,4]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
sys.path.insert(0, os.path.join(HERE, ".."))


def painted_dome():
    """(triangles (n, 3, 3) mm, painted face indices): the dome and its curved face."""
    import numpy as np
    from engine.everyday import dome, mesh_triangles

    tri = mesh_triangles(dome())
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    return tri, np.flatnonzero(normal[:, 2] > -0.5)


def layer_times(region, heights, repeats: int) -> list[float]:
    """The fastest of `repeats` CPU times (s) of ``region.at(z)`` per height, each with an empty cache."""
    out = []
    for z in heights:
        best = float("inf")
        for _ in range(repeats):
            region._cache.clear()
            start = time.process_time()
            region.at(float(z))
            best = min(best, time.process_time() - start)
        out.append(best)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--step", type=float, default=1.0, help="mm between the layer heights timed")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--depths", default="1,2,3,4", help="painted depths, mm")
    args = parser.parse_args(argv)
    import numpy as np
    import shapely

    from DelaunayInfill.painting import PaintedRegion

    tri, faces = painted_dome()
    heights = np.arange(0.3, 20.0, args.step)
    print(f"dome: {len(tri)} triangles, {len(faces)} painted; {len(heights)} heights; "
          f"numpy {np.__version__}, shapely {shapely.__version__}")
    print(f"{'depth':>6} {'mean ms/layer':>14} {'largest':>8}")
    for depth in (float(d) for d in args.depths.split(",")):
        times = layer_times(PaintedRegion(tri, faces, 0.6, depth), heights, args.repeats)
        print(f"{depth:6.1f} {1e3 * sum(times) / len(times):14.1f} {1e3 * max(times):8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
