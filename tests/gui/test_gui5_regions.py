"""Density regions in the real Cura 5.0 (Debian trixie, PyQt6, CuraEngine 5.0) under Xvfb.

The same session and the same checks as test_gui_regions.py (Cura 4.13), run in the
Cura 5.0 of the trixie chroot (scripts/cura5_chroot.sh): the tool's Qt 6 panel, a
region through the API and one by a real mouse click, panel edit, Add, delete,
undo/redo, a Per Model Settings modifier, density measured per region in the saved
G-code, Preview and the print estimates rebuilt from the processed G-code.
"""

from __future__ import annotations

import pytest
from test_gui_regions import *  # noqa: F401,F403 - the same tests, on this module's session
from test_gui_regions import start_large_font_session, start_session


@pytest.fixture(scope="module")
def session(gui_artifacts):
    return start_session(gui_artifacts, version="5.0", name="cura5-regions")


@pytest.fixture(scope="module")
def large_font_session(gui_artifacts):
    return start_large_font_session(gui_artifacts, version="5.0", name="cura5-regions-large-font")
