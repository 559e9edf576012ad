"""Run the real Cura GUI headless with the plugin installed, and a job.

Two Curas: ``version="4.13"`` (default) is Debian 12's Cura 4.13 (PyQt5) on this
machine; ``version="5.0"`` is Debian trixie's Cura 5.0.0 (PyQt6, Uranium 5.0,
CuraEngine 5.0, Python 3.13) in the chroot that ``scripts/cura5_chroot.sh``
builds at /srv/trixie (its /tmp is the host's /tmp).

One call of :func:`run_cura` does what a user's session does, automated:

1. make sure Cura, Xvfb and ImageMagick are installed (``ensure_deps.sh``; for
   5.0 the chroot, built or refreshed with ``scripts/cura5_chroot.sh``) and,
   for 4.13, that trimesh 3.9.36 is in a PYTHONPATH folder (Debian 12 has no
   python3-trimesh; without it Cura pops up "could not be loaded" messages);
2. build the ``.curapackage`` with the project's own packager and install the
   plugin from the package's ``files/plugins/DelaunayInfill`` into a fresh,
   seeded profile (no first-run wizard);
3. start Xvfb on a free display and Cura with the test driver plugin, which
   executes the job (see driver/DelaunayGuiDriver/driver.py);
4. wait for the driver's status, then stop only the processes started here
   (by PID: Cura, its CuraEngine child, Xvfb).

Everything lands in the run's folder: ``status.json``, ``cura.log``,
``cura.out``, the G-code and the screenshots the job asked for.  Cura 5.0 sees
only the chroot's files, so its session runs in a folder under /tmp: the job's
paths under the run folder are mapped there, the files it reads (models, step
files) are copied in, and the results are copied back into the run folder.

Cura 5.0 at times crashes while it starts (about 1 start in 30: a ``KeyError``
in ``ContainerRegistry._clearQueryCacheByContainer``, a race between the main
thread and the build-plate mesh job, not caused by a plugin). A session that
ended before Cura logged "Booting Cura took" is started again, up to
``START_ATTEMPTS`` times; ``CuraRun.start_retries`` counts the retries, and the
tests report them (a retry is never a pass by itself: the job must still run).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
DRIVER = HERE / "driver" / "DelaunayGuiDriver"
SYSTEM_PYTHON = "/usr/bin/python3"
TRIMESH = "trimesh==3.9.36"  # the version Cura pins
REQUIRED_COMMANDS = ("cura", "Xvfb", "xauth")
REQUIRED_FILES = ("/usr/bin/import", "/usr/bin/CuraEngine")
VERSIONS = ("4.13", "5.0")
CHROOT = Path(os.environ.get("DELAUNAY_CURA5_ROOT", "/srv/trixie"))
CHROOT_SCRIPT = REPO / "scripts" / "cura5_chroot.sh"
#: inside the chroot, for Cura 5.0 (qt6-svg-plugins: Debian's cura lacks it, and no icon loads without it)
CHROOT_FILES = ("usr/bin/cura", "usr/bin/CuraEngine", "usr/bin/import", "usr/bin/python3",
                "usr/lib/python3/dist-packages/PyQt6", "usr/lib/python3/dist-packages/shapely",
                "usr/lib/python3/dist-packages/trimesh")
CHROOT_TMP = Path("/tmp")  # bind-mounted at CHROOT/tmp: the same paths inside and outside
START_ATTEMPTS = 3
BOOTED = "Booting Cura took"

sys.path.insert(0, str(HERE))
from cura_profile import data_dir, plugins_dir, seed_profile  # noqa: E402


class CuraTierError(RuntimeError):
    """The GUI tier cannot run (missing packages, Cura did not start...): the test fails."""


@dataclass
class CuraRun:
    """What one Cura session left behind."""

    folder: Path
    status: dict
    cura_log: str
    cura_out: str
    seconds: float
    plugin_ids: list = field(default_factory=list)
    version: str = "4.13"
    start_retries: int = 0  # Cura 5.0 sessions started again after a crash before "Booting Cura took"

    @property
    def ok(self) -> bool:
        return bool(self.status.get("ok"))

    def records(self) -> dict:
        return self.status.get("records", {})

    def loaded(self, plugin_id: str) -> bool:
        return re.search(rf"Loaded plugin {re.escape(plugin_id)}\s*$", self.cura_log + self.cura_out, re.M) is not None

    def error_blocks(self, needle: str = "DelaunayInfill") -> list[str]:
        """Log entries at ERROR/CRITICAL level (with their tracebacks) that mention `needle`.

        The test driver's own entries are excluded: its failures show in the status.
        """
        # A traceback is logged line by line from one place (level, logger, thread); another thread's
        # entry may land between its lines, so lines join the latest block of their own source when
        # it was last written within a second.
        blocks: list[list[str]] = []
        latest: dict[tuple, tuple[int, float]] = {}  # source -> (block index, time of its last entry)
        current = None
        for line in self.cura_log.splitlines():
            entry = re.match(r"^\d{4}-\d\d-\d\d (\d\d):(\d\d):(\d\d),(\d+) - (\w+) - (.*? \[\d+\]):", line)
            if entry:
                h, m, sec, ms = (int(v) for v in entry.groups()[:4])
                stamp = 3600 * h + 60 * m + sec + ms / 1000
                source = entry.groups()[4:]
                hit = latest.get(source)
                if hit is not None and 0 <= stamp - hit[1] <= 1.0:
                    current = hit[0]
                    blocks[current].append(line)
                else:
                    blocks.append([line])
                    current = len(blocks) - 1
                latest[source] = (current, stamp)
            elif current is not None:
                blocks[current].append(line)
        found = []
        for block in blocks:
            text = "\n".join(block)
            level = re.search(r" - (ERROR|CRITICAL) - ", block[0])
            if level and needle in text and "DelaunayGuiDriver" not in block[0]:
                found.append(text)
        return found

    def failure(self) -> str:
        """A readable summary for assertion messages."""
        tail = "\n".join(self.cura_log.splitlines()[-40:])
        text = f"--- cura.log tail ---\n{tail}"
        fatal = self.fatal_error()
        if fatal:  # a native crash: Python's fault handler wrote the threads' stacks to stdout
            text = f"--- Cura crashed (cura.out) ---\n{fatal}\n{text}"
        return f"status: {json.dumps(self.status, indent=1, default=str)[:2500]}\n{text}"

    def fatal_error(self) -> str:
        """The fault handler's report in ``cura.out`` ("Fatal Python error: ..." and the stacks), or ''."""
        start = self.cura_out.find("Fatal Python error")
        return self.cura_out[start:start + 6000] if start >= 0 else ""


def _missing() -> list[str]:
    missing = [c for c in REQUIRED_COMMANDS if shutil.which(c) is None]
    missing += [f for f in REQUIRED_FILES if not os.path.exists(f)]
    if not os.path.exists(SYSTEM_PYTHON):
        missing.append(SYSTEM_PYTHON)
    else:
        probe = subprocess.run([SYSTEM_PYTHON, "-c", "import zeroconf, pip"], capture_output=True, check=False)
        if probe.returncode != 0:
            missing.append("python3-zeroconf/python3-pip")
    return missing


def ensure_dependencies() -> None:
    """Install what the tier needs (apt), or raise :class:`CuraTierError`."""
    if not _missing():
        return
    result = subprocess.run(["bash", str(HERE / "ensure_deps.sh")], capture_output=True, text=True, check=False)
    still = _missing()
    if still:
        raise CuraTierError(
            f"the GUI tier needs {', '.join(still)}; ensure_deps.sh could not install them:\n"
            f"{result.stdout[-2000:]}\n{result.stderr[-2000:]}"
        )


def ensure_pydeps(folder: Path) -> Path:
    """trimesh for Cura's system Python, in a PYTHONPATH folder (pip --target)."""
    folder.mkdir(parents=True, exist_ok=True)
    if (folder / "trimesh").is_dir():
        return folder
    result = subprocess.run(
        [SYSTEM_PYTHON, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "--no-deps",
         "--target", str(folder), TRIMESH],
        capture_output=True, text=True, check=False,
    )
    if result.returncode != 0 or not (folder / "trimesh").is_dir():
        raise CuraTierError(f"could not pip-install {TRIMESH} into {folder}:\n{result.stderr[-2000:]}")
    return folder


def install_from_package(plugins: Path, build_dir: Path) -> Path:
    """Build the .curapackage and install the plugin from its contents, as Cura does."""
    sys.path.insert(0, str(REPO))
    from DelaunayInfill.packaging import PLUGIN_ID, build_package

    package = build_package(build_dir)
    prefix = f"files/plugins/{PLUGIN_ID}/"
    target = plugins / PLUGIN_ID
    if target.exists():
        shutil.rmtree(target)
    with zipfile.ZipFile(package) as archive:
        for name in archive.namelist():
            if name.startswith(prefix) and not name.endswith("/"):
                out = target / name[len(prefix):]
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_bytes(archive.read(name))
    if not (target / "plugin.json").is_file():
        raise CuraTierError(f"{package} has no {prefix}plugin.json")
    return package


def _chroot_missing() -> list[str]:
    missing = [str(CHROOT / f) for f in CHROOT_FILES if not (CHROOT / f).exists()]
    if not missing:
        # the host's /tmp must be bound at CHROOT/tmp (the run folder lives there)
        probe = CHROOT_TMP / f".delaunay-chroot-probe-{os.getpid()}"
        probe.write_text("probe")
        try:
            if not (CHROOT / "tmp" / probe.name).exists():
                missing.append(f"{CHROOT}/tmp bound to the host's /tmp")
        finally:
            probe.unlink(missing_ok=True)
    return missing


def ensure_cura5() -> None:
    """The trixie chroot with Cura 5.0, built or refreshed with scripts/cura5_chroot.sh, or raise."""
    for tool in ("Xvfb", "chroot"):
        if shutil.which(tool) is None and not os.path.exists(f"/usr/sbin/{tool}"):
            raise CuraTierError(f"the Cura 5.0 GUI tier needs {tool} on the host")
    if not _chroot_missing():
        return
    if os.geteuid() != 0:
        raise CuraTierError(f"the Cura 5.0 GUI tier needs root (chroot {CHROOT}); missing: {_chroot_missing()}")
    result = subprocess.run(["bash", str(CHROOT_SCRIPT), "--root", str(CHROOT)], capture_output=True, text=True,
                            check=False)
    still = _chroot_missing()
    if still:
        raise CuraTierError(f"the Cura 5.0 chroot is incomplete ({', '.join(still)}); {CHROOT_SCRIPT.name} said:\n"
                            f"{result.stdout[-2000:]}\n{result.stderr[-2000:]}")


def _cura_command() -> list[str]:
    """``cura``, in a network namespace of its own when the machine allows one.

    Cura listens for its engine on 127.0.0.1:49674 and up; another process's connection that happens
    to use one of those ports makes the bind fail, and Cura 4.13 at times crashes natively on that
    path. A private loopback makes every session start on a clean port range.
    """
    return _isolated("exec cura", ["cura"])


def _isolated(inner: str, fallback: list[str]) -> list[str]:
    isolated = ["unshare", "--net", "sh", "-c", f"ip link set lo up && {inner}"]
    if shutil.which("unshare") and shutil.which("ip"):
        probe = subprocess.run(isolated[:-1] + ["ip link set lo up"], capture_output=True, check=False)
        if probe.returncode == 0:
            return isolated
    return fallback


def _cura5_command(env: dict) -> list[str]:
    """Cura 5.0 in the chroot, with a clean environment (the host's variables mean nothing there)."""
    chroot = shutil.which("chroot") or "/usr/sbin/chroot"
    command = [chroot, str(CHROOT), "/usr/bin/env", "-i"] + [f"{k}={v}" for k, v in sorted(env.items())] + ["cura"]
    return _isolated("exec " + " ".join(shlex.quote(c) for c in command), command)


def _work_folder(folder: Path) -> Path:
    """Where a Cura 5.0 session of `folder` runs: under /tmp, which the chroot shares."""
    digest = hashlib.sha1(str(folder).encode()).hexdigest()[:10]
    return CHROOT_TMP / f"delaunay-gui5-{folder.name}-{digest}"


def _map_job(job, folder: Path, work: Path, inputs: Path):
    """The job with paths under `folder` moved to `work`, and other files it names copied to `inputs`."""
    copied: dict[str, str] = {}

    def walk(value):
        if isinstance(value, dict):
            return {k: walk(v) for k, v in value.items()}
        if isinstance(value, list):
            return [walk(v) for v in value]
        if not isinstance(value, str) or not value.startswith("/"):
            return value
        if value == str(folder) or value.startswith(str(folder) + "/"):
            return str(work) + value[len(str(folder)):]
        if value.startswith(str(CHROOT_TMP) + "/") or not os.path.isfile(value):
            return value
        if value not in copied:
            target = inputs / str(len(copied)) / os.path.basename(value)  # the name stays: Cura names models by it
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(value, target)
            if value.endswith(".py"):  # a steps file loads its helper modules from beside itself
                for sibling in Path(value).parent.glob("*.py"):
                    if not (target.parent / sibling.name).exists():
                        shutil.copy2(sibling, target.parent / sibling.name)
            copied[value] = str(target)
        return copied[value]

    return walk(job)


def _free_display() -> int:
    for number in range(90, 400):
        if not os.path.exists(f"/tmp/.X{number}-lock") and not os.path.exists(f"/tmp/.X11-unix/X{number}"):
            return number
    raise CuraTierError("no free X display number")


def _children(pid: int) -> list[int]:
    result = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True, check=False)
    return [int(p) for p in result.stdout.split()]


def _stop(process: subprocess.Popen, grace_s: float = 15.0) -> None:
    """Stop `process` and its direct children (CuraEngine), by PID only."""
    if process.poll() is not None:
        return
    children = _children(process.pid)
    process.send_signal(signal.SIGTERM)
    try:
        process.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(timeout=10)
    for child in children:
        try:
            os.kill(child, signal.SIGTERM)
        except ProcessLookupError:
            pass


def run_cura(job: dict, folder: Path, *, timeout_s: float = 300.0, extra_plugins=(), geometry=(1600, 1000),
             install_plugin: bool = True, fresh: bool = True, version: str = "4.13",
             extra_env: dict | None = None) -> CuraRun:
    """Run one Cura session with the plugin (from the .curapackage) and the driver.

    Parameters
    ----------
    job : dict
        The driver's job (``actions``...); ``status`` is filled in.
    folder : Path
        Output folder of this run (profile, logs, screenshots).
    timeout_s : float
        Hard limit for the whole session (per start, for Cura 5.0).
    install_plugin : bool
        Install the plugin from the built .curapackage's ``files/plugins`` (False: leave the
        profile's plugins as they are, e.g. to let Cura install a dropped package).
    fresh : bool
        Start from an empty folder and a newly seeded profile (False: reuse the folder's
        profile from an earlier session, as a restarted Cura does).
    version : {"4.13", "5.0"}
        Which Cura: the host's 4.13 or the chroot's 5.0.
    extra_env : dict or None
        More environment for Cura, e.g. ``{"QT_FONT_DPI": "144"}`` (a larger font).

    Returns
    -------
    CuraRun
    """
    if version not in VERSIONS:
        raise ValueError(f"unknown Cura version {version!r}; use one of {', '.join(VERSIONS)}")
    folder = Path(folder).resolve()
    if version == "4.13":
        ensure_dependencies()
        work = folder
    else:
        ensure_cura5()
        work = _work_folder(folder)
    home = work / "home"
    if fresh:
        for path in {folder, work}:
            if path.exists():
                shutil.rmtree(path)
    folder.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)
    for stale in ("status.json", "job.json", "cura.log", "cura.out"):
        (work / stale).unlink(missing_ok=True)
    pydeps = ensure_pydeps(REPO / "test-artifacts" / "gui" / "_pydeps") if version == "4.13" else None
    if fresh or not home.exists():
        seed_profile(home, width=geometry[0], height=geometry[1], version=version)
    plugins = plugins_dir(home, version)
    if install_plugin:
        install_from_package(plugins, work / "dist")
    if (plugins / DRIVER.name).exists():
        shutil.rmtree(plugins / DRIVER.name)
    shutil.copytree(DRIVER, plugins / DRIVER.name)
    for extra in extra_plugins:
        if (plugins / Path(extra).name).exists():
            shutil.rmtree(plugins / Path(extra).name)
        shutil.copytree(extra, plugins / Path(extra).name)

    job = dict(job) if version == "4.13" else _map_job(dict(job), folder, work, work / "inputs")
    job["status"] = str(work / "status.json")
    job.setdefault("timeout_s", timeout_s - 30)
    job_path = work / "job.json"
    job_path.write_text(json.dumps(job, indent=1), encoding="utf-8")

    env = dict(
        HOME=str(home), DELAUNAY_GUI_JOB=str(job_path),
        XDG_CONFIG_HOME=str(home / ".config"), XDG_DATA_HOME=str(home / ".local" / "share"),
        XDG_CACHE_HOME=str(home / ".cache"), LC_ALL="C.UTF-8",
    )
    if version == "4.13":
        env = {**{k: v for k, v in os.environ.items() if not k.startswith(("XDG_", "PYTHON", "QT_"))}, **env,
               "PYTHONPATH": str(pydeps)}
    else:
        # USER: Cura 5.0's removable-drive plugin builds "/run/media/" + $USER and its thread dies without it
        env.update(USER=os.environ.get("USER") or "root", LANG="C.UTF-8", PATH="/usr/bin:/bin")
    env.update(extra_env or {})

    started = time.monotonic()
    retries = 0
    for attempt in range(START_ATTEMPTS if version != "4.13" else 1):
        (data_dir(home, version) / "cura.log").unlink(missing_ok=True)
        (work / "status.json").unlink(missing_ok=True)
        status = _session(work, env, version, timeout_s, geometry)
        cura_out = (work / "cura.out").read_text(errors="replace")
        if version == "4.13" or BOOTED in cura_out or status.get("ok") is True or attempt == START_ATTEMPTS - 1:
            break
        retries += 1  # crashed while starting (see the module docstring): start it again
        (work / f"cura.out.start{attempt + 1}").write_text(cura_out)
    log_path = data_dir(home, version) / "cura.log"
    cura_log = log_path.read_text(errors="replace") if log_path.exists() else ""
    (work / "cura.log").write_text(cura_log)
    if not status:
        status = {"ok": False, "error": "Cura wrote no status (did the driver plugin load?)"}
    if work != folder:
        _copy_back(work, folder)
    if retries:
        # reported, never hidden: pytest lists it in its warnings summary, and the run folder keeps the crashes
        warnings.warn(f"Cura {version} crashed while starting ({retries} of {retries + 1} starts) in {folder.name}; "
                      f"started again (see cura.out.start*)", RuntimeWarning, stacklevel=2)
    return CuraRun(
        folder=folder,
        status=status,
        cura_log=cura_log,
        cura_out=cura_out,
        seconds=time.monotonic() - started,
        version=version,
        start_retries=retries,
    )


def _copy_back(work: Path, folder: Path) -> None:
    """The session's results (not its profile, not the copied inputs) into the run folder."""
    for item in work.iterdir():
        if item.name in ("home", "inputs", "dist"):
            continue
        target = folder / item.name
        if item.is_dir():
            shutil.copytree(item, target, dirs_exist_ok=True)
        else:
            shutil.copy2(item, target)


def _session(work: Path, env: dict, version: str, timeout_s: float, geometry) -> dict:
    """One start of Cura with the job: Xvfb, Cura, wait for the driver's status, stop both."""
    display = _free_display()
    env = {**env, "DISPLAY": f":{display}"}
    command = _cura_command() if version == "4.13" else _cura5_command(env)
    xvfb_log = open(work / "xvfb.log", "w")  # noqa: SIM115 - closed in finally
    cura_out = open(work / "cura.out", "w")  # noqa: SIM115
    xvfb = subprocess.Popen(
        ["Xvfb", f":{display}", "-screen", "0", f"{geometry[0]}x{geometry[1]}x24", "-nolisten", "tcp"],
        stdout=xvfb_log, stderr=subprocess.STDOUT,
    )
    cura = None
    started = time.monotonic()
    status: dict = {}
    status_path = work / "status.json"
    try:
        for _ in range(100):
            if os.path.exists(f"/tmp/.X11-unix/X{display}"):
                break
            if xvfb.poll() is not None:
                raise CuraTierError(f"Xvfb :{display} exited: {(work / 'xvfb.log').read_text()[-500:]}")
            time.sleep(0.1)
        cura = subprocess.Popen(command, env=env if version == "4.13" else {"PATH": os.environ.get("PATH", "")},
                                stdout=cura_out, stderr=subprocess.STDOUT, cwd=work)
        while time.monotonic() - started < timeout_s:
            if status_path.exists():
                try:
                    status = json.loads(status_path.read_text())
                except ValueError:
                    status = {}
                if status.get("ok") is not None:
                    break
            if cura.poll() is not None:
                break
            time.sleep(0.5)
        if status.get("ok") is None and cura.poll() is None:
            status = {**status, "ok": False, "error": f"no result within {timeout_s:.0f} s"}
        try:
            cura.wait(timeout=20)  # the driver closes Cura when the job is done
        except subprocess.TimeoutExpired:
            pass
    finally:
        if cura is not None:
            _stop(cura)
        _stop(xvfb, grace_s=5)
        xvfb_log.close()
        cura_out.close()
    if status_path.exists():
        try:
            status = {**json.loads(status_path.read_text()), **({"ok": False} if status.get("ok") is False else {})}
        except ValueError:
            pass
    return status
