"""Shared fixtures of the Python module's tests: the shipped models, a short procedural drive made with the gaia
binary (`gaia synth`, then `gaia tokenize` with the shipped tokenizer), and the binary itself for cross-checks."""
import json
import os
import pathlib
import shutil
import subprocess
import tempfile

import numpy as np
import pytest

try:
    import gaia
except ImportError:  # test_module.py skips with one message; the other files are not collected
    gaia = None
    collect_ignore_glob = ["test_[!m]*.py"]

ROOT = pathlib.Path(os.environ.get("GAIA_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))
MODELS = ROOT / "models"
BINARY = os.environ.get("GAIA_BINARY") or shutil.which("gaia")


def run_gaia(*args, stdin=None):
    """The gaia binary at one thread (as the module is run in these tests), its output on failure."""
    if not BINARY:
        pytest.skip("no gaia binary (GAIA_BINARY) to cross-check against")
    r = subprocess.run([BINARY, *map(str, args), "--threads", "1"], input=stdin, capture_output=True, text=True)
    assert r.returncode == 0, f"gaia {' '.join(map(str, args))}:\n{r.stdout}\n{r.stderr}"
    return r.stdout


@pytest.fixture(autouse=True, scope="session")
def one_thread():
    if gaia:
        gaia.set_threads(1)  # the CLI's tokens are compared at one thread


@pytest.fixture(scope="session")
def models():
    if not (MODELS / "world.safetensors").exists():
        pytest.skip(f"no shipped models in {MODELS}")
    return MODELS


def shared_fixture(name, inputs, build):
    """A directory made once for every pytest process of a build (ctest runs two at once), as the C++ tests'
    test::shared_fixture: under the build's test-fixtures/, behind a lock, made again when an input file changes."""
    import fcntl
    root = pathlib.Path(os.environ["GAIA_BUILD_DIR"]) / "test-fixtures" if os.environ.get("GAIA_BUILD_DIR") else None
    if root is None:  # run by hand without a build directory: a fresh one for this process
        d = pathlib.Path(tempfile.mkdtemp(prefix=name))
        build(d)
        return d
    root.mkdir(parents=True, exist_ok=True)
    d, stamp = root / name, root / name / ".built-for"
    key = " ".join(f"{os.stat(f).st_mtime_ns}.{os.stat(f).st_size}" for f in inputs)
    with open(root / (name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released as the file closes
        if stamp.exists() and stamp.read_text() == key:
            return d
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir()
        build(d)
        stamp.write_text(key)
    return d


@pytest.fixture(scope="session")
def drive(models):
    """An 8-second procedural drive (episodes) and its tokens through the shipped tokenizer."""
    def build(d):
        run_gaia("synth", "--episodes", "1", "--seconds", "8", "--scene", "bend", "--seed", "3", "--out", d / "ds")
        run_gaia("tokenize", d / "ds", "--tokenizer", models / "tokenizer.safetensors", "--out", d / "tokens")
    d = shared_fixture("python-drive", [BINARY, models / "tokenizer.safetensors"] if BINARY else [], build)
    return {"episodes": d / "ds", "tokens": d / "tokens", "dir": d}


@pytest.fixture(scope="session")
def tokenizer(models):
    return gaia.Tokenizer(str(models / "tokenizer.safetensors"))


@pytest.fixture(scope="session")
def world(models):
    return gaia.WorldModel(str(models / "world.safetensors"))


def read_rollout(path):
    """tokens of a rollout.safetensors (int32 [futures, steps, h, w]), read with NumPy alone."""
    raw = pathlib.Path(path).read_bytes()
    n = int.from_bytes(raw[:8], "little")
    header = json.loads(raw[8:8 + n])
    t = header["tokens"]
    a, b = t["data_offsets"]
    dtype = {"I32": np.int32, "I16": np.int16, "I64": np.int64}[t["dtype"]]
    return np.frombuffer(raw[8 + n + a:8 + n + b], dtype=dtype).reshape(t["shape"])
