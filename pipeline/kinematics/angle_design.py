"""The angle model's design and its weighted Gauss-Newton solve.

A :class:`ModelSpec` is one model order of eq. (2) of :mod:`meshphase.kinematics.angles`
(spline intervals, ripple harmonics per shaft, amplitude modulation, planet-term harmonics);
a :class:`Design` holds the observations of every train, stacked, and evaluates the mesh
angle, its rate and the Jacobian of one spec's columns; :func:`solve` fits one spec and
returns a :class:`ModelFit`.

Estimation: weighted Gauss-Newton on (2) (the ripple arguments depend on S), each step a
least-squares solve of the column-scaled weighted Jacobian by Householder QR (never the
normal equations; rank-revealing QR where a column has become dependent), halved while it
raises the misfit, and an iteration whose full step moves no prediction by the convergence
tolerance ends there (such a step is rounding). Weights 1 / (sigma_t A'(t)) from each
onset's timing bound. A column the data cannot tell apart from earlier ones (its share
outside their span below ``RANK_TOL``, :func:`rank_keep`) is dropped and its parameter held
at zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..runtime.lazy import interpolate, linalg
from .shafts import Kinematics
from .trains import PassTrain
from ..signal.median import median_of_finite

__all__ = ["ModelSpec", "Design", "ModelFit", "FitBasis", "fit_basis", "spline_basis",
           "rank_keep", "fix_rate", "plausible_rate", "column_norms", "appended_diagonal",
           "solve", "extend_theta", "RANK_TOL", "CHI2_FLOOR", "RATE_SPREAD", "STEP_QR_TOL"]

TWO_PI = 2.0 * math.pi
#: columns whose share outside the span of earlier columns is below this are dropped [-]
RANK_TOL = 1e-7
#: floor of the mean squared weighted residual in the criterion [-] when no timing bound was
#: given (noise-free data); with bounds the floor is 1
CHI2_FLOOR = 1e-8


@dataclass
class ModelSpec:
    """One model order of eq. (2) of :mod:`meshphase.kinematics.angles`.

    Attributes
    ----------
    knots : int
        Spline intervals [-].
    harm : dict of str to int
        Highest ripple harmonic per shaft rate ("carrier", "sun", "ring", "planet") [-].
    mod : dict of str to bool
        Amplitude modulation (linear in the scaled time) per shaft rate.
    sig : int
        Planet-term harmonics [-].
    first : {"", "planet", "ripple"}
        Rank order between the planet terms and a ripple at the planet-spin period where
        the data cannot tell them apart (comment at the field).
    """

    knots: int = 1
    harm: dict = field(default_factory=dict)      # rate -> highest harmonic
    mod: dict = field(default_factory=dict)       # rate -> amplitude modulation on/off
    sig: int = 0                                  # planet-term harmonics
    # rank order between the planet terms and a ripple at the planet-spin period where the
    # data cannot tell them apart: "" the default (carrier, sun and ring ripple before the
    # planet terms, the planet-rate ripple after), "planet" the planet terms before every
    # ripple, "ripple" every ripple before the planet terms
    first: str = ""

    def copy(self) -> "ModelSpec":
        """An independent copy (its dicts copied too)."""
        return ModelSpec(self.knots, dict(self.harm), dict(self.mod), self.sig, self.first)

    def describe(self) -> str:
        """The model order in words (as :attr:`meshphase.kinematics.angles.AngleModel.terms`)."""
        parts = [f"spline {self.knots} interval(s)"]
        for r, h in self.harm.items():
            if h:
                parts.append(f"{r} ripple x{h}" + (" (modulated)" if self.mod.get(r) else ""))
        if self.sig:
            parts.append(f"planet terms x{self.sig}")
        return ", ".join(parts)


def spline_basis(x: np.ndarray, K: int, nu: int = 0) -> np.ndarray:
    """Uniform cubic B-spline basis on [-1, 1] with K intervals (knots continued past both
    ends, so polynomials up to degree 3 are in the span), value or derivative ``nu``."""
    h = 2.0 / K
    kk = -1.0 + h * np.arange(-3, K + 4)
    nb = K + 3
    spl = interpolate.BSpline(kk, np.eye(nb), 3, extrapolate=True)
    return spl(x, nu) if x.size else np.zeros((0, nb))


class Design:
    """Observations of all trains, stacked, and the column layout of one model spec."""

    def __init__(self, trains: list[PassTrain], kin: Kinematics, n_planets: int):
        self.trains = trains
        self.kin = kin
        self.N = n_planets
        self.t = np.concatenate([tr.times for tr in trains])
        self.y = np.concatenate([tr.target for tr in trains])
        self.sig = np.concatenate([tr.sigma for tr in trains])
        self.q = np.concatenate([np.full(len(tr), i) for i, tr in enumerate(trains)])
        self.pl = np.concatenate([tr.planet for tr in trains])
        # mesh cycles per radian of a planet's carrier-frame angle shift, per row (0: tacho)
        self.ps = np.concatenate([np.full(len(tr), tr.order * tr.z / TWO_PI if tr.kind != "tacho" else 0.0)
                                  for tr in trains])
        self.t_lo, self.t_hi = float(self.t.min()), float(self.t.max())
        self.t_mid = 0.5 * (self.t_lo + self.t_hi)
        self.half = max(0.5 * (self.t_hi - self.t_lo), 1e-12)
        self.x = (self.t - self.t_mid) / self.half
        self.active = np.ones(self.t.size, bool)      # False: left out as an outlier
        # spline bases at every observation, per (intervals, derivative): the iterations of a
        # fit evaluate the same rows again and again (a few recent entries are kept)
        self._bases: dict = {}
        self._layouts: dict = {}
        # reference planet of each gauge train: planet 1 when present, else the lowest
        self.ref = []
        for tr in trains:
            if tr.kind == "tacho" or not len(tr):
                self.ref.append(-1)
            else:
                present = np.unique(tr.planet)
                self.ref.append(0 if 0 in present else int(present[0]))

    def x_of(self, t: np.ndarray) -> np.ndarray:
        return (np.asarray(t, dtype=float) - self.t_mid) / self.half

    #: spline bases kept by :meth:`Design.basis_rows` (a window of 6000 observations and 64
    #: intervals: 3 MB each)
    _BASES_KEPT = 4

    def basis_rows(self, K: int, nu: int, rows: np.ndarray) -> np.ndarray:
        """The spline basis (``nu``: 0 value, 1 derivative per second) at observations
        ``rows``: evaluated once at every observation and kept, then gathered."""
        key = (int(K), int(nu))
        full = self._bases.pop(key, None)
        if full is None:
            full = spline_basis(self.x, K, nu)
            if nu:
                full /= self.half ** nu
        self._bases[key] = full                      # most recently used last
        while len(self._bases) > self._BASES_KEPT:
            del self._bases[next(iter(self._bases))]
        rows = np.asarray(rows)
        if rows.size == full.shape[0] and np.array_equal(rows, np.arange(rows.size)):
            return full                              # every row, in order: no gather
        return full[rows]

    def release(self) -> None:
        """Drop the kept spline bases and layouts (a fitted model keeps its design; a
        layout holds three index arrays of the observations' length)."""
        self._bases.clear()
        self._layouts.clear()

    def layout(self, spec: ModelSpec) -> dict:
        """Parameter blocks of ``spec``: name -> slice, column names, priorities, and the
        (train, planet) -> column tables of the offsets and planet terms (made once per spec
        and design; read-only)."""
        key = (spec.knots, tuple(sorted(spec.harm.items())), tuple(sorted(spec.mod.items())),
               spec.sig, spec.first)
        lay = self._layouts.get(key)
        if lay is None:
            lay = self._layouts[key] = self._layout(spec)
        return lay

    def _layout(self, spec: ModelSpec) -> dict:
        names, prio = [], []
        blocks = {}
        i = 0

        def add(key, cols, p):
            nonlocal i
            blocks[key] = slice(i, i + len(cols))
            names.extend(cols)
            prio.extend(p if isinstance(p, list) else [p] * len(cols))
            i += len(cols)

        add("spline", [f"spline[{j}]" for j in range(spec.knots + 3)], 0)
        for r in self.kin.periods:
            h = spec.harm.get(r, 0)
            if h:
                # a common ripple at the planet spin is what identical planet terms on every
                # planet would look like: where the data cannot tell them apart, the planet
                # terms (always present, from the planets' own shaft hole offsets) are kept
                # so is a harmonic of another shaft's ripple at a period of the planet spin
                # (the carrier's third on Z_r / Z_p = 3): the planet terms go first there too
                k = np.arange(1, h + 1) * (self.kin.planet_period or 0.0) / self.kin.periods[r]
                spin = (r == "planet") | ((k > 0) & (np.abs(k - np.round(k)) < 1e-9))
                pr = [6 if sp else 3 for sp in spin for _ in range(2)]
                if spec.first:
                    pr = [6 if spec.first == "planet" else 3] * (2 * h)
                add(f"rip:{r}", [f"{r} ripple {c}{m}" for m in range(1, h + 1) for c in ("cos", "sin")], pr)
                if spec.mod.get(r):
                    add(f"mod:{r}", [f"{r} ripple x*{c}{m}" for m in range(1, h + 1)
                                     for c in ("cos", "sin")], [x + 1 for x in pr])
        add("const", [f"{tr.name}: constant" for q, tr in enumerate(self.trains) if q > 0], 1)
        T = len(self.trains)
        off_table = np.full((T, self.N), -1, dtype=np.int64)
        offs = []
        for q, tr in enumerate(self.trains):
            if tr.kind == "tacho":
                continue
            for n in np.unique(tr.planet):
                if n != self.ref[q]:
                    off_table[q, n] = len(offs)
                    offs.append(f"{tr.name}: planet {n + 1} offset")
        add("off", offs, 2)
        # planet terms: one set per planet, shared by every gauge (a planet's own shaft hole
        # offset turns the line of centres of its sun and its ring mesh alike, to first order
        # in e / R_c: d psi_n(t) [rad]), each gauge seeing it scaled by order * Z / 2 pi
        sig_index = np.full(self.N, -1, dtype=np.int64)
        sigs = []
        if spec.sig and self.kin.planet_period:
            for n in np.unique(self.pl[self.pl >= 0]):
                sig_index[n] = len(sigs)
                sigs += [f"planet {n + 1} spin term {c}{m}"
                         for m in range(1, spec.sig + 1) for c in ("cos", "sin")]
        add("sig", sigs, 5)
        # the gauges time their passes at features that sit a (small, gauge-specific) angle
        # off the engagement; the planet terms turn with the planet, so each gauge after the
        # first carries that angle as a phase lag of the planet terms [mesh cycles]
        lag_index = np.full(T, -1, dtype=np.int64)
        lags = []
        if sigs:
            gauges = [q for q, tr in enumerate(self.trains) if tr.kind != "tacho"]
            for q in gauges[1:]:
                lag_index[q] = len(lags)
                lags.append(f"{self.trains[q].name}: planet-term lag")
        add("lag", lags, 5)
        pl = np.maximum(self.pl, 0)
        return {"blocks": blocks, "names": names, "priority": np.asarray(prio), "p": i,
                "off_table": off_table, "sig_index": sig_index, "lag_index": lag_index,
                "li": lag_index[self.q],
                "oi": np.where(self.pl >= 0, off_table[self.q, pl], -1),
                "si": np.where((self.pl >= 0) & (self.ps != 0), sig_index[pl], -1)}

    # ------------------------------------------------------------------ evaluation
    def _ripple(self, theta, lay, spec, A, x):
        """R(A, x), dR/dA, dR/dx at mesh angles A and scaled times x; and the columns
        dR/dtheta (one array per ripple block, in layout order)."""
        R = np.zeros(A.size)
        RA = np.zeros(A.size)
        Rx = np.zeros(A.size)
        cols = []
        for r, P in self.kin.periods.items():
            h = spec.harm.get(r, 0)
            if not h:
                continue
            m = np.arange(1, h + 1)
            ph = TWO_PI * np.mod(np.outer(A, m / P), 1.0)             # (n, h), reduced
            c, sn = np.cos(ph), np.sin(ph)
            trig = np.empty((A.size, 2 * h))
            trig[:, 0::2], trig[:, 1::2] = c, sn
            dtrig = np.empty_like(trig)                               # d trig / dA
            dtrig[:, 0::2] = -sn * (TWO_PI * m / P)
            dtrig[:, 1::2] = c * (TWO_PI * m / P)
            a = theta[lay["blocks"][f"rip:{r}"]]
            R += trig @ a
            RA += dtrig @ a
            cols.append(trig)
            if spec.mod.get(r):
                am = theta[lay["blocks"][f"mod:{r}"]]
                R += x * (trig @ am)
                RA += x * (dtrig @ am)
                Rx += trig @ am
                cols.append(trig * x[:, None])
        return R, RA, Rx, cols

    def _common(self, theta, lay, spec, x, A_fixed=None, rows=None):
        """Solve A = S(t) + R(A, x) (Newton from A = S) at scaled times x.

        Returns A, dA/dt, the columns dA/dtheta restricted to spline and ripple blocks (as a
        dense (n, p) array with zeros elsewhere) and dR/dA. With ``A_fixed`` the columns are
        evaluated at those angles instead of the solved ones. ``rows``: x are the scaled
        times of these observations (their spline bases are kept between calls)."""
        if rows is None:
            B = spline_basis(x, spec.knots)
            dB = spline_basis(x, spec.knots, 1) / self.half
        else:
            B = self.basis_rows(spec.knots, 0, rows)
            dB = self.basis_rows(spec.knots, 1, rows)
        beta = theta[lay["blocks"]["spline"]]
        S = B @ beta
        dS = dB @ beta
        A = S.copy() if A_fixed is None else np.asarray(A_fixed, dtype=float)
        if A_fixed is None and any(spec.harm.get(r, 0) for r in self.kin.periods):
            scale = max(1.0, float(np.max(np.abs(S))) if S.size else 1.0)
            for _ in range(30):
                R, RA, _, _ = self._ripple(theta, lay, spec, A, x)
                F = A - S - R
                A = A - F / (1.0 - RA)
                if not F.size or float(np.max(np.abs(F))) <= 4 * np.finfo(float).eps * scale:
                    break
        R, RA, Rx, cols = self._ripple(theta, lay, spec, A, x)
        den = 1.0 - RA if A_fixed is None else np.ones(A.size)
        G = np.zeros((x.size, lay["p"]))
        np.divide(B, den[:, None], out=G[:, lay["blocks"]["spline"]])
        c = 0
        for key, sl in lay["blocks"].items():
            if key.startswith("rip:") or key.startswith("mod:"):
                np.divide(cols[c], den[:, None], out=G[:, sl])
                c += 1
        rate = (dS + Rx / self.half) / den
        return A, rate, G, RA

    def evaluate(self, theta, lay, spec, rows=None, *, jac=True, nominal=False):
        """Model value f, Jacobian J (rows x p), and the observation's angle rate [cycles/s].

        ``nominal``: the first-order (structural) design instead: columns evaluated at the
        angles the observations put A at (target minus the train's constant, offset and
        planet term), without the slope factors (1 + h') / (1 - R'). Those angles are exactly
        periodic where the geometry makes them so (a planet meeting a ring gauge at the same
        spin angle every time), so structural dependence between columns is exact, not
        blurred by residuals or by second-order coupling of ripple and planet terms (which no
        real record resolves); used to judge identifiability.
        """
        idx = np.arange(self.t.size) if rows is None else rows
        x = self.x[idx]
        q = self.q[idx]
        n = idx.size
        cb = lay["blocks"]["const"]
        ob = lay["blocks"]["off"]
        th_c = theta[cb]
        th_o = theta[ob]
        has_c = q > 0
        oi = lay["oi"][idx]
        train_terms = np.zeros(n)
        if th_c.size:
            train_terms += np.where(has_c, th_c[np.maximum(q - 1, 0)], 0.0)
        if th_o.size:
            train_terms += np.where(oi >= 0, th_o[np.maximum(oi, 0)], 0.0)
        if nominal:
            # the angle the observation names: its target less its train's constant and
            # offset, exactly periodic wherever the geometry is (the planet terms, a few
            # 1e-3 cycles, and the residuals are left out on purpose)
            A, rate, G, _ = self._common(theta, lay, spec, x,
                                         A_fixed=self.y[idx] - train_terms, rows=idx)
        else:
            A, rate, G, _ = self._common(theta, lay, spec, x, rows=idx)
        f = A + train_terms
        # planet terms, periodic in the planet's spin: functions of the mesh angle A
        sb = lay["blocks"]["sig"]
        hA = np.zeros(n)
        sig_cols = None
        hA_lag = np.zeros(n)
        lb = lay["blocks"]["lag"]
        li = lay["li"][idx]
        lag = np.zeros(n)
        if lb.stop > lb.start:
            has = li >= 0
            lag[has] = theta[lb][li[has]]
        if sb.stop > sb.start:
            P = self.kin.planet_period
            m = np.arange(1, spec.sig + 1)
            ph = TWO_PI * np.mod(np.outer(A - lag, m / P), 1.0)
            trig = np.empty((n, 2 * spec.sig))
            trig[:, 0::2], trig[:, 1::2] = np.cos(ph), np.sin(ph)
            dtrig = np.empty_like(trig)
            dtrig[:, 0::2] = -np.sin(ph) * (TWO_PI * m / P)
            dtrig[:, 1::2] = np.cos(ph) * (TWO_PI * m / P)
            si = lay["si"][idx]
            ps = self.ps[idx]
            th_s = theta[sb]
            w = 2 * spec.sig
            ok = si >= 0
            if np.any(ok):
                gather = th_s[si[ok, None] + np.arange(w)[None, :]]
                f[ok] += ps[ok] * np.sum(gather * trig[ok], axis=1)
                hA[ok] = ps[ok] * np.sum(gather * dtrig[ok], axis=1)
            sig_cols = (si, trig * ps[:, None])
        hA_lag = hA.copy()
        if nominal:
            hA = np.zeros(n)
        obs_rate = rate * (1.0 + hA)
        if not jac:
            return f, None, obs_rate
        J = G                              # _common's own array: scaled in place
        J *= (1.0 + hA)[:, None]
        if cb.stop > cb.start:
            J[np.flatnonzero(has_c), cb.start + q[has_c] - 1] = 1.0
        if ob.stop > ob.start:
            k = np.flatnonzero(oi >= 0)
            J[k, ob.start + oi[k]] = 1.0
        if sig_cols is not None:
            si, trig = sig_cols
            k = np.flatnonzero(si >= 0)
            w = trig.shape[1]
            J[k[:, None], sb.start + si[k][:, None] + np.arange(w)[None, :]] = trig[k]
        if lb.stop > lb.start:
            k = np.flatnonzero((li >= 0) & (lay["si"][idx] >= 0))
            J[k, lb.start + li[k]] = -hA_lag[k]
        return f, J, obs_rate

    def a_part(self, theta, lay, spec, t):
        """A(t), dA/dt and dA/dtheta (the common angle only, no train terms) at times t."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        A, rate, G, _ = self._common(theta, lay, spec, self.x_of(t))
        return A, rate, G


def rank_keep(d: "Design", theta, lay, spec, rows, basis: "FitBasis | None" = None) -> np.ndarray:
    """Identifiable columns: the Jacobian at the nominal angles, weighted by the timing bounds
    alone (a train's variance factor must not decide what is identifiable).

    ``basis``: the :class:`FitBasis` of a fit that ``theta`` extends (:func:`extend_theta`:
    the fit's spline and terms, the new terms at zero) on the same ``rows``; the columns this
    spec shares with that fit, in rank order before its first new column, then come from the
    basis's factorisation instead of a fresh one (:func:`_independent_columns`)."""
    _, J, rate = d.evaluate(theta, lay, spec, rows, nominal=True)
    w = 1.0 / (d.sig[rows] * fix_rate(rate))
    prefix = None
    if basis is not None and basis.knots == spec.knots and np.array_equal(basis.rows, rows):
        prefix = (lay["names"], basis)
    return _independent_columns(J * w[:, None], lay["priority"], prefix=prefix)


def fix_rate(rate: np.ndarray) -> np.ndarray:
    """Angle rates with non-finite or non-positive entries (a model not yet fitted) replaced
    by the median of the good ones (1 when there is none) [cycles/s]."""
    ok = np.isfinite(rate) & (rate > 0)
    if np.all(ok):
        return rate
    return np.where(ok, rate, float(np.median(rate[ok])) if np.any(ok) else 1.0)


#: mesh-angle rates within one fit stay within this factor of their median [-]: a model
#: beyond it has left the implicit angle equation's domain (a step to dR/dA near 1)
RATE_SPREAD = 100.0


def plausible_rate(rate: np.ndarray) -> bool:
    """Whether every mesh-angle rate is finite, positive and within ``RATE_SPREAD`` of the
    median (a recording that speeds up 100-fold is split by operating point, not fitted)."""
    rate = np.asarray(rate, dtype=np.float64)
    if rate.size == 0:
        return True
    if not (np.all(np.isfinite(rate)) and np.all(rate > 0)):
        return False
    med = float(median_of_finite(rate))             # finite, checked above
    return bool(np.all(rate <= RATE_SPREAD * med) and np.all(rate >= med / RATE_SPREAD))


def column_norms(A: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column, without overflow when entries are huge (a near-exact
    observation, such as a synthetic tacho, carries weights where squares pass 1e308)."""
    A = np.asarray(A, dtype=np.float64)
    if A.size == 0:
        return np.zeros(A.shape[1] if A.ndim == 2 else 0)
    amax = np.maximum(np.max(A, axis=0), -np.min(A, axis=0))     # max |A|, no |A| copy
    safe = np.where(amax > 0, amax, 1.0)
    # np.linalg.norm(A / safe, axis=0) to the bit, squared in place (without its temporaries
    # and dispatch, which cost more than the sum itself on the fits' tall designs)
    T = A / safe
    np.multiply(T, T, out=T)
    return np.where(amax > 0, amax * np.sqrt(np.add.reduce(T, axis=0)), 0.0)


def appended_diagonal(Q: np.ndarray, T: np.ndarray) -> np.ndarray:
    """|R_jj| of columns ``T`` appended to a matrix whose columns ``Q`` span orthonormally:
    the last ``T.shape[1]`` diagonal entries of the Householder R of [A | T], A any matrix
    with Q's span (each column's distance to the span of A and of the columns of T before it).

    ``T`` is projected out of Q's span twice (classical Gram-Schmidt, reorthogonalised: one
    pass leaves a component of order eps * cond of the unprojected part, the second brings
    it to rounding) and its own QR taken; the cost is that of T's columns alone, not of
    refactorising A's. In exact arithmetic this equals the full QR's diagonal; in floating
    point the two differ by O(eps * cond([A | T])) relative to the columns' norms.

    Parameters
    ----------
    Q : ndarray, shape (n, m)
        Orthonormal columns (m may be 0).
    T : ndarray, shape (n, k)

    Returns
    -------
    ndarray, shape (min(n - m, k),) when n > m, else (0,)

    Raises
    ------
    ValueError
        ``Q`` and ``T`` not 2-D with the same number of rows.
    """
    Q = np.asarray(Q, dtype=np.float64)
    T = np.asarray(T, dtype=np.float64)
    if Q.ndim != 2 or T.ndim != 2 or Q.shape[0] != T.shape[0]:
        raise ValueError(f"Q and T must be 2-D with one row count, got {Q.shape} and {T.shape}")
    n, m = Q.shape
    k = T.shape[1]
    if k == 0 or n <= m:
        return np.zeros(0)
    P = np.array(T, order="F")
    if m:
        for _ in range(2):
            P -= Q @ (Q.T @ P)
    qr = linalg.qr(P, mode="raw", overwrite_a=True, check_finite=False)[0][0]
    return np.abs(np.diag(qr))[:min(n - m, k)]


def _independent_columns(Jw: np.ndarray, priority: np.ndarray, tol: float = RANK_TOL,
                         prefix=None) -> np.ndarray:
    """Columns kept, in priority order (then left to right): a column whose part outside the
    span of the columns kept before it is below ``tol`` of its norm is dropped.

    Householder QR without pivoting on the unit-norm columns in priority order gives, in
    |R_jj|, each column's distance to the span of the ones before it. The first column
    below ``tol`` is dropped and the QR repeated (a dependent column would otherwise steer
    the later reflections), until none is.

    ``prefix``: (column names, :class:`FitBasis`). The leading columns in priority order
    that are the basis's own (same names, in its order, none below ``tol`` there) keep
    the basis's |R_jj| and span; only the columns after them are factorised
    (:func:`appended_diagonal`), again after each drop. A candidate that extends a fit by
    a term shares every column before its first new one: the same columns kept, in exact
    arithmetic, for a fraction of the work."""
    p = Jw.shape[1]
    order = np.lexsort((np.arange(p), priority))
    norms = column_norms(Jw)
    cand = [j for j in order if norms[j] > 0]
    m = 0
    if prefix is not None:
        names, basis = prefix
        lim = min(len(cand), basis.valid)
        while m < lim and names[cand[m]] == basis.names[m]:
            m += 1
        if Jw.shape[0] <= len(cand):
            m = 0                           # wide: the plain path's min(n, p) diagonal
    if m:
        head, tail = cand[:m], cand[m:]
        Qm = basis.q_nominal[:, :m]
        while tail:
            dt = appended_diagonal(Qm, Jw[:, tail] / norms[tail])
            small = np.flatnonzero(dt < tol)
            if small.size == 0:
                break
            clear = small[dt[small] < 1e-3 * tol]
            drop = clear if clear.size else small[:1]
            for i in sorted(drop.tolist(), reverse=True):
                del tail[int(i)]
        cand = head + tail
    else:
        while cand:
            A = Jw[:, cand] / norms[cand]
            # geqrf's packed result: R is its upper triangle (mode "r" would copy it out whole)
            qr = linalg.qr(A, mode="raw", overwrite_a=True, check_finite=False)[0][0]
            d = np.abs(np.diag(qr))
            small = np.flatnonzero(d < tol)
            if small.size == 0:
                break
            # clear-cut dependence (far below tol) is dropped at once; a borderline column one
            # at a time, since a dependent column steers the later reflections
            clear = small[d[small] < 1e-3 * tol]
            drop = clear if clear.size else small[:1]
            for i in sorted(drop.tolist(), reverse=True):
                del cand[int(i)]
    keep = np.zeros(p, bool)
    keep[cand] = True
    return keep


@dataclass
class FitBasis:
    """Factorisations of one fitted model's design, made once and shared by every candidate
    that extends it by a term (:func:`fit_basis`; the selection's screen,
    :func:`meshphase.kinematics.angle_selection.select_terms`).

    Attributes
    ----------
    knots : int
        The fit's spline intervals (a candidate with another spline shares no column).
    rows : ndarray of int
        The active observations the factorisations are of.
    names : list of str
        The fit's columns of nonzero norm in rank order (priority, then layout), nominal.
    q_nominal : ndarray, shape (n, len(names))
        Orthonormal basis of those weighted unit-norm nominal columns (:func:`rank_keep`'s
        design), leading columns first: its first m columns span the first m columns.
    valid : int
        Leading columns whose |R_jj| is at least ``RANK_TOL`` (a prefix that long is the
        same in every candidate's rank check).
    kept : frozenset of str
        Names of the fit's identifiable columns.
    q : ndarray, shape (n, rank)
        Orthonormal basis of the fit's weighted unit-norm identifiable columns at its
        parameters (the Gauss-Newton design).
    r, chi : ndarray, float
        Weighted residual at the fit (timing bounds alone) and its squared norm [-].
    r_out, chi_out : ndarray, float
        Its part outside the span of ``q`` and that part's squared norm [-].
    fac : ndarray
        Row factor every spline's columns share at the fit, (1 + h') / (1 - R') times the
        weight (the row sums of the fitted spline's columns).
    """

    knots: int
    rows: np.ndarray
    names: list
    q_nominal: np.ndarray
    valid: int
    kept: frozenset
    q: np.ndarray
    r: np.ndarray
    chi: float
    r_out: np.ndarray
    chi_out: float
    fac: np.ndarray


def fit_basis(d: Design, fit: "ModelFit", *, nominal: bool = True) -> "FitBasis | None":
    """The :class:`FitBasis` of ``fit`` on the design's active rows: one evaluation and one
    QR each of its nominal and its Gauss-Newton design (``nominal=False``: the Gauss-Newton
    design's alone, ``valid`` 0). None when there is no active row or the weighted misfit
    is not finite (nothing to share).

    Raises
    ------
    TypeError
        ``d`` not a :class:`Design` or ``fit`` not a :class:`ModelFit`.
    """
    if not isinstance(d, Design) or not isinstance(fit, ModelFit):
        raise TypeError(f"fit_basis takes a Design and a ModelFit, got {type(d).__name__} "
                        f"and {type(fit).__name__}")
    rows = np.flatnonzero(d.active)
    n = rows.size
    if n == 0:
        return None
    f, J, rate = d.evaluate(fit.theta, fit.lay, fit.spec, rows)
    w = 1.0 / (d.sig[rows] * fix_rate(rate))
    with np.errstate(over="ignore", invalid="ignore"):
        r = (d.y[rows] - f) * w
        chi = float(r @ r)
    if not math.isfinite(chi):
        return None
    sb = fit.lay["blocks"]["spline"]
    fac = J[:, sb].sum(axis=1) * w
    Ac = (J * w[:, None])[:, fit.keep]
    cn = column_norms(Ac)
    cn[~(cn > 0)] = 1.0
    Q = linalg.qr(Ac / cn, mode="economic", check_finite=False)[0]
    r_out = r - Q @ (Q.T @ r)
    # the nominal design in rank order: the leading columns of every candidate's rank check
    cand = []
    if nominal:
        _, Jn, rn = d.evaluate(fit.theta, fit.lay, fit.spec, rows, nominal=True)
        Jn *= (1.0 / (d.sig[rows] * fix_rate(rn)))[:, None]
        p = Jn.shape[1]
        order = np.lexsort((np.arange(p), fit.lay["priority"]))
        norms = column_norms(Jn)
        cand = [j for j in order if norms[j] > 0]
    if cand and n > len(cand):
        Qn, Rn = linalg.qr(Jn[:, cand] / norms[cand], mode="economic", check_finite=False)
        small = np.flatnonzero(np.abs(np.diag(Rn)) < RANK_TOL)
        valid = int(small[0]) if small.size else len(cand)
    else:
        Qn, valid = np.zeros((n, 0)), 0
    names = fit.lay["names"]
    return FitBasis(int(fit.spec.knots), rows, [names[j] for j in cand], Qn, valid,
                    frozenset(nm for nm, k in zip(names, fit.keep) if k), Q, r, chi, r_out,
                    float(r_out @ r_out), fac)


@dataclass
class ModelFit:
    """One spec fitted by :func:`solve`.

    Attributes
    ----------
    spec : ModelSpec
    lay : dict
        The column layout of ``spec`` (:meth:`Design.layout`).
    theta : ndarray
        Parameters (zero where a column was dropped).
    keep : ndarray of bool
        Identifiable columns (:func:`rank_keep`).
    chi2 : float
        Weighted misfit of the active rows [-].
    n, rank, iterations : int
        Active rows, kept columns and Gauss-Newton iterations.
    converged : bool
    resid, rate : ndarray
        Residuals [mesh cycles] and angle rates [cycles/s] at every row (outliers too).
    cov : ndarray or None
        Covariance of the kept parameters (with ``full``).
    lev : ndarray or None
        Leverages of the active rows (with ``full``).
    floor : float
        Floor of chi2 / n in the criterion [-] (1 with timing bounds, else ``CHI2_FLOOR``).
    """

    spec: ModelSpec
    lay: dict
    theta: np.ndarray
    keep: np.ndarray
    chi2: float
    n: int
    rank: int
    iterations: int
    converged: bool
    resid: np.ndarray = None        # [mesh cycles], all rows (outliers too)
    rate: np.ndarray = None         # [cycles/s]
    cov: np.ndarray = None          # kept-parameter covariance (scaled)
    lev: np.ndarray = None          # leverages of the active rows

    floor: float = CHI2_FLOOR

    def bic(self) -> float:
        """n ln(max(chi2 / n, floor)) + rank ln n. With timing bounds given the floor is 1:
        residuals already inside the bounds are no evidence for another term."""
        n = max(self.n, 1)
        return n * math.log(max(self.chi2 / n, self.floor)) + self.rank * math.log(n)


def _conv_tol(d: Design, rows: np.ndarray, rate: np.ndarray) -> float:
    """With timing bounds, a step that moves no prediction by 1e-3 of its own bound changes
    nothing that matters: that move is the convergence tolerance [mesh cycles] (0 without);
    ``rate``: the angle rates at ``rows`` at the start [cycles/s]."""
    if not all(tr.sigma_given for tr in d.trains):
        return 0.0
    r0 = fix_rate(rate)
    if np.all(np.isfinite(r0)) and np.any(r0 != 1.0):
        return 1e-3 * float(np.min(d.sig[rows] * r0))
    return 0.0


#: a Gauss-Newton step is solved by unpivoted QR while every |R_jj| of the unit-norm columns
#: is above this [-]; below it (a column the converged point made dependent) by gelsy,
#: rank-revealing
STEP_QR_TOL = 1e-10


def _gn_step(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least-squares solution of A x ~ b for the unit-norm columns of a Gauss-Newton design.

    Householder QR of [A | b] (LAPACK geqrf through :func:`scipy.linalg.qr`): its last
    column holds Q^T b, so x solves R x = (Q^T b)[:p]. geqrf releases the GIL (gelsy does
    not), so fits on several threads overlap. The columns were screened for independence
    (:func:`_independent_columns`); where one has become dependent at this point (an |R_jj|
    below ``STEP_QR_TOL``) the step falls back to gelsy's rank-revealing solution."""
    n, p = A.shape
    if p == 0:
        return np.zeros(0)
    if n > p:
        Ab = np.empty((n, p + 1), order="F")
        Ab[:, :p] = A
        Ab[:, p] = b
        qr, _ = linalg.qr(Ab, mode="raw", overwrite_a=True, check_finite=False)[0]
        d = np.abs(np.diag(qr[:p, :p]))
        if np.all(np.isfinite(qr[:p, :p + 1])) and np.min(d) > STEP_QR_TOL * np.max(d):
            return linalg.solve_triangular(qr[:p, :p], qr[:p, p], check_finite=False)
    return linalg.lstsq(A, b, lapack_driver="gelsy", check_finite=False)[0]


def solve(d: Design, spec: ModelSpec, theta0: np.ndarray | None, scale: np.ndarray, *,
           max_iter: int = 12, tol: float = 1e-10, full: bool = False,
           recheck: bool = True, keep: np.ndarray | None = None) -> ModelFit:
    """Weighted Gauss-Newton for one spec; ``scale`` is the per-train variance factor.
    ``keep``: the identifiable columns at ``theta0`` when already known (what the first
    check would find; every parameter it drops must be zero in ``theta0``)."""
    lay = d.layout(spec)
    p = lay["p"]
    theta = np.zeros(p) if theta0 is None else theta0.copy()
    rows = np.flatnonzero(d.active)
    conv = False
    it = 0
    budget = max_iter
    rechecked = not recheck
    last = {}     # the latest evaluation: _finish reuses it when every row is active

    def weighted(theta_):
        f_, J_, rate_ = d.evaluate(theta_, lay, spec, rows)
        last.update(theta=theta_, f=f_, J=J_, rate=rate_)
        w_ = 1.0 / (d.sig[rows] * fix_rate(rate_) * scale[d.q[rows]])
        r_ = d.y[rows] - f_
        # a trial step can throw the implicit angle equation near its singular point (rates
        # past 1e190): such a point is no candidate, never a floating-point overflow
        with np.errstate(over="ignore", invalid="ignore"):
            chi_ = float(np.sum((r_ * w_) ** 2))
        if not (math.isfinite(chi_) and plausible_rate(rate_)):
            chi_ = math.inf
        return f_, J_, w_, r_, chi_

    f, J, w, r, chi = weighted(theta)
    conv_tol = _conv_tol(d, rows, last["rate"])
    while it < budget:
        it += 1
        if keep is None:
            keep = rank_keep(d, theta, lay, spec, rows)
            if not np.all(keep):
                # unidentifiable parameters sit at zero (minimum norm), not at stale values
                theta[~keep] = 0.0
                f, J, w, r, chi = weighted(theta)
        A = J[:, keep] * w[:, None]
        cn = column_norms(A)
        cn[~(cn > 0)] = 1.0
        step = _gn_step(A / cn, r * w) / cn
        # the largest move of a prediction the full step makes, to first order [mesh cycles]
        pred = float(np.max(np.abs(J[:, keep] @ step))) if step.size else 0.0
        tol_it = max(tol, conv_tol, 64 * np.finfo(float).eps * float(np.max(np.abs(d.y))))
        # Gauss-Newton with step halving: never accept a step that raises the misfit
        lam = 1.0
        at_theta = dict(last)
        for _ in range(12):
            trial = theta.copy()
            trial[keep] += lam * step
            ft, Jt, wt, rt, chit = weighted(trial)
            if chit <= chi * (1.0 + 1e-12) or not np.isfinite(chi):
                break
            if pred <= tol_it:
                # a step that moves no prediction by the tolerance is rounding: where it
                # raises the misfit, halving it only repeats the evaluation (up to 12 times
                # per converged solve); the iteration stands where it is, converged
                lam = 0.0
                trial, ft, Jt, wt, rt, chit = theta, f, J, w, r, chi
                last.clear()
                last.update(at_theta)
                break
            lam *= 0.5
        change = lam * pred
        theta, f, J, w, r, chi = trial, ft, Jt, wt, rt, chit
        if change <= tol_it:
            if rechecked:
                conv = True
                break
            # identifiability is judged where the columns are evaluated: check it again at
            # the converged point (a start far off can make dependent columns look apart)
            rechecked = True
            k2 = rank_keep(d, theta, lay, spec, rows)
            if np.array_equal(k2, keep):
                conv = True
                break
            keep = k2
            theta[~keep] = 0.0
            f, J, w, r, chi = weighted(theta)
            budget = it + max_iter   # a fresh allowance from the new start
    if full and not rechecked:
        # the iteration limit came first: the identifiability check at the end still decides
        k2 = rank_keep(d, theta, lay, spec, rows)
        if not np.array_equal(k2, keep):
            keep = k2
            theta[~keep] = 0.0
            return solve(d, spec, theta, scale, max_iter=max_iter, tol=tol, full=full,
                          recheck=False) if max_iter > 1 else solve(d, spec, theta, scale,
                                                                       max_iter=2, full=full)
    same = rows.size == d.t.size and last.get("theta") is theta
    return _finish(d, spec, lay, theta, keep, scale, rows, it, conv, full,
                   (last["f"], last["J"], last["rate"]) if same else None)


def _finish(d: Design, spec: ModelSpec, lay: dict, theta: np.ndarray, keep: np.ndarray,
            scale: np.ndarray, rows: np.ndarray, it: int, conv: bool, full: bool,
            at_theta=None) -> ModelFit:
    """The :class:`ModelFit` of converged parameters: residuals and rates at every observation,
    the weighted misfit and, with ``full``, the covariance and the leverages. ``at_theta``:
    (f, J, rate) already evaluated at ``theta`` on every observation, or None."""
    if at_theta is None:
        f, J, rate = d.evaluate(theta, lay, spec, np.arange(d.t.size), jac=full)
    else:
        f, J, rate = at_theta
    resid = d.y - f
    rate = fix_rate(rate)
    w_all = 1.0 / (d.sig * rate * scale[d.q])
    chi2 = float(np.sum((resid[rows] * w_all[rows]) ** 2))
    fit = ModelFit(spec, lay, theta, keep, chi2, rows.size, int(keep.sum()), it, conv, resid, rate)
    fit.floor = 1.0 if all(tr.sigma_given for tr in d.trains) else CHI2_FLOOR
    if full:
        A = (J[rows] * w_all[rows, None])[:, keep]
        cn = column_norms(A)
        cn[~(cn > 0)] = 1.0
        # covariance from the SVD of the (column-scaled) weighted design: R's diagonal from
        # an unpivoted QR can sit above any tolerance while R^-1 still overflows (110 passes
        # at 51.2 kHz: entries past 1e154); the singular values say it. A direction that
        # became dependent at the converged point has unbounded variance, which the
        # truncated pseudo-inverse reports as the smallest-norm split
        U, sv, Vt = linalg.svd(A / cn, full_matrices=False, check_finite=False)
        use = sv > RANK_TOL * (sv[0] if sv.size else 0.0)
        Vs = Vt[use].T / sv[use]
        C = (Vs @ Vs.T) / np.outer(cn, cn)
        fit.cov = C
        lev = np.zeros(d.t.size)
        lev[rows] = np.sum(U[:, use] ** 2, axis=1)
        fit.lev = lev
    return fit


def extend_theta(fit: ModelFit, spec: ModelSpec, d: Design) -> np.ndarray:
    """Parameters of ``fit`` mapped onto the layout of ``spec`` (new terms start at 0; a
    finer spline starts from the old one's least-squares projection)."""
    new = d.layout(spec)
    th = np.zeros(new["p"])
    old = fit.lay
    for key, sl in old["blocks"].items():
        if key == "spline":
            continue
        if key in new["blocks"]:
            ns = new["blocks"][key]
            k = min(sl.stop - sl.start, ns.stop - ns.start)
            if key.startswith("rip:") or key.startswith("mod:"):
                # harmonic pairs keep their place
                th[ns.start:ns.start + k] = fit.theta[sl.start:sl.start + k]
            elif key == "sig":
                # per (train, planet) groups of 2 * sig columns
                w_old = 2 * fit.spec.sig
                w_new = 2 * spec.sig
                if w_old and w_new:
                    g = (sl.stop - sl.start) // w_old
                    w = min(w_old, w_new)            # fewer harmonics: the lower ones kept
                    for i in range(g):
                        th[ns.start + i * w_new: ns.start + i * w_new + w] = \
                            fit.theta[sl.start + i * w_old: sl.start + i * w_old + w]
            else:
                th[ns.start:ns.start + k] = fit.theta[sl.start:sl.start + k]
    sb = new["blocks"]["spline"]
    if spec.knots == fit.spec.knots:
        th[sb] = fit.theta[old["blocks"]["spline"]]
    else:
        xs = np.linspace(-1.0, 1.0, 8 * (spec.knots + 3))
        s_old = spline_basis(xs, fit.spec.knots) @ fit.theta[old["blocks"]["spline"]]
        th[sb] = linalg.lstsq(spline_basis(xs, spec.knots), s_old, check_finite=False)[0]
    return th
