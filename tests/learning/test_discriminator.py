import pytest
import torch

from avrisk.learning.imitation.discriminator import mlp, train_discriminator

pytestmark = pytest.mark.usefixtures("one_thread")


def test_discriminator_separates_shifted_accelerations_and_not_identical_ones():
    gen = torch.Generator().manual_seed(0)
    human = torch.randn(4000, 5, generator=gen)
    accuracy = {}
    for shift in (0.0, 3.0):
        policy = torch.randn(2000, 5, generator=gen)
        policy[:, 4] += shift
        torch.manual_seed(1)
        disc = mlp(5, 32)
        opt = torch.optim.Adam(disc.parameters(), lr=3e-3)
        accuracy[shift] = train_discriminator(
            disc, human, policy, opt, epochs=15, batch=256, generator=gen
        )
    assert accuracy[3.0] > 0.85  # Bayes accuracy 0.93
    assert accuracy[0.0] < 0.6
