"""gaia.Tokenizer and gaia.Dataset: arrays in and out (dtype, shape, no copies), the CLI's tokens, clear errors."""
import json
import sys

import numpy as np
import pytest

import gaia


def test_encode_gives_the_tokens_of_gaia_tokenize(drive, tokenizer):
    eps = gaia.Dataset(str(drive["episodes"]))
    toks = gaia.Dataset(str(drive["tokens"]))
    assert eps.kind == "episodes" and toks.kind == "tokens" and len(eps) == len(toks) == 1
    ep, tep = eps[0], toks[0]
    step_frames = json.loads((drive["tokens"] / "episodes" / tep.id / "episode.json").read_text())["frames"]
    frames = ep.frames()
    assert frames.dtype == np.uint8 and frames.shape == (len(ep), 72, 128, 3)
    z = tokenizer.encode(frames[step_frames])
    assert z.dtype == np.int16 and z.shape == (len(step_frames), 9, 16)
    np.testing.assert_array_equal(z, tep.tokens)  # the module and `gaia tokenize`, token for token
    np.testing.assert_array_equal(tokenizer.encode(frames[step_frames[0]]), z[0])  # one frame: [h, w]
    # Any positive strides are read in place: every other frame of the episode, and a Fortran-ordered copy.
    np.testing.assert_array_equal(tokenizer.encode(frames[::2][:5]), tokenizer.encode(np.ascontiguousarray(frames[:10:2])))
    np.testing.assert_array_equal(tokenizer.encode(np.asfortranarray(frames[:3])), tokenizer.encode(frames[:3]))
    assert tokenizer.grid == (9, 16) and tokenizer.frame_size == (72, 128) and tokenizer.K == 1024


def test_decode_gives_frames_close_to_the_encoded_ones(tokenizer, drive):
    frames = gaia.Dataset(str(drive["episodes"]))[0].frames(0, 48)[::8]
    tokens = tokenizer.encode(frames)
    again = tokenizer.decode(tokens)
    assert again.dtype == np.uint8 and again.shape == (6, 72, 128, 3) and again.flags.c_contiguous
    mse = np.mean((again.astype(np.float64) - frames) ** 2)
    assert 10 * np.log10(255 ** 2 / mse) > 20  # the shipped tokenizer's procedural PSNR is about 25 dB
    # One frame alone or in a batch: the same up to the products' float rounding (batch sizes take other kernels)
    assert np.abs(tokenizer.decode(tokens[0]).astype(int) - again[0]).max() <= 1
    np.testing.assert_array_equal(tokenizer.decode(tokens.astype(np.int64)), again)  # any integer dtype


def test_arrays_come_out_without_a_copy_and_outlive_their_source(tokenizer, drive):
    tokens = gaia.Dataset(str(drive["tokens"]))[0].tokens[:2]
    frames = tokenizer.decode(tokens)
    assert frames.base is not None and not frames.flags.owndata  # a view over the tensor's memory
    before = sys.getrefcount(frames.base)
    view = frames[0]
    assert sys.getrefcount(frames.base) >= before
    del frames
    assert view.shape == (72, 128, 3) and int(view.sum()) > 0  # the memory lives as long as a view of it
    torch = pytest.importorskip("torch", reason="python3-torch is not installed")
    t = torch.from_numpy(tokenizer.encode(tokenizer.decode(tokens)))
    assert t.dtype == torch.int16 and tuple(t.shape) == (2, 9, 16)


def test_bad_arrays_and_files_are_one_clear_error(tokenizer, tmp_path, models):
    with pytest.raises(ValueError, match=r"frames: uint8 of shape \[\*, 72, 128, 3\] or \[72, 128, 3\] expected, got dtype float32"):
        tokenizer.encode(np.zeros((2, 72, 128, 3), np.float32))
    with pytest.raises(ValueError, match=r"got shape \[2, 64, 128, 3\]"):
        tokenizer.encode(np.zeros((2, 64, 128, 3), np.uint8))
    with pytest.raises(ValueError, match="positive, aligned strides"):
        tokenizer.encode(np.zeros((2, 72, 128, 3), np.uint8)[::-1])
    z = np.zeros((1, 9, 16), np.int16)
    z[0, 0, 0] = 5000
    with pytest.raises(ValueError, match=r"tokens: ids in \[0, 1024\) expected, got 0..5000"):
        tokenizer.decode(z)
    with pytest.raises(ValueError, match="tokens: an integer dtype"):
        tokenizer.decode(np.zeros((1, 9, 16), np.float32))
    with pytest.raises(FileNotFoundError, match="tokenizer: no such file or directory: .*nowhere.safetensors"):
        gaia.Tokenizer(str(tmp_path / "nowhere.safetensors"))
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"\x10\x00\x00\x00\x00\x00\x00\x00{not json at all}")
    with pytest.raises(ValueError, match="bad.safetensors"):
        gaia.Tokenizer(str(bad))
    with pytest.raises(ValueError):  # a world model's weights are not a tokenizer's
        gaia.Tokenizer(str(models / "world.safetensors"))


def test_dataset_reads_signals_captions_and_metadata(drive):
    eps, toks = gaia.Dataset(str(drive["episodes"])), gaia.Dataset(str(drive["tokens"]))
    ep = eps[eps.ids[0]]
    assert ep.id == eps.ids[0] == toks.ids[0]
    assert ep.speed.dtype == np.float32 and ep.speed.shape == (len(ep),)
    assert ep.curvature.shape == (len(ep),) and ep.time_s.dtype == np.float64
    assert np.all(np.diff(ep.time_s) > 0) and np.all(np.isfinite(ep.speed))
    assert ep.actions.shape == (len(ep), 2)
    assert ep.metadata["fps"] == 25 and ep.metadata["signals_source"] == "synth"
    assert len(ep.captions) == len(ep) and all(isinstance(c, str) for c in ep.captions)
    tep = toks[0]
    assert len(tep) == len(tep.tokens) == len(tep.speed) and toks.grid == (9, 16) and toks.rate_hz == 6.25
    # A step's speed is the mean over its frames (gaia tokenize): within the drive's range.
    assert ep.speed.min() - 1e-4 <= tep.speed.min() and tep.speed.max() <= ep.speed.max() + 1e-4
    assert tep.time_s is None
    with pytest.raises(ValueError, match="holds frames, not tokens"):
        ep.tokens
    with pytest.raises(ValueError, match="holds tokens, not frames"):
        tep.frames()
    with pytest.raises(KeyError, match="no episode 'nowhere'"):
        eps["nowhere"]
    with pytest.raises(IndexError):
        eps[5]
    assert [e.id for e in eps] == eps.ids and eps[-1].id == eps.ids[-1]
    with pytest.raises(FileNotFoundError):
        gaia.Dataset(str(drive["dir"] / "missing"))
