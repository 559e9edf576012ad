"""Everyday models (holes, domes, cones, lettering, bridges, thin features...) through the G-code pass.

Parametrized over the corpus cases of ``everyday.CASES`` x ``everyday.DENSITIES`` x the CuraEngines of
``engines.ENGINES``.  Each case is sliced twice (the sparse slice and its dense-lines reference, see
``everyday.slice_everyday``), the sparse G-code is processed through ``process_gcode`` on Cura's
in-memory form, and ``everyday_check.check_everyday`` judges the result against the reference (where
infill may go) and manifold3d's own sections of the model (where there is material).  A failing case
shows the checker's report; with ``-s`` every case prints its row of the table that
``python3 -m tests.engine.everyday --report OUT_DIR`` prints.

    python3 -m pytest tests/engine/test_everyday.py -q -c tests/pytest.ini
    python3 -m pytest tests/engine/test_everyday.py -q -c tests/pytest.ini -k "4.13"
"""

from __future__ import annotations

import pytest

from DelaunayInfill.curaengine import CuraEngineError

from .engines import ENGINES
from .everyday import CASES, DENSITIES, EverydaySlice, EverydaySliceCache, process_and_check, report_row

PARAMETERS = [
    pytest.param(case, density, version, id=f"{case.name}-{density}-{version}")
    for version in ENGINES for case in CASES for density in DENSITIES
]


@pytest.fixture(scope="session")
def everyday_slices(engine_info, tmp_path_factory) -> EverydaySliceCache:
    return EverydaySliceCache(tmp_path_factory.mktemp("everyday"))


def _slice(cache: EverydaySliceCache, case, density, version) -> EverydaySlice:
    try:
        return cache.get(case, density, version)
    except CuraEngineError as exc:
        pytest.fail(f"CuraEngine {version} cannot slice {case.name} at {density} %: {exc}", pytrace=False)


@pytest.mark.parametrize("case, density, version", PARAMETERS)
def test_everyday(everyday_slices, case, density, version):
    sliced = _slice(everyday_slices, case, density, version)
    _, report, result = process_and_check(sliced)
    print(f"\n[everyday] {report_row(sliced, report, result)}")
    if not result.ok:
        pytest.fail(
            f"{case.name} at {density} % with CuraEngine {version}: {case.exercises}\n"
            f"settings: {case.settings}; slices in {sliced.folder}\n{result.report()}",
            pytrace=False)


@pytest.mark.parametrize("case", [pytest.param(case, id=f"{case.name}-20-4.13") for case in CASES])
def test_everyday_everything_but_the_infill_is_cura_s(everyday_slices, case):
    """Check 1 of the matrix on the corpus (20 %, CuraEngine 4.13): every non-FILL line the same, move
    for move, and after every FILL block the machine state Cura's next line expects (E continuity)."""
    from . import gcode_check as gc

    sliced = _slice(everyday_slices, case, 20, "4.13")
    processed, _, _ = process_and_check(sliced)
    with open(sliced.cura_gcode, encoding="utf-8") as f:
        original = gc.parse_gcode(f.read())
    result = gc.check_unchanged(original, gc.parse_gcode(processed))
    assert result.ok, result.report()
