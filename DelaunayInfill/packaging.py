"""Build the .curapackage and install the plugin into a Cura plugins folder.

``delaunay-infill package`` writes ``dist/DelaunayInfill-<version>.curapackage``:
a zip (Open Packaging Conventions) with ``package.json``, ``[Content_Types].xml``,
``_rels/.rels`` and the plugin under ``files/plugins/DelaunayInfill/``.  Cura
(4.13 and 5.x) installs it when the file is dropped onto its window: it moves
``files/plugins`` to ``<data dir>/plugins/<package_id>/``.

``delaunay-infill install-cura`` copies the same files straight into the newest
Cura's plugins folder (or ``--dest``); Cura loads them at its next start.

No Cura import here: this runs from the command line.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

PLUGIN_ID = "DelaunayInfill"
#: What Cura needs at run time, relative to the plugin folder (the repository root).
PLUGIN_FILES = ("plugin.json", "__init__.py", "LICENSE")
PLUGIN_DIRS = ("DelaunayInfill", "qml")
#: Engine modules Cura never imports (command line, demo, test and figure tools) and build leftovers.
EXCLUDED_PARTS = {"__pycache__", "data", ".pytest_cache", ".ruff_cache"}
EXCLUDED_FILES = {
    f"DelaunayInfill/{name}"
    for name in ("cli.py", "curaengine.py", "figures.py", "packaging.py", "models.py",
                 "gcode/demo.py", "gcode/preview.py", "gcode/verify.py")
}
EXCLUDED_SUFFIXES = (".pyc", ".pyo", ".qmlc", ".orig", ".rej", "~")

CONTENT_TYPES_XML = """<?xml version="1.0" encoding="UTF-8"?>
<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">
  <Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>
  <Default Extension="json" ContentType="application/json"/>
  <Default Extension="py" ContentType="text/x-python"/>
  <Default Extension="qml" ContentType="text/plain"/>
  <Default Extension="svg" ContentType="image/svg+xml"/>
  <Default Extension="png" ContentType="image/png"/>
</Types>
"""
RELS_XML = """<?xml version="1.0" encoding="UTF-8"?>
<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">
  <Relationship Id="rel0" Target="/package.json" Type="http://schemas.ultimaker.org/package/2018/relationships/curapackage_metadata"/>
</Relationships>
"""


class PackagingError(Exception):
    """A clear, user-facing reason why packaging or installing failed."""


def plugin_root() -> Path:
    """The plugin folder: the repository root holding plugin.json."""
    root = Path(__file__).resolve().parent.parent
    if not (root / "plugin.json").is_file():
        raise PackagingError(
            f"{root} has no plugin.json: run this from a source checkout of DelaunayInfill "
            "(an installed wheel does not carry the Cura plugin files)"
        )
    return root


def read_plugin_json(root: Path) -> dict:
    try:
        meta = json.loads((root / "plugin.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise PackagingError(f"cannot read {root / 'plugin.json'}: {error}") from error
    for key in ("name", "version", "supported_sdk_versions"):
        if key not in meta:
            raise PackagingError(f"plugin.json has no {key!r}")
    return meta


def _included(relative: Path) -> bool:
    if any(part in EXCLUDED_PARTS or part.startswith(".") for part in relative.parts):
        return False
    if relative.name.endswith(EXCLUDED_SUFFIXES):
        return False
    return relative.as_posix() not in EXCLUDED_FILES


def plugin_files(root: Path) -> list[Path]:
    """Files of the plugin, relative to `root`, sorted (what the package holds)."""
    files = [Path(name) for name in PLUGIN_FILES if (root / name).is_file()]
    for directory in PLUGIN_DIRS:
        base = root / directory
        if not base.is_dir():
            continue
        for path in sorted(base.rglob("*")):
            relative = path.relative_to(root)
            if path.is_file() and _included(relative):
                files.append(relative)
    return sorted(files)


def package_json(meta: dict) -> dict:
    """The marketplace metadata Cura reads from the package.

    ``sdk_version`` is the oldest SDK the plugin supports; whether Cura loads
    the plugin is decided by plugin.json's ``supported_sdk_versions``.
    """
    sdks = sorted(meta["supported_sdk_versions"], key=lambda v: tuple(int(x) for x in re.findall(r"\d+", v)))
    return {
        "package_id": PLUGIN_ID,
        "package_type": "plugin",
        "display_name": meta["name"],
        "description": meta.get("description", ""),
        "package_version": meta["version"],
        "sdk_version": int(sdks[0].split(".")[0]),  # marketplace convention: the major as an int
        "sdk_version_semver": sdks[0],
        "supported_sdk_versions": sdks,
        "website": meta.get("website", "https://github.com/DelaunayInfill/DelaunayInfill"),
        "author": {
            "author_id": "DelaunayInfill",
            "display_name": meta.get("author", "DelaunayInfill developers"),
            "website": meta.get("website", "https://github.com/DelaunayInfill/DelaunayInfill"),
        },
        "tags": ["infill", "post-processing", "variable density", "delaunay"],
    }


def _atomic_zip(path: Path, entries) -> None:
    """Write a zip of (archive name, bytes) entries to `path` atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, temp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(temp, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            for name, data in entries:
                info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))  # reproducible bytes
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                archive.writestr(info, data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temp, 0o666 & ~umask)  # mkstemp makes 0600: give the package the mode a new file gets
        os.replace(temp, path)
    except BaseException:
        os.unlink(temp)
        raise


def build_package(out_dir: Path | str = "dist", root: Path | None = None) -> Path:
    """Write ``<out_dir>/DelaunayInfill-<version>.curapackage``.

    Returns
    -------
    Path
        The package written.
    """
    root = Path(root) if root is not None else plugin_root()
    meta = read_plugin_json(root)
    if not (root / "DelaunayInfill" / "cura" / "delaunay_infill.def.json").is_file():
        raise PackagingError("DelaunayInfill/cura/delaunay_infill.def.json is missing")
    entries = [
        ("[Content_Types].xml", CONTENT_TYPES_XML.encode()),
        ("_rels/.rels", RELS_XML.encode()),
        ("package.json", json.dumps(package_json(meta), indent=2).encode()),
    ]
    prefix = f"files/plugins/{PLUGIN_ID}/"
    for relative in plugin_files(root):
        entries.append((prefix + relative.as_posix(), (root / relative).read_bytes()))
    out = Path(out_dir) / f"{PLUGIN_ID}-{meta['version']}.curapackage"
    _atomic_zip(out, entries)
    return out


def cura_data_dirs() -> list[Path]:
    """Existing Cura data folders (``.../cura/<version>``), newest version first."""
    home = Path.home()
    bases = []
    if sys.platform.startswith("win"):
        if os.environ.get("APPDATA"):
            bases.append(Path(os.environ["APPDATA"]) / "cura")
    elif sys.platform == "darwin":
        bases.append(home / "Library" / "Application Support" / "cura")
    else:
        bases.append(Path(os.environ.get("XDG_DATA_HOME") or home / ".local" / "share") / "cura")
    found = []
    for base in bases:
        if not base.is_dir():
            continue
        for child in base.iterdir():
            match = re.fullmatch(r"(\d+)\.(\d+)(?:\.(\d+))?", child.name)
            if match and child.is_dir():
                found.append((tuple(int(g or 0) for g in match.groups()), child))
    return [path for _, path in sorted(found, reverse=True)]


def install_plugin(dest: Path | str | None = None, root: Path | None = None) -> Path:
    """Copy the plugin into a Cura plugins folder, replacing an older copy.

    Parameters
    ----------
    dest : path or None
        The plugins folder (the plugin goes to ``dest/DelaunayInfill``).
        None: ``plugins`` in the newest Cura data folder found.

    Returns
    -------
    Path
        The installed plugin folder.
    """
    root = Path(root) if root is not None else plugin_root()
    read_plugin_json(root)
    if dest is None:
        data_dirs = cura_data_dirs()
        if not data_dirs:
            raise PackagingError(
                "no Cura data folder found (start Cura once, or give the plugins folder with --dest)"
            )
        dest = data_dirs[0] / "plugins"
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    target = dest / PLUGIN_ID
    staging = Path(tempfile.mkdtemp(prefix=f".{PLUGIN_ID}-", dir=dest))
    try:
        for relative in plugin_files(root):
            (staging / relative).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(root / relative, staging / relative)
        old = None
        if target.exists():
            old = dest / f".{PLUGIN_ID}-old-{os.getpid()}"
            os.replace(target, old)
        os.replace(staging, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return target


def _cmd_package(args) -> int:
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        print(f"error: {out} is a file: give a folder with -o", file=sys.stderr)
        return 2
    try:
        path = build_package(args.output)
    except PackagingError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except OSError as error:  # the OS's words, without Python's [Errno n] prefix
        print(f"error: cannot write the package into {out}: {error.strerror or error}", file=sys.stderr)
        return 2
    with zipfile.ZipFile(path) as archive:
        count = sum(1 for name in archive.namelist() if name.startswith("files/"))
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB, {count} plugin files)")
    print("Install: drag the file onto Cura's window and restart Cura.")
    return 0


def _cmd_install(args) -> int:
    try:
        target = install_plugin(args.dest)
    except (PackagingError, OSError) as error:
        print(f"delaunay-infill install-cura: {error}", file=sys.stderr)
        return 2
    print(f"installed into {target}")
    print('Restart Cura, then turn on "Delaunay Variable Infill" in the Infill settings.')
    return 0


def register_cli(subparsers) -> None:
    """Add the ``package`` and ``install-cura`` subcommands to the CLI."""
    package = subparsers.add_parser(
        "package",
        help="build dist/DelaunayInfill-<version>.curapackage (drag it onto Cura to install)",
        description="Build the Cura package of the plugin.",
    )
    package.add_argument("-o", "--output", default="dist", help="output folder (default: dist)")
    package.set_defaults(func=_cmd_package)
    install = subparsers.add_parser(
        "install-cura",
        help="copy the plugin into the newest Cura's plugins folder",
        description="Copy the plugin into a Cura plugins folder; Cura loads it at its next start.",
    )
    install.add_argument("--dest", help="plugins folder to install into (default: the newest Cura's)")
    install.set_defaults(func=_cmd_install)


def main(argv=None) -> int:
    """Standalone entry point (``python -m DelaunayInfill.packaging``)."""
    parser = argparse.ArgumentParser(prog="delaunay-infill")
    register_cli(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
