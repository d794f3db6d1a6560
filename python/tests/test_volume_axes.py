"""Arrays in either index order give the same volume: [z, y, x] (SimpleITK's) by default, [x, y, z]
(nibabel's) with axes='xyz'. The truth: the voxel the caller's own indexing names."""
import numpy as np
import pytest

import isotouch

SP = (1e-3, 2e-3, 3e-3)


@pytest.fixture
def zyx():
    return np.random.default_rng(5).random((4, 5, 6), dtype=np.float32)  # nz, ny, nx


def test_both_orders_give_the_same_volume(zyx):
    xyz = zyx.T  # (nx, ny, nz), F-ordered: a[x, y, z]
    a = isotouch.Volume(zyx, SP)
    b = isotouch.Volume(xyz, SP, axes="xyz")
    c = isotouch.Volume(np.ascontiguousarray(xyz), SP, axes="xyz")  # C-ordered [x, y, z]
    for v in (a, b, c):
        assert v.dims == (6, 5, 4) and v.shape == (4, 5, 6)
        assert v.array[3, 2, 1] == xyz[1, 2, 3] == zyx[3, 2, 1]  # voxel x=1, y=2, z=3
    assert a.crc32() == b.crc32() == c.crc32()
    np.testing.assert_array_equal(c.array, zyx)


def test_a_bad_axes_value_or_an_f_ordered_default_says_what_to_do(zyx):
    with pytest.raises(ValueError, match=r"axes: 'yxz', must be 'zyx' .* or 'xyz'"):
        isotouch.Volume(zyx, SP, axes="yxz")
    with pytest.raises(ValueError, match=r"not C-contiguous.*axes='xyz'"):
        isotouch.Volume(zyx.T, SP)
