import torch

from avrisk.tensors.noise import normal, random_bits, uniform


def test_the_same_seed_step_and_stream_give_the_same_numbers_in_any_batch():
    s = torch.tensor([5, 9, 11, 2], dtype=torch.int64)
    full = uniform(s, step=7, stream=1, shape=(6,))
    for b in range(4):
        assert torch.equal(uniform(s[b : b + 1], 7, 1, (6,))[0], full[b])
    perm = torch.tensor([2, 0, 3, 1])
    assert torch.equal(uniform(s[perm], 7, 1, (6,)), full[perm])


def test_seeds_steps_streams_and_elements_all_change_the_numbers():
    s = torch.tensor([5], dtype=torch.int64)
    base = random_bits(s, 3, 0, (8,))
    assert len(set(base[0].tolist())) == 8
    assert not torch.equal(base, random_bits(s + 1, 3, 0, (8,)))
    assert not torch.equal(base, random_bits(s, 4, 0, (8,)))
    assert not torch.equal(base, random_bits(s, 3, 1, (8,)))


def test_uniforms_lie_strictly_inside_the_unit_interval_and_look_uniform():
    u = uniform(torch.arange(2000, dtype=torch.int64), step=0, stream=0, shape=(50,))
    assert u.min().item() > 0.0 and u.max().item() < 1.0
    # 1e5 draws: mean within 5 standard errors (sd 0.289 / sqrt(1e5) = 0.0009).
    assert abs(u.mean().item() - 0.5) < 0.0046
    counts = torch.histc(u, bins=10, min=0.0, max=1.0)
    assert (counts - 1e4).abs().max().item() < 5 * 95  # binomial sd ~ 95


def test_normals_have_mean_zero_and_unit_variance():
    z = normal(
        torch.arange(2000, dtype=torch.int64),
        step=1,
        stream=0,
        shape=(50,),
        dtype=torch.float64,
    )
    assert abs(z.mean().item()) < 5 / 316
    assert abs(z.var().item() - 1.0) < 5 * (2 / 1e5) ** 0.5
    assert ((z.abs() > 1.96).double().mean().item() - 0.05) < 0.004


def test_a_step_per_rollout_gives_each_rollout_its_own_steps_numbers():
    s = torch.tensor([5, 9, 11], dtype=torch.int64)
    steps = torch.tensor([0, 7, 3])
    mixed = normal(s, steps, stream=2, shape=(4,))
    for b in range(3):
        alone = normal(s[b : b + 1], int(steps[b]), stream=2, shape=(4,))
        assert torch.equal(mixed[b], alone[0])
