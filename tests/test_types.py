"""The feature and match containers: moving features between pixel frames."""

import torch

from slime_match.slime.blocks import make_blocks
from slime_match.types import Features


def test_moved_features_move_centres_only():
    laf = torch.tensor([[[2.0, 0.5, 10.0], [0.0, 3.0, 20.0]]])
    f = Features(laf, torch.ones(1, 4), torch.ones(1), laf.clone())
    moved = f.moved((-32.0, 5.0))
    assert torch.equal(moved.xy, torch.tensor([[-22.0, 25.0]]))
    assert torch.equal(moved.shape_laf[:, :, 2], torch.tensor([[-22.0, 25.0]]))
    assert torch.equal(moved.laf[:, :, :2], laf[:, :, :2]) and torch.equal(f.laf, laf)


def test_moved_by_a_box_corner_puts_it_at_the_origin():
    """A level point x is x - box[:2] in a block's frame; features without shape frames keep None."""
    block = make_blocks(480, 640)[1]  # scale 1, second column: box (x0 > 0, y0 = -32)
    x0, y0 = block.box[:2]
    assert x0 > 0 and y0 < 0
    laf = torch.tensor([[[1.0, 0.0, 100.0], [0.0, 1.0, 50.0]],
                        [[2.0, 0.0, float(x0)], [0.0, 2.0, float(y0)]]])
    moved = Features(laf, torch.ones(2, 3), torch.ones(2)).moved((-x0, -y0))
    assert torch.equal(moved.xy, torch.tensor([[100.0 - x0, 50.0 - y0], [0.0, 0.0]]))
    assert torch.equal(moved.laf[:, :, :2], laf[:, :, :2]) and moved.shape_laf is None


def test_strongest_features_come_highest_response_first_ties_in_index_order():
    response = torch.tensor([0.2, 0.9, 0.5, 0.9, 0.1])
    features = Features(torch.zeros(5, 2, 3), torch.zeros(5, 4), response)
    assert features.strongest(3).tolist() == [1, 3, 2]
    assert features.strongest(10).tolist() == [1, 3, 2, 0, 4]
