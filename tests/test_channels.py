"""Channel names over results, in memory and read back from a file."""

from __future__ import annotations

import numpy as np
import pytest

import se3dyn as sd
from se3dyn.results.channels import (
    channel_unit,
    escape_name,
    get_channel,
    list_channels,
    unescape_name,
)


def _model() -> sd.Model:
    mb = sd.ModelBuilder(gravity=(0.0, 0.0, -9.81), name="cardan_pendulum")
    mb.node("ground", fixed=True)
    mb.node("hub", mass=0.1, inertia=(1e-3, 1e-3, 1e-3))
    mb.node("arm/tip%", position=(0.3, 0.1, 0.0), mass=1.0, inertia=(1e-2, 2e-2, 3e-2))
    mb.joint("cardan", "universal", "ground", "hub", axes=[(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)])
    mb.joint("link", "rigid", "hub", "arm/tip%")
    return mb.build()


@pytest.fixture(scope="module")
def crank():
    return sd.simulate(sd.examples.slider_crank(), 0.2, 1e-2)


@pytest.fixture(scope="module")
def cardan():
    return sd.simulate(_model(), 0.2, 1e-2)


def test_every_listed_channel_resolves(crank, cardan):
    for res in (crank, cardan):
        names = list_channels(res)
        assert len(names) == len(set(names))
        for name in names:
            x = get_channel(res, name)
            assert x.shape == (len(res),), name
            assert isinstance(channel_unit(name, res), str)


def test_values_match_accessors(crank):
    np.testing.assert_array_equal(get_channel(crank, "node/6/position/x"),
                                  crank.node_position("6")[:, 0])
    d = get_channel(crank, "node/6/displacement/z")
    assert d[0] == 0.0 and np.any(d != 0.0)
    z = crank.node_position("6")[:, 2]
    np.testing.assert_array_equal(d, z - z[0])
    np.testing.assert_array_equal(get_channel(crank, "joint/1/alpha/0"),
                                  crank.joint_coordinates("1")[:, 0])
    np.testing.assert_array_equal(get_channel(crank, "joint/8/velocity/1"),
                                  crank.joint_velocities("8")[:, 1])
    np.testing.assert_array_equal(get_channel(crank, "joint/4/multiplier/5"),
                                  crank.joint_multipliers("4")[:, 5])
    np.testing.assert_array_equal(get_channel(crank, "node/3/velocity/inertial/wx"),
                                  crank.node_velocity("3", frame="inertial")[:, 3])
    np.testing.assert_array_equal(get_channel(crank, "node/3/rotation/R23"),
                                  crank.node_rotation("3")[:, 1, 2])
    np.testing.assert_array_equal(get_channel(crank, "energy/total"), crank.total_energy)
    np.testing.assert_array_equal(get_channel(crank, "energy/balance"), crank.energy_balance)
    np.testing.assert_array_equal(get_channel(crank, "solver/iterations"), crank.iterations)
    np.testing.assert_array_equal(get_channel(crank, "time"), crank.t)
    # a clamped node has zero velocity
    assert not np.any(get_channel(crank, "node/1/velocity/material/x"))


def test_composite_joint_and_escaped_names(cardan):
    names = list_channels(cardan)
    assert "joint/cardan/alpha/1" in names and "joint/cardan/multiplier/11" in names
    assert not any(n.startswith("joint/cardan:") for n in names)  # parts via the composite
    esc = escape_name("arm/tip%")
    assert esc == "arm%2Ftip%25" and unescape_name(esc) == "arm/tip%"
    assert f"node/{esc}/position/y" in names
    np.testing.assert_array_equal(get_channel(cardan, f"node/{esc}/position/y"),
                                  cardan.node_position("arm/tip%")[:, 1])
    np.testing.assert_array_equal(get_channel(cardan, "joint/cardan/alpha/1"),
                                  cardan.joint_coordinates("cardan")[:, 1])
    assert channel_unit("joint/cardan/alpha/0", cardan) == "rad"
    assert channel_unit("joint/cardan/velocity/0", cardan) == "rad/s"


@pytest.mark.parametrize("name", ["a", "a/b", "%2F", "50%", "x%25y/z", "//", ""])
def test_escaping_round_trips(name):
    e = escape_name(name)
    assert "/" not in e and unescape_name(e) == name


def test_unknown_channel_suggests(crank):
    with pytest.raises(KeyError, match="did you mean.*node/6/position/x"):
        get_channel(crank, "node/6/positon/x")
    with pytest.raises(KeyError, match="did you mean.*energy/kinetic"):
        get_channel(crank, "energy/kinetik")
    for bad in ("node/99/position/x", "joint/1/alpha/1", "joint/1/multiplier/6", "nope",
                "joint/zz/alpha/0", "node/6/velocity/body/x"):
        with pytest.raises(KeyError, match="unknown channel"):
            get_channel(crank, bad)


def test_units(crank):
    assert channel_unit("node/6/position/x") == "m"
    assert channel_unit("node/6/velocity/material/wy") == "rad/s"
    assert channel_unit("node/6/velocity/inertial/y") == "m/s"
    assert channel_unit("energy/kinetic") == "J"
    assert channel_unit("solver/iterations") == ""
    assert channel_unit("joint/4/multiplier/2") == "N"
    assert channel_unit("joint/4/multiplier/4") == "N m"
    assert channel_unit("joint/8/alpha/0", crank) == "m"  # cylindrical: translation along x
    assert channel_unit("joint/8/alpha/1", crank) == "rad"
    assert channel_unit("joint/1/velocity/0", crank) == "rad/s"


def test_channels_of_read_results_equal_in_memory(tmp_path):
    pytest.importorskip("h5py")
    from se3dyn.io.h5 import ResultsWriter, read_results

    s = sd.compile_model(_model())
    with ResultsWriter(tmp_path / "c.h5", s) as w:
        res = sd.simulate(s, 0.1, 1e-2, on_output=w.append)
    back = read_results(tmp_path / "c.h5")
    assert list_channels(back) == list_channels(res)
    for name in list_channels(res):
        np.testing.assert_array_equal(get_channel(back, name), get_channel(res, name))
        assert channel_unit(name, back) == channel_unit(name, res)
