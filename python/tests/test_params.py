"""The renderers' parameter objects and what render() does with them, judged from the outside:
the values a constructor was given, the text a user reads, the force a known isovalue gives."""
import numpy as np
import pytest

import isotouch


def test_params_take_keywords_and_say_them_back():
    p = isotouch.HriParams(tau=400.0, stiffness_n_per_m=500.0, inside=isotouch.InsideIs.below)
    assert (p.tau, p.stiffness_n_per_m, p.inside) == (400.0, 500.0, isotouch.InsideIs.below)
    assert p.force_limit_n == isotouch.HriParams().force_limit_n  # the rest: defaults
    text = repr(p)
    assert text.startswith("HriParams(") and "tau=400.0" in text and "inside=InsideIs.below" in text
    b = isotouch.BaselineParams(tau=-3.5, inch_iterations=7)
    assert (b.tau, b.inch_iterations) == (-3.5, 7) and "tau=-3.5" in repr(b)
    assert isotouch.SurfaceFriction(mu_s=0.25).mu_s == 0.25


def test_params_docs_give_units():
    assert "value units" in isotouch.HriParams.tau.__doc__
    assert "[N/m]" in isotouch.HriParams.stiffness_n_per_m.__doc__
    assert "[m" in isotouch.BaselineParams.max_reach_m.__doc__


def test_an_unknown_keyword_is_a_type_error_naming_it():
    with pytest.raises(TypeError, match=r"HriParams\(\): no field 'tua'.*tau"):
        isotouch.HriParams(tua=400)
    with pytest.raises(TypeError, match="stiffness_n_per_m"):
        isotouch.BaselineParams(stiffness_n_per_m="stiff")


@pytest.fixture(scope="module")
def sphere_stroke():
    return isotouch.stroke_scene("sphere", device="cpu")


def test_the_wrong_params_kind_is_a_type_error_naming_both(sphere_stroke):
    s = sphere_stroke
    with pytest.raises(TypeError, match=r"params: BaselineParams given for 'hri', expected isotouch.HriParams"):
        isotouch.render(s.field, s.hip, "hri", isotouch.BaselineParams(tau=s.tau))
    with pytest.raises(TypeError, match=r"HriParams given for 'avila', expected isotouch.BaselineParams"):
        isotouch.render(s.field, s.hip, "avila", isotouch.HriParams(tau=s.tau))


def test_render_without_an_isovalue_is_refused(sphere_stroke):
    """A Field does not carry its isovalue: render() must be told it, never assume 0."""
    s = sphere_stroke
    for algo in ("hri", "avila", "blezek"):
        with pytest.raises(ValueError, match=rf"tau: no isovalue given for '{algo}'"):
            isotouch.render(s.field, s.hip, algo)
    with pytest.raises(ValueError, match="tau: no isovalue"):
        isotouch.render(s.field, s.hip, "hri", isotouch.HriParams(stiffness_n_per_m=500.0))


def test_tau_given_once_or_twice_alike(sphere_stroke):
    s = sphere_stroke
    by_kw = isotouch.render(s.field, s.hip, "hri", tau=s.tau)
    by_params = isotouch.render(s.field, s.hip, "hri", isotouch.HriParams(tau=s.tau))
    both = isotouch.render(s.field, s.hip, "hri", isotouch.HriParams(tau=s.tau), tau=s.tau)
    assert by_kw["contact"].sum() > 50  # the sphere's surface is felt at the scene's isovalue
    np.testing.assert_array_equal(by_kw["force"], by_params["force"])
    np.testing.assert_array_equal(by_kw["force"], both["force"])
    with pytest.raises(ValueError, match=r"tau: 0.5 given, but params.tau is"):
        isotouch.render(s.field, s.hip, "hri", isotouch.HriParams(tau=s.tau + 1.0), tau=0.5)
    with pytest.raises(ValueError, match=r"the scene.s isovalue: .* given, but params.tau is"):
        isotouch.measure_stroke(s, "avila", isotouch.BaselineParams(tau=s.tau + 1.0), 1)
