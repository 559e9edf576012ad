"""The .curapackage, `install-cura`, plugin.json and the Cura adapters' static properties.

The real proof that Cura loads the package is the GUI tier (tests/gui); these
check what can be checked without Cura.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from DelaunayInfill import packaging

REPO = Path(__file__).resolve().parent.parent
PREFIX = "files/plugins/DelaunayInfill/"


@pytest.fixture(scope="module")
def package(tmp_path_factory) -> Path:
    return packaging.build_package(tmp_path_factory.mktemp("dist"))


@pytest.fixture(scope="module")
def names(package) -> list[str]:
    with zipfile.ZipFile(package) as archive:
        return archive.namelist()


def _version_tuple(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in text.split("."))


def _loads_in(sdk: str, supported: list[str]) -> bool:
    """Uranium's rule: same major, plugin minor <= running minor."""
    running = _version_tuple(sdk)
    return any(_version_tuple(v)[0] == running[0] and _version_tuple(v)[1] <= running[1] for v in supported)


def test_package_name_and_opc_parts(package, names):
    assert package.name == f"DelaunayInfill-{json.loads((REPO / 'plugin.json').read_text())['version']}.curapackage"
    assert {"package.json", "[Content_Types].xml", "_rels/.rels"} <= set(names)
    with zipfile.ZipFile(package) as archive:
        rels = archive.read("_rels/.rels").decode()
        assert 'Target="/package.json"' in rels and "curapackage_metadata" in rels
        meta = json.loads(archive.read("package.json"))
    required = {"package_id", "display_name", "description", "package_type", "package_version", "sdk_version", "website"}
    assert required <= set(meta)
    assert {"author_id", "display_name", "website"} <= set(meta["author"])
    assert meta["package_id"] == "DelaunayInfill" and meta["package_type"] == "plugin"


def test_package_holds_exactly_the_plugin(names):
    files = [n[len(PREFIX):] for n in names if n.startswith(PREFIX)]
    assert set(n for n in names if not n.startswith(PREFIX)) == {"package.json", "[Content_Types].xml", "_rels/.rels"}
    for needed in ("plugin.json", "__init__.py", "DelaunayInfill/__init__.py", "DelaunayInfill/cura/extension.py",
                   "DelaunayInfill/cura/delaunay_infill.def.json", "DelaunayInfill/gcode/process.py"):
        assert needed in files, needed
    for name in files:
        top = name.split("/")[0]
        assert top in ("plugin.json", "__init__.py", "LICENSE", "DelaunayInfill", "qml"), name
        assert "__pycache__" not in name and not name.endswith(".pyc"), name
    for tool in ("cli.py", "curaengine.py", "figures.py", "packaging.py", "models.py", "gcode/demo.py"):
        assert f"DelaunayInfill/{tool}" not in files
    assert not any(n.startswith("DelaunayInfill/data/") for n in files)


def test_package_is_reproducible(tmp_path, package):
    again = packaging.build_package(tmp_path)
    assert again.read_bytes() == package.read_bytes()


def test_plugin_json_loads_in_cura_4_13_and_5(names):
    meta = json.loads((REPO / "plugin.json").read_text())
    supported = meta["supported_sdk_versions"]
    assert "api" not in meta  # a bare "api": 7 would also claim Cura 4.0-4.12
    for sdk in ("7.9.0", "8.0.0", "8.1.0", "8.5.0", "8.11.0"):  # Cura 4.13, 5.0, 5.1, 5.5, 5.11
        assert _loads_in(sdk, supported), sdk
    for sdk in ("7.8.0", "6.0.0", "9.0.0"):  # Cura 4.12, 4.x-era, a future major
        assert not _loads_in(sdk, supported), sdk


def test_packaged_engine_runs_on_its_own(tmp_path, package):
    with zipfile.ZipFile(package) as archive:
        archive.extractall(tmp_path)
    plugin = tmp_path / "files" / "plugins" / "DelaunayInfill"
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]);"
        "import DelaunayInfill, DelaunayInfill.gcode; from DelaunayInfill import process_gcode;"
        "from shapely.geometry import box;"
        "assert DelaunayInfill.__file__.startswith(sys.argv[1]), DelaunayInfill.__file__;"
        "r = DelaunayInfill.generate_infill(box(0, 0, 20, 20), 0.2, 0.4, seed=1);"
        "print(len(r.paths), round(r.density, 3))"
    )
    result = subprocess.run([sys.executable, "-c", code, str(plugin)], capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    count, density = result.stdout.split()
    assert int(count) > 0 and abs(float(density) - 0.2) < 0.03


def test_install_replaces_an_old_copy(tmp_path):
    plugins = tmp_path / "plugins"
    stale = plugins / "DelaunayInfill" / "DelaunayInfill" / "stale_module.py"
    stale.parent.mkdir(parents=True)
    stale.write_text("raise ImportError('old version')\n")
    target = packaging.install_plugin(plugins)
    assert target == plugins / "DelaunayInfill"
    assert (target / "plugin.json").read_bytes() == (REPO / "plugin.json").read_bytes()
    assert (target / "DelaunayInfill" / "cura" / "delaunay_infill.def.json").is_file()
    assert not stale.exists()
    assert sorted(p.name for p in plugins.iterdir()) == ["DelaunayInfill"]  # no staging leftovers


def test_install_finds_the_newest_cura(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    monkeypatch.setattr(sys, "platform", "linux")
    for version in ("4.13", "5.2", "5.11", "notaversion"):
        (tmp_path / "cura" / version).mkdir(parents=True)
    assert packaging.cura_data_dirs()[0] == tmp_path / "cura" / "5.11"
    target = packaging.install_plugin()
    assert target == tmp_path / "cura" / "5.11" / "plugins" / "DelaunayInfill"


def test_install_without_cura_is_a_clear_error(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "empty"))
    monkeypatch.setattr(sys, "platform", "linux")
    assert packaging.main(["install-cura"]) == 2
    assert "no Cura data folder found" in capsys.readouterr().err


def test_cli_subcommands(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "DelaunayInfill.cli", "package", "-o", str(tmp_path)], capture_output=True, text=True
    )
    if result.returncode != 0 and "invalid choice" in result.stderr:  # cli.py without register_cli yet
        result = subprocess.run([sys.executable, "-m", "DelaunayInfill.packaging", "package", "-o", str(tmp_path)],
                                capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert list(tmp_path.glob("DelaunayInfill-*.curapackage"))


def test_setting_definitions():
    definitions = json.loads((REPO / "DelaunayInfill" / "cura" / "delaunay_infill.def.json").read_text())
    main = definitions["delaunay_infill_enabled"]
    assert main["type"] == "bool" and main["default_value"] is False and main["settable_per_mesh"] is True
    children = main["children"]
    assert set(children) == {"delaunay_infill_seed", "delaunay_infill_layout"}
    assert set(children["delaunay_infill_layout"]["options"]) == {"seamless", "paper"}
    for key, body in {"delaunay_infill_enabled": main, **children}.items():
        assert body["label"] and body["description"] and "default_value" in body, key
        assert body["settable_per_mesh"] is True, key


# Cura's adapters may import Cura, Uranium and Qt, but never numpy/scipy/shapely at import time:
# Cura imports the plugin at start-up, and a missing package must not stop it from loading.
LIGHT_MODULES = ["__init__.py", *(f"DelaunayInfill/cura/{n}" for n in (
    "__init__.py", "extension.py", "job.py", "settings_injector.py", "snapshot.py", "adapter.py"))]


@pytest.mark.parametrize("relative", LIGHT_MODULES)
def test_cura_modules_do_no_heavy_imports_at_import_time(relative):
    tree = ast.parse((REPO / relative).read_text())
    heavy = {"numpy", "scipy", "shapely"}
    for node in tree.body:  # module level only; imports inside functions run later
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            names = [node.module or ""]
            # "from .. import x" inside DelaunayInfill/cura/ pulls in the engine (numpy, shapely)
            assert node.level < 2, f"{relative}: imports the engine at import time"
        else:
            continue
        for name in names:
            assert name.split(".")[0] not in heavy, f"{relative}: imports {name} at import time"
