"""GUI tier: the real Cura 4.13 (test_gui_*.py) and the real Cura 5.0 of the trixie
chroot (test_gui5_*.py, the same tests on Cura 5.0 sessions) under Xvfb (see cura_runner.py).

Nothing here skips: if Cura, Xvfb or ImageMagick are missing and cannot be
installed (for 5.0: the chroot cannot be built), every GUI test fails with the reason.
"""

import os
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))  # tests/: the engine tier's independent checker (engine.gcode_check)

ARTIFACTS = HERE.parent.parent / "test-artifacts" / "gui"


def pytest_collection_modifyitems(items):
    for item in items:
        if Path(str(item.fspath)).resolve().parent == HERE:
            item.add_marker(pytest.mark.gui)


@pytest.fixture(scope="session")
def gui_artifacts() -> Path:
    """Where GUI runs keep their folders (profile, logs, G-code, screenshots)."""
    path = Path(os.environ.get("DELAUNAY_GUI_ARTIFACTS", ARTIFACTS))
    path.mkdir(parents=True, exist_ok=True)
    return path


@pytest.fixture(scope="session")
def gui_models(gui_artifacts) -> dict:
    """The project's test models as STL files (star.stl, cube.stl, ...)."""
    from DelaunayInfill import models

    return models.write_test_models(gui_artifacts / "models")
