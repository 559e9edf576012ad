"""Resolve Cura's setting formulas and slice with the CuraEngine command line.

``CuraEngine slice -j fdmprinter.def.json`` reads only each setting's
``default_value``: it never evaluates the definitions' Python ``value``
formulas.  ``-s infill_sparse_density=50`` alone therefore changes nothing
(the engine prints with ``infill_line_distance``), and the same holds for
``wall_line_count``, ``top_layers``, ``infill_sparse_thickness``, speeds,
temperatures...  This module does what Cura's front end does before it
starts the engine: it merges a machine definition's inheritance chain with
its extruder definition, evaluates every formula with the user's overrides
on top, evaluates per-mesh overrides together with every setting that
depends on them, and passes the complete result to the engine.

One extruder definition per machine: with ``machine_extruder_count`` above 1
every extruder gets the first one's values (a mesh picks its extruder with a
per-mesh ``extruder_nr``); quality, material and variant profiles are
not read (give their values as user settings).  Used by the engine-tier
tests, the G-code benchmark and ``delaunay-infill demo --reslice``.

Example
-------
>>> result = slice_models([("star.stl", {})], {"infill_sparse_density": 20}, "star.gcode")
>>> result.seconds  # wall time of the CuraEngine process
"""

from __future__ import annotations

import datetime
import json
import math
import os
import re
import shutil
import subprocess
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

__all__ = [
    "DEFAULT_SETTINGS",
    "CuraEngineError",
    "Definitions",
    "SettingStack",
    "SliceResult",
    "find_curaengine",
    "find_resources",
    "infill_modifier_settings",
    "engine_arguments",
    "mesh_groups",
    "resolve_settings",
    "slice_models",
]

#: Settings applied under the user's own: 0.4 mm nozzle, 0.2 mm layers,
#: 1.75 mm filament, 20 % grid, 2 walls, a skirt, a 220 x 220 x 250 mm bed
#: whose origin is a corner (so model (0, 0) is printed at (110, 110)).
DEFAULT_SETTINGS: dict[str, object] = {
    "machine_width": 220,
    "machine_depth": 220,
    "machine_height": 250,
    "machine_center_is_zero": False,
    "machine_heated_bed": True,
    "machine_gcode_flavor": "RepRap (Marlin/Sprinter)",
    "machine_nozzle_size": 0.4,
    "material_diameter": 1.75,
    "layer_height": 0.2,
    "layer_height_0": 0.2,
    "infill_sparse_density": 20,
    "infill_pattern": "grid",
    "wall_thickness": 0.8,
    "top_bottom_thickness": 0.8,
    "material_print_temperature": 200,
    "material_bed_temperature": 60,
    "adhesion_type": "skirt",
    "speed_print": 50,
    "retraction_amount": 5,
}

_RESOURCE_DIRS = ("/usr/share/cura/resources", "/usr/local/share/cura/resources")


class CuraEngineError(RuntimeError):
    """CuraEngine or Cura's definitions are missing, or a slice failed."""


# --------------------------------------------------------------------------- locating things


def find_resources(resources: str | os.PathLike | None = None) -> str:
    """Cura's resources folder (holding ``definitions/`` and ``extruders/``).

    Looks at `resources`, then ``$CURA_RESOURCES``, then the Debian/Ubuntu
    install locations.

    Raises
    ------
    CuraEngineError
        When no folder holds ``definitions/fdmprinter.def.json``.
    """
    candidates = [resources, os.environ.get("CURA_RESOURCES"), *_RESOURCE_DIRS]
    for folder in candidates:
        if folder and os.path.isfile(os.path.join(folder, "definitions", "fdmprinter.def.json")):
            return os.fspath(folder)
    raise CuraEngineError(
        "Cura's setting definitions were not found (looked in "
        + ", ".join(str(c) for c in candidates if c)
        + "). Install them with `apt-get install cura` or point $CURA_RESOURCES at a Cura resources folder."
    )


def find_curaengine(engine: str | os.PathLike | None = None) -> str:
    """Path of the CuraEngine executable (`engine`, ``$CURAENGINE`` or ``CuraEngine`` on PATH).

    Raises
    ------
    CuraEngineError
        When it cannot be found.
    """
    name = os.fspath(engine or os.environ.get("CURAENGINE") or "CuraEngine")
    path = shutil.which(name)
    if path is None:
        raise CuraEngineError(
            f"CuraEngine not found ({name!r} is not an executable on PATH). "
            "Install it with `apt-get install cura-engine` or set $CURAENGINE."
        )
    return path


def setup_problem() -> str | None:
    """Why CuraEngine cannot slice here (no executable, no Cura resources), or None when it can."""
    try:
        find_curaengine()
        find_resources()
    except CuraEngineError as exc:
        return str(exc)
    return None


# --------------------------------------------------------------------------- definitions


class Definitions:
    """The merged setting properties of one machine and its first extruder.

    Parameters
    ----------
    printer : str
        Machine definition id (``"fdmprinter"``, ``"creality_ender3"``...) or a
        path to a ``*.def.json``.
    resources : path-like, optional
        Cura resources folder; see :func:`find_resources`.

    Attributes
    ----------
    properties : dict
        Setting key -> merged property dict (``type``, ``default_value``,
        ``value``, ``resolve``...), later definitions in the chain winning.
    keys : list of str
        Setting keys in definition order.
    metadata : dict
        Merged metadata of the machine chain.
    fdmprinter_path : str
        The path passed to the engine with ``-j``.
    """

    def __init__(self, printer: str = "fdmprinter", resources: str | os.PathLike | None = None):
        self.resources = find_resources(resources)
        self.folders = [os.path.join(self.resources, "definitions"), os.path.join(self.resources, "extruders")]
        self.properties: dict[str, dict] = {}
        self.keys: list[str] = []
        self.metadata: dict = {}
        for document in self._chain(printer):
            self.metadata.update(document.get("metadata", {}))
            self._merge(document)
        extruder = self.metadata.get("machine_extruder_trains", {}).get("0", "fdmextruder")
        # One extruder: the extruder definition's values win for the keys it
        # defines, as they do in Cura's extruder stack.
        for document in self._chain(extruder):
            self._merge(document)
        self.extruder_id = extruder
        self.fdmprinter_path = self._path("fdmprinter")
        self._dependents: dict[str, set[str]] | None = None

    def _path(self, name: str) -> str:
        if name.endswith(".def.json") and os.path.isfile(name):
            return name
        for folder in self.folders:
            path = os.path.join(folder, f"{name}.def.json")
            if os.path.isfile(path):
                return path
        raise CuraEngineError(f"no Cura definition named {name!r} in {', '.join(self.folders)}")

    def _chain(self, name: str) -> list[dict]:
        """Definition documents from the root (fdmprinter) down to `name`."""
        documents = []
        seen = set()
        while name:
            if name in seen:
                raise CuraEngineError(f"definition inheritance loop at {name!r}")
            seen.add(name)
            with open(self._path(name), encoding="utf-8") as f:
                document = json.load(f)
            documents.append(document)
            name = document.get("inherits")
        return documents[::-1]

    def _merge(self, document: dict) -> None:
        stack = [document.get("settings", {})]
        while stack:
            for key, props in stack.pop(0).items():
                if props.get("type") != "category":
                    self._update(key, props)
                if props.get("children"):
                    stack.insert(0, props["children"])
        for key, props in document.get("overrides", {}).items():
            self._update(key, props)

    def _update(self, key: str, props: dict) -> None:
        if key not in self.properties:
            self.properties[key] = {}
            self.keys.append(key)
        self.properties[key].update({k: v for k, v in props.items() if k != "children"})

    def type_of(self, key: str) -> str:
        return self.properties[key].get("type", "str")

    def parse(self, key: str, value):
        """Convert a user value (often a string from a command line) to the setting's type.

        Strings starting with ``=`` are kept: they are formulas, as Cura stores them.
        """
        if key not in self.properties:
            raise KeyError(f"unknown Cura setting {key!r}")
        if not isinstance(value, str) or value.startswith("="):
            return value
        kind = self.type_of(key)
        text = value.strip()
        if kind == "bool":
            return text.lower() in ("1", "true", "yes", "on")
        if kind == "int":
            return int(round(float(text)))
        if kind == "float":
            return float(text)
        if kind in ("polygon", "polygons"):
            return json.loads(text)
        return value

    def dependents(self, keys) -> set[str]:
        """`keys` plus every setting whose ``value`` formula depends on them, transitively."""
        if self._dependents is None:
            graph: dict[str, set[str]] = {}
            for key, props in self.properties.items():
                formula = props.get("value")
                if isinstance(formula, str):
                    for name in _formula_names(formula):
                        graph.setdefault(name, set()).add(key)
            self._dependents = graph
        found = set(keys)
        todo = list(found)
        while todo:
            for key in self._dependents.get(todo.pop(), ()):
                if key not in found:
                    found.add(key)
                    todo.append(key)
        return found


_DEFINITIONS_CACHE: dict[tuple, Definitions] = {}


def _cached_definitions(printer: str, resources: str) -> Definitions:
    """Definitions are read-only once loaded; reading fdmprinter's 300 KB of JSON takes a while."""
    key = (printer, resources, os.path.getmtime(os.path.join(resources, "definitions", "fdmprinter.def.json")))
    if key not in _DEFINITIONS_CACHE:
        _DEFINITIONS_CACHE[key] = Definitions(printer, resources)
    return _DEFINITIONS_CACHE[key]


_CODE_CACHE: dict[str, object] = {}


def _compiled(formula: str):
    code = _CODE_CACHE.get(formula)
    if code is None:
        code = _CODE_CACHE[formula] = compile(formula.strip(), "<cura setting formula>", "eval")
    return code


def _code_names(code) -> set[str]:
    """Every global name a code object (and its nested comprehensions) reads."""
    names = set(code.co_names)
    for const in code.co_consts:
        if hasattr(const, "co_names"):
            names |= _code_names(const)
    return names


def _formula_names(formula: str) -> set[str]:
    try:
        return _code_names(_compiled(formula))
    except SyntaxError:
        return set()


# --------------------------------------------------------------------------- evaluation


class SettingStack:
    """Settings of one machine as a Cura container stack sees them.

    Lookup order: the user's value (a ``"=formula"`` string is evaluated),
    the definition's ``value`` formula, its ``default_value``.

    Parameters
    ----------
    definitions : Definitions
    user : mapping
        The user's settings (already typed, or strings parsed by
        :meth:`Definitions.parse`).
    parent : SettingStack, optional
        The global stack, for a per-mesh stack: ``resolveOrValue`` and
        ``extruderValue`` read from it, as in Cura.
    """

    def __init__(self, definitions: Definitions, user: Mapping | None = None, parent: SettingStack | None = None):
        self.definitions = definitions
        self.user = {key: definitions.parse(key, value) for key, value in (user or {}).items()}
        self.parent = parent
        self._cache: dict[str, object] = {}
        self._evaluating: set[str] = set()
        self.warnings: list[str] = []

    def _functions(self) -> dict:
        root = self.parent or self
        return {
            "math": math,
            "resolveOrValue": root.resolved,
            "extruderValue": lambda extruder, key: root.value(key),
            "extruderValues": lambda key: [root.value(key)],
            "defaultExtruderPosition": lambda: "0",
            "anyExtruderWithMaterial": lambda key: "0",
            "anyExtruderNrWithOrDefault": lambda key: root.value(key),
            "valueFromContainer": lambda key, index=0: root.value(key),
            "extruderValueFromContainer": lambda extruder, key, index=0: root.value(key),
        }

    def evaluate(self, formula: str):
        """Evaluate a setting formula in this stack."""
        code = _compiled(formula)
        scope = self._functions()
        for name in _code_names(code):
            if name in self.definitions.properties and name not in scope:
                scope[name] = self.value(name)
        scope["__builtins__"] = __builtins__
        return eval(code, scope)  # noqa: S307 - Cura's own definitions, evaluated as Cura does

    def _typed(self, key: str, value):
        kind = self.definitions.type_of(key)
        try:
            if kind == "int" and not isinstance(value, bool):
                return int(round(float(value)))
            if kind == "float":
                return float(value)
            if kind == "bool":
                return bool(value)
            if kind in ("extruder", "optional_extruder"):
                return str(int(float(value)))
        except (TypeError, ValueError):
            pass
        return value

    def value(self, key: str):
        """The setting's value (what an extruder stack would give)."""
        if key in self._cache:
            return self._cache[key]
        props = self.definitions.properties[key]
        user = self.user.get(key)
        if key in self.user and not (isinstance(user, str) and user.startswith("=")):
            result = user
        else:
            formula = user[1:] if key in self.user else props.get("value")
            result = props.get("default_value")
            if isinstance(formula, str):
                if key in self._evaluating:  # a formula cycle: fall back like Cura does
                    return result
                self._evaluating.add(key)
                try:
                    result = self.evaluate(formula)
                except Exception as exc:  # Cura also tolerates broken formulas
                    self.warnings.append(f"{key}: formula {formula!r} failed ({exc}); using default")
                finally:
                    self._evaluating.discard(key)
            elif formula is not None:
                result = formula
        result = self._typed(key, result)
        self._cache[key] = result
        return result

    def resolved(self, key: str):
        """The global stack's view: a ``resolve`` formula wins unless the user set the key."""
        props = self.definitions.properties[key]
        if key not in self.user and isinstance(props.get("resolve"), str):
            try:
                return self._typed(key, self.evaluate(props["resolve"]))
            except Exception as exc:
                self.warnings.append(f"{key}: resolve formula failed ({exc})")
        return self.value(key)


def _engine_text(value) -> str:
    """A setting value as the engine's ``-s key=value`` text."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if value.is_integer() and abs(value) < 1e15:
            return str(int(value))
        return repr(value)
    if isinstance(value, (list, tuple, dict)):
        return json.dumps(value)
    return str(value)


_GCODE_FIELD = re.compile(r"\{\s*([A-Za-z_]\w*)\s*(?:,\s*-?\d+\s*)?\}")


def _expand_start_end_gcode(text: str, stack: SettingStack) -> str:
    """Replace ``{setting}`` fields of start/end G-code, as Cura's front end does."""
    now = datetime.datetime.now()
    extra = {
        "print_bed_temperature": lambda: stack.value("material_bed_temperature"),
        "print_temperature": lambda: stack.value("material_print_temperature"),
        "travel_speed": lambda: stack.value("speed_travel"),
        "initial_extruder_nr": lambda: 0,
        "date": lambda: now.strftime("%d-%m-%Y"),
        "time": lambda: now.strftime("%H:%M:%S"),
        "day": lambda: now.strftime("%a"),
    }

    def field_value(match):
        key = match.group(1)
        if key in stack.definitions.properties:
            return _engine_text(stack.resolved(key))
        if key in extra:
            return _engine_text(extra[key]())
        return match.group(0)

    return _GCODE_FIELD.sub(field_value, text)


@dataclass
class ResolvedSettings:
    """Everything the engine needs for one slice.

    Attributes
    ----------
    global_values, extruder_values : dict
        Setting key -> typed value for the global stack and extruder 0.
    meshes : list of (str, dict)
        Model path and its per-mesh values (overridden keys and their dependents).
    definitions : Definitions
    """

    global_values: dict
    extruder_values: dict
    meshes: list
    definitions: Definitions
    warnings: list = field(default_factory=list)


def resolve_settings(
    settings: Mapping | None = None,
    models: Sequence = (),
    *,
    printer: str = "fdmprinter",
    resources: str | os.PathLike | None = None,
    defaults: Mapping | None = None,
    definitions: Definitions | None = None,
) -> ResolvedSettings:
    """Evaluate all settings for a slice.

    Parameters
    ----------
    settings : mapping
        The user's settings (key -> value or ``"=formula"``), over `defaults`.
    models : sequence of (path, mapping)
        Models and their per-mesh settings.
    printer : str
        Machine definition id or path.
    defaults : mapping, optional
        Settings under the user's; :data:`DEFAULT_SETTINGS` when None.
    """
    definitions = definitions or _cached_definitions(printer, find_resources(resources))
    user = {**(DEFAULT_SETTINGS if defaults is None else defaults), **(settings or {})}
    unknown = sorted(k for k in user if k not in definitions.properties)
    if unknown:
        raise CuraEngineError(f"unknown Cura setting(s): {', '.join(unknown)}")
    stack = SettingStack(definitions, user)
    global_values = {}
    for key in definitions.keys:
        value = stack.resolved(key)
        if key in ("machine_start_gcode", "machine_end_gcode") and isinstance(value, str):
            value = _expand_start_end_gcode(value, stack)
        global_values[key] = value
    extruder_values = {key: stack.value(key) for key in definitions.keys}
    for key in ("machine_start_gcode", "machine_end_gcode"):
        if key in global_values:
            extruder_values[key] = global_values[key]
    meshes = []
    warnings = list(stack.warnings)
    for path, per_mesh in models:
        per_mesh = dict(per_mesh or {})
        unknown = sorted(k for k in per_mesh if k not in definitions.properties)
        if unknown:
            raise CuraEngineError(f"unknown per-mesh Cura setting(s) for {path}: {', '.join(unknown)}")
        mesh_stack = SettingStack(definitions, {**user, **per_mesh}, parent=stack)
        keys = definitions.dependents(per_mesh)
        meshes.append((os.fspath(path), {k: mesh_stack.value(k) for k in definitions.keys if k in keys}))
        warnings += mesh_stack.warnings
    return ResolvedSettings(global_values, extruder_values, meshes, definitions, warnings)


def infill_modifier_settings(density_percent: float, **extra) -> dict:
    """Per-mesh settings of an infill-density modifier, as Cura's per-model tool makes it.

    An ``infill_mesh`` with its own ``infill_sparse_density`` and no walls or
    skin of its own (``wall_thickness = top_bottom_thickness = 0``).
    """
    return {
        "infill_mesh": True,
        "infill_sparse_density": float(density_percent),
        "wall_thickness": 0,
        "top_bottom_thickness": 0,
        **extra,
    }


_MODIFIER_KEYS = ("infill_mesh", "cutting_mesh", "anti_overhang_mesh", "support_mesh")


def mesh_groups(resolved: ResolvedSettings) -> list[list[int]]:
    """Indices of `resolved.meshes` per engine mesh group.

    One group for "all at once"; for "one at a time" every printed model
    starts a group and modifier meshes join the group of the model before them.
    """
    if resolved.global_values.get("print_sequence") != "one_at_a_time":
        return [list(range(len(resolved.meshes)))]
    groups: list[list[int]] = []
    for index, (_, values) in enumerate(resolved.meshes):
        modifier = any(values.get(key) for key in _MODIFIER_KEYS)
        if modifier and groups:
            groups[-1].append(index)
        else:
            groups.append([index])
    return groups


def engine_arguments(resolved: ResolvedSettings) -> list[str]:
    """The ``CuraEngine slice`` arguments (without ``-o``) for resolved settings.

    Mesh groups (one-at-a-time printing) are separated by ``--next``.
    """
    args = ["-j", resolved.definitions.fdmprinter_path]
    for key, value in resolved.global_values.items():
        args += ["-s", f"{key}={_engine_text(value)}"]
    # -j loads fdmextruder's defaults into extruder 0 and those win over
    # global values, so extruder keys must be given again after -e0.
    extruders = max(1, int(resolved.global_values.get("machine_extruder_count") or 1))
    for number in range(extruders):
        args.append(f"-e{number}")
        for key, value in {**resolved.extruder_values, "extruder_nr": number}.items():
            args += ["-s", f"{key}={_engine_text(value)}"]
    for number, group in enumerate(mesh_groups(resolved)):
        if number:
            args.append("--next")
        for index in group:
            path, values = resolved.meshes[index]
            args += ["-l", path]
            if extruders > 1:
                # (a mesh's settings fall back on the extruder named last on the command line, not the first)
                values = {"extruder_nr": 0, **values}
            for key, value in values.items():
                args += ["-s", f"{key}={_engine_text(value)}"]
    return args


def _prepare_groups_for_cli(resolved: ResolvedSettings, workdir: str, base: str) -> ResolvedSettings:
    """Work around the engine CLI not placing mesh groups before the last one.

    CuraEngine 4.13's ``--next`` slices a group without shifting it to the bed
    centre (only the last group is shifted), so those models are written
    already shifted into `workdir`.  The engine runs in `workdir`; a relative (to `base`)
    model path keeps its name there (``;MESH:`` shows the ``-l`` argument), the
    other models are linked in, an absolute path becomes ``gN/<file name>``.
    """
    groups = mesh_groups(resolved)
    if len(groups) < 2 or resolved.global_values.get("machine_center_is_zero"):
        return resolved
    from .models import read_stl, write_stl

    shift = [resolved.global_values["machine_width"] / 2, resolved.global_values["machine_depth"] / 2, 0.0]
    last = set(groups[-1])
    meshes = []
    for index, (path, values) in enumerate(resolved.meshes):
        relative = not os.path.isabs(path) and ".." not in os.path.normpath(path).split(os.sep)
        name = os.path.normpath(path) if relative else os.path.join(f"g{index}", os.path.basename(path))
        target = os.path.join(workdir, name)
        os.makedirs(os.path.dirname(target) or workdir, exist_ok=True)
        source = os.path.join(base, path)
        if index in last:
            shutil.copyfile(source, target)
        else:
            write_stl(target, read_stl(source) + shift)
        meshes.append((name, values))
    return ResolvedSettings(resolved.global_values, resolved.extruder_values, meshes, resolved.definitions,
                            resolved.warnings)


def _chmod_like_open(path: str) -> None:
    """Give a mkstemp file (mode 0600) the mode a plain open() would have given it."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


@dataclass
class SliceResult:
    """Outcome of :func:`slice_models`.

    Attributes
    ----------
    path : str
        The G-code file written.
    seconds : float
        Wall time of the CuraEngine process, s.
    log : str
        The engine's stderr (``-v`` log).
    settings : ResolvedSettings
        What was sent to the engine.
    """

    path: str
    seconds: float
    log: str
    settings: ResolvedSettings


def slice_models(
    models: Sequence,
    settings: Mapping | None = None,
    out_path: str | os.PathLike = "out.gcode",
    *,
    printer: str = "fdmprinter",
    resources: str | os.PathLike | None = None,
    engine: str | os.PathLike | None = None,
    defaults: Mapping | None = None,
    timeout: float = 600.0,
    cwd: str | os.PathLike | None = None,
) -> SliceResult:
    """Slice models with the CuraEngine command line.

    Parameters
    ----------
    models : sequence of (path, mapping)
        STL files (model coordinates: the engine centres (0, 0) on the bed
        unless ``machine_center_is_zero``) and their per-mesh settings, e.g.
        ``("box.stl", infill_modifier_settings(60))``.
    settings : mapping
        User settings over :data:`DEFAULT_SETTINGS` (or `defaults`).
    out_path : path-like
        G-code output; written atomically (a failed slice leaves no file).
    printer : str
        Machine definition id or path (its first extruder definition serves every extruder).
    cwd : path-like, optional
        Folder the engine runs in; relative model paths are relative to it.
        ``;MESH:`` lines show the model path exactly as given, so bare file
        names give G-code like Cura's own (which shows node names).

    Raises
    ------
    CuraEngineError
        Engine or definitions missing, unknown setting, or the engine failed.
    """
    if not models:
        raise CuraEngineError("nothing to slice: no models given")
    base = os.fspath(cwd) if cwd is not None else os.getcwd()
    for path, _ in models:
        if not os.path.isfile(os.path.join(base, path)):
            raise CuraEngineError(f"model file not found: {os.path.join(base, path)}")
    executable = find_curaengine(engine)
    resolved = resolve_settings(settings, models, printer=printer, resources=resources, defaults=defaults)
    out_path = os.path.abspath(os.fspath(out_path))
    folder = os.path.dirname(os.path.abspath(out_path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".slice-", suffix=".gcode", dir=folder)
    os.close(fd)
    env = dict(os.environ)
    env["CURA_ENGINE_SEARCH_PATH"] = os.pathsep.join(resolved.definitions.folders)
    workdir = tempfile.mkdtemp(prefix=".slice-", dir=folder)
    try:
        prepared = _prepare_groups_for_cli(resolved, workdir, base)
        run_in = workdir if prepared is not resolved else base
        argv = [executable, "slice", "-v", *engine_arguments(prepared), "-o", os.path.abspath(tmp)]
        start = time.perf_counter()
        proc = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, timeout=timeout,
                              cwd=run_in)
        seconds = time.perf_counter() - start
        log = proc.stderr.decode("utf-8", "replace")
        if proc.returncode != 0 or os.path.getsize(tmp) == 0:
            lines = log.splitlines()
            errors = [line for line in lines if "[ERROR]" in line]
            tail = "\n".join(errors or lines[-15:])
            raise CuraEngineError(f"CuraEngine failed (exit code {proc.returncode}); last log lines:\n{tail}")
        _chmod_like_open(tmp)
        os.replace(tmp, out_path)
    except subprocess.TimeoutExpired as exc:
        raise CuraEngineError(f"CuraEngine did not finish within {timeout:.0f} s") from exc
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
        shutil.rmtree(workdir, ignore_errors=True)
    return SliceResult(out_path, seconds, log, resolved)
