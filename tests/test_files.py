"""Long runs and results files that stay safe (issue 16, sections 3 and 4).

Facts checked: a streamed ``se3dyn run`` keeps its memory flat however many steps it takes,
in-memory results cost about their own size, and a huge run reserves no memory up front; two
writers of one file are refused, an existing file is not overwritten unless asked, SIGTERM
closes the file (exit 143), a file left by ``kill -9`` is repaired by the next se3dyn command;
a run continued from a checkpoint (API ``initial_state``, CLI ``--resume``) equals the
uninterrupted run bit for bit.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import se3dyn as sd

h5py = pytest.importorskip("h5py")

from se3dyn.dynamics.run import CHECKPOINT_EVERY, Checkpoint  # noqa: E402
from se3dyn.io.h5 import ResultsFileError, ResultsWriter, read_results, repair  # noqa: E402
from se3dyn.io.modelfile import load_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = ROOT / "examples" / "a01_simple_pendulum.yaml"
LINUX = sys.platform.startswith("linux")

# a cheap model: one free rigid body tumbling under gravity (no joints), so that a million
# steps take a few seconds
BODY = """\
se3dyn: 1
name: body
gravity: [0.0, 0.0, -9.81]
nodes:
  b: {position: [0.0, 0.0, 0.0], mass: 1.0, inertia: [1.0, 2.0, 3.0],
      angular_velocity: [0.1, 0.2, 0.3]}
simulation: {t_end: 1.0, step: 1.0e-3}
"""

#: every dataset of rows in a results file
SERIES = ("time", "nodes/position", "nodes/rotation", "nodes/velocity", "nodes/acceleration",
          "joints/alpha", "joints/velocity", "joints/acceleration", "joints/multipliers",
          "energy/kinetic", "energy/potential", "energy/spring", "energy/work_actuators",
          "energy/work_loads", "energy/dissipation", "solver/iterations", "solver/residual",
          "solver/constraint")


def _cmd() -> list[str]:
    exe = Path(sys.executable).parent / "se3dyn"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("se3dyn")
    return [found] if found else [sys.executable, "-m", "se3dyn.cli"]


def run(*args, timeout=300) -> subprocess.CompletedProcess:
    p = subprocess.run(_cmd() + [str(a) for a in args], capture_output=True, text=True,
                       timeout=timeout)
    assert "Traceback" not in p.stderr, p.stderr
    return p


def start(*args) -> subprocess.Popen:
    return subprocess.Popen(_cmd() + [str(a) for a in args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_for_rows(path: Path, proc: subprocess.Popen, rows: int, timeout: float = 60.0) -> int:
    """Wait until the running writer has flushed at least ``rows`` rows (read by SWMR)."""
    deadline = time.monotonic() + timeout
    n = 0
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            with h5py.File(path, "r", libver="latest", swmr=True) as f:
                n = f["time"].shape[0]
        except (OSError, KeyError):
            n = 0
        if n >= rows:
            return n
        time.sleep(0.05)
    raise AssertionError(f"only {n} rows flushed in {timeout} s")


def stored(path: Path) -> dict:
    with h5py.File(path, "r") as f:  # h5py's default mode: what every ordinary tool does
        return {name: f[name][()] for name in SERIES}


def assert_same_rows(a: dict, b: dict):
    for name in SERIES:
        assert a[name].shape == b[name].shape, name
        assert np.array_equal(a[name], b[name]), name


# ---------------------------------------------------------------------------------------------
# 3. memory
_MEASURE = """
import sys
from se3dyn.cli.commands import main
code = main(sys.argv[1:])
hwm = [int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM")][0]
print("VmHWM", hwm, "exit", code)
"""


@pytest.mark.skipif(not LINUX, reason="reads /proc/self/status")
def test_streamed_run_memory_is_flat_over_a_million_steps(tmp_path):
    """10^5 and 10^6 steps of a tumbling body, every step stored: the peak resident memory of
    the whole process grows by less than 20 MB (it grew by about 3 kB a step before)."""
    (tmp_path / "body.yaml").write_text(BODY)
    peak = {}
    for n, t_end in ((10**5, 100), (10**6, 1000)):
        out = tmp_path / f"o{n}"
        p = subprocess.run([sys.executable, "-c", _MEASURE, "run", str(tmp_path / "body.yaml"),
                            "--t-end", str(t_end), "--out", str(out), "--quiet"],
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        assert "exit 0" in p.stdout
        peak[n] = int(p.stdout.split("VmHWM")[1].split()[0]) * 1024
        with h5py.File(out / "body.h5", "r") as f:
            assert f["time"].shape == (n + 1,)  # every step is in the file
            assert f["time"][-1] == t_end
        (out / "body.h5").unlink()
    growth = peak[10**6] - peak[10**5]
    assert growth <= 20 * 2**20, f"peak memory grew by {growth / 2**20:.1f} MB"


_IN_MEMORY = """
import sys
import se3dyn as sd
from se3dyn.io.modelfile import loads_model
def hwm():
    return [int(l.split()[1]) for l in open("/proc/self/status")
            if l.startswith("VmHWM")][0] * 1024
model, _ = loads_model(sys.argv[1])
s = sd.compile_model(model)
sd.simulate(s, 1.0, 1e-3)  # compiled and warm
h0 = hwm()
r = sd.simulate(s, 300.0, 1e-3)
own = sum(getattr(r, f).nbytes for f in ("t", "H", "v", "vd", "lam", "alpha", "kinetic",
          "potential", "spring", "work_actuators", "work_loads", "dissipation", "iterations",
          "residual", "constraint"))
print(len(r.t), own, hwm() - h0)
"""


@pytest.mark.skipif(not LINUX, reason="reads /proc/self/status")
def test_in_memory_results_cost_about_their_own_size():
    """3e5 stored rows: the peak memory of the run exceeds the size of the results by at most
    a third (the scalar columns are split at the end) plus 10 MB (twice their size before:
    copies on growth and a full copy at the end)."""
    p = subprocess.run([sys.executable, "-c", _IN_MEMORY, BODY], capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    n, own, growth = map(int, p.stdout.split())
    assert n == 300001
    assert growth <= 1.33 * own + 10 * 2**20, (own / 2**20, growth / 2**20)


@pytest.mark.skipif(not LINUX, reason="reads /proc")
def test_ten_million_steps_reserve_nothing_up_front_and_sigterm_closes_the_file(tmp_path):
    """A run of 1e7 steps starts without reserving memory for them (28 GB of address space
    before), and SIGTERM ends it like Ctrl-C: exit 143, one line, a complete file that h5py's
    default mode opens."""
    (tmp_path / "body.yaml").write_text(BODY)
    path = tmp_path / "o" / "body.h5"
    proc = start("run", tmp_path / "body.yaml", "--t-end", "1e4", "--out", tmp_path / "o",
                 "--quiet")
    try:
        wait_for_rows(path, proc, 2000)
        status = Path(f"/proc/{proc.pid}/status").read_text()
        peak = int(status.split("VmPeak:")[1].split()[0]) * 1024
        assert peak < 2 * 2**30, f"address space {peak / 2**30:.1f} GiB"
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 143, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "terminated" in lines[0] and str(path) in lines[0], err
    assert "--resume" in lines[0]
    with h5py.File(path, "r") as f:  # opens in the default (non-SWMR) mode
        assert bool(f.attrs["complete"]) and f.attrs["rows"] == f["time"].shape[0] > 2000
        assert f["stats"].attrs["message"] == "terminated"
    assert not Path(str(path) + ".lock").exists()


def test_streamed_results_keep_the_ends_and_summarise_every_row():
    m = sd.examples.slider_crank()
    full = sd.simulate(m, 1.0, 1e-3)
    blocks = []
    part = sd.simulate(m, 1.0, 1e-3, store=False, on_rows=lambda r, c: blocks.append(r))
    assert len(part.t) == 2 and part.t[0] == 0.0 and part.t[-1] == 1.0
    assert np.array_equal(part.H[-1], full.H[-1]) and np.array_equal(part.H[0], full.H[0])
    assert np.array_equal(np.concatenate([b.t for b in blocks]), full.t)
    assert np.array_equal(np.concatenate([b.lam for b in blocks]), full.lam)
    eb = full.energy_balance
    st = part.stats
    assert st["rows"] == len(full.t) == full.stats["rows"]
    assert st["energy_balance_error"] == np.abs(eb - eb[0]).max()
    assert st["max_energy"] == np.abs(full.total_energy).max()
    assert st["max_constraint"] == full.constraint.max()
    assert st["max_iterations"] == full.iterations.max()


# ---------------------------------------------------------------------------------------------
# 4c. restart from a state (API)
FIELDS = ("t", "H", "v", "vd", "lam", "alpha", "kinetic", "potential", "work_actuators",
          "dissipation", "iterations", "residual", "constraint")


@pytest.mark.parametrize("kw", [dict(), dict(output_every=7), dict(output_step=0.0013),
                                dict(tol=1e-6), dict(formulation="index3", rho_inf=0.8)],
                         ids=["fixed", "output_every", "output_step", "adaptive", "index3"])
def test_a_run_continued_from_a_checkpoint_equals_the_uninterrupted_run(kw, monkeypatch):
    # rows (with the newest checkpoint) are handed on at most every _EMIT_EVERY seconds in the
    # step-by-step runs, a checkpoint then replacing the one still waiting: emitting at every
    # chance makes the checkpoints seen independent of the machine's speed
    monkeypatch.setattr(sys.modules["se3dyn.dynamics.recorder"], "_EMIT_EVERY", 0.0)
    m = sd.examples.slider_crank()
    full = sd.simulate(m, 3.0, 1e-3, **kw)
    cps = []
    sd.simulate(m, 3.0, 1e-3, on_rows=lambda r, c: cps.append(c) if c else None, **kw)
    assert len(cps) >= 3
    for cp in (cps[1], cps[-2]):
        oe = kw.get("output_every", 1)  # every CHECKPOINT_EVERY steps, a multiple of oe
        assert isinstance(cp, Checkpoint)
        assert cp.steps % (oe * -(-CHECKPOINT_EVERY // oe)) == 0
        cont = sd.simulate(m, 3.0, 1e-3, initial_state=cp, **kw)
        # the first row of the continued run is the checkpoint's state (in a dense-output
        # run not a stored row), the others are the uninterrupted run's
        assert cont.t[0] == cp.state.t and np.array_equal(cont.H[0], cp.state.H)
        for f in FIELDS:
            assert np.array_equal(getattr(full, f)[cp.rows:], getattr(cont, f)[1:]), f


def test_final_state_continues_bit_for_bit_when_it_is_a_checkpoint():
    m = sd.examples.slider_crank()
    full = sd.simulate(m, 2.5, 1e-3)
    first = sd.simulate(m, 2.0, 1e-3)  # 2000 steps: a checkpoint at its end
    cont = sd.simulate(m, 2.5, 1e-3, initial_state=first.stats["final_state"])
    assert cont.t[0] == 2.0 and cont.stats["steps"] == 500
    for f in FIELDS:
        assert np.array_equal(np.concatenate([getattr(first, f), getattr(cont, f)[1:]]),
                              getattr(full, f)), f
    assert np.array_equal(cont.H[0], first.H[-1]) and cont.iterations[0] == 0


def test_initial_state_is_validated():
    m = sd.examples.slider_crank()
    res = sd.simulate(m, 0.1, 1e-2)
    st = res.stats["final_state"]
    with pytest.raises(sd.ModelError, match="initial_state.*State"):
        sd.simulate(m, 1.0, 1e-2, initial_state="nope")
    with pytest.raises(sd.ModelError, match=r"initial_state.*\[t_start, t_end\)"):
        sd.simulate(m, 0.1, 1e-2, initial_state=st)
    with pytest.raises(sd.ModelError, match="step time"):
        sd.simulate(m, 1.0, 0.03, initial_state=st)
    mb = sd.ModelBuilder()
    mb.node("b", mass=1.0, inertia=(1.0, 1.0, 1.0))
    with pytest.raises(sd.ModelError, match="initial_state.*shape"):
        sd.simulate(mb.build(), 1.0, 1e-2, initial_state=st)


# ---------------------------------------------------------------------------------------------
# 4a. one writer per file, no silent overwrite
def test_run_refuses_to_overwrite_a_results_file(tmp_path):
    args = ("run", PENDULUM, "--t-end", "0.1", "--out", tmp_path, "--quiet")
    assert run(*args).returncode == 0
    before = stored(tmp_path / "a01_simple_pendulum.h5")
    p = run(*args[:-3], "--t-end", "0.2", "--out", tmp_path, "--quiet")
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "--overwrite" in lines[0] and "a01_simple_pendulum.h5" in lines[0]
    assert_same_rows(stored(tmp_path / "a01_simple_pendulum.h5"), before)  # untouched
    p = run(*args, "--overwrite")
    assert p.returncode == 0, p.stderr
    assert stored(tmp_path / "a01_simple_pendulum.h5")["time"][-1] == 0.1


def test_a_second_writer_of_the_same_file_is_refused(tmp_path):
    path = tmp_path / "a01_simple_pendulum.h5"
    first = start("run", PENDULUM, "--t-end", "2000", "--step", "1e-3", "--out", tmp_path,
                  "--quiet")
    try:
        wait_for_rows(path, first, 100)
        p = run("run", PENDULUM, "--t-end", "1", "--out", tmp_path, "--overwrite", "--quiet")
        assert p.returncode == 2
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and "another se3dyn run" in lines[0] and str(path) in lines[0]
        assert f"process {first.pid}" in lines[0]
        with pytest.raises(ResultsFileError, match="another se3dyn run"):
            ResultsWriter(path, sd.compile_model(load_model(PENDULUM)[0]))
        assert first.poll() is None  # the first run goes on
        first.send_signal(signal.SIGTERM)
        first.communicate(timeout=60)
    finally:
        first.kill()
        first.wait()
    assert first.returncode == 143
    res = read_results(path)
    assert res.stats["complete"] and res.t[0] == 0.0 and len(res.t) >= 100
    np.testing.assert_allclose(np.diff(res.t), 1e-3, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# 4b. kill -9: repaired on first touch
def _killed_run(tmp_path: Path, t_end: str = "2000", rows: int = 3000) -> Path:
    path = tmp_path / "a01_simple_pendulum.h5"
    proc = start("run", PENDULUM, "--t-end", t_end, "--step", "1e-3", "--out", tmp_path,
                 "--quiet")
    try:
        wait_for_rows(path, proc, rows)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return path


def test_a_file_left_by_kill_9_is_repaired_by_the_next_command(tmp_path):
    path = _killed_run(tmp_path)
    with pytest.raises(OSError):  # flagged as still open: ordinary tools refuse it
        h5py.File(path, "r").close()
    p = run("channels", path)
    assert p.returncode == 0, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "repaired" in lines[0] and str(path) in lines[0], p.stderr
    assert "node/P1/position/x" in p.stdout.split()
    with h5py.File(path, "r") as f:  # now h5py's default mode opens it
        n = f["time"].shape[0]
        assert n >= 3000 and not bool(f.attrs["complete"])
    p = run("channels", path)
    assert p.returncode == 0 and p.stderr == ""  # repaired once
    res = read_results(path)
    assert len(res.t) == n and not res.stats["repaired"]
    assert repair(path) is False


# ---------------------------------------------------------------------------------------------
# 4c. --resume
def test_resume_after_kill_9_equals_one_uninterrupted_run(tmp_path):
    # (a run of 600 s, some 6 s of wall time: the writer flushes once a second, and a run
    # over before its first flush would leave nothing to kill; with 200 s, some 2 s, a parent
    # slowed by a loaded machine could see the first flush after the run had ended)
    killed = _killed_run(tmp_path / "k", t_end="600", rows=1000)
    p = run("run", PENDULUM, "--resume", killed)  # (not --quiet: its summary is read)
    assert p.returncode == 0, p.stderr
    assert "resumed at t = " in p.stdout
    assert run("run", PENDULUM, "--t-end", "600", "--step", "1e-3", "--out", tmp_path / "u",
               "--quiet").returncode == 0
    whole = tmp_path / "u" / "a01_simple_pendulum.h5"
    assert_same_rows(stored(killed), stored(whole))
    a, b = read_results(killed), read_results(whole)
    assert a.stats["complete"] and a.stats["steps"] == b.stats["steps"] == 600000
    assert a.stats["newton_iterations"] == b.stats["newton_iterations"]


def test_resume_of_a_finished_run_to_a_later_time_equals_one_run(tmp_path):
    a = ("--out", tmp_path / "a", "--quiet")
    assert run("run", PENDULUM, "--t-end", "3.3", *a).returncode == 0
    path = tmp_path / "a" / "a01_simple_pendulum.h5"
    p = run("run", PENDULUM, "--resume", path, "--t-end", "7", "--quiet")
    assert p.returncode == 0, p.stderr
    assert run("run", PENDULUM, "--t-end", "7", "--out", tmp_path / "b",
               "--quiet").returncode == 0
    assert_same_rows(stored(path), stored(tmp_path / "b" / "a01_simple_pendulum.h5"))
    assert read_results(path).stats["settings"]["t_end"] == 7.0
    # and once more, from the end of the continued run
    p = run("run", PENDULUM, "--resume", path, "--t-end", "9", "--quiet")
    assert p.returncode == 0, p.stderr
    assert run("run", PENDULUM, "--t-end", "9", "--out", tmp_path / "b", "--overwrite",
               "--quiet").returncode == 0
    assert_same_rows(stored(path), stored(tmp_path / "b" / "a01_simple_pendulum.h5"))


def test_resume_refuses_what_it_cannot_continue_in_one_line(tmp_path):
    assert run("run", PENDULUM, "--t-end", "1", "--out", tmp_path, "--quiet").returncode == 0
    path = tmp_path / "a01_simple_pendulum.h5"
    other = tmp_path / "other.yaml"
    other.write_text(PENDULUM.read_text().replace("mass: 1.0,", "mass: 2.0,"))
    cases = [
        (["run", other, "--resume", path], "not the model stored"),
        (["run", PENDULUM, "--resume", path, "--step", "1e-4"], "only --t-end"),
        (["run", PENDULUM, "--resume", path, "--overwrite"], "--overwrite"),
        (["run", PENDULUM, "--resume", path, "--t-end", "0.5"], "before the end of its rows"),
        (["run", PENDULUM, "--resume", tmp_path / "nope.h5"], "no such file"),
    ]
    for args, msg in cases:
        p = run(*args)
        assert p.returncode == 2, (args, p.stderr)
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and msg in lines[0], (args, p.stderr)
    p = run("run", PENDULUM, "--resume", path)  # complete to its t_end: nothing to do
    assert p.returncode == 0 and "complete" in p.stdout and p.stderr == ""
    with h5py.File(path, "r+") as f:  # a file of an older se3dyn: no checkpoints
        del f["restart"]
    p = run("run", PENDULUM, "--resume", path, "--t-end", "2")
    assert p.returncode == 2 and "no checkpoint" in p.stderr
    assert not Path(str(path) + ".lock").exists()


def test_a_half_written_checkpoint_is_passed_over(tmp_path):
    """kill -9 in the middle of a flush can leave the newest restart slot half written: its
    CRC fails and the run resumes from the other slot, still bit for bit."""
    m = sd.examples.slider_crank()
    s = sd.compile_model(m)
    path = tmp_path / "r.h5"
    with ResultsWriter(path, s, flush_interval=0.0) as w:  # a flush (and slot) per block
        sd.simulate(s, 3.0, 1e-3, on_rows=w.add_rows, store=False)
    with h5py.File(path, "r+") as f:
        slots = f["restart/state"]
        newest = int(np.argmax(slots[:, 0]))
        older = slots[1 - newest]
        assert older[0] == slots[newest, 0] - 1  # both slots in use
        bad = slots[newest]
        bad[20] += 1.0  # a value of the state
        slots[newest] = bad
    w = ResultsWriter.resume(path, s)
    assert w.checkpoint.steps == int(older[2]) and w.rows == int(older[1])
    with w:
        sd.simulate(s, 3.0, 1e-3, initial_state=w.checkpoint, on_rows=w.add_rows, store=False)
    full = sd.simulate(s, 3.0, 1e-3)
    back = read_results(path)
    for f in FIELDS:
        assert np.array_equal(getattr(back, f), getattr(full, f)), f
