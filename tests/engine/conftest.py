"""Engine tier: slices the project's models with the real CuraEngine 4.13.

The tier FAILS (it never skips) when CuraEngine or Cura's definitions are
missing.  When they are missing and we run as root with apt-get available, the
tier installs Debian's ``cura-engine`` and ``cura`` itself first (set
``DELAUNAY_NO_APT=1`` to forbid that).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass

import pytest

from DelaunayInfill import curaengine, models

from .cases import Case, matrix

HERE = os.path.dirname(os.path.abspath(__file__))


def pytest_collection_modifyitems(items):
    # every test of this folder belongs to the engine tier (`-m engine` selects them with the real
    # CuraEngine tests that live beside the unit tests)
    for item in items:
        if os.path.dirname(os.path.abspath(str(item.fspath))) == HERE:
            item.add_marker(pytest.mark.engine)


def ensure_engine() -> str:
    """Make sure CuraEngine and Cura's definitions are present; install them with apt when root.

    Returns a one-line description of what is installed.  Raises
    :class:`DelaunayInfill.curaengine.CuraEngineError` when they are missing and
    cannot be installed.
    """
    def missing() -> list[str]:
        out = []
        try:
            curaengine.find_curaengine()
        except curaengine.CuraEngineError:
            out.append("cura-engine")
        try:
            curaengine.find_resources()
        except curaengine.CuraEngineError:
            out.append("cura")
        return out

    packages = missing()
    if packages and os.geteuid() == 0 and shutil.which("apt-get") and not os.environ.get("DELAUNAY_NO_APT"):
        env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
        print(f"engine tier: installing {' '.join(packages)} with apt-get", file=sys.stderr)
        subprocess.run(["apt-get", "update"], env=env, check=False, stdout=subprocess.DEVNULL)
        subprocess.run(["apt-get", "install", "-y", "--no-install-recommends", *packages], env=env, check=False,
                       stdout=subprocess.DEVNULL)
        packages = missing()
    if packages:
        raise curaengine.CuraEngineError(
            f"the engine tier needs Debian's {' and '.join(packages)} (apt-get install {' '.join(packages)})")
    version = subprocess.run([curaengine.find_curaengine(), "help"], capture_output=True, text=True).stderr
    first = next((line for line in version.splitlines() if "version" in line.lower()), "CuraEngine")
    return f"{first.strip()} at {curaengine.find_curaengine()}, definitions in {curaengine.find_resources()}"


@pytest.fixture(scope="session")
def engine_info() -> str:
    try:
        return ensure_engine()
    except curaengine.CuraEngineError as exc:
        pytest.fail(f"engine tier cannot run: {exc}", pytrace=False)


@dataclass
class Sliced:
    """A case sliced by CuraEngine."""

    case: Case
    gcode: str  # path of Cura's G-code
    seconds: float
    resolved: dict  # resolved global settings
    stl: dict  # mesh name -> STL path (the name is what ;MESH: shows)
    folder: str


class SliceCache:
    """Slices each distinct case (by settings hash) once per session."""

    def __init__(self, folder):
        self.folder = folder
        self._done: dict[str, Sliced] = {}

    def get(self, case: Case) -> Sliced:
        key = case.key()
        if key not in self._done:
            folder = self.folder / f"{case.name}-{key}"
            folder.mkdir(parents=True, exist_ok=True)
            stl = {}
            for model in case.models:
                path = folder / model.name
                models.write_stl(path, model.triangles(), name=model.name)
                stl[model.name] = str(path)
            # bare file names: ;MESH: shows them as Cura's GUI shows node names
            result = curaengine.slice_models([(m.name, m.per_mesh) for m in case.models], case.settings,
                                             folder / "cura.gcode", cwd=folder)
            self._done[key] = Sliced(case, result.path, result.seconds, result.settings.global_values, stl,
                                     str(folder))
        return self._done[key]


@pytest.fixture(scope="session")
def slices(engine_info, tmp_path_factory) -> SliceCache:
    return SliceCache(tmp_path_factory.mktemp("slices"))


MATRIX = matrix()


@pytest.fixture(scope="session", params=sorted(MATRIX))
def sliced(request, slices) -> Sliced:
    return slices.get(MATRIX[request.param])


# --------------------------------------------------------------------------- the pipeline under test


def split_like_cura(text: str) -> list[str]:
    """Cura's in-memory form: header, start G-code, one string per ``;LAYER:``, end G-code.

    Every string keeps its newlines, so ``"".join(...)`` gives the file back.
    """
    lines = text.splitlines(keepends=True)
    starts = [i for i, line in enumerate(lines) if line.startswith(";LAYER:")]
    first_code = next(i for i, line in enumerate(lines) if line.strip() and not line.startswith(";"))
    elapsed = [i for i, line in enumerate(lines) if line.startswith(";TIME_ELAPSED:")]
    end_start = elapsed[-1] + 1 if elapsed else len(lines)
    cuts = sorted({0, first_code, *starts, end_start, len(lines)})
    return ["".join(lines[a:b]) for a, b in zip(cuts[:-1], cuts[1:], strict=True) if b > a]


def cli_command() -> list[str]:
    """The console script, as a user runs it."""
    script = shutil.which("delaunay-infill")
    if script is None:
        pytest.fail("the `delaunay-infill` console script is not installed (pip install -e .)", pytrace=False)
    return [script]


def cli_arguments(sliced: Sliced) -> list[str]:
    """``--density``, ``--mesh NAME:PCT`` and ``--no-combing`` for a case, as a user would give them."""
    args = ["--density", f"{100 * sliced.case.density:g}"]
    for name, percent in sliced.case.mesh_densities().items():
        args += ["--mesh", f"{name}:{percent:g}"]
    if sliced.case.settings.get("retraction_combing") == "off":
        args.append("--no-combing")  # what Cura was told: retract rather than travel round inside
    return args


@dataclass
class Processed:
    sliced: Sliced
    text: str  # the processed G-code
    path: str
    report: object  # ProcessReport (API) or the CompletedProcess (CLI)
    seconds: float


def _sha(path) -> str:
    import hashlib

    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


@pytest.fixture(scope="session")
def processed_api(sliced) -> Processed:
    """The case processed in-process through ``process_gcode`` on Cura's in-memory form."""
    import time

    from DelaunayInfill import process_gcode

    with open(sliced.gcode, encoding="utf-8") as f:
        original = f.read()
    chunks = split_like_cura(original)
    assert "".join(chunks) == original
    before = list(chunks)
    start = time.perf_counter()
    layers, report = process_gcode(chunks)
    seconds = time.perf_counter() - start
    assert chunks == before, "process_gcode modified its input list"
    path = os.path.join(sliced.folder, "api.gcode")
    text = "".join(layers)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    return Processed(sliced, text, path, report, seconds)


@pytest.fixture(scope="session")
def processed_cli(sliced) -> Processed:
    """The case processed by the console script with explicit densities."""
    import time

    out = os.path.join(sliced.folder, "cli.gcode")
    before = _sha(sliced.gcode)
    start = time.perf_counter()
    proc = subprocess.run([*cli_command(), "process", sliced.gcode, "-o", out, *cli_arguments(sliced)],
                          capture_output=True, text=True, timeout=600)
    seconds = time.perf_counter() - start
    assert proc.returncode == 0, f"CLI failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
    assert "Traceback" not in proc.stderr, proc.stderr
    assert _sha(sliced.gcode) == before, "the CLI modified its input"
    with open(out, encoding="utf-8") as f:
        text = f.read()
    return Processed(sliced, text, out, proc, seconds)


@pytest.fixture(scope="session", params=["api", "cli"])
def processed(request, sliced) -> Processed:
    return request.getfixturevalue(f"processed_{request.param}")


BIG_FILE_BYTES = int(os.environ.get("DELAUNAY_BIG_GCODE_MB", "500")) * 1_000_000


@pytest.fixture(scope="session")
def big_gcode(slices, tmp_path_factory):
    """A 500 MB G-code (relative E H-bracket, middle layers repeated with consistent numbering)."""
    from .bigfile import write_big_gcode

    source = slices.get(MATRIX["relative_e"])
    with open(source.gcode, encoding="utf-8") as f:
        text = f.read()
    path = tmp_path_factory.mktemp("big") / "big.gcode"
    yield write_big_gcode(text, str(path), BIG_FILE_BYTES)
    path.unlink()  # half a gigabyte: do not keep it in pytest's retained tmp dirs
