"""Random everyday shapes (``random_shapes``) through the G-code pass, checked as the corpus is.

Each seed draws a model (holes, pockets, bosses, overhangs, slopes, slots) and its Cura settings and
density; both engines slice it, ``process_gcode`` replaces the infill, and
``everyday_check.check_everyday`` judges it: no new infill outside Cura's infill area, in mid-air or
on skin, Cura's infill places covered, every other line Cura's.

    python3 -m pytest tests/engine/test_random_shapes.py -q -c tests/pytest.ini
    python3 -m tests.engine.random_shapes --seeds 0-59 --out /tmp/random-shapes   # more seeds, a table
"""

from __future__ import annotations

import pytest

from DelaunayInfill.curaengine import CuraEngineError

from .engines import ENGINES
from .everyday import EverydaySliceCache, process_and_check, report_row
from .random_shapes import random_case

SEEDS = range(10)


@pytest.fixture(scope="module")
def random_slices(engine_info, tmp_path_factory) -> EverydaySliceCache:
    return EverydaySliceCache(tmp_path_factory.mktemp("random-shapes"))


@pytest.mark.parametrize("version", ENGINES)
@pytest.mark.parametrize("seed", SEEDS)
def test_random_shape(random_slices, seed, version):
    case, density = random_case(seed)
    try:
        sliced = random_slices.get(case, density, version)
    except CuraEngineError as exc:
        pytest.fail(f"CuraEngine {version} cannot slice random shape {seed}: {exc}", pytrace=False)
    _, report, result = process_and_check(sliced)
    print(f"\n[random] {report_row(sliced, report, result)} {case.settings}")
    if not result.ok:
        pytest.fail(f"random shape {seed} at {density} % with CuraEngine {version}, settings {case.settings}; "
                    f"slices in {sliced.folder}\n{result.report()}", pytrace=False)


def test_random_shapes_are_the_same_on_every_run():
    """A seed is one model and one set of settings: a failure reproduces."""
    from .random_shapes import random_model, random_settings

    first, again = random_model(3), random_model(3)
    assert first.volume() == pytest.approx(again.volume()) and first.volume() > 100.0
    assert random_settings(3) == random_settings(3)
    assert random_model(4).volume() != pytest.approx(first.volume())
