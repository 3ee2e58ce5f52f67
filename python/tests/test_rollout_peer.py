"""gaia's rollout against its PyTorch-Python peer (tools/rollout_torch.py): the same sampling loop written in plain
PyTorch on the same weights gives the same argmax tokens, through the window's one-step slides (a 7-frame prompt
fills the context, so every generated frame slides it). Drawn tokens (top-k) agree too until the two sides' float
rounding moves one draw across a boundary of the distribution, after which that future goes its own way."""
import sys

import pytest

from conftest import MODELS, ROOT

torch = pytest.importorskip("torch", reason="PyTorch (Debian python3-torch) is the peer: not installed here")
sys.path.insert(0, str(ROOT / "tools"))
import rollout_torch  # noqa: E402

import gaia  # noqa: E402


@pytest.fixture(scope="module")
def shipped():
    path = str(MODELS / "world.safetensors")
    model, sampling = rollout_torch.load_world(path)
    return model, sampling, gaia.WorldModel(path)


@pytest.mark.parametrize("threads", [1, 2])
def test_argmax_tokens_equal_the_pytorch_peer(shipped, threads):
    model, s, world = shipped
    before = gaia.threads()
    gaia.set_threads(threads)  # 1: the fused token step with the lookahead; 2: LibTorch's operators
    strategy, futures, seed, frames, P = "argmax", 1, 0, 3, model.T - 1
    prompt, actions = rollout_torch.prompt_case(model, P, frames, seed=seed)
    peer = rollout_torch.rollout(model, prompt, rollout_torch.normalised(actions), frames, futures, strategy,
                                 s["top_k"], s["temperature"], s["copy_bias"], seed=seed,
                                 copy_bias_run=s["copy_bias_run"])
    ours = rollout_torch.gaia_rollout(world, prompt, actions, frames, futures, strategy, seed)
    assert ours.shape == peer.shape == (futures, P + frames, model.n)
    assert torch.equal(ours[:, :P], prompt.expand(futures, -1, -1))
    differing = int((ours != peer).sum())
    gaia.set_threads(before)
    assert differing == 0, f"{differing} of {peer[:, P:].numel()} generated tokens differ from the peer's"
    assert len(set(ours[0, P:].reshape(-1).tolist())) > 10  # a real rollout, not a constant frame
