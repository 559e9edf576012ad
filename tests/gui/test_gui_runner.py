"""The GUI tier's own machinery, without starting Cura: it must fail loudly, never skip."""

from __future__ import annotations

import shlex
import socket
import subprocess
import sys

import cura_runner
import pytest
from cura_profile import data_dir, seed_profile


def test_missing_cura_is_a_failure_not_a_skip(monkeypatch):
    monkeypatch.setattr(cura_runner, "REQUIRED_COMMANDS", ("cura-that-does-not-exist",))
    with pytest.raises(cura_runner.CuraTierError, match="cura-that-does-not-exist"):
        cura_runner.ensure_dependencies()


def test_seeded_profile_has_an_active_printer(tmp_path):
    data = seed_profile(tmp_path)
    assert data == data_dir(tmp_path)
    config = (tmp_path / ".config" / "cura" / "4.13" / "cura.cfg").read_text()
    assert "active_machine = Creality Ender-3" in config and "last_run_version = 4.13.0" in config
    stack = (data / "machine_instances" / "Creality+Ender-3.global.cfg").read_text()
    assert "7 = creality_ender3" in stack and "0 = Creality Ender-3_user" in stack
    assert (data / "user" / "Creality+Ender-3_user.inst.cfg").exists()


def test_log_errors_are_grouped_with_their_traceback():
    log = "\n".join([
        "2026-01-01 10:00:00,000 - INFO - [MainThread] x.y [1]: fine",
        "2026-01-01 10:00:01,000 - ERROR - [JobQueueWorker [1]] DelaunayInfill.cura.job.run [54]: Exception: boom",
        "2026-01-01 10:00:01,001 - ERROR - [JobQueueWorker [1]] DelaunayInfill.cura.job.run [54]: Traceback",
        "2026-01-01 10:00:01,002 - ERROR - [JobQueueWorker [1]] DelaunayInfill.cura.job.run [54]: ValueError: why",
        "2026-01-01 10:00:02,000 - ERROR - [MainThread] Toolbox.x [9]: no network",
    ])
    run = cura_runner.CuraRun(folder=None, status={}, cura_log=log, cura_out="", seconds=0.0)
    blocks = run.error_blocks("DelaunayInfill")
    assert len(blocks) == 1 and "ValueError: why" in blocks[0]
    assert run.error_blocks("Toolbox") == ["2026-01-01 10:00:02,000 - ERROR - [MainThread] Toolbox.x [9]: no network"]


def test_a_native_crash_is_reported_with_its_stacks():
    out = "QML noise\nFatal Python error: Segmentation fault\n\nThread 0x1 (most recent call first):\n  <no Python frame>\n"
    run = cura_runner.CuraRun(folder=None, status={"ok": None}, cura_log="last line", cura_out=out, seconds=1.0)
    assert run.fatal_error().startswith("Fatal Python error: Segmentation fault")
    assert "<no Python frame>" in run.failure() and "last line" in run.failure()
    quiet = cura_runner.CuraRun(folder=None, status={"ok": True}, cura_log="", cura_out="QML noise\n", seconds=1.0)
    assert quiet.fatal_error() == "" and "crashed" not in quiet.failure()


def test_cura_gets_a_private_loopback_when_the_machine_allows_it():
    """Other processes' connections on Cura's engine ports crash Cura 4.13 at times (see _cura_command)."""
    command = cura_runner._cura_command()
    if command == ["cura"]:  # no namespaces here: Cura runs as a user starts it, nothing to check
        return
    assert command[:2] == ["unshare", "--net"] and command[-1].endswith("exec cura")
    with socket.socket() as busy:  # the host's 49674 busy; inside the namespace it is free
        busy.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        busy.bind(("127.0.0.1", 49674))
        busy.listen(1)
        probe = "import socket; s = socket.socket(); s.bind(('127.0.0.1', 49674)); s.listen(1); print('ok')"
        inner = command[-1].replace("exec cura", f"{shlex.quote(sys.executable)} -c {shlex.quote(probe)}")
        result = subprocess.run(command[:-1] + [inner], capture_output=True, text=True, check=False)
    assert result.stdout.strip() == "ok", result.stderr


def test_a_missing_cura5_chroot_is_a_failure_not_a_skip(monkeypatch, tmp_path):
    script = tmp_path / "fails.sh"
    script.write_text("echo cannot build >&2; exit 1\n")
    monkeypatch.setattr(cura_runner, "CHROOT", tmp_path / "no-chroot")
    monkeypatch.setattr(cura_runner, "CHROOT_SCRIPT", script)
    with pytest.raises(cura_runner.CuraTierError, match="no-chroot"):
        cura_runner.ensure_cura5()


def test_seeded_cura5_profile_uses_its_own_folders_and_container_format(tmp_path):
    data = seed_profile(tmp_path, version="5.0")
    assert data == data_dir(tmp_path, "5.0") and data.parts[-2:] == ("cura", "5.0")
    config = (tmp_path / ".config" / "cura" / "5.0" / "cura.cfg").read_text()
    assert "last_run_version = 5.0.0" in config and "setting_version = 20" in config
    stack = (data / "machine_instances" / "Creality+Ender-3.global.cfg").read_text()
    assert "setting_version = 20" in stack and "7 = creality_ender3" in stack


def test_a_cura5_job_sees_its_files_under_tmp(tmp_path):
    """Cura 5.0 runs in the chroot: paths under the run folder move to /tmp, other input files are copied."""
    folder = tmp_path / "run"
    model = tmp_path / "models" / "star.stl"
    model.parent.mkdir()
    model.write_text("solid x\nendsolid x\n")
    work = cura_runner._work_folder(folder)
    # a steps file outside /tmp, which the chroot does not see (the checkout itself may lie under /tmp)
    import tempfile

    outside = tempfile.mkdtemp(dir="/var/tmp")
    steps = f"{outside}/test_gui_runner.py"
    with open(steps, "w") as f:
        f.write("STEPS = 'plain text'\n")
    job = {"actions": [{"do": "load", "file": str(model)}, {"do": "save", "path": f"{folder}/out.gcode"},
                       {"do": "step", "file": steps, "args": {"name": "plain text", "missing": "/no/such/file"}}]}
    mapped = cura_runner._map_job(job, folder, work, work / "inputs")
    try:
        assert str(work).startswith("/tmp/")
        assert mapped["actions"][0]["file"] == str(model)  # under /tmp: the chroot sees it as it is
        copied = mapped["actions"][2]["file"]
        assert copied.startswith(str(work / "inputs")) and copied.endswith("/test_gui_runner.py")  # the name stays
        assert open(copied).read() == open(steps).read()
        assert mapped["actions"][1]["path"] == f"{work}/out.gcode"
        assert mapped["actions"][2]["args"] == {"name": "plain text", "missing": "/no/such/file"}
    finally:
        import shutil

        shutil.rmtree(work, ignore_errors=True)
        shutil.rmtree(outside, ignore_errors=True)
