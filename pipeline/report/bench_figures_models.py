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

    Parameters
    ----------
    result : dict
        The dict returned by :func:`meshphase.bench.models.run_models_bench`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    rows = result["rows"]
    fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.8))
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
            for ax in axes:
                ax.axhline(lvl, color="0.5", ls=ls, lw=0.7)
    axes[0].set_xlabel("wall time [s]")
    axes[1].set_xlabel("samples [-]")
    for ax in axes:
        ax.set_ylabel("error [reference std]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    w = result.get("meta", {}).get("window", {})
    fig.suptitle(f"Monte Carlo error vs cost, seed 000 case 3 ({w.get('name', '')} window)",
                 fontsize=10)
    fig.tight_layout()
    return fig


def save_models_bench_figure(result: dict, path) -> None:
    """Draw :func:`models_bench_figure` into ``path`` (PNG) and close it."""
    fig = models_bench_figure(result)
    fig.savefig(path, dpi=120)
    plt.close(fig)
