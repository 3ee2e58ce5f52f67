"""The module loads with every class; where it was not built, the suite skips here with one message."""
import pytest

gaia = pytest.importorskip("gaia", reason="the gaia Python module was not built (it needs pybind11-dev, python3-dev "
                                          "and python3-numpy; scripts/setup.sh installs them): nothing to test")


def test_the_module_offers_its_classes():
    for name in ["Tokenizer", "WorldModel", "Sim", "Session", "Dataset", "Episode", "VideoDecoder"]:
        assert getattr(gaia, name).__doc__, name
    from gaia.env import DrivingEnv
    assert callable(DrivingEnv.reset) and callable(DrivingEnv.step)
    before = gaia.threads()
    gaia.set_threads(2)
    assert gaia.threads() == 2
    gaia.set_threads(before)
    with pytest.raises(ValueError, match="threads: at least 1"):
        gaia.set_threads(0)
