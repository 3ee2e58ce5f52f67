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


def test_importing_gaia_after_numpy_still_runs_openblas_kernels_for_this_cpu():
    # NumPy loads the OpenBLAS that LibTorch uses; where it fell back to its oldest kernels on a CPU it does not
    # know, gaia switches it as it loads (the last "Core:" line OpenBLAS prints); a core type the user set stands.
    import os
    import subprocess
    import sys
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    env["OPENBLAS_VERBOSE"] = "2"

    def last_core(extra):
        out = subprocess.run([sys.executable, "-c", "import numpy, gaia"], env=dict(env, **extra),
                             capture_output=True, text=True, check=True)
        lines = [ln for ln in (out.stdout + out.stderr).splitlines() if ln.startswith("Core: ")]
        return lines[-1][6:].lower() if lines else None

    core = last_core({})
    if core is None:
        pytest.skip("this OpenBLAS says nothing of its kernels")
    flags = open("/proc/cpuinfo").read()
    if " avx2 " in flags and " fma " in flags:
        assert core in {"haswell", "zen", "skylakex", "cooperlake", "sapphirerapids"}
    assert last_core({"OPENBLAS_CORETYPE": "Prescott"}) == "prescott"
