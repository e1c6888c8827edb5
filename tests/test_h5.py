"""HDF5 results files: streaming writer, reader, kill -9 robustness, clear errors."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

h5py = pytest.importorskip("h5py")

import se3dyn as sd  # noqa: E402
from se3dyn.io.h5 import FORMAT_VERSION, ResultsFileError, ResultsWriter, read_results  # noqa: E402
from se3dyn.io.modelfile import loads_model, save_model  # noqa: E402

SRC = str(Path(__file__).resolve().parents[1] / "src")


def universal_model() -> sd.Model:
    """A body hung on a universal joint (a composite joint) from a clamped node; the tip node
    name contains a '/'."""
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name="cardan_pendulum")
    mb.node("ground", position=(0.0, 0.0, 0.0), fixed=True)
    mb.node("hub", position=(0.0, 0.0, 0.0), mass=0.1, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("arm/tip", position=(0.3, 0.1, 0.0), mass=1.0, inertia=(1e-2, 2e-2, 3e-2))
    mb.joint("cardan", "universal", "ground", "hub", axes=[(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)])
    mb.joint("link", "rigid", "hub", "arm/tip")
    return mb.build()


def _simulate_to_file(model, path, t_end, step, **kw):
    s = sd.compile_model(model)
    with ResultsWriter(path, s, settings={"t_end": t_end, "step": step}, **kw) as w:
        res = sd.simulate(s, t_end, step, on_output=w.append)
        w.close(res.stats)
    return res


def _assert_same_accessors(a: sd.Results, b: sd.Results):
    s = a.system
    np.testing.assert_array_equal(a.t, b.t)
    for name in s.node_names:
        np.testing.assert_array_equal(a.node_position(name), b.node_position(name))
        np.testing.assert_array_equal(a.node_rotation(name), b.node_rotation(name))
        np.testing.assert_array_equal(a.node_frame(name), b.node_frame(name))
        for frame in ("material", "inertial"):
            np.testing.assert_array_equal(a.node_velocity(name, frame=frame),
                                          b.node_velocity(name, frame=frame))
            np.testing.assert_array_equal(a.node_acceleration(name, frame=frame),
                                          b.node_acceleration(name, frame=frame))
    for name in list(s.joint_names) + list(s.composites):
        np.testing.assert_array_equal(a.joint_coordinates(name), b.joint_coordinates(name))
        np.testing.assert_array_equal(a.joint_velocities(name), b.joint_velocities(name))
        np.testing.assert_array_equal(a.joint_multipliers(name), b.joint_multipliers(name))
    for arr in ("H", "v", "vd", "lam", "alpha", "kinetic", "potential", "spring",
                "work_actuators", "work_loads", "dissipation", "iterations", "residual",
                "constraint", "total_energy", "energy_balance"):
        x, y = getattr(a, arr), getattr(b, arr)
        assert x.shape == y.shape, arr
        np.testing.assert_array_equal(x, y, err_msg=arr)
    assert b.iterations.dtype.kind == "i"


@pytest.mark.parametrize("make", [sd.examples.slider_crank, universal_model])
def test_round_trip_equals_in_memory_results(tmp_path, make):
    model = make()
    path = tmp_path / "res.h5"
    res = _simulate_to_file(model, path, 0.3, 1e-2)
    back = read_results(path)
    assert len(back) == len(res) == 31
    _assert_same_accessors(res, back)
    assert back.stats["complete"] is True
    assert back.stats["steps"] == res.stats["steps"] == 30
    assert back.stats["newton_iterations"] == res.stats["newton_iterations"]
    assert back.stats["failed"] is False
    assert back.stats["settings"] == {"t_end": 0.3, "step": 1e-2}
    assert back.stats["se3dyn_version"] == sd.__version__
    # the stored model text loads back to the same model (saving it again gives the same text)
    m2, _ = loads_model(back.stats["model"])
    assert save_model(m2) == save_model(model)
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "se3dyn-results"
        assert f.attrs["format_version"] == FORMAT_VERSION
        assert f["nodes/rotation"].shape == (31, len(model.nodes), 3, 3)
        assert f["nodes/position"].chunks[0] > 1 and f["time"].maxshape == (None,)


def test_model_with_python_callable_stores_empty_model_text(tmp_path):
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    mb.node("g", fixed=True)
    mb.node("b", position=(0.2, 0.0, 0.0), mass=1.0, inertia=(1.0, 1.0, 1.0))
    mb.joint("h", "hinge", "g", "b", axis=(0.0, 1.0, 0.0),
             torque=sd.Callable(lambda t: 0.0 * t))
    model = mb.build()
    with pytest.raises(sd.ModelError):
        save_model(model)
    path = tmp_path / "cb.h5"
    _simulate_to_file(model, path, 0.05, 1e-2)
    back = read_results(path)
    assert back.stats["model"] == ""
    assert len(back) == 6


def test_writer_context_manager_marks_failure(tmp_path):
    path = tmp_path / "fail.h5"
    s = sd.compile_model(sd.examples.slider_crank())
    with pytest.raises(RuntimeError, match="boom"):
        with ResultsWriter(path, s) as w:
            sd.simulate(s, 0.05, 1e-2, on_output=w.append)
            raise RuntimeError("boom")
    back = read_results(path)
    assert back.stats["complete"] is True and back.stats["failed"] is True
    assert "boom" in back.stats["failure"]
    assert len(back) == 6


_CHILD = """
import sys
import se3dyn as sd
from se3dyn.io.h5 import ResultsWriter
s = sd.compile_model(sd.examples.slider_crank())
w = ResultsWriter(sys.argv[1], s, flush_interval=0.2)
sd.simulate(s, 3600.0, 1e-3, on_output=w.append, store=False)   # (killed long before)
w.close()
"""


def test_kill_9_leaves_a_readable_consistent_file(tmp_path):
    path = tmp_path / "killed.h5"
    env = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(path)], env=env)
    try:
        seen = 0
        # (the writer runs for an hour of model time, minutes of CPU: it is still running when
        # killed however slow or loaded the machine; a bound of 20 s on the first flush and a
        # run of 60 s model time, about 1.5 s, made this test depend on the machine's load)
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and seen < 100:
            time.sleep(0.05)
            assert proc.poll() is None, "writer ended before it was killed"
            try:
                seen = len(read_results(path))  # reading while the writer appends
            except ResultsFileError:
                pass  # not created yet
        assert seen >= 100, "no rows were flushed within 120 s"
        time.sleep(0.3)  # mid-run, usually between two flushes
        assert proc.poll() is None, "writer ended before it was killed"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    res = read_results(path)
    n = len(res)
    assert n >= seen  # nothing flushed is lost
    assert n < 3600001
    assert res.stats["complete"] is False
    assert res.t[0] == 0.0
    np.testing.assert_allclose(np.diff(res.t), 1e-3, rtol=0, atol=1e-12)
    # every row is a whole state: the spherical joint keeps nodes 4 and 5 together, every frame
    # is a rotation, and energy-like columns are finite
    np.testing.assert_allclose(res.node_position("4"), res.node_position("5"), rtol=0,
                               atol=1e-9)
    R = res.H[:, :, :3, :3]
    np.testing.assert_allclose(np.einsum("nmji,nmjk->nmik", R, R),
                               np.broadcast_to(np.eye(3), R.shape), atol=1e-9)
    assert np.all(res.H[:, :, 3, 3] == 1.0)
    for arr in (res.kinetic, res.potential, res.residual, res.constraint, res.lam, res.v):
        assert np.all(np.isfinite(arr))
    assert np.all(res.iterations[1:] >= 1)  # each stored step really ran Newton


def test_missing_file(tmp_path):
    path = tmp_path / "nope.h5"
    with pytest.raises(ResultsFileError, match="nope.h5"):
        read_results(path)


def test_text_file(tmp_path):
    path = tmp_path / "notes.h5"
    path.write_text("hello\n")
    with pytest.raises(ResultsFileError, match="notes.h5.*not an HDF5 file"):
        read_results(path)


def test_other_hdf5_file(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(ResultsFileError, match="other.h5.*format"):
        read_results(path)


def test_newer_format_version(tmp_path):
    path = tmp_path / "new.h5"
    _simulate_to_file(sd.examples.slider_crank(), path, 0.02, 1e-2)
    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = FORMAT_VERSION + 1
    with pytest.raises(ResultsFileError, match="new.h5.*newer"):
        read_results(path)


def test_errors_are_se3dyn_and_value_errors(tmp_path):
    with pytest.raises(sd.Se3dynError):
        read_results(tmp_path / "x.h5")
    with pytest.raises(ValueError):
        read_results(tmp_path / "x.h5")


def test_core_package_does_not_import_h5():
    code = ("import sys, se3dyn; "
            "assert 'se3dyn.io.h5' not in sys.modules and 'h5py' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True,
                   env={**os.environ, "PYTHONPATH": SRC})
