"""Painting density regions in the real Cura 5.0 (Debian trixie, PyQt6, CuraEngine 5.0) under Xvfb.

The same session and the same checks as test_gui_paint.py (Cura 4.13), run in the Cura 5.0 of the
trixie chroot (scripts/cura5_chroot.sh): the Qt 6 paint section, a real mouse drag painting a box's
top faces at 60 %, 6 mm deep, undo, the set's row edits, the export the CLI reads, the saved G-code
measured (denser under the painted faces), the project saved and reopened with its painting.
"""

from __future__ import annotations

import pytest
from test_gui_paint import *  # noqa: F401,F403 - the same tests, on this module's session
from test_gui_paint import start_session


@pytest.fixture(scope="module")
def session(gui_artifacts):
    return start_session(gui_artifacts, version="5.0", name="cura5-paint")
