"""The selection's shared factorisations: a fit's basis reused by every candidate of a step.

``meshphase.kinematics.angle_design.fit_basis`` factorises a fitted model's designs once per
selection step; each candidate then adds only its own columns
(``appended_diagonal``, the projected QR of ``angle_selection._linear_bound``). Checked
here: the appended columns' |R_jj| and least-squares residual against a fresh QR / lstsq of
the whole design on random well-conditioned designs (tolerance from the condition number),
and the selection with and without the reuse on the screening records of test_angles.py
(the same model and the same numbers, bit for bit: the reuse changes only the screen's
bounds, at rounding level, never a decision).

Tolerance: Householder QR is backward stable (computed R is the exact R of A + E with
||E|| <= c m n eps ||A||, Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed.,
Thm. 19.4), and the reorthogonalised Gram-Schmidt projection is too; a diagonal entry of R
and the least-squares residual norm then move by at most O(n p eps cond(A)) on unit-norm
columns. The tests allow 10 n p eps cond(A), cond(A) <= 4 by construction (singular values
in [0.5, 2]).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy import linalg

import meshphase.kinematics.angle_design as angle_design
import meshphase.kinematics.angle_selection as angle_selection
import meshphase.kinematics.angles as angles
from meshphase.kinematics.angles import fit_angle_model
from meshphase.kinematics.shafts import kinematics

from test_angles import _screening_record  # tests/processing, on sys.path

EPS = np.finfo(float).eps


def _design(rng, n, p):
    """Unit-norm columns with singular values in [0.5, 2] before the scaling (cond <= 4
    then, and the column scaling keeps it within a small factor)."""
    u, _ = np.linalg.qr(rng.standard_normal((n, p)))
    v, _ = np.linalg.qr(rng.standard_normal((p, p)))
    a = (u * rng.uniform(0.5, 2.0, p)) @ v.T
    return a / np.linalg.norm(a, axis=0)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(3, 300), m=st.integers(0, 10), k=st.integers(1, 6),
       seed=st.integers(0, 2 ** 31 - 1))
def test_appended_diagonal_equals_a_fresh_qr_of_the_whole_design(n, m, k, seed):
    rng = np.random.default_rng(seed)
    p = min(m + k, n - 1)
    m = min(m, p - 1) if p > 1 else 0
    k = p - m
    a = _design(rng, n, p)
    fresh = np.abs(np.diag(linalg.qr(a, mode="r")[0]))
    q = linalg.qr(a[:, :m], mode="economic")[0] if m else np.zeros((n, 0))
    got = angle_design.appended_diagonal(q, a[:, m:])
    cond = np.linalg.cond(a)
    assert got.shape == (k,)
    np.testing.assert_allclose(got, fresh[m:], rtol=0, atol=10 * n * p * EPS * cond)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(4, 300), m=st.integers(1, 10), k=st.integers(1, 6),
       seed=st.integers(0, 2 ** 31 - 1))
def test_residual_from_the_shared_basis_equals_a_fresh_lstsq(n, m, k, seed):
    # _linear_bound's update: [N | r] projected out of the fit's basis, its QR's last
    # diagonal entry is the residual norm of the least-squares fit of r by [A | N]
    rng = np.random.default_rng(seed)
    p = min(m + k, n - 2)
    m = min(m, p - 1) if p > 1 else 0
    k = p - m
    a = _design(rng, n, p)
    b = rng.standard_normal(n)
    x, *_ = linalg.lstsq(a, b)
    fresh = float(np.linalg.norm(b - a @ x))
    q = linalg.qr(a[:, :m], mode="economic")[0] if m else np.zeros((n, 0))
    ab = np.column_stack([a[:, m:], b])
    d = angle_design.appended_diagonal(q, ab)
    cond = np.linalg.cond(a)
    assert d[-1] == pytest.approx(fresh, abs=10 * n * p * EPS * cond * np.linalg.norm(b))


def test_appended_diagonal_empty_and_bad_input():
    q = np.linalg.qr(np.random.default_rng(0).standard_normal((5, 2)))[0]
    assert angle_design.appended_diagonal(q, np.zeros((5, 0))).shape == (0,)
    assert angle_design.appended_diagonal(np.zeros((3, 3)), np.ones((3, 1))).shape == (0,)
    with pytest.raises(ValueError, match="one row count"):
        angle_design.appended_diagonal(q, np.ones((4, 1)))
    with pytest.raises(ValueError, match="2-D"):
        angle_design.appended_diagonal(q, np.ones(5))


def test_fit_basis_empty_and_bad_input():
    trains = _screening_record("steady_noisy")
    kin = kinematics(25, 87, 29, fixed="ring")
    d = angle_design.Design(trains, kin, 4)
    spec = angle_design.ModelSpec(knots=1, harm={r: 0 for r in kin.periods},
                                  mod={r: False for r in kin.periods})
    fit = angle_design.solve(d, spec, None, np.ones(len(trains)))
    basis = angle_design.fit_basis(d, fit)
    n = int(np.count_nonzero(d.active))
    assert basis.q.shape == (n, fit.rank) and basis.q_nominal.shape[0] == n
    np.testing.assert_allclose(basis.q.T @ basis.q, np.eye(fit.rank), atol=1e-12)
    assert basis.valid == len(basis.names) and basis.chi_out <= basis.chi
    d.active[:] = False                                  # every observation left out
    assert angle_design.fit_basis(d, fit) is None
    with pytest.raises(TypeError, match="Design and a ModelFit"):
        angle_design.fit_basis(fit, d)


@pytest.mark.parametrize("profile", ["drift", "ramp_ripple", "steady_noisy"])
def test_each_candidates_bound_with_the_basis_equals_the_fresh_one(monkeypatch, profile):
    # every candidate the screen bounds: the same identifiable columns, and the bound within
    # rounding of the one from a fresh QR of the candidate's whole design
    trains = _screening_record(profile)
    pairs = []
    orig = angle_selection._linear_bound

    def both(d, fit, spec, theta0, basis=None):
        got = orig(d, fit, spec, theta0, basis)
        if basis is not None:
            pairs.append((got, orig(d, fit, spec, theta0, None)))
        return got

    monkeypatch.setattr(angle_selection, "_linear_bound", both)
    fit_angle_model(trains, kinematics(25, 87, 29, fixed="ring"), 4)
    assert pairs
    for (b1, k1), (b0, k0) in pairs:
        assert (k1 is None) == (k0 is None)
        if k0 is not None:
            np.testing.assert_array_equal(k1, k0)
        if math.isinf(b0):
            assert b1 == b0
        else:
            # n ln(chi / n): a relative change of chi by 1e-9 moves it by n 1e-9
            assert b1 == pytest.approx(b0, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("profile", ["drift", "ramp_ripple", "steady_noisy"])
def test_reused_factorisations_leave_the_selection_unchanged(monkeypatch, profile):
    trains = _screening_record(profile)
    kin = kinematics(25, 87, 29, fixed="ring")
    bases = []
    orig_basis = angle_selection.fit_basis

    def counted(*a, **k):
        bases.append(1)
        return orig_basis(*a, **k)

    monkeypatch.setattr(angle_selection, "fit_basis", counted)
    reused = fit_angle_model(trains, kin, 4)
    assert bases                                        # the shared basis was made and used
    monkeypatch.setattr(angles, "select_terms",
                        functools.partial(angle_selection.select_terms, reuse=False))
    fresh = fit_angle_model(trains, kin, 4)
    assert reused.terms == fresh.terms
    assert reused.selection == fresh.selection
    assert reused.rank == fresh.rank and reused.dropped == fresh.dropped
    t = np.linspace(*fresh.t_span, 501)
    np.testing.assert_array_equal(reused.mesh_angle(t), fresh.mesh_angle(t))
    np.testing.assert_array_equal(reused.difference_std(t[:-1], t[1:]),
                                  fresh.difference_std(t[:-1], t[1:]))
