"""The kernels' element-by-element copies (they replace slice assignments, lab notebook
2026-11-29) refuse blocks of another shape, as the slice assignment did, instead of writing
past the target's end."""

from __future__ import annotations

import numpy as np
import pytest

from features.extract import _copy_block
from slam.scan_candidates import _put_block, _put_row


def test_the_copies_copy_and_refuse_another_shape():
    out = np.zeros((3, 2))
    _put_row(out, 1, np.arange(6.0).reshape(3, 2), 2)
    assert out.tolist() == [[0, 0], [4, 5], [0, 0]]
    with pytest.raises(ValueError, match="differ in length"):
        _put_row(out, 0, np.zeros((1, 3)), 0)
    blocks = np.zeros((2, 2, 2))
    _put_block(blocks, 0, np.arange(8.0).reshape(2, 2, 2), 1)
    assert blocks[0].tolist() == [[4, 5], [6, 7]]
    with pytest.raises(ValueError, match="differ in shape"):
        _put_block(blocks, 0, np.zeros((1, 3, 2)), 0)
    _copy_block(blocks, 1, np.array([[1.0, 2.0], [3.0, 4.0]]))
    assert blocks[1].tolist() == [[1, 2], [3, 4]]
    with pytest.raises(ValueError, match="differ in shape"):
        _copy_block(blocks, 1, np.zeros((3, 2)))
