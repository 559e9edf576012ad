"""Cura UI estimates from the processed G-code header (DelaunayInfill/cura/estimates.py, pure part)."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from DelaunayInfill.cura.estimates import (
    corrected_estimates,
    header_totals,
    needs_update,
    times_matching_total,
)

MARLIN = ";FLAVOR:Marlin\n;TIME:3351\n;Filament used: 2.67553m, 0.5m\n;Layer height: 0.2\n;MINX:76.5\n"
GRIFFIN = (
    ";START_OF_HEADER\n;HEADER_VERSION:0.1\n;FLAVOR:Griffin\n"
    ";EXTRUDER_TRAIN.0.MATERIAL.VOLUME_USED:1234.5\n;EXTRUDER_TRAIN.1.MATERIAL.VOLUME_USED:0\n"
    ";PRINT.TIME:4396\n;END_OF_HEADER\n"
)
VOLUMETRIC = ";FLAVOR:RepRap (Volumetric)\n;TIME:60\n;Filament used: 321.5mm3\n"

CURA_TIMES = {"inset_0": 600, "inset_x": 500, "skin": 400, "infill": 1500, "travel": 300, "retract": 51, "support": 0}


def test_header_totals_read_every_flavour():
    marlin = header_totals(MARLIN)
    assert marlin.time_s == 3351
    assert marlin.filament_m == [2.67553, 0.5]
    assert marlin.volumes_mm3([1.75])[0] == pytest.approx(2675.53 * math.pi * 0.875**2)
    griffin = header_totals(GRIFFIN)
    assert griffin.time_s == 4396
    assert griffin.volumes_mm3([2.85]) == [1234.5, 0.0]
    volumetric = header_totals(VOLUMETRIC)
    assert volumetric.volumes_mm3([1.75]) == [321.5]
    assert header_totals(";FLAVOR:Marlin\n").time_s is None


@given(st.floats(0, 20000))
@settings(max_examples=80, deadline=None)
def test_feature_times_sum_to_the_new_total(total):
    times = times_matching_total(CURA_TIMES, total)
    assert sum(times.values()) == pytest.approx(total, abs=1e-6)
    assert all(value >= 0 for value in times.values())
    if total >= sum(CURA_TIMES.values()) - CURA_TIMES["infill"]:
        # only the infill changed
        assert {k: v for k, v in times.items() if k != "infill"} == {
            k: v for k, v in CURA_TIMES.items() if k != "infill"
        }


def test_corrected_estimates_follow_the_processed_header():
    times, amounts = corrected_estimates(CURA_TIMES, [9999.0, 0.0], MARLIN, [1.75, 1.75])
    assert sum(times.values()) == pytest.approx(3351)
    assert times["inset_0"] == 600
    assert amounts[0] == pytest.approx(2675.53 * math.pi * 0.875**2)
    assert amounts[1] == pytest.approx(500 * math.pi * 0.875**2)
    assert corrected_estimates(CURA_TIMES, [1.0], ";FLAVOR:Marlin\n", [1.75]) is None


def test_needs_update_only_beyond_the_tolerance():
    assert not needs_update(3351, [100.0], 3352, [100.2])
    assert needs_update(3000, [100.0], 3351, [100.0])
    assert needs_update(3351, [100.0], 3351, [120.0])
    assert needs_update(None, [], 3351, [])
