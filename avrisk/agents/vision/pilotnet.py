"""PilotNet: NVIDIA's end-to-end steering network (Bojarski et al. 2016).

The published architecture, on a 66 x 200 image::

    normalise: 2 rgb - 1                            (3, 66, 200)
    conv 5x5 stride 2, 24 ch, ReLU                  (24, 31, 98)
    conv 5x5 stride 2, 36 ch, ReLU                  (36, 14, 47)
    conv 5x5 stride 2, 48 ch, ReLU                  (48, 5, 22)
    conv 3x3, 64 ch, ReLU                           (64, 3, 20)
    conv 3x3, 64 ch, ReLU                           (64, 1, 18)
    flatten 1152, dense 1164, 100, 50, 10 (ReLU), 1 (linear)

about 1.6 million weights and 27 million multiply-adds per image. The paper
feeds YUV planes; this one takes RGB in ``[0, 1]`` (the renderer's colours).
The output is the steering angle in a standardised unit; ``steer_mean`` and
``steer_scale`` (set from the training labels) turn it into radians.

Batch independence
------------------
A convolution or matrix-product library picks its kernel by the batch size,
and different kernels may round differently in the last bit.
:meth:`PilotNet.steer` therefore runs the network on fixed inner batches of
:data:`INNER_BATCH` images (the last one zero-padded), so that an image's
steering is bit-identical alone, in any batch and at any position (on one
machine; the tests check it). The inner batch is the device's: 8 images on a
CPU, where larger passes gain nothing (their activations leave the cache), and
512 on a GPU, where each pass is a dozen kernel launches and small passes would
leave the device idle (BENCHMARKS.md, "The vision ego"). CPU and GPU steering
then agree within rounding, not bit for bit, as any two devices do.

References
----------
.. [1] M. Bojarski et al., "End to End Learning for Self-Driving Cars",
   arXiv:1604.07316, 2016.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

__all__ = ["IMAGE_SHAPE", "INNER_BATCH", "PilotNet", "inner_batch"]

#: Input shape (channels, height, width) of the published network.
IMAGE_SHAPE = (3, 66, 200)
#: Images per network pass in :meth:`PilotNet.steer` (batch independence), by
#: device type; a device type not named here takes the CPU's.
INNER_BATCH = {"cpu": 8, "cuda": 512}


def inner_batch(device: torch.device) -> int:
    """Images per network pass on ``device`` (:data:`INNER_BATCH`).

    Examples
    --------
    >>> inner_batch(torch.device("cpu")), inner_batch(torch.device("cuda", 1))
    (8, 512)
    """
    return INNER_BATCH.get(device.type, INNER_BATCH["cpu"])


_CONVS = ((3, 24, 5, 2), (24, 36, 5, 2), (36, 48, 5, 2), (48, 64, 3, 1), (64, 64, 3, 1))
_DENSE = (64 * 1 * 18, 1164, 100, 50, 10, 1)


class PilotNet(nn.Module):
    """The PilotNet steering network (see the module docstring).

    Parameters
    ----------
    steer_mean, steer_scale : float, default=0.0, 1.0
        Steering [rad] = ``steer_mean + steer_scale * output``.

    Examples
    --------
    >>> net = PilotNet()
    >>> sum(p.numel() for p in net.parameters())
    1595511
    >>> net.steer(torch.zeros(2, *IMAGE_SHAPE)).shape
    torch.Size([2])
    """

    def __init__(self, steer_mean: float = 0.0, steer_scale: float = 1.0) -> None:
        super().__init__()
        self.convs = nn.ModuleList(
            nn.Conv2d(c_in, c_out, k, stride=s) for c_in, c_out, k, s in _CONVS
        )
        sizes = zip(_DENSE[:-1], _DENSE[1:], strict=True)
        self.dense = nn.ModuleList(nn.Linear(n_in, n_out) for n_in, n_out in sizes)
        self.register_buffer("steer_mean", torch.tensor(float(steer_mean)))
        self.register_buffer("steer_scale", torch.tensor(float(steer_scale)))

    def forward(self, rgb: Tensor) -> Tensor:
        """The network's output, standardised steering.

        Parameters
        ----------
        rgb : Tensor of shape (N, 3, 66, 200)
            Colour in ``[0, 1]``.

        Returns
        -------
        Tensor of shape (N,)
        """
        x = 2.0 * rgb - 1.0
        for conv in self.convs:
            x = F.relu(conv(x))
        x = x.flatten(1)
        for layer in self.dense[:-1]:
            x = F.relu(layer(x))
        return self.dense[-1](x).squeeze(-1)

    def steer(self, rgb: Tensor, *, inner: int | None = None) -> Tensor:
        """Steering angle [rad] of every image, batch-independent.

        Parameters
        ----------
        rgb : Tensor of shape (B, 3, 66, 200)
            Colour in ``[0, 1]``, on the network's device.
        inner : int, optional
            Images per network pass (the last pass zero-padded); default
            :func:`inner_batch` of the images' device.

        Returns
        -------
        Tensor of shape (B,)
            Front-wheel angle [rad], positive turns left.

        Raises
        ------
        ValueError
            If the images are not of shape (B, 3, 66, 200).
        """
        if tuple(rgb.shape[1:]) != IMAGE_SHAPE:
            raise ValueError(
                f"PilotNet takes images of shape (B, 3, 66, 200); got "
                f"{tuple(rgb.shape)} (set the scenario's camera to width 200, "
                "height 66)"
            )
        n = rgb.shape[0]
        inner = inner_batch(rgb.device) if inner is None else inner
        pad = (-n) % inner
        if pad:
            rgb = torch.cat([rgb, rgb.new_zeros(pad, *IMAGE_SHAPE)])
        out = torch.cat([self(part) for part in rgb.split(inner)])[:n]
        return self.steer_mean + self.steer_scale * out

    def to_arrays(self, dtype: type = np.float16) -> dict[str, np.ndarray]:
        """Every weight as a NumPy array (weights in ``dtype``, scales in float32)."""
        arrays = {}
        for name, value in self.state_dict().items():
            kind = np.float32 if name.startswith("steer_") else dtype
            arrays[name] = value.detach().cpu().numpy().astype(kind)
        return arrays

    def save(self, path: str | Path) -> None:
        """Write the weights as a compressed ``.npz`` in float16 (no pickle)."""
        np.savez_compressed(Path(path), **self.to_arrays())

    @classmethod
    def load(cls, path: str | Path) -> PilotNet:
        """Read weights written by :meth:`save` (``allow_pickle=False``), float32.

        Raises
        ------
        ValueError
            If the file lacks a weight of the network or has one it does not.
        """
        net = cls()
        with np.load(Path(path), allow_pickle=False) as data:
            state = {
                k: torch.from_numpy(data[k].astype(np.float32)) for k in data.files
            }
        expected = set(net.state_dict())
        if set(state) != expected:
            raise ValueError(
                f"{path}: not PilotNet weights; missing {sorted(expected - set(state))}"
                f", unexpected {sorted(set(state) - expected)}"
            )
        net.load_state_dict(state)
        return net.eval()
