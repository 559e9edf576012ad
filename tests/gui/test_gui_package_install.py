"""Installing the .curapackage the way a user does: drop it onto Cura, restart Cura.

Two sessions of the real Cura 4.13 on one profile: the first has no DelaunayInfill
and gets the package dropped on it; the second is the restart, in which Cura
unpacks the package into its plugins folder and loads the plugin.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from cura_profile import plugins_dir
from cura_runner import run_cura

from DelaunayInfill.packaging import build_package

STEPS = str(Path(__file__).with_name("plugin_steps.py"))


@pytest.fixture(scope="module")
def sessions(gui_artifacts):
    folder = gui_artifacts / "package-install"
    package = build_package(gui_artifacts / "package-install-dist")
    drop = {"actions": [{"do": "step", "file": STEPS, "function": "drop_package", "args": {"path": str(package)}}]}
    first = run_cura(drop, folder, install_plugin=False, fresh=True, timeout_s=180)
    restart = {"actions": [{"do": "inspect", "key": "delaunay_infill_enabled"}]}
    second = run_cura(restart, folder, install_plugin=False, fresh=False, timeout_s=180)
    return first, second


def test_dropped_package_is_accepted(sessions):
    first, _ = sessions
    assert first.ok, first.failure()
    assert not first.loaded("DelaunayInfill"), "the first session must run without the plugin"
    assert first.records()["dropped_package"] == "DelaunayInfill"


def test_after_the_restart_the_plugin_is_installed_and_loaded(sessions):
    _, second = sessions
    assert second.ok, second.failure()
    installed = plugins_dir(second.folder / "home") / "DelaunayInfill" / "DelaunayInfill"
    assert (installed / "plugin.json").is_file() and (installed / "DelaunayInfill" / "cura" / "extension.py").is_file()
    assert second.loaded("DelaunayInfill"), second.failure()
    assert not second.error_blocks("DelaunayInfill"), second.error_blocks("DelaunayInfill")[:3]
    info = second.records()["inspect:delaunay_infill_enabled"]
    assert info["defined"] and info["category"] == "infill" and info["visible"], info
