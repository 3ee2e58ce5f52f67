"""`pip install .` of the checkout into a fresh venv, as docs/python.md says, then `import gaia` from elsewhere."""
import os
import pathlib
import subprocess
import sys

import pytest

from conftest import ROOT


def test_pip_install_of_the_checkout_imports_in_a_fresh_venv(tmp_path):
    build = os.environ.get("GAIA_BUILD_DIR")
    if not build:
        pytest.skip("GAIA_BUILD_DIR is not set (ctest sets it): no build to package")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    py = venv / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["GAIA_BUILD_DIR"] = build
    r = subprocess.run([str(py), "-m", "pip", "install", "--no-build-isolation", "--no-index", "--no-deps", "-q",
                        str(ROOT)], env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    r = subprocess.run([str(py), "-c", "import gaia, gaia.env; print(gaia.__file__); print(gaia.Tokenizer.__doc__)"],
                       env=env, cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    where = pathlib.Path(r.stdout.splitlines()[0])
    assert venv in where.parents, where  # the installed copy, not the build's
    assert "image tokenizer" in r.stdout
