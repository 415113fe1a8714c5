"""Figure of the Monte Carlo error-vs-runtime benchmark (:mod:`meshphase.bench.models`)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["models_bench_figure", "save_models_bench_figure"]


def models_bench_figure(result: dict):
    """Log-log error against wall time [s] and against sample count, per sampler.

    Solid: worst error of the moment statistics (mean, mean + 3 std); dashed: worst error of
    the 99.865 % quantile bounds; grey lines: plain random's error at its largest count.
    With an estimator table (``result["estimators"]``) a third panel shows each estimator's
    largest relative error against its one-thread wall time, with the 1e-3 goal dotted and
    the reference's own largest relative standard errors (thin grey, solid: means/stds,
    dashed: bounds), below which an error is not resolved.

    Parameters
    ----------
    result : dict
        The dict returned by :func:`meshphase.bench.models.run_models_bench`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    rows = result["rows"]
    est = (result.get("estimators") or {}).get("rows") or []
    fig, axes = plt.subplots(1, 3 if est else 2, figsize=(14.0 if est else 9.5, 3.8))
    samplers = sorted({r["sampler"] for r in rows})
    curves = (("err_moments", "-", "moments"), ("err_quantile", "--", "99.865 % quantile"))
    for i, s in enumerate(samplers):
        rr = sorted((r for r in rows if r["sampler"] == s), key=lambda r: r["n_samples"])
        n = np.array([r["n_samples"] for r in rr], float)
        tm = np.array([r["wall_time_s"] for r in rr], float)
        for key, ls, label in curves:
            err = np.array([r.get(key, np.nan) for r in rr], float)
            ok = (tm > 0) & (err > 0) & np.isfinite(err)
            axes[0].loglog(tm[ok], err[ok], "o" + ls, color=f"C{i}", label=f"{s}, {label}", ms=4)
            axes[1].loglog(n[ok], err[ok], "o" + ls, color=f"C{i}", label=f"{s}, {label}", ms=4)
    cx = result.get("crossover") or {}
    for key, ls, label in curves:
        lvl = cx.get("metrics", {}).get(key, {}).get("random_error")
        if lvl is not None and np.isfinite(lvl) and lvl > 0:
            for ax in axes[:2]:
                ax.axhline(lvl, color="0.5", ls=ls, lw=0.7)
    axes[0].set_xlabel("wall time [s]")
    axes[1].set_xlabel("samples [-]")
    if est:
        _estimator_panel(axes[2], est, result["estimators"].get("reference") or {})
    for ax in axes[:2]:
        ax.set_ylabel("error [reference std]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    w = result.get("meta", {}).get("window", {})
    fig.suptitle(f"Monte Carlo error vs cost, seed 000 case 3 ({w.get('name', '')} window)",
                 fontsize=10)
    fig.tight_layout()
    return fig


def _estimator_panel(ax, rows, ref):
    """Largest relative error against wall time per estimator (solid: means and stds,
    dashed: 3-sigma bounds) with the 1e-3 goal and the reference's own standard errors."""
    methods = sorted({r["method"] for r in rows})
    for i, mth in enumerate(methods):
        rr = sorted((r for r in rows if r["method"] == mth), key=lambda r: r["wall_s"])
        tm = np.array([r["wall_s"] for r in rr], float)
        for key, ls, label in (("err_mean_std", "-", "mean/std"), ("err_bound3", "--",
                                                                    "3-sigma bounds")):
            err = np.array([r[key] for r in rr], float)
            ok = (tm > 0) & (err > 0) & np.isfinite(err)
            ax.loglog(tm[ok], err[ok], "o" + ls, color=f"C{i + 2}", ms=4,
                      label=f"{mth}, {label}")
    ax.axhline(1e-3, color="0.3", lw=0.8, ls=":")
    for key, ls, label in (("se_mean_std", "-", "reference SE, mean/std"),
                           ("se_bound3", "--", "reference SE, bounds")):
        v = ref.get(key)
        if v is not None and np.isfinite(v) and v > 0:
            ax.axhline(v, color="0.6", lw=0.7, ls=ls, label=label)
    ax.set_xlabel("wall time, one thread [s]")
    kind = "directional" if ref.get("method") == "directional-cv" else "plain"
    ax.set_ylabel(f"largest relative error vs {kind} reference [-]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def save_models_bench_figure(result: dict, path) -> None:
    """Draw :func:`models_bench_figure` into ``path`` (PNG) and close it."""
    fig = models_bench_figure(result)
    fig.savefig(path, dpi=120)
    plt.close(fig)
