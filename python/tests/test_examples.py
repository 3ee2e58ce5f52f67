"""The Python examples run in-process (briefly) and print their scores."""
import re
import subprocess
import sys

import pytest

from conftest import ROOT


def run_example(name, *args):
    r = subprocess.run([sys.executable, str(ROOT / "examples" / name), *args], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


def test_the_in_process_lane_keeper_drives_and_scores(models, drive):
    out = run_example("lane_keeper_inprocess.py", "--tokens", str(drive["tokens"]), "--seconds", "3")
    assert re.search(r"read-back against the plan over \d+ steps: curvature Spearman", out), out
    assert re.search(r"19 steps in [0-9.]+ s: [0-9.]+ frames/s", out), out


def test_the_torch_policy_learns_and_is_scored_against_the_scripted_one(models):
    pytest.importorskip("torch", reason="python3-torch is not installed (scripts/setup.sh installs it)")
    out = run_example("torch_policy.py", "--steps", "16", "--episode-steps", "8", "--eval-episodes", "1")
    assert len(re.findall(r"^episode +\d+ +steps", out, re.M)) == 2, out
    m = re.search(r"learned (-?[0-9.]+), scripted (-?[0-9.]+)", out)
    assert m and float(m.group(1)) <= 0 and float(m.group(2)) <= 0, out
