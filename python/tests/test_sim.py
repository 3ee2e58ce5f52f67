"""gaia.Sim: sessions token for token as `gaia sim --stdio` steps them, frames and read-back as it answers them,
fork, fork along plans, reset; a thousand-step session's memory stays flat."""
import json
import resource

import numpy as np
import pytest

import gaia
from conftest import run_gaia


@pytest.fixture(scope="module")
def sim(world, tokenizer, models):
    return gaia.Sim(world, tokenizer, probe=str(models / "probe-dynamics.safetensors"))


COMMANDS = [(8.0, 0.01), (8.0, 0.01), (9.0, -0.02), (7.5, 0.0), (8.0, 0.033), (8.0, 0.033)]


def test_a_session_gives_the_tokens_frames_and_read_back_of_gaia_sim(sim, drive, models, tokenizer):
    lines = [{"op": "create", "prompt": {"episode": 0, "start": 2, "frames": 3}, "seed": 11, "guidance": 8}]
    lines += [{"op": "step", "session": 1, "speed": v, "curvature": c, "frame": "png"} for v, c in COMMANDS]
    out = run_gaia("sim", drive["tokens"], "--world", models / "world.safetensors", "--tokenizer",
                   models / "tokenizer.safetensors", "--probe", models / "probe-dynamics.safetensors", "--stdio",
                   stdin="".join(json.dumps(x) + "\n" for x in lines))
    answers = [json.loads(line) for line in out.splitlines()]
    assert [a["status"] for a in answers] == [200] * len(lines)
    ep = gaia.Dataset(str(drive["tokens"]))[0]
    s = sim.create(prompt=ep.tokens[2:5], prompt_actions=ep.actions[2:5], seed=11, guidance=8)
    assert s.prompt_frames == 3 and s.steps == 3
    for (v, c), want in zip(COMMANDS, answers[1:]):
        r = s.step(v, c)
        assert r["step"] == want["step"]
        np.testing.assert_array_equal(r["tokens"].reshape(-1), want["tokens"])
        assert r["frame"].shape == (72, 128, 3) and r["frame"].dtype == np.uint8
        np.testing.assert_array_equal(r["frame"], tokenizer.decode(r["tokens"]))
        if want.get("read_back") is None:
            assert r["read_back"] is None
        else:
            assert r["read_back"]["speed"] == pytest.approx(want["read_back"]["speed"], abs=1e-4)
            assert r["read_back"]["curvature"] == pytest.approx(want["read_back"]["curvature"], abs=1e-6)
    assert s.tokens.shape == (3 + len(COMMANDS), 9, 16)


def test_fork_plans_and_reset_continue_as_the_session_would(sim, drive):
    ep = gaia.Dataset(str(drive["tokens"]))[0]
    s = sim.create(prompt=ep.tokens[:3], prompt_actions=ep.actions[:3], seed=4, guidance=8)
    s.step(8, 0.01, frame=False)
    copy = s.fork()
    a = [s.step(8, -0.02, frame=False)["tokens"] for _ in range(3)]
    b = [copy.step(8, -0.02, frame=False)["tokens"] for _ in range(3)]
    np.testing.assert_array_equal(np.stack(a), np.stack(b))  # the same state and random stream
    s.reset()
    assert s.steps == 3
    s.step(8, 0.01, frame=False)
    np.testing.assert_array_equal(s.step(8, -0.02, frame=False)["tokens"], a[0])
    # One plan: the frames of fork() then step(); the session itself is unchanged.
    before = s.steps
    plan = [(8.0, 0.02), (8.0, 0.02)]
    (branch, answers), = s.fork([plan])
    direct = s.fork()
    want = [direct.step(v, c) for v, c in plan]
    for got, w in zip(answers, want):
        np.testing.assert_array_equal(got["tokens"], w["tokens"])
        np.testing.assert_array_equal(got["frame"], w["frame"])
        assert (got["read_back"] is None) == (w["read_back"] is None)
    assert s.steps == before and branch.steps == before + 2
    # Two plans of one length: two copies, each with its plan's frames.
    two = s.fork([[(8.0, 0.03)] * 2, [(8.0, -0.03)] * 2], frame=False)
    assert len(two) == 2 and all(len(frames) == 2 and frames[0]["frame"] is None for _, frames in two)


def test_bad_steps_are_one_clear_error(sim, models):
    s = sim.create()
    with pytest.raises(ValueError, match="curvature"):
        s.step(8, 3.0)
    with pytest.raises(ValueError, match="speed"):
        s.step(-1, 0)
    with pytest.raises(ValueError, match="action_negative"):
        sim.create(action_negative="sideways")
    with pytest.raises(ValueError, match="precision 'half': expected fp32, bf16 or fp16"):
        sim.create(precision="half")
    with pytest.raises(ValueError, match=r"prompt: an integer dtype"):
        sim.create(prompt=np.zeros((2, 9, 16), np.float64))
    with pytest.raises(ValueError, match="not a dynamics probe"):
        gaia.Sim(sim.world, sim.tokenizer, probe=str(models / "probe-scene.safetensors"))
    with pytest.raises(ValueError, match="probe: reads decoded frames"):
        gaia.Sim(sim.world, probe="x")
    assert s.step(8, 0.0, frame=False)["tokens"].shape == (9, 16)  # the session still steps


def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def test_a_long_session_leaks_nothing(world, drive):
    sim = gaia.Sim(world)  # tokens only: what a policy's thousand steps cost
    ep = gaia.Dataset(str(drive["tokens"]))[0]
    s = sim.create(prompt=ep.tokens[:3], prompt_actions=ep.actions[:3], window_stride=4)
    for _ in range(24):  # the caches and the allocator reach their working size (the window slides from step 6)
        s.step(8, 0.0, frame=False)
    start = rss_mb()
    for k in range(100):
        r = s.step(8, 0.01 * np.sin(k / 10), frame=False)
        assert r["tokens"].shape == (9, 16)
    grown = rss_mb() - start
    assert grown < 10, f"resident size grew {grown:.1f} MB over 100 steps"  # 100 KB a step
