"""tools/codec_reference.py: HEVC intra at a bit budget, the reference column of the tokenizer's figures."""
import shutil
import subprocess
import sys

import numpy as np
import pytest

import gaia
from conftest import ROOT

sys.path.insert(0, str(ROOT / "tools"))
import codec_reference  # noqa: E402


@pytest.fixture(scope="module")
def frames(drive):
    if not shutil.which("ffmpeg") or "libx265" not in subprocess.run(
            ["ffmpeg", "-hide_banner", "-encoders"], capture_output=True, text=True).stdout:
        pytest.skip("ffmpeg with libx265 is not installed (scripts/setup.sh installs it)")
    ep = gaia.Dataset(str(drive["episodes"]))[0]
    return np.stack([ep.frames(i, i + 1)[0] for i in (0, 50, 100, 150)])


def test_finer_settings_cost_more_bits_and_give_higher_psnr(frames, tmp_path):
    points = codec_reference.curve(frames, str(tmp_path), crfs=(20, 35, 51))
    bits = [p[1] for p in points]
    db = [p[2] for p in points]
    assert bits[0] > bits[1] > bits[2] > 0
    assert db[0] > db[1] > db[2] > 10
    r = codec_reference.reference(points, bits=1e9, target_db=30)
    assert r["psnr_at_budget"] == db[0]  # everything fits: the finest
    assert r["fewest_bits"] == bits[2]
    # A budget between two settings takes the finer one that fits; none fits one bit.
    mid = codec_reference.reference(points, bits=(bits[0] + bits[1]) / 2, target_db=db[1])
    assert mid["psnr_at_budget"] == db[1] and mid["bits_for_target"] == bits[1]
    none = codec_reference.reference(points, bits=1, target_db=99)
    assert none["psnr_at_budget"] is None and none["bits_for_target"] is None


def test_psnr_is_the_mean_of_each_frames(frames):
    noisy = frames.copy()
    noisy[0] ^= 1  # one frame off by one level where the low bit flips
    one = 10 * np.log10(255.0 ** 2 / ((noisy[0].astype(float) - frames[0]) ** 2).mean())
    same = 10 * np.log10(255.0 ** 2 / 1e-10)
    assert codec_reference.psnr(frames, noisy) == pytest.approx((one + 3 * same) / 4)
