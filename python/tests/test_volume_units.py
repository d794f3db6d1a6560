"""Spacing and origin in metres (Volume) or millimetres (Volume.from_mm): the same grid either way,
judged by the mm a caller gave; a value that looks like the other unit warns."""
import warnings

import numpy as np
import pytest

import isotouch

A = np.zeros((4, 5, 6), np.float32)


def test_from_mm_is_the_metre_volume():
    mm = isotouch.Volume.from_mm(A, spacing_mm=(0.5, 0.5, 1.25), origin_mm=(-120.0, 30.0, 7.5))
    m = isotouch.Volume(A, spacing=(0.5e-3, 0.5e-3, 1.25e-3), origin=(-0.12, 0.03, 0.0075))
    assert mm.spacing_mm == pytest.approx((0.5, 0.5, 1.25)) and mm.origin_mm == pytest.approx((-120.0, 30.0, 7.5))
    assert mm.spacing == pytest.approx(m.spacing) and mm.origin == pytest.approx(m.origin)
    assert m.spacing_mm == pytest.approx((0.5, 0.5, 1.25))


def test_from_mm_takes_the_other_order_too():
    a = isotouch.Volume.from_mm(np.ascontiguousarray(A.T), (1.0, 2.0, 3.0), axes="xyz")
    assert a.dims == (6, 5, 4) and a.spacing_mm == pytest.approx((1.0, 2.0, 3.0))


@pytest.mark.parametrize("make, match", [
    (lambda: isotouch.Volume(A, spacing=(0.5, 0.5, 1.0)), r"spacing \(0.5, 0.5, 1\) m: a voxel over 50 mm"),
    (lambda: isotouch.Volume(A, spacing=(1e-3,) * 3, origin=(-120.0, 30.0, 7.5)), r"origin \(-120, 30, 7.5\) m"),
    (lambda: isotouch.Volume.from_mm(A, spacing_mm=(5e-4, 5e-4, 1e-3)), r"spacing_mm .* mm: voxels under 10 um"),
])
def test_a_value_in_the_other_unit_warns(make, match):
    with pytest.warns(isotouch.UnitsWarning, match=match):
        make()


def test_plausible_values_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        isotouch.Volume(A, spacing=(0.05,) * 3, origin=(-2.0, 2.0, 0.0))  # a 5 cm voxel, 2 m: accepted quietly
        isotouch.Volume.from_mm(A, spacing_mm=(0.01,) * 3)  # a 10 um micro-CT
