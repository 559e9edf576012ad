"""Run the real Cura 4.13 GUI headless with the plugin installed, and a job.

One call of :func:`run_cura` does what a user's session does, automated:

1. make sure Cura, Xvfb and ImageMagick are installed (``ensure_deps.sh``) and
   that trimesh 3.9.36 is in a PYTHONPATH folder (Debian has no
   python3-trimesh; without it Cura pops up "could not be loaded" messages);
2. build the ``.curapackage`` with the project's own packager and install the
   plugin from the package's ``files/plugins/DelaunayInfill`` into a fresh,
   seeded profile (no first-run wizard);
3. start Xvfb on a free display and Cura with the test driver plugin, which
   executes the job (see driver/DelaunayGuiDriver/driver.py);
4. wait for the driver's status, then stop only the processes started here
   (by PID: Cura, its CuraEngine child, Xvfb).

Everything lands in the run's folder: ``status.json``, ``cura.log``,
``cura.out``, the G-code and the screenshots the job asked for.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
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


def _cura_command() -> list[str]:
    """``cura``, in a network namespace of its own when the machine allows one.

    Cura listens for its engine on 127.0.0.1:49674 and up; another process's connection that happens
    to use one of those ports makes the bind fail, and Cura 4.13 at times crashes natively on that
    path. A private loopback makes every session start on a clean port range.
    """
    isolated = ["unshare", "--net", "sh", "-c", "ip link set lo up && exec cura"]
    if shutil.which("unshare") and shutil.which("ip"):
        probe = subprocess.run(isolated[:-1] + ["ip link set lo up"], capture_output=True, check=False)
        if probe.returncode == 0:
            return isolated
    return ["cura"]


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
             install_plugin: bool = True, fresh: bool = True) -> CuraRun:
    """Run one Cura session with the plugin (from the .curapackage) and the driver.

    Parameters
    ----------
    job : dict
        The driver's job (``actions``...); ``status`` is filled in.
    folder : Path
        Output folder of this run (profile, logs, screenshots).
    timeout_s : float
        Hard limit for the whole session.
    install_plugin : bool
        Install the plugin from the built .curapackage's ``files/plugins`` (False: leave the
        profile's plugins as they are, e.g. to let Cura install a dropped package).
    fresh : bool
        Start from an empty folder and a newly seeded profile (False: reuse the folder's
        profile from an earlier session, as a restarted Cura does).

    Returns
    -------
    CuraRun
    """
    ensure_dependencies()
    folder = Path(folder).resolve()
    home = folder / "home"
    if fresh and folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for stale in ("status.json", "job.json", "cura.log", "cura.out"):
        (folder / stale).unlink(missing_ok=True)
    pydeps = ensure_pydeps(REPO / "test-artifacts" / "gui" / "_pydeps")
    if fresh or not home.exists():
        seed_profile(home, width=geometry[0], height=geometry[1])
    (data_dir(home) / "cura.log").unlink(missing_ok=True)
    plugins = plugins_dir(home)
    if install_plugin:
        install_from_package(plugins, folder / "dist")
    if (plugins / DRIVER.name).exists():
        shutil.rmtree(plugins / DRIVER.name)
    shutil.copytree(DRIVER, plugins / DRIVER.name)
    for extra in extra_plugins:
        if (plugins / Path(extra).name).exists():
            shutil.rmtree(plugins / Path(extra).name)
        shutil.copytree(extra, plugins / Path(extra).name)

    job = dict(job)
    job["status"] = str(folder / "status.json")
    job.setdefault("timeout_s", timeout_s - 30)
    job_path = folder / "job.json"
    job_path.write_text(json.dumps(job, indent=1), encoding="utf-8")

    display = _free_display()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("XDG_", "PYTHON", "QT_"))}
    env.update(
        HOME=str(home), DISPLAY=f":{display}", DELAUNAY_GUI_JOB=str(job_path), PYTHONPATH=str(pydeps),
        XDG_CONFIG_HOME=str(home / ".config"), XDG_DATA_HOME=str(home / ".local" / "share"),
        XDG_CACHE_HOME=str(home / ".cache"), LC_ALL="C.UTF-8",
    )
    xvfb_log = open(folder / "xvfb.log", "w")  # noqa: SIM115 - closed in finally
    cura_out = open(folder / "cura.out", "w")  # noqa: SIM115
    xvfb = subprocess.Popen(
        ["Xvfb", f":{display}", "-screen", "0", f"{geometry[0]}x{geometry[1]}x24", "-nolisten", "tcp"],
        stdout=xvfb_log, stderr=subprocess.STDOUT,
    )
    cura = None
    started = time.monotonic()
    status: dict = {}
    status_path = folder / "status.json"
    try:
        for _ in range(100):
            if os.path.exists(f"/tmp/.X11-unix/X{display}"):
                break
            if xvfb.poll() is not None:
                raise CuraTierError(f"Xvfb :{display} exited: {(folder / 'xvfb.log').read_text()[-500:]}")
            time.sleep(0.1)
        cura = subprocess.Popen(_cura_command(), env=env, stdout=cura_out, stderr=subprocess.STDOUT, cwd=folder)
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
    log_path = data_dir(home) / "cura.log"
    cura_log = log_path.read_text(errors="replace") if log_path.exists() else ""
    (folder / "cura.log").write_text(cura_log)
    if not status:
        status = {"ok": False, "error": "Cura wrote no status (did the driver plugin load?)"}
    return CuraRun(
        folder=folder,
        status=status,
        cura_log=cura_log,
        cura_out=(folder / "cura.out").read_text(errors="replace"),
        seconds=time.monotonic() - started,
    )
