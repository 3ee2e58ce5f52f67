"""The Python examples of docs/python.md and the README run as written, in order, against a short drive; their
rollouts are cut to a few frames (SHORTER) so that the suite stays short: every call still runs as the docs write it."""
import os
import re
import shutil
import subprocess
import sys

import pytest

import gaia
from conftest import ROOT


# The lengths the docs show a user, and the ones the test runs: each must be in the docs, so an edit there is seen.
SHORTER = {"frames=16": "frames=3", "futures=3": "futures=2"}


def blocks(path):
    return re.findall(r"```python\n(.*?)```", (ROOT / path).read_text(), re.S)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, drive, models):
    """runs/synth72 and runs/tokens72 (the docs' names) for the test's drive, models/, and a drive.mp4."""
    if not shutil.which("ffmpeg"):
        pytest.skip("ffmpeg is not installed (scripts/setup.sh installs it)")
    d = tmp_path_factory.mktemp("docs")
    (d / "runs").mkdir()
    os.symlink(drive["episodes"], d / "runs" / "synth72")
    os.symlink(drive["tokens"], d / "runs" / "tokens72")
    os.symlink(models, d / "models")
    frames = gaia.Dataset(str(drive["episodes"]))[0].frames(0, 100)
    subprocess.run(["ffmpeg", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", "128x72", "-r",
                    "25", "-i", "-", "-pix_fmt", "yuv420p", str(d / "drive.mp4")], input=frames.tobytes(), check=True)
    return d


@pytest.mark.parametrize("doc", ["docs/python.md", "README.md"])
def test_the_examples_run_as_written(workdir, doc):
    code = "\n".join(blocks(doc))
    assert "import gaia" in code
    for written, run in SHORTER.items():
        assert written in code, f"{doc} no longer has {written}: update SHORTER"
        code = code.replace(written, run)
    r = subprocess.run([sys.executable, "-c", "import gaia; gaia.set_threads(1)\n" + code], cwd=workdir,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"{doc}:\n{r.stderr[-3000:]}"
