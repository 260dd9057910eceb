import pytest
import torch

from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.xi import (
    N_HIDDEN_LAST,
    N_OUTPUTS,
    OUTPUT_NAMES,
    XI_DIM,
    XI_NAMES,
    pack_xi,
    unpack_xi,
    xi_bias_slice,
    xi_row_slice,
)


def test_xi_has_404_entries_weights_row_major_then_biases():
    assert XI_DIM == 404 == N_OUTPUTS * N_HIDDEN_LAST + N_OUTPUTS
    assert len(XI_NAMES) == XI_DIM == len(set(XI_NAMES))
    assert XI_NAMES[101] == "w.steer_mean.1"
    assert XI_NAMES[xi_bias_slice()] == tuple(f"b.{o}" for o in OUTPUT_NAMES)
    assert xi_row_slice("accel_log_var") == slice(200, 300)


@pytest.mark.parametrize("batch", [(), (1,), (7,), (2, 3)])
def test_packing_and_unpacking_round_trip_exactly(batch):
    g = torch.Generator().manual_seed(0)
    w = torch.randn(*batch, N_OUTPUTS, N_HIDDEN_LAST, generator=g)
    b = torch.randn(*batch, N_OUTPUTS, generator=g)
    xi = pack_xi(w, b)
    assert xi.shape == (*batch, XI_DIM)
    w2, b2 = unpack_xi(xi)
    assert torch.equal(w2, w) and torch.equal(b2, b)
    assert torch.equal(pack_xi(w2, b2), xi)


def test_entry_o_times_100_plus_h_is_the_weight_from_unit_h_to_output_o():
    xi = torch.arange(XI_DIM, dtype=torch.float64)
    w, b = unpack_xi(xi)
    assert w[2, 7].item() == 2 * 100 + 7
    assert b[3].item() == 403


def test_the_network_head_is_the_unpacked_default_xi():
    net = DriverNet()
    w, b = unpack_xi(net.default_xi)
    assert torch.equal(w, net.last.weight) and torch.equal(b, net.last.bias)


def test_wrong_shapes_are_rejected_with_the_expected_shape():
    with pytest.raises(ValueError, match="404"):
        unpack_xi(torch.zeros(400))
    with pytest.raises(ValueError, match="weight must have shape"):
        pack_xi(torch.zeros(4, 99), torch.zeros(4))
    with pytest.raises(ValueError, match="bias must have shape"):
        pack_xi(torch.zeros(2, 4, 100), torch.zeros(4))
