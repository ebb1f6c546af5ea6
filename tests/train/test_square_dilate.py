"""``square_dilate``, the censored map's neighbourhood: the same values as max pooling."""

from __future__ import annotations

import pytest
import torch

from fusiongs.train.data import square_dilate


@pytest.mark.parametrize("radius", [0, 1, 2, 3])
@pytest.mark.parametrize("shape", [(18, 24), (7, 5), (1, 9)])
def test_square_dilate_is_max_pooling(radius, shape):
    gen = torch.Generator().manual_seed(radius * 100 + shape[0])
    x = (torch.rand(shape, generator=gen) > 0.85).float() * torch.randint(1, 5, shape, generator=gen)
    ref = torch.nn.functional.max_pool2d(x[None, None], 2 * radius + 1, stride=1, padding=radius)[0, 0]
    got = square_dilate(x, radius)
    assert got.shape == x.shape and torch.equal(got, ref)


def test_square_dilate_reaches_the_square_and_no_farther():
    x = torch.zeros(9, 9)
    x[4, 4] = 2.0
    got = square_dilate(x, 2)
    assert torch.equal(got[2:7, 2:7], torch.full((5, 5), 2.0)) and got.sum() == 50.0
