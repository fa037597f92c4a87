"""Autosave and recovery: the writer is atomic and debounced, a crash is told
from a clean exit, a corrupt autosave is set aside in one line; a window killed
with SIGKILL comes back with --restore in its last autosaved state exactly."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from nbrdf.neural.material import load_material
from nbrdf.viewer.options import DEFAULT_MATERIAL
from nbrdf.viewer.session.autosave import Autosave, WindowAutosave, state_dir, write_atomic
from nbrdf.viewer.session.document import SessionDoc


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def doc(roughness: float = 0.3) -> dict:
    d = SessionDoc(load_material(DEFAULT_MATERIAL)).to_dict()
    d["material"]["layers"][-1]["roughness"] = roughness
    return d


def test_state_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("NBRDF_STATE_DIR", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert state_dir() == tmp_path / "xdg" / "nbrdf"
    monkeypatch.delenv("XDG_STATE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert state_dir() == tmp_path / "home" / ".local" / "state" / "nbrdf"
    monkeypatch.setenv("NBRDF_STATE_DIR", str(tmp_path / "over"))
    assert state_dir() == tmp_path / "over"


def test_debounce_writes_once_after_a_burst(tmp_path):
    clock = Clock()
    a = Autosave(tmp_path, delay=3.0, max_delay=15.0, clock=clock)
    assert a.start() is False and a.active
    for k in range(10):  # a slider drag: a change every 0.5 s
        assert not a.tick(doc(0.1 + 0.05 * k))
        clock.t += 0.5
    assert not a.autosave_path.exists()
    clock.t += 2.4
    assert not a.tick(doc(0.55))  # unchanged for 2.9 s: not yet
    clock.t += 0.2
    assert a.tick(doc(0.55))
    assert json.loads(a.autosave_path.read_text())["material"]["layers"][-1]["roughness"] == 0.55
    clock.t += 10
    assert not a.tick(doc(0.55))  # nothing changed: nothing written


def test_continuous_changes_are_written_by_max_delay(tmp_path):
    clock = Clock()
    a = Autosave(tmp_path, delay=3.0, max_delay=15.0, clock=clock)
    a.start()
    wrote = []
    for k in range(40):  # a change every second for 40 s (a turntable)
        wrote.append(a.tick(doc(0.01 * k)))
        clock.t += 1.0
    assert sum(wrote) == 2 and wrote.index(True) == 15


def test_write_is_atomic(tmp_path, monkeypatch):
    """A failure between writing and renaming leaves the previous file whole and no temporary behind."""
    p = tmp_path / "a.json"
    write_atomic(p, "old\n")
    real = os.replace

    def boom(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        write_atomic(p, "new\n")
    monkeypatch.setattr(os, "replace", real)
    assert p.read_text() == "old\n" and [q.name for q in tmp_path.iterdir()] == ["a.json"]


def test_a_failed_write_is_one_line_and_retried(tmp_path, monkeypatch):
    clock = Clock()
    a = Autosave(tmp_path, delay=1.0, clock=clock)
    a.start()
    a.tick(doc(0.2))
    clock.t += 2
    assert a.tick(doc(0.2))
    monkeypatch.setattr("nbrdf.viewer.session.autosave.write_atomic",
                        lambda p, t: (_ for _ in ()).throw(OSError(28, "No space left on device")))
    a.tick(doc(0.7))
    clock.t += 2
    assert not a.tick(doc(0.7)) and "No space left" in a.error and "\n" not in a.error
    assert json.loads(a.autosave_path.read_text())["material"]["layers"][-1]["roughness"] == 0.2  # kept
    monkeypatch.undo()
    clock.t += 2
    assert a.tick(doc(0.7)) and a.error is None


def test_clean_exit_and_crash_are_told_apart(tmp_path):
    a = Autosave(tmp_path, clock=Clock())
    assert not a.start()
    a.close(doc(0.4))
    assert not a.lock_path.exists() and a.autosave_path.exists()
    b = Autosave(tmp_path, clock=Clock())
    assert not b.start()  # clean exit: nothing offered
    b.flush(doc(0.6))
    # A crash: the lock stays, naming a process that no longer runs.
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    b.lock_path.write_text(f"{dead.pid}\n")
    c = Autosave(tmp_path, clock=Clock())
    assert c.start() is True
    assert json.loads(c.recovery_path.read_text())["material"]["layers"][-1]["roughness"] == 0.6
    assert not c.autosave_path.exists() and c.lock_path.read_text().strip() == str(os.getpid())


def test_another_running_window_keeps_its_lock(tmp_path):
    (tmp_path / "session.lock").write_text(f"{os.getppid()}\n")  # a live process
    a = Autosave(tmp_path, clock=Clock())
    assert a.start() is False and not a.active and "another nbrdf-view" in a.error
    assert not a.tick(doc()) and not a.autosave_path.exists()


def test_an_unwritable_state_folder_turns_autosave_off_in_one_line(tmp_path):
    blocker = tmp_path / "state"
    blocker.write_text("")  # a file where the folder should be: nothing can be created under it (even as root)
    a = Autosave(blocker / "nbrdf", clock=Clock())
    assert a.start() is False and not a.active and "not writable" in a.error and "\n" not in a.error
    assert not a.tick(doc()) and not a.flush(doc())


class FakeLookDev:
    """What WindowAutosave uses of a LookDev: its session document and restore."""

    def __init__(self):
        self.doc = SessionDoc(load_material(DEFAULT_MATERIAL))
        self.notice = ""
        self.restored = None

    def session(self) -> dict:
        return self.doc.to_dict()

    def restore(self, doc) -> None:
        self.restored = doc


def _crash(tmp_path, text: str) -> None:
    (tmp_path / "autosave.json").write_text(text)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / "session.lock").write_text(f"{dead.pid}\n")


@pytest.mark.parametrize("text", ["{ half a fi", json.dumps({"format": "nbrdf-session/1", "material": 3}), ""])
def test_a_corrupt_autosave_is_set_aside_in_one_line(tmp_path, text):
    _crash(tmp_path, text)
    ld = FakeLookDev()
    w = WindowAutosave(ld, None, Autosave(tmp_path, clock=Clock()))
    assert not w.pending and ld.restored is None
    assert "cannot be restored" in ld.notice and "set aside" in ld.notice and "\n" not in ld.notice
    aside = list(tmp_path.glob("recovery.corrupt-*.json"))
    assert len(aside) == 1 and aside[0].read_text() == text


def test_recovery_is_offered_restored_or_kept(tmp_path):
    saved = doc(0.77)
    for restore in (None, True, False):
        _crash(tmp_path, json.dumps(saved))
        ld = FakeLookDev()
        w = WindowAutosave(ld, restore, Autosave(tmp_path, clock=Clock()))
        if restore is None:
            assert w.pending and ld.restored is None
            assert w.restore()
        if restore is False:
            assert not w.pending and ld.restored is None and "kept" in ld.notice
            assert (tmp_path / "recovery.json").exists()
        else:
            assert json.loads(json.dumps(ld.restored.to_dict())) == json.loads(json.dumps(saved))
        w.close()


# ----------------------------------------------------------------------- a real window, killed
WINDOW = textwrap.dedent("""
    import json, sys, time
    from pathlib import Path
    from nbrdf.cli.view import parse_args
    from nbrdf.viewer.ui.app import App
    opts = parse_args(sys.argv[1:])
    app = App(opts, size=(64, 48))
    app.autosave.saver.delay = 0.2
    ld = app.lookdev
    out = Path(opts.out).parent
    if opts.restore:
        app.step()
        (out / "restored.json").write_text(json.dumps(ld.session(), sort_keys=True))
        app.close()
        sys.exit(0)
    ld.set_param(len(ld.material.layers) - 1, "roughness", 0.37)
    ld.orbit(25.0, -10.0)
    ld.state.exposure = 1.25
    ld.set_compare("wipe")
    ld.set_wipe(0.3)
    for _ in range(6):
        app.step()
        time.sleep(0.1)
    (out / "expected.json").write_text(json.dumps(ld.session(), sort_keys=True))
    print("edited", flush=True)
    while True:  # killed here
        app.step()
        time.sleep(0.05)
""")


def _ppid(pid: int) -> int:
    """The parent of ``pid`` (0 once it is gone or a zombie)."""
    try:
        fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    except OSError:
        return 0
    return 0 if fields[0] == "Z" else int(fields[1])


def _children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid``."""
    return [int(d) for d in os.listdir("/proc") if d.isdigit() and _ppid(int(d)) == pid]


@pytest.mark.gl
def test_a_killed_window_restores_its_last_autosave_exactly(xvfb_display, tmp_path):
    env = dict(os.environ, DISPLAY=xvfb_display, NBRDF_STATE_DIR=str(tmp_path / "state"))
    args = [str(DEFAULT_MATERIAL), "--out", str(tmp_path / "x.png")]
    p = subprocess.Popen([sys.executable, "-c", WINDOW, *args], env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "edited"
        deadline = time.monotonic() + 120
        expected = json.loads((tmp_path / "expected.json").read_text())
        while time.monotonic() < deadline:  # the autosave lands within the debounce delay
            a = tmp_path / "state" / "autosave.json"
            if a.exists() and json.loads(a.read_text()) == expected:
                break
            time.sleep(0.1)
        children = _children(p.pid)  # the Monte Carlo worker
        p.send_signal(signal.SIGKILL)
        p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == -signal.SIGKILL
    assert children, "the window started no worker process"
    left = set(children)
    for _ in range(300):  # a worker notices its window is gone within a second or two
        left = {c for c in left if os.path.exists(f"/proc/{c}") and _ppid(c) != 0}
        if not left:
            break
        time.sleep(0.1)
    assert not left, f"worker processes left behind by the killed window: {sorted(left)}"
    assert (tmp_path / "state" / "session.lock").exists()  # the kill left the lock: an abnormal end
    r = subprocess.run([sys.executable, "-c", WINDOW, *args, "--restore"], env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    restored = json.loads((tmp_path / "restored.json").read_text())
    assert restored == expected
    assert restored["material"]["layers"][-1]["roughness"] == 0.37 and restored["view"]["exposure"] == 1.25
    assert not (tmp_path / "state" / "session.lock").exists()  # that window closed cleanly


RUN = textwrap.dedent("""
    import sys
    from nbrdf.cli.view import parse_args
    from nbrdf.viewer.ui.app import App
    app = App(parse_args(sys.argv[1:]), size=(64, 48))
    app.autosave.saver.delay = 0.2
    app.lookdev.set_param(len(app.lookdev.material.layers) - 1, "roughness", 0.41)
    app.run()
    print("closed", flush=True)
""")


@pytest.mark.gl
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
def test_sigterm_and_sighup_close_the_window_cleanly(xvfb_display, tmp_path, sig):
    """A logout or ``kill`` closes the window as its close button does: the session
    written, the lock released, no recovery offered to the next window."""
    state = tmp_path / "state"
    env = dict(os.environ, DISPLAY=xvfb_display, NBRDF_STATE_DIR=str(state))
    p = subprocess.Popen([sys.executable, "-c", RUN, str(DEFAULT_MATERIAL)], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120  # a guard against a hang, not a timing assertion
        while time.monotonic() < deadline and p.poll() is None and not (state / "autosave.json").exists():
            time.sleep(0.1)  # the loop runs (it writes the autosave), so its handlers are in place
        assert (state / "autosave.json").exists(), p.stderr.read()[-2000:] if p.poll() is not None else ""
        p.send_signal(getattr(signal, sig))
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0 and out.strip() == "closed", err[-2000:]
    assert not (state / "session.lock").exists()
    saved = json.loads((state / "autosave.json").read_text())
    assert saved["material"]["layers"][-1]["roughness"] == 0.41
    assert Autosave(state).start() is False  # a clean exit: nothing to recover
