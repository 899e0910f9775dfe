"""Actor/critic of thesis Tables 9.1-9.2, the learner against TorchRL's losses, exploration schedule."""

from __future__ import annotations

import math

import pytest
import torch
from torchrl.data import Bounded

from pamrun.config import AlgoConfig, ConfigError
from pamrun.learning import exploration, networks

SPEC = Bounded(-torch.ones(10), torch.ones(10), (10,))


def test_actor_is_table_9_1():
    actor = networks.make_actor(AlgoConfig(), 43, 10).module
    layers = [m for m in actor.net]
    assert [type(m).__name__ for m in layers] == ["Linear", "ReLU", "Linear", "ReLU", "Linear", "Tanh"]
    assert [(m.in_features, m.out_features) for m in layers if isinstance(m, torch.nn.Linear)] == [
        (43, 400), (400, 300), (300, 10)]
    out = actor(torch.randn(5, 43) * 100)
    assert out.shape == (5, 10) and out.abs().max() <= 1


def test_critic_is_table_9_2():
    critic = networks.make_critic(AlgoConfig(), 43, 10)
    assert (critic.obs_path[0].in_features, critic.obs_path[0].out_features) == (43, 400)
    assert (critic.obs_path[2].in_features, critic.obs_path[2].out_features) == (400, 300)
    assert (critic.action_path.in_features, critic.action_path.out_features) == (10, 300)
    assert (critic.head[1].in_features, critic.head[1].out_features) == (300, 1)
    assert critic(torch.randn(4, 43), torch.randn(4, 10)).shape == (4, 1)


def _batch(n: int = 64, terminated_every: int = 5):
    from tensordict import TensorDict

    terminated = (torch.arange(n) % terminated_every == 0).reshape(n, 1)
    return TensorDict({
        "observation": torch.randn(n, 43), "action": torch.rand(n, 10) * 2 - 1,
        "next": {"observation": torch.randn(n, 43), "reward": torch.randn(n, 1),
                 "done": terminated.clone(), "terminated": terminated},
    }, batch_size=[n])


def _critic_loss(learner, batch) -> float:
    nxt = batch["next"]
    with torch.no_grad():
        return float(learner.critic_loss(batch["observation"], batch["action"], nxt["reward"], nxt["observation"],
                                         nxt["terminated"]))


def _copy_into(params, nets) -> None:
    """Write each net's parameters into TorchRL's (possibly stacked) parameter TensorDict."""
    flat = params.flatten_keys()
    with torch.no_grad():
        for key in flat.keys():
            stacked = torch.stack([dict(net.named_parameters())[key.removeprefix("module.")] for net in nets])
            flat[key].copy_(stacked if flat[key].dim() == stacked.dim() else stacked[0])


def _torchrl_loss(name: str, learner: networks.Learner):
    """TorchRL's own loss for this algorithm, holding copies of the learner's networks and targets."""
    from tensordict.nn import TensorDictModule
    from torchrl.modules import ValueOperator
    from torchrl.objectives import DDPGLoss, TD3Loss

    actor = TensorDictModule(learner.actor.module, in_keys=["observation"], out_keys=["action"])
    critic = ValueOperator(learner.critics[0], in_keys=["observation", "action"])
    if name == "ddpg":
        loss = DDPGLoss(actor, critic, loss_function="l2", delay_actor=True, delay_value=True)
        critic_params, critic_targets = loss.value_network_params, loss.target_value_network_params
    else:
        loss = TD3Loss(actor, critic, action_spec=SPEC, num_qvalue_nets=2, policy_noise=0.0, noise_clip=0.5,
                       loss_function="l2", delay_actor=True, delay_qvalue=True)
        critic_params, critic_targets = loss.qvalue_network_params, loss.target_qvalue_network_params
    loss.make_value_estimator(gamma=learner.cfg.gamma)
    # TorchRL copies the networks; give it the learner's parameters and (different) targets.
    for params, nets in ((critic_params, learner.critics), (critic_targets, learner.critic_targets),
                         (loss.target_actor_network_params, [learner.actor_target])):
        _copy_into(params, nets)
    return loss


@pytest.mark.parametrize("name", ["ddpg", "td3"])
def test_learner_losses_equal_torchrl(name):
    """The learner's critic and actor losses are TorchRL's DDPGLoss / TD3Loss on the same
    networks, targets and batch (TD3 without target noise, which is random), and so are
    the critic's gradients."""
    torch.manual_seed(0)
    cfg = AlgoConfig(name=name, policy_noise=0.0)
    learner = networks.make_learner(cfg, 43, 10, SPEC)
    with torch.no_grad():  # targets that differ from the networks, so a swapped network would show
        for p in [*learner.actor_target.parameters(), *learner.critic_targets.parameters()]:
            p.add_(0.05 * torch.randn_like(p))
    batch = _batch()
    reference = _torchrl_loss(name, learner)
    critic_ref, actor_ref = ((reference.loss_value, reference.loss_actor) if name == "ddpg" else
                             (reference.value_loss, reference.actor_loss))
    nxt = batch["next"]
    ours = learner.critic_loss(batch["observation"], batch["action"], nxt["reward"], nxt["observation"],
                               nxt["terminated"])
    theirs = critic_ref(batch)[0]
    assert float(ours.detach()) == pytest.approx(float(theirs), rel=1e-5)
    assert float(learner.actor_loss(batch["observation"])) == pytest.approx(float(actor_ref(batch)[0]), rel=1e-5)
    # the critic gradient of the first critic's first layer, ours vs TorchRL's
    ours.backward()
    grad_ours = learner.critics[0].obs_path[0].weight.grad.clone()
    learner.critics.zero_grad()  # DDPGLoss shares the critic's parameters rather than copying them
    params = reference.value_network_params if name == "ddpg" else reference.qvalue_network_params
    theirs.backward()
    grad_theirs = params.flatten_keys()["module.obs_path.0.weight"].grad
    grad_theirs = grad_theirs if grad_theirs.dim() == 2 else grad_theirs[0]
    torch.testing.assert_close(grad_ours, grad_theirs, rtol=1e-4, atol=1e-7)


@pytest.mark.parametrize("name", ["ddpg", "td3"])
def test_learner_updates_fit_the_critic_and_move_the_targets(name):
    """Updates on a fixed batch reduce the critic loss, and the targets follow the networks by tau."""
    torch.manual_seed(0)
    learner = networks.make_learner(AlgoConfig(name=name, critic_lr=1e-3), 43, 10, SPEC)
    batch = _batch()
    first = _critic_loss(learner, batch)
    actor_before = learner.actor.module.net[0].weight.detach().clone()
    target_before = learner.actor_target.net[0].weight.detach().clone()
    for _ in range(30):
        learner.update(batch)
    assert _critic_loss(learner, batch) < 0.5 * first
    moved = learner.actor.module.net[0].weight.detach() - actor_before
    assert moved.abs().max() > 0
    target_moved = learner.actor_target.net[0].weight - target_before
    assert 0 < target_moved.abs().max() < moved.abs().max()
    assert all(not p.requires_grad for p in learner.actor_target.parameters())
    assert all(p.requires_grad for p in learner.critics.parameters())


def test_td3_has_two_independent_critics():
    learner = networks.make_learner(AlgoConfig(name="td3"), 43, 10, SPEC)
    assert len(learner.critics) == 2
    assert not torch.equal(learner.critics[0].obs_path[0].weight, learner.critics[1].obs_path[0].weight)
    assert len(networks.make_learner(AlgoConfig(name="ddpg"), 43, 10, SPEC).critics) == 1


@pytest.mark.parametrize("name", ["td3", "sac"])
def test_crossq_learns_without_targets_from_one_joint_pass(name):
    """algo.crossq: batch-renormalised critics and no critic targets; the critic loss is TD3's / SAC's
    with a' from the actor itself and Q(s', a') from the same pass as Q(s, a), whose statistics (the
    two batches together) the renormalisation keeps; the actor's step leaves them alone; updates on a
    fixed batch fit the critics."""
    torch.manual_seed(0)
    cfg = AlgoConfig(name=name, critic="concat", crossq=True, policy_noise=0.0, adam_beta1=0.5, critic_lr=1e-3)
    learner = networks.make_learner(cfg, 43, 10, SPEC)
    norms = [m for m in learner.critics[0].modules() if isinstance(m, networks.BatchRenorm)]
    assert len(norms) == 3 and len(learner.critic_targets) == 0 and learner.critic_opt.param_groups[0]["betas"][0] == 0.5
    batch = _batch()
    nxt = batch["next"]
    obs, action = batch["observation"], batch["action"]
    # the loss by hand: both batches through each critic at once, the target from the second half
    torch.manual_seed(1)
    ours = learner.critic_loss(obs, action, nxt["reward"], nxt["observation"], nxt["terminated"]).detach()
    torch.manual_seed(1)
    with torch.no_grad():
        next_action, correction = learner.next_action(nxt["observation"], action)
        if name == "td3":
            assert torch.equal(next_action, learner.actor.module(nxt["observation"]))  # no target actor
        both = [c(torch.cat([obs, nxt["observation"]]), torch.cat([action, next_action])) for c in learner.critics]
        y = nxt["reward"] + cfg.gamma * (~nxt["terminated"]) * (torch.min(both[0][64:], both[1][64:]) - correction)
        expected = sum(((q[:64] - y) ** 2).mean() for q in both)
    assert float(ours) == pytest.approx(float(expected), rel=1e-5)
    mean_in = torch.cat([torch.cat([obs, nxt["observation"]]), torch.cat([action, next_action])], dim=1).mean(0)
    # two training passes of this critic so far (the loss's and the one by hand), each 0.01 of the way
    torch.testing.assert_close(norms[0].running_mean, mean_in * (1 - 0.99 ** 2), rtol=1e-4, atol=1e-6)
    first = _critic_loss(learner, batch)
    before = [m.running_mean.clone() for m in norms]
    learner.updates = 0  # an actor step at the next update
    learner.critics.eval()
    learner.actor_loss(obs).backward()
    learner.critics.train()
    assert all(torch.equal(m.running_mean, b) for m, b in zip(norms, before))
    for _ in range(40):
        learner.update(batch)
    assert _critic_loss(learner, batch) < 0.5 * first
    assert all(m.training for m in learner.critics.modules())


def test_batch_renorm_is_torchrl_s_with_its_warm_up_ending():
    """pamrun's BatchRenorm gives TorchRL's BatchRenorm1d's outputs, gradients and running statistics,
    in the warm-up, after it (r and d clipped: a shifted, scaled input) and in eval mode; and after
    the warm-up its factor stays 1, where TorchRL 0.14.1's count runs on and its factor grows."""
    from torchrl.modules import BatchRenorm1d

    torch.manual_seed(0)
    ours, theirs = networks.BatchRenorm(5, warmup_steps=3), BatchRenorm1d(5, warmup_steps=3)
    with torch.no_grad():
        for norm in (ours, theirs):
            norm.weight.copy_(torch.linspace(0.5, 2.0, 5))
            norm.bias.copy_(torch.linspace(-1.0, 1.0, 5))
    for step in range(5):  # 3 batch-norm steps, then 2 renormalised ones (TorchRL's factor still 1)
        x = (torch.randn(32, 5) * (1 + 4 * step) + 3 * step).requires_grad_()
        y_ours, y_theirs = ours(x), theirs(x)
        torch.testing.assert_close(y_ours, y_theirs, rtol=1e-4, atol=1e-5)
        g_ours = torch.autograd.grad((y_ours ** 3).sum(), (x, ours.weight))
        g_theirs = torch.autograd.grad((y_theirs ** 3).sum(), (x, theirs.weight))
        for a, b in zip(g_ours, g_theirs):
            torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(ours.running_mean, theirs.running_mean)
    torch.testing.assert_close(ours.running_var, theirs.running_var)
    ours.eval(), theirs.eval()
    x = torch.randn(16, 5)
    torch.testing.assert_close(ours(x), theirs(x), rtol=1e-5, atol=1e-5)
    ours.train()
    for _ in range(7):
        ours(torch.randn(8, 5))
    assert int(ours.num_batches_tracked) == 3


def test_noise_schedule_follows_matlab_variance_decay():
    cfg = AlgoConfig(noise_variance=0.5, noise_decay=1e-5, noise_variance_min=0.0)
    assert exploration.noise_scale(cfg, 0) == 1.0
    # variance 0.5 * (1 - 1e-5)^k, so the std halves after ln(4) / 1e-5 ~ 138,629 steps
    assert exploration.noise_scale(cfg, 138_629) == pytest.approx(0.5, rel=1e-3)
    floor = AlgoConfig(noise_variance=0.5, noise_decay=1e-5, noise_variance_min=0.05)
    assert exploration.noise_scale(floor, 10_000_000) == pytest.approx(math.sqrt(0.1))


def test_exploration_modules_take_the_scale():
    """The scale written by set_noise_scale is the spread of the actions the policy explores with."""
    from tensordict import TensorDict

    for name in ("ddpg", "td3"):
        cfg = AlgoConfig(name=name)
        actor = networks.make_actor(cfg, 43, 10)
        explore = exploration.make_exploration(cfg, actor, SPEC)
        spread = {}
        for scale in (0.1, 0.2):
            exploration.set_noise_scale(explore, scale)
            td = TensorDict({"observation": torch.zeros(4000, 43), "is_init": torch.ones(4000, 1, dtype=torch.bool)},
                            [4000])
            with torch.no_grad():
                deviation = explore(td.clone())["action"] - actor(td.clone())["action"]
            spread[scale] = float(deviation.std())
        assert spread[0.1] > 0.01, name
        assert spread[0.2] / spread[0.1] == pytest.approx(2.0, rel=0.1), name


def test_colored_noise_has_the_spectrum_it_is_asked_for():
    """Unit RMS; white independent from step to step, pink and red ever more correlated; the power
    spectrum's log-log slope is -beta."""
    torch.manual_seed(0)
    for beta, lag1 in ((0.0, (-0.02, 0.02)), (1.0, (0.5, 0.9)), (2.0, (0.95, 1.0))):
        series = exploration.colored_noise(beta, 400, (500,))
        assert series.shape == (400, 500)
        assert torch.allclose(series.pow(2).mean(dim=0), torch.ones(500), atol=1e-4)
        correlation = float((series[1:] * series[:-1]).mean())
        assert lag1[0] < correlation < lag1[1], (beta, correlation)
        power = torch.fft.rfft(series, dim=0).abs().pow(2).mean(dim=1)[1:]
        freqs = torch.fft.rfftfreq(400)[1:]
        slope = torch.linalg.lstsq(torch.stack([freqs.log(), torch.ones_like(freqs)], 1), power.log()[:, None]).solution[0]
        assert float(slope) == pytest.approx(-beta, abs=0.15), beta


def test_pink_exploration_is_correlated_in_time_and_takes_the_scale():
    """algo.noise_beta=1: TD3's exploration adds pink noise of the Gaussian's std, scaled by
    set_noise_scale, successive actions' deviations correlated, and kept in the action's bounds."""
    from tensordict import TensorDict

    cfg = AlgoConfig(name="td3", noise_variance=0.01, noise_beta=1.0)
    actor = networks.make_actor(cfg, 43, 10)
    explore = exploration.make_exploration(cfg, actor, SPEC)
    td = TensorDict({"observation": torch.zeros(64, 43)}, [64])
    with torch.no_grad():
        clean = actor(td.clone())["action"]
        runs = {}
        for scale in (1.0, 2.0):
            exploration.set_noise_scale(explore, scale)
            runs[scale] = torch.stack([explore(td.clone())["action"] - clean for _ in range(400)])
    for scale, deviation in runs.items():
        assert float(deviation.std()) == pytest.approx(0.1 * scale, rel=0.15), scale
        assert float((deviation[1:] * deviation[:-1]).mean() / deviation.pow(2).mean()) > 0.5
        assert float((deviation + clean).abs().max()) <= 1.0


def test_the_noise_spectrum_changes_during_a_run():
    """A colored exploration module (``train.walk_noise_beta``) at beta 0 adds white noise; set to 1,
    it adds pink from the next action on, its chunk drawn at 0 dropped, at the same std."""
    from tensordict import TensorDict

    cfg = AlgoConfig(name="td3", noise_variance=0.01)
    actor = networks.make_actor(cfg, 43, 10)
    explore = exploration.make_exploration(cfg, actor, SPEC, colored=True)
    assert isinstance(explore.module[-1], exploration.ColoredNoiseModule)
    assert not isinstance(exploration.make_exploration(cfg, actor, SPEC).module[-1], exploration.ColoredNoiseModule)
    td = TensorDict({"observation": torch.zeros(64, 43)}, [64])
    with torch.no_grad():
        clean = actor(td.clone())["action"]
        runs = {}
        for beta in (0.0, 1.0):  # 100 steps at each: the change lands inside the first chunk of 400
            exploration.set_noise_beta(explore, beta)
            runs[beta] = torch.stack([explore(td.clone())["action"] - clean for _ in range(100)])
    lag1 = {beta: float((d[1:] * d[:-1]).mean() / d.pow(2).mean()) for beta, d in runs.items()}
    assert abs(lag1[0.0]) < 0.05 and lag1[1.0] > 0.5, lag1
    assert float(runs[1.0].std()) == pytest.approx(0.1, rel=0.2)


def test_bad_algo_values():
    with pytest.raises(ConfigError, match="name"):
        AlgoConfig(name="ppo")
    with pytest.raises(ConfigError, match="batch_size"):
        AlgoConfig(batch_size=-128)
    with pytest.raises(ConfigError, match="noise_beta"):
        AlgoConfig(name="td3", noise_beta=3.0)
    with pytest.raises(ConfigError, match="noise_beta"):
        AlgoConfig(name="ddpg", noise_beta=1.0)
    with pytest.raises(ConfigError, match="noise_chunk_steps"):
        AlgoConfig(name="td3", noise_chunk_steps=1)
    with pytest.raises(ConfigError, match="crossq"):
        AlgoConfig(name="ddpg", critic="concat", crossq=True)
    with pytest.raises(ConfigError, match="crossq"):
        AlgoConfig(name="td3", crossq=True)  # the thesis' critic
    with pytest.raises(ConfigError, match="adam_beta1"):
        AlgoConfig(adam_beta1=1.0)
    with pytest.raises(ConfigError, match="renorm_warmup_updates"):
        AlgoConfig(renorm_warmup_updates=-1)


def test_critic_only_updates_leave_the_actor_alone():
    """``update(actor=False)`` (train.actor_start_frames): the critics learn, the actor does not."""
    torch.manual_seed(0)
    learner = networks.make_learner(AlgoConfig(name="td3", actor_update_every=2), 43, 10, SPEC)
    actor = [p.detach().clone() for p in learner.actor_params]
    critic = [p.detach().clone() for p in learner.critic_params]
    batch = _batch()
    for _ in range(4):
        learner.update(batch, actor=False)
    assert all(torch.equal(a, p) for a, p in zip(actor, learner.actor_params))
    assert not all(torch.equal(c, p) for c, p in zip(critic, learner.critic_params))
    assert learner.updates == 4 and math.isnan(learner.losses()["actor"])
    learner.update(batch)
    assert not all(torch.equal(a, p) for a, p in zip(actor, learner.actor_params))


def test_sac_log_probability_is_the_squashed_gaussian():
    """SAC's log pi(a|s) equals torch.distributions' tanh-transformed Normal at the same sample."""
    from torch.distributions import Normal, TanhTransform, TransformedDistribution

    torch.manual_seed(0)
    actor = networks.SquashedGaussianActor(43, 10, (400, 300), 3e-3)
    obs = torch.randn(64, 43)
    action, log_prob = actor.sample(obs)
    h = actor.net[:4](obs)
    std = actor.log_std_head(h).clamp(*actor.LOG_STD_RANGE).exp()
    reference = TransformedDistribution(Normal(actor.net[4](h), std), [TanhTransform(cache_size=1)])
    torch.testing.assert_close(log_prob.squeeze(-1), reference.log_prob(action).sum(-1), rtol=1e-4, atol=1e-4)
    assert torch.equal(actor(obs), torch.tanh(actor.net[4](h)))  # forward: the deterministic policy


def test_sac_sample_is_the_hand_written_tanh_gaussian():
    """pamrun's sample (TorchRL's TanhNormal) draws the same actions from the same generator state
    as the hand-written tanh-Gaussian, bit for bit, with the same log-probabilities and gradients
    to float precision, saturated actions (|a| = 1 in float32) included."""
    torch.manual_seed(0)
    actor = networks.SquashedGaussianActor(43, 10, (400, 300), 3e-3)
    with torch.no_grad():  # means up to ~45 and a wider spread: a third of the actions saturate
        actor.net[4].weight.mul_(2000)
        actor.log_std_head.weight.mul_(3)
    obs = torch.randn(512, 43)
    results = []
    for sample in (actor.sample, actor.sample_by_hand):
        actor.zero_grad()
        torch.manual_seed(1)
        action, log_prob = sample(obs)
        (log_prob.sum() + action.sum()).backward()
        results.append((action.detach(), log_prob.detach(), [p.grad.clone() for p in actor.parameters()]))
    (action, log_prob, grads), (ref_action, ref_log_prob, ref_grads) = results
    assert (ref_action.abs() == 1).float().mean() > 0.2
    assert torch.equal(action, ref_action)
    assert log_prob.shape == ref_log_prob.shape == (512, 1)
    torch.testing.assert_close(log_prob, ref_log_prob, rtol=2e-6, atol=1e-5)
    for grad, ref in zip(grads, ref_grads):
        torch.testing.assert_close(grad, ref, rtol=1e-4, atol=1e-4)


def test_sac_learns_its_critics_and_temperature():
    """SAC updates fit the critics, and alpha falls while the policy's entropy is above its target."""
    torch.manual_seed(0)
    learner = networks.make_learner(AlgoConfig(name="sac", critic_lr=1e-3, actor_lr=3e-3), 43, 10, SPEC)
    assert len(learner.critics) == 2 and learner.log_alpha.item() == 0.0
    batch = _batch()
    first = _critic_loss(learner, batch)
    for _ in range(30):
        learner.update(batch)
    assert _critic_loss(learner, batch) < 0.5 * first
    assert learner.log_alpha.item() < 0  # entropy of a fresh policy (std ~1) is far above -10
    assert set(learner.policy_state()) == set(networks.ThesisActor(43, 10, (400, 300), 3e-3).state_dict())
    state = learner.state_dict()
    other = networks.make_learner(AlgoConfig(name="sac"), 43, 10, SPEC)
    other.load_state_dict(state, learner.updates)
    assert other.log_alpha.item() == learner.log_alpha.item()


def test_concat_critic_takes_observation_and_action_at_its_input():
    critic = networks.make_critic(AlgoConfig(critic="concat"), 43, 10)
    assert isinstance(critic, networks.ConcatCritic) and critic.net[0].in_features == 53
    obs, act = torch.randn(4, 43), torch.randn(4, 10)
    assert critic(obs, act).shape == (4, 1)
    assert not torch.equal(critic(obs, act), critic(obs, -act))  # the action matters
    with pytest.raises(ConfigError, match="critic"):
        AlgoConfig(critic="wide")


@pytest.mark.parametrize("name", ["td3", "sac"])
def test_mirror_loss_makes_the_actor_its_own_mirror_image(name):
    """algo.mirror_loss (Yu, Turk & Liu 2018): the actor's updates shrink ||pi(s) - M_a pi(M_s s)||^2,
    which TD3's stays near without it; the maps are the env's own (pamrun/task/symmetry.py)."""
    from pamrun.task.symmetry import action_map, observation_map

    maps = (*observation_map(10), *action_map(10))
    o_index, o_sign = maps[0], torch.as_tensor(maps[1], dtype=torch.float32)
    obs = _batch()["observation"]
    assert torch.equal(obs[:, o_index][:, o_index] * o_sign[o_index] * o_sign, obs)  # M_s M_s s = s

    def asymmetry(weight: float) -> tuple[float, float]:
        torch.manual_seed(0)
        learner = networks.make_learner(AlgoConfig(name=name, actor_lr=1e-3, mirror_loss=weight), 43, 10, SPEC,
                                        maps)
        with torch.no_grad():
            learner.actor.module.net[-2].weight.mul_(300)  # a random actor, far from symmetric
        before = learner.mirror_residual(obs).item()
        for _ in range(40):
            learner.update(_batch())
        return before, learner.mirror_residual(obs).item()

    before, after = asymmetry(100.0)
    assert before > 0.05 and after < 0.3 * before
    if name == "td3":  # (SAC's entropy term alone shrinks these saturated outputs too)
        before_off, after_off = asymmetry(0.0)
        assert before_off == before and after_off > 0.6 * before
    with pytest.raises(ConfigError, match="mirror_loss"):
        AlgoConfig(mirror_loss=-1)


@pytest.mark.parametrize("q_factor", [100.0, 10_000.0])
def test_the_mirror_loss_weighs_the_same_under_any_reward_scale(q_factor):
    """algo.mirror_loss is scaled by the batch's mean |Q|, as the anchor (TD3+BC's lambda), so one
    weight holds the actor to its mirror image whether the critics say tens or thousands (a trained
    walker's |Q| is in the thousands): unscaled, 4 was nothing beside a gradient of Q that large.
    The unscaled mean square before each update is what TensorBoard's loss/mirror shows."""
    from pamrun.task.symmetry import action_map, observation_map

    maps = (*observation_map(10), *action_map(10))
    obs = _batch()["observation"]

    def residual_after(weight: float) -> tuple[float, float]:
        torch.manual_seed(0)
        learner = networks.make_learner(AlgoConfig(name="td3", actor_lr=1e-3, mirror_loss=weight), 43, 10, SPEC, maps)
        with torch.no_grad():
            learner.actor.module.net[-2].weight.mul_(30)
            for critic in learner.critics:  # critics that say q_factor times more
                last = [m for m in critic.modules() if isinstance(m, torch.nn.Linear)][-1]
                last.weight.mul_(q_factor)
                last.bias.mul_(q_factor)
        before = learner.mirror_residual(obs).item()
        for _ in range(30):
            batch = _batch()
            with torch.no_grad():
                logged = learner.mirror_residual(batch["observation"]).item()
            learner.update(batch)
            assert weight == 0 or learner.losses()["mirror"] == pytest.approx(logged, rel=1e-5)
        return before, learner.mirror_residual(obs).item()

    before, off = residual_after(0.0)
    assert off > 10 * before and "mirror" not in networks.make_learner(AlgoConfig(), 43, 10, SPEC, maps).losses()
    before, on = residual_after(3.0)
    assert on < before


@pytest.mark.parametrize("name", ["td3", "sac"])
def test_anchor_holds_a_started_actor_near_the_one_it_started_from(name):
    """algo.anchor: a learner that starts from a trained actor (start_from, an agent file's actor and new
    critics) charges mean|Q| ||pi(s) - pi_0(s)||^2; its updates move the actor far less than the same
    updates without it, and a resume state keeps pi_0. Faded out (algo.anchor_fade_*, at a frame past the
    fade) the same updates move it as far as without the anchor."""
    obs = _batch()["observation"]

    def drift(anchor: float, frames: int | None = None):
        torch.manual_seed(1)
        trained = networks.make_learner(AlgoConfig(name=name), 43, 10, SPEC)
        with torch.no_grad():
            trained.actor.module.net[-2].bias.uniform_(-0.5, 0.5)  # an actor away from the new one's
        torch.manual_seed(0)
        fade = {} if frames is None else {"anchor_fade_start_frames": 1000, "anchor_fade_frames": 500}
        cfg = AlgoConfig(name=name, actor_lr=1e-3, anchor=anchor, **fade)
        learner = networks.make_learner(cfg, 43, 10, SPEC)
        took = learner.start_from({"actor": trained.policy_state()})
        if frames is not None:
            learner.anchor_weight = networks.anchor_weight(cfg, frames)  # as the trainer sets it
        with torch.no_grad():
            start = trained.actor.module(obs)
            assert torch.equal(learner.actor.module(obs), start)
        for _ in range(60):
            learner.update(_batch())
        with torch.no_grad():
            return learner, took, (learner.actor.module(obs) - start).pow(2).mean().item()

    free, took_free, moved_free = drift(0.0)
    held, took_held, moved_held = drift(50.0)
    assert free.anchor_actor is None and "anchored" not in took_free and "algo.anchor 50" in took_held
    assert moved_free > 1e-3 and moved_held < 0.3 * moved_free, (moved_free, moved_held)
    assert held.anchor_loss(obs).item() > 0  # the actor moved a little, and the anchor says how far
    assert "fading to 0 from 1,000 to 1,500 frames" in drift(50.0, 0)[1]
    assert drift(50.0, 0)[2] == pytest.approx(moved_held, rel=1e-4)  # before the fade: held as tightly
    assert drift(50.0, 1250)[2] < moved_free  # half faded: held, less
    assert drift(50.0, 1500)[2] == pytest.approx(moved_free, rel=1e-4)  # faded out: as free
    state = held.state_dict()
    resumed = networks.make_learner(AlgoConfig(name=name, anchor=50.0), 43, 10, SPEC)
    resumed.load_state_dict(state, held.updates)
    torch.testing.assert_close(resumed.anchor_actor(obs), held.anchor_actor(obs))
    with pytest.raises(ValueError, match="algo.anchor"):
        resumed.load_state_dict(free.state_dict(), free.updates)
    with pytest.raises(ConfigError, match="anchor"):
        AlgoConfig(anchor=-0.1)


@pytest.mark.parametrize("overrides", [["experiment=walker"], ["experiment=walker", "muscle.command=independent",
                                                               "env.speed_command=true"]])
def test_the_recipe_gives_the_learner_the_envs_mirror_maps(overrides):
    """pamrun train with algo.mirror_loss builds its learner with the mirror maps of its own env's
    observation (clock, speed command) and action (joints or muscles); without it, none."""
    from pamrun.config import to_object
    from pamrun.training.recipe import make_learner
    from tests.conftest import compose_config

    cfg = to_object(compose_config(*overrides, "algo.mirror_loss=4"))
    learner = make_learner(cfg)
    obs = torch.randn(8, learner.actor.module.net[0].in_features)
    o_index, o_sign, a_index, _ = learner.mirror
    assert len(o_index) == obs.shape[1] and len(a_index) == learner.actor.module.net[-2].out_features
    assert learner.mirror_residual(obs).item() > 0
    assert make_learner(to_object(compose_config(*overrides))).mirror is None
