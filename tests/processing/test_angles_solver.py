"""meshphase.kinematics.angle_design's Gauss-Newton iteration: the QR step and the stop at a converged point.

Truth: exact engagement instants from meshphase.synthetic.kinematics (test_angles.py's
``trains_from_truth``); the step solver is checked against scipy's gelsy (rank-revealing
QR), which it replaced on the well-conditioned path.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy import linalg

import meshphase.kinematics.angle_design as angle_design
from meshphase.kinematics.angles import fit_angle_model
from meshphase.kinematics.shafts import kinematics
from meshphase.models.tolerance import table2_case
from meshphase.synthetic.kinematics import ShaftRipple, SpeedProfile

from test_angles import rig, trains_from_truth  # tests/processing, on sys.path

KIN = kinematics(25, 87, 29, fixed="ring")


def _unit_columns(a):
    return a / np.linalg.norm(a, axis=0)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 400), p=st.integers(1, 12), seed=st.integers(0, 2 ** 31 - 1))
def test_gn_step_solves_well_conditioned_least_squares_like_gelsy(n, p, seed):
    """Both are backward-stable QR solutions; on unit-norm columns with singular values in
    [0.5, 2] (condition number <= 4) they agree to a few hundred eps of the solution."""
    rng = np.random.default_rng(seed)
    p = min(p, n)
    u, _ = np.linalg.qr(rng.standard_normal((n, p)))
    v, _ = np.linalg.qr(rng.standard_normal((p, p)))
    a = _unit_columns((u * rng.uniform(0.5, 2.0, p)) @ v.T)
    b = rng.standard_normal(n)
    x = angle_design._gn_step(a, b)
    ref = linalg.lstsq(a, b, lapack_driver="gelsy")[0]
    assert x.shape == (p,)
    scale = max(1.0, float(np.max(np.abs(ref))))
    assert np.max(np.abs(x - ref)) <= 1e-12 * scale


def test_gn_step_falls_back_to_rank_revealing_on_a_dependent_column():
    """A column equal to another (|R_jj| = 0 in an unpivoted QR) would give an infinite or
    huge step; gelsy's answer (a finite one with the same fit) is taken instead."""
    rng = np.random.default_rng(3)
    a = _unit_columns(rng.standard_normal((200, 4)))
    a = np.column_stack([a, a[:, 1]])
    b = rng.standard_normal(200)
    x = angle_design._gn_step(a, b)
    ref = linalg.lstsq(a, b, lapack_driver="gelsy")[0]
    assert np.all(np.isfinite(x))
    np.testing.assert_allclose(a @ x, a @ ref, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(x, ref)


def test_gn_step_empty_and_square_and_wide():
    assert angle_design._gn_step(np.zeros((5, 0)), np.ones(5)).shape == (0,)
    a = np.eye(3)
    np.testing.assert_allclose(angle_design._gn_step(a, np.array([1.0, 2.0, 3.0])), [1, 2, 3])
    wide = angle_design._gn_step(np.array([[1.0, 1.0]]), np.array([2.0]))   # minimum norm
    np.testing.assert_allclose(wide, [1.0, 1.0])


def test_gn_step_bad_input():
    with pytest.raises(ValueError):
        angle_design._gn_step(np.ones(3), np.ones(3))


@pytest.fixture(scope="module")
def converged():
    g, sp = rig()
    prof = SpeedProfile(shaft=(ShaftRipple("carrier", 0.01, 1, 0.3),))
    trains, _ = trains_from_truth(g, sp, prof, 60.0, errors=table2_case(1)[2], jitter=2e-5,
                                  sigma=2e-5)
    model = fit_angle_model(trains, KIN, 4)
    d, spec = model._design, model._fit.spec
    # the final model weighs each train by its variance factor; here every factor is 1
    fit = angle_design.solve(d, spec, model._fit.theta, np.ones(len(d.trains)))
    assert fit.converged
    return d, fit


def test_a_converged_start_is_not_halved_over_rounding(converged, monkeypatch):
    """At a converged point the Gauss-Newton step is rounding; where it raises the misfit
    (here forced: every prediction away from the start is moved 1e-10 cycles away from its
    observation, far below the convergence tolerance of about 3e-7) the iteration stops where it is instead of halving the
    step up to 12 times, one full evaluation each. The old loop took 15 evaluations here."""
    d, fit = converged
    start = fit.theta.copy()
    calls = []
    orig = angle_design.Design.evaluate

    def nudged(self, theta, lay, spec, rows=None, **k):
        f, J, rate = orig(self, theta, lay, spec, rows, **k)
        calls.append(1)
        if not k.get("nominal") and not np.array_equal(theta, start):
            y = self.y if rows is None else self.y[rows]
            f = f - 1e-10 * np.sign(y - f)
        return f, J, rate

    monkeypatch.setattr(angle_design.Design, "evaluate", nudged)
    again = angle_design.solve(d, fit.spec, start, np.ones(len(d.trains)), recheck=False)
    assert again.converged
    np.testing.assert_array_equal(again.theta, start)
    # the start, the identifiability check, one trial, and the final residuals at most
    assert len(calls) <= 4, len(calls)


def test_converged_fit_unchanged_by_a_second_solve(converged):
    """Solving again from a fitted model's parameters moves no prediction by more than the
    convergence tolerance (1e-3 of the 20-us timing bound in mesh cycles, about 3e-7)."""
    d, fit = converged
    again = angle_design.solve(d, fit.spec, fit.theta, np.ones(len(d.trains)))
    assert again.converged and again.iterations <= 3
    rows = np.flatnonzero(d.active)
    f0 = d.evaluate(fit.theta, fit.lay, fit.spec, rows, jac=False)[0]
    f1 = d.evaluate(again.theta, again.lay, again.spec, rows, jac=False)[0]
    assert np.max(np.abs(f1 - f0)) < 1e-6
