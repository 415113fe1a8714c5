"""Error against run time of the tolerance Monte Carlo (``meshphase bench models``).

Seed 000 case 3 (Table 1 gearset, Table 2 case 3 bands, angles as given) is run with
increasing sample counts, with plain pseudo-random and with scrambled Sobol sampling. Each
run's statistics (mean, mean + 3 std and the 99.865 % quantile, i.e. the upper 3-sigma
bounds, of Dev_sn, Dev_rn, Ave_sn, Ave_rn) are held
against a converged reference (a large Sobol run) and the wall time is measured. Errors are
RMS over ``n_repeats`` independent runs, in units of the reference standard deviation of the
statistic, worst planet.

Second table (``estimators``): every estimator of :func:`monte_carlo` (plain random, plain
Sobol, the control variate ``method="cv"``) against a reference of ``estimator_reference``
full-model evaluations (1e7 by default; :mod:`.models_reference`, cached in the output folder
so reruns are quick): by default the directional control-variate reference
(:func:`.models_reference.directional_reference`, relative standard errors of the 3-sigma
bounds ~1e-4 and below), with the plain pseudo-random reference as the fallback when the
case does not allow it (the table says which was used). On one numba thread: wall time, the
largest relative error of the means and standard deviations and of the 3-sigma bounds
(quantiles at Phi(-+3)) over every statistic and planet with a spread, beside each the
reference's own relative standard error at that entry (``ref_se_*``: the error is resolved
when it is well above it), the estimator's own largest relative standard error, and the
largest |error| / sqrt(SE_est^2 + SE_ref^2). Relative means
|estimate - reference| / max(|reference|, reference std of that statistic), so that values
near zero (Ave means, the lower bound of Dev) are judged against the spread. The kernel
throughput (G realisation x time x planet evaluations per second, one thread and all
threads) is measured too. Results: ``models_bench.json``, ``models_bench.md`` and a log-log
figure ``models_bench.png``. Measured, never asserted.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from ..runtime.log import logger
from ..models import _kernels
from ..models.tolerance import (ALL_STATISTICS, STATISTICS, monte_carlo, observation_window,
                                table2_case, WINDOW_KINDS)
from .models_reference import CASE3_NAME, directional_reference, plain_reference
from .phasing_stage import PHASING_MINUTES, phasing_markdown, phasing_stage_rows
from ..validate import as_choice, as_positive_int

__all__ = ["run_models_bench", "METRICS", "TABLE_COLUMNS", "ESTIMATOR_COLUMNS"]

#: Summaries whose error is measured: "mean"; "m3s" the moment 3-sigma bound mean + 3 std;
#: "q3s" the quantile 3-sigma bound (upper bound3, the 99.865 % quantile).
KINDS = ("mean", "m3s", "q3s")
#: (statistic, summary) pairs whose error is measured.
METRICS = tuple((s, k) for s in ("dev_s", "dev_r", "ave_s", "ave_r") for k in KINDS)
TABLE_COLUMNS = (("sampler", "n_samples", "repeats", "wall_time_s")
                 + tuple(f"err_{k}_{s}" for s, k in METRICS)
                 + ("err_moments", "err_quantile", "err_max"))
#: Columns of the estimator table (errors relative, see the module docstring).
ESTIMATOR_COLUMNS = ("method", "samples", "tail_directions", "evaluations", "repeats",
                     "wall_s", "err_mean_std", "ref_se_mean_std", "err_bound3",
                     "err_bound3_worst", "ref_se_bound3", "se_mean_std", "se_bound3", "max_z")
#: Kinds of the estimator table's reference (:func:`run_models_bench`).
REFERENCE_METHODS = ("directional", "plain")
#: (method, sampler, n_samples, tail_directions) of the estimator table; quick: the first
#: two rows shrunk.
ESTIMATORS = (("plain", "random", 10000, None), ("plain", "random", 100000, None),
              ("plain", "sobol", 32768, None), ("cv", "sobol", 256, 8), ("cv", "sobol", 512, 8),
              ("cv", "sobol", 2048, 16), ("cv", "sobol", 2048, 32), ("cv", "sobol", 2048, 64),
              ("cv", "sobol", 4096, 32), ("cv", "sobol", 8192, 32))
#: Rows of the estimator table in a quick run.
QUICK_ESTIMATORS = (("plain", "random", 4096, None), ("cv", "sobol", 256, 8))


def _metric_values(res, stat, kind):
    st = res.stat(stat)
    if kind == "mean":
        return st.mean
    if kind == "m3s":
        return st.mean_pm_3std[1]
    return st.bound3[1]


def _metric_se(res, stat, kind):
    st = res.stat(stat)
    if kind == "mean":
        return st.se_mean
    if kind == "m3s":
        return np.sqrt(st.se_mean ** 2 + 9.0 * st.se_std ** 2)   # (ignores their correlation)
    return st.se_bound3[1]


def _sobol_count(n, replicates):
    """Smallest replicates * 2**m >= n (Sobol balance)."""
    per = max(1, math.ceil(n / replicates))
    return replicates * (1 << (per - 1).bit_length())


def _interp_crossover(ns, errs, target):
    """Smallest n (log-log interpolation) where the error curve first drops to ``target``."""
    ns = np.asarray(ns, float)
    errs = np.asarray(errs, float)
    order = np.argsort(ns)
    ns, errs = ns[order], errs[order]
    for i in range(ns.size):
        if errs[i] <= target:
            if i == 0:
                return float(ns[0])
            x0, x1 = math.log(ns[i - 1]), math.log(ns[i])
            y0, y1 = math.log(errs[i - 1]), math.log(errs[i])
            if y1 == y0:
                return float(ns[i])
            x = x0 + (math.log(target) - y0) * (x1 - x0) / (y1 - y0)
            return float(math.exp(min(max(x, x0), x1)))
    return float("nan")


def run_models_bench(out_dir, *, sample_counts=(256, 1000, 3000, 10000, 30000, 100000),
                     samplers=("random", "sobol"), reference_samples: int = 2 ** 21,
                     rng=0, quick: bool = False, n_repeats: int = 5, replicates: int = 8,
                     window: str = "slowest-offset", case3_samples: int = 100000,
                     figure: bool = True, estimator_reference: int = 10 ** 7,
                     reference_method: str = "directional",
                     reference_progress: bool | None = None,
                     estimator_repeats: int = 5, phasing_minutes=None) -> dict:
    """Monte Carlo error against wall time for both samplers; writes table, JSON and figure.

    Parameters
    ----------
    out_dir : path-like
        Output folder (created if missing).
    sample_counts : sequence of int
        Sample counts [-]. Sobol counts are rounded up to ``replicates * 2**m`` (balance);
        the table shows the count actually run.
    samplers : sequence of {"random", "sobol"}
        Samplers to compare.
    reference_samples : int
        Samples of the converged Sobol reference [-] (rounded like the Sobol counts).
    rng : int
        Base seed; run ``j`` of a configuration uses an independent child stream.
    quick : bool
        Tiny sizes for a smoke run (counts 64 and 256, reference 4096, 2 repeats, no
        separate case-3 timing).
    n_repeats : int
        Independent runs per configuration (errors are RMS over them) [-].
    replicates : int
        Replicates per Monte Carlo run (standard errors; Sobol randomisation) [-].
    window : str
        Observation window kind (:func:`meshphase.models.tolerance.observation_window`).
    case3_samples : int
        Sample count of the separately timed seed case 3 run (plain random) [-].
    figure : bool
        Write the log-log figure (needs matplotlib).
    estimator_reference : int
        Full-model evaluations of the estimator table's reference [-] (quick: 20000); cached
        in ``out_dir`` as ``models_reference_directional_<n>_<seed>.json`` (directional) or
        ``models_reference_<n>_<seed>.json`` (plain). Building the 1e7 directional reference
        takes minutes (its wall time is in the table's header and the cache file).
    reference_method : {"directional", "plain"}
        Reference of the estimator table: the directional control-variate one (falls back to
        plain, with the reason recorded, when the case does not allow it) or plain.
    estimator_repeats : int
        Independent runs per row of the estimator table [-] (quick: 1): errors RMS over
        them, the worst bound error beside.
    reference_progress : bool, optional
        Show a progress bar (stderr) while the reference is computed (not when read from the
        cache); default: when stderr is a terminal. ``meshphase bench reference --out
        OUT_DIR`` builds it as a separate step.
    phasing_minutes : sequence of float, optional
        Lengths [min] of the 8-channel recordings on which ``meshphase process``'s wall time,
        its phasing stage's time and share, and the fixed cost per run are measured
        (:mod:`.phasing_stage`, ``models_phasing_stage.md``); default
        :data:`.phasing_stage.PHASING_MINUTES`, none when ``quick``.

    Returns
    -------
    dict
        ``{"rows": [...], "reference": {...}, "crossover": {...}, "case3": {...},
        "estimators": {...}, "meta": {...}, "files": {...}}``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    samplers = tuple(as_choice(s, "samplers", ("random", "sobol")) for s in samplers)
    window = as_choice(window, "window", WINDOW_KINDS)
    if quick:
        sample_counts, reference_samples, n_repeats = (64, 256), 4096, 2
    counts = sorted({as_positive_int(n, "sample_counts") for n in sample_counts})
    n_repeats = as_positive_int(n_repeats, "n_repeats")
    replicates = as_positive_int(replicates, "replicates")
    ref_n = _sobol_count(as_positive_int(reference_samples, "reference_samples"), replicates)
    seeds = np.random.SeedSequence(rng)

    g, sp, tol = table2_case(3)
    win = observation_window(sp, window)
    engine = _kernels.resolve_engine("auto")
    case = (g, sp, tol, win)

    t = time.perf_counter()
    monte_carlo(g, sp, tol, win, 16, rng=0, replicates=2)       # JIT compile / cache load
    warmup = time.perf_counter() - t

    ref_seed, run_seeds, case_seed = seeds.spawn(3)
    ref, reference, scale, active = _reference(case, ref_n, ref_seed, replicates)
    rows = []
    config_seeds = iter(run_seeds.spawn(len(samplers) * len(counts)))
    for sampler in samplers:
        for n0 in counts:
            n = _sobol_count(n0, replicates) if sampler == "sobol" else n0
            rows.append(_error_row(case, sampler, n, next(config_seeds), n_repeats, replicates,
                                   ref, scale, active))
    crossover = _crossover(rows, samplers, active)
    case3 = {} if quick else _case3(case, case3_samples, case_seed, replicates)
    reference_method = as_choice(reference_method, "reference_method", REFERENCE_METHODS)
    if reference_progress is None:
        reference_progress = sys.stderr.isatty()
    est_ref = 20000 if quick else as_positive_int(estimator_reference, "estimator_reference")
    estimators = _estimator_table(case, out, est_ref, quick, reference_method,
                                  reference_progress, 1 if quick else
                                  as_positive_int(estimator_repeats, "estimator_repeats"))
    throughput = _throughput(case, 2048 if quick else 32768)
    meta = {"case": "seed000 Table 2 case 3 (angles given)", "window": win.to_dict(),
            "n_times": ref.n_times, "engine": engine, "replicates": replicates,
            "jit_warmup_s": warmup, "cpu_count": os.cpu_count(),
            "python": platform.python_version(),
            "numpy": np.__version__, "quick": quick,
            "error_unit": "RMS over repeats of |estimate - reference| / reference std, "
                          "worst planet (2..N)"}
    meta["kernel_throughput"] = throughput
    result = {"rows": rows, "reference": reference, "crossover": crossover, "case3": case3,
              "estimators": estimators, "meta": meta, "files": {}}
    _write(result, out, figure)
    # the models' consumer in a run: the phasing stage's time and share, the fixed cost
    ph_min = (() if quick else PHASING_MINUTES) if phasing_minutes is None else tuple(phasing_minutes)
    if ph_min:
        result["phasing_stage"] = phasing_stage_rows(out / "phasing-work", ph_min)
        shutil.rmtree(out / "phasing-work", ignore_errors=True)
        md = out / "models_phasing_stage.md"
        md.write_text(phasing_markdown(result["phasing_stage"]), encoding="utf-8")
        result["files"]["phasing_stage"] = str(md)
    return result


def _reference(case, ref_n: int, ref_seed, replicates: int):
    """(reference result, its table entry, std per statistic, metrics with a spread) of the
    converged Sobol run."""
    g, sp, tol, win = case
    t = time.perf_counter()
    ref = monte_carlo(g, sp, tol, win, ref_n, sampler="sobol", rng=np.random.default_rng(ref_seed),
                      replicates=replicates)
    ref_time = time.perf_counter() - t
    scale = {s: ref.stat(s).std for s in STATISTICS}
    active = [(s, k) for s, k in METRICS if np.max(scale[s][1:]) > 1e-12]
    reference = {"n_samples": ref_n, "sampler": "sobol", "wall_time_s": ref_time,
                 "values": {f"{k}_{s}": _metric_values(ref, s, k).tolist() for s, k in METRICS},
                 "std": {s: scale[s].tolist() for s in STATISTICS},
                 "stderr": {f"{k}_{s}": (_metric_se(ref, s, k) / np.where(
                     scale[s] > 0, scale[s], np.inf)).tolist() for s, k in METRICS},
                 "skipped_metrics": [f"{k}_{s}" for s, k in METRICS if (s, k) not in active]}
    return ref, reference, scale, active


def _error_row(case, sampler: str, n: int, sq, n_repeats: int, replicates: int, ref, scale,
               active) -> dict:
    """Errors against the reference and median wall time of ``n_repeats`` runs of one
    (sampler, sample count) configuration."""
    g, sp, tol, win = case
    errs = {m: [] for m in METRICS}
    times = []
    for child in sq.spawn(n_repeats):
        res = monte_carlo(g, sp, tol, win, n, sampler=sampler,
                          rng=np.random.default_rng(child), replicates=replicates)
        times.append(res.wall_time)
        for s, k in METRICS:
            if (s, k) not in active:
                continue
            d = (_metric_values(res, s, k) - _metric_values(ref, s, k))[1:]
            errs[(s, k)].append(float(np.max(np.abs(d) / scale[s][1:])))
    row = {"sampler": sampler, "n_samples": n, "repeats": n_repeats,
           "wall_time_s": float(np.median(times))}
    for s, k in METRICS:
        e = errs[(s, k)]
        row[f"err_{k}_{s}"] = float(np.sqrt(np.mean(np.square(e)))) if e else float("nan")
    for col, kinds in (("err_moments", ("mean", "m3s")), ("err_quantile", ("q3s",)),
                       ("err_max", KINDS)):
        vals = [row[f"err_{k}_{s}"] for s, k in active if k in kinds]
        row[col] = float(np.max(vals)) if vals else float("nan")
    logger.info("bench models: %s n=%d  %.3f s  err_max=%.3g", sampler, n,
                row["wall_time_s"], row["err_max"])
    return row


def _case3(case, case3_samples: int, case_seed, replicates: int) -> dict:
    """The separately timed seed case 3 run (plain random)."""
    g, sp, tol, win = case
    t = time.perf_counter()
    res = monte_carlo(g, sp, tol, win, case3_samples, sampler="random",
                      rng=np.random.default_rng(case_seed), replicates=replicates)
    return {"n_samples": case3_samples, "sampler": "random", "wall_time_s":
            time.perf_counter() - t, "window": win.to_dict(), "n_times": res.n_times,
            "dev_s_bound3_hi": res.dev_s.bound3[1].tolist(),
            "dev_r_bound3_hi": res.dev_r.bound3[1].tolist(),
            "ave_r_bound3": res.ave_r.bound3.tolist()}


class _Threads:
    """Run with ``n`` numba threads (restored after); no-op without numba."""

    def __init__(self, n):
        self.n = n
        self.old = None

    def __enter__(self):
        if _kernels.HAVE_NUMBA:
            import numba
            self.old = numba.get_num_threads()
            numba.set_num_threads(min(self.n, numba.config.NUMBA_NUM_THREADS))
        return self

    def __exit__(self, *exc):
        if self.old is not None:
            import numba
            numba.set_num_threads(self.old)


def _throughput(case, n: int) -> dict:
    """Kernel throughput [G evaluations/s] of a plain Monte Carlo of n samples: the default
    engine on one thread and on all, and the numpy path (``numpy``: what a Monte Carlo runs
    on where numba is not installed) on n / 4 samples."""
    g, sp, tol, win = case
    out = {"n_samples": n}
    for label, threads in (("one_thread", 1), ("all_threads", os.cpu_count() or 1)):
        with _Threads(threads):
            res = monte_carlo(g, sp, tol, win, n, sampler="random", rng=0, replicates=2)
        out[label] = n * res.n_times * g.n_planets / res.wall_time / 1e9
    n_np = max(2, n // 4)
    res = monte_carlo(g, sp, tol, win, n_np, sampler="random", rng=0, replicates=2, engine="numpy")
    out["numpy"] = n_np * res.n_times * g.n_planets / res.wall_time / 1e9
    out["numpy_n_samples"] = n_np
    out["unit"] = "G (realisation x time x planet) evaluations/s, both meshes, all statistics"
    return out


def _rel_errors(res, ref, stats):
    """Largest relative errors, the reference's relative standard error at the entry of each
    largest error, the estimator's largest relative standard errors and the largest z."""
    vals, se = ref["values"], ref["stderr"]
    err = {"mean_std": (-1.0, float("nan")), "bound3": (-1.0, float("nan"))}
    own = {"mean_std": [], "bound3": []}
    zs = []
    for s in stats:
        st = res.stat(s)
        scale = np.asarray(vals["std"][s])
        for key, est, e_se, group in (
                ("mean", st.mean, st.se_mean, "mean_std"),
                ("std", st.std, st.se_std, "mean_std"),
                ("bound3_lo", st.bound3[0], st.se_bound3[0], "bound3"),
                ("bound3_hi", st.bound3[1], st.se_bound3[1], "bound3")):
            r = np.asarray(vals[key][s])
            den = np.maximum(np.abs(r), scale)
            ok = scale > 1e-12
            if not np.any(ok):
                continue
            d = np.abs(np.asarray(est) - r)[ok]
            rel = d / den[ok]
            i = int(np.argmax(rel))
            if rel[i] > err[group][0]:
                err[group] = (float(rel[i]), float(np.asarray(se[key][s])[ok][i] / den[ok][i]))
            own[group].append(float(np.nanmax(np.asarray(e_se)[ok] / den[ok])))
            tot = np.sqrt(np.asarray(e_se)[ok] ** 2 + np.asarray(se[key][s])[ok] ** 2)
            zs.append(float(np.max(d / np.where(tot > 0, tot, np.inf))))
    return ({k: (v[0] if v[0] >= 0 else float("nan")) for k, v in err.items()},
            {k: v[1] for k, v in err.items()},
            {k: max(v) if v else float("nan") for k, v in own.items()},
            max(zs) if zs else float("nan"))


def _bench_reference(case, out: Path, ref_n: int, quick: bool, method: str, progress: bool):
    """The estimator table's reference: directional, or plain (asked for, or the fallback
    when the case does not allow the directional one; the reason is recorded)."""
    if method == "directional":
        try:
            return directional_reference(case, out, n_evaluations=ref_n, case_name=CASE3_NAME,
                                         check_directions=32 if quick else 256,
                                         progress=progress)
        except ValueError as exc:
            reason = str(exc)
            logger.warning("bench models: directional reference not possible (%s); using the "
                           "plain reference", reason)
    else:
        reason = "asked for"
    ref = plain_reference(case, out, n_samples=ref_n, case_name=CASE3_NAME)
    ref["fallback_reason"] = reason
    return ref


def _estimator_row(case, spec, seeds, ref, stats) -> dict:
    """One row of the estimator table: ``len(seeds)`` runs of one (method, sampler, samples,
    tail directions); wall time the median, errors RMS over the runs (``err_bound3_worst``
    the largest), the reference's SE at the largest error of the worst run, the estimator's
    SEs the median, max_z the largest."""
    g, sp, tol, win = case
    mth, sampler, n, n_dir = spec
    if not seeds:
        raise ValueError("_estimator_row needs at least one seed")
    runs = []
    for seed in seeds:
        kw = {"method": mth, "sampler": sampler, "rng": seed}
        if n_dir is not None:
            kw["tail_directions"] = n_dir
        t = time.perf_counter()
        res = monte_carlo(g, sp, tol, win, n, **kw)
        runs.append((time.perf_counter() - t, res, *_rel_errors(res, ref, stats)))
    label = mth if mth == "cv" else f"plain-{sampler}"
    res = runs[0][1]

    def rms(group):
        return float(np.sqrt(np.mean([r[2][group] ** 2 for r in runs])))

    def worst(group):
        return max(runs, key=lambda r: r[2][group])

    row = {"method": label, "samples": res.n_samples, "tail_directions": n_dir,
           "evaluations": res.n_evaluations or res.n_samples, "repeats": len(runs),
           "wall_s": float(np.median([r[0] for r in runs])),
           "err_mean_std": rms("mean_std"), "ref_se_mean_std": worst("mean_std")[3]["mean_std"],
           "err_bound3": rms("bound3"), "err_bound3_worst": worst("bound3")[2]["bound3"],
           "ref_se_bound3": worst("bound3")[3]["bound3"],
           "se_mean_std": float(np.median([r[4]["mean_std"] for r in runs])),
           "se_bound3": float(np.median([r[4]["bound3"] for r in runs])),
           "max_z": max(r[5] for r in runs)}
    logger.info("bench models: %s n=%d %.3f s err %.3g / %.3g", label, n, row["wall_s"],
                row["err_mean_std"], row["err_bound3"])
    return row


def _estimator_table(case, out: Path, ref_n: int, quick: bool, method: str = "directional",
                     progress: bool = False, repeats: int = 5) -> dict:
    """Error of each estimator against the cached reference, on one thread, ``repeats``
    independent runs per row."""
    g, sp, tol, win = case
    ref = _bench_reference(case, out, ref_n, quick, method, progress)
    stats = [s for s in ALL_STATISTICS
             if np.max(np.asarray(ref["values"]["std"][s]), initial=0.0) > 1e-12]
    specs = QUICK_ESTIMATORS if quick else ESTIMATORS
    load = [_load_average()]
    with _Threads(1):
        monte_carlo(g, sp, tol, win, 64, method="cv", rng=0)       # warm-up (JIT, imports)
        rows = [_estimator_row(case, spec, [1000 + 100 * j + i for j in range(repeats)], ref,
                               stats) for i, spec in enumerate(specs)]
    ref_se = _rel_errors_ref(ref, stats)
    info = {"method": ref.get("method", "plain"), "n_samples": ref["n_samples"],
            "seed": ref["seed"], "wall_time_s": ref["wall_time_s"], "cached": ref["cached"],
            "file": ref.get("file"), "se_mean_std": ref_se[0], "se_bound3": ref_se[1],
            "fallback_reason": ref.get("fallback_reason")}
    if info["method"] == "directional-cv":
        info["se_batch_mean_std"], info["se_batch_bound3"] = _rel_errors_ref(
            {"values": ref["values"], "stderr": ref["stderr_batch"]}, stats)
        info.update({"n_directions": ref["n_directions"], "nodes": ref["nodes"],
                     "interpolation": ref["interpolation"], "unconverged": ref["unconverged"]})
    load.append(_load_average())
    return {"rows": rows, "reference": info, "statistics": stats, "threads": 1,
            "load_average": load}


def _load_average():
    """(1, 5, 15 min) load average of the machine, or None where the OS has none."""
    try:
        return list(os.getloadavg())
    except (AttributeError, OSError):
        return None


def _rel_errors_ref(ref, stats):
    """The reference's own largest relative standard errors (means/stds, bounds); an SE
    that could not be formed (null in the cache) makes the result NaN."""
    vals, se = ref["values"], ref["stderr"]
    out = []
    for keys in (("mean", "std"), ("bound3_lo", "bound3_hi")):
        m = 0.0
        for s in stats:
            scale = np.asarray(vals["std"][s], dtype=float)
            ok = scale > 1e-12
            for k in keys:
                den = np.maximum(np.abs(np.asarray(vals[k][s], dtype=float)), scale)[ok]
                if den.size:
                    m = max(m, float(np.max(np.asarray(se[k][s], dtype=float)[ok] / den)))
        out.append(m)
    return out


def _write(result: dict, out: Path, figure: bool) -> None:
    """models_bench.json, .md (and .png when ``figure``) into ``out``; sets ``result["files"]``."""
    jpath = out / "models_bench.json"
    mpath = out / "models_bench.md"
    jpath.write_text(json.dumps(result, indent=2, default=float))
    mpath.write_text(_markdown(result))
    result["files"] = {"json": str(jpath), "markdown": str(mpath)}
    if figure:
        from ..report.bench_figures_models import save_models_bench_figure
        fpath = out / "models_bench.png"
        save_models_bench_figure(result, fpath)
        result["files"]["figure"] = str(fpath)
    jpath.write_text(json.dumps(result, indent=2, default=float))


def _crossover(rows, samplers, active):
    """Sobol sample count that matches plain random's error at its largest count."""
    if not ("random" in samplers and "sobol" in samplers):
        return {}
    rnd = [r for r in rows if r["sampler"] == "random"]
    sob = [r for r in rows if r["sampler"] == "sobol"]
    top = max(rnd, key=lambda r: r["n_samples"])
    out = {"random_n": top["n_samples"], "metrics": {}}
    for key in ["err_max", "err_moments", "err_quantile"] + [f"err_{k}_{s}" for s, k in active]:
        target = top[key]
        n_match = _interp_crossover([r["n_samples"] for r in sob], [r[key] for r in sob], target)
        out["metrics"][key] = {"random_error": target, "sobol_n_match": n_match,
                               "ratio": (top["n_samples"] / n_match if n_match == n_match
                                         else float("nan"))}
    return out


def _fmt(v):
    if v is None:
        return "-"
    if isinstance(v, float):
        if v != v:
            return "-"
        return f"{v:.3g}"
    return str(v)


def _reference_lines(er):
    """Markdown lines describing the estimator table's reference."""
    cached = ", read from the cache" if er["cached"] else ""
    where = f" File: `{er['file']}`." if er.get("file") else ""
    own = (f"its own largest relative standard error: means/stds {_fmt(er['se_mean_std'])}, "
           f"3-sigma bounds {_fmt(er['se_bound3'])}")
    if er.get("method") == "directional-cv":
        it = er["interpolation"]
        return ["Reference: directional control variate "
                f"(`meshphase.bench.models_reference_tail`), "
                f"{er['n_samples']} full-model evaluations ({er['n_directions']} rays x "
                f"{er['nodes']} radii, seed {er['seed']}, built in {er['wall_time_s']:.0f} s"
                f"{cached}); {own} (delta method; batch means over 10 groups: "
                f"{_fmt(er['se_batch_mean_std'])}, {_fmt(er['se_batch_bound3'])}). "
                f"Interpolation check on {it['n_directions']} rays: largest tail-probability "
                f"bias {_fmt(it['max_rel_tail_bias'])} of the tail mass; unconverged crossings "
                f"{er['unconverged']}.{where}", ""]
    why = f" (fallback: {er['fallback_reason']})" if er.get("fallback_reason") else ""
    return [f"Reference: plain pseudo-random{why}, {er['n_samples']} samples (seed "
            f"{er['seed']}, {er['wall_time_s']:.0f} s{cached}); {own}.{where}", ""]


def _markdown(result):
    lines = ["# Monte Carlo error against run time (seed 000 case 3)", ""]
    m = result["meta"]
    w = m["window"]
    lines.append(f"Window: {w['name']} [{w['t0']:g}, {w['t0'] + w['duration']:g}] s, "
                 f"{m['n_times']} time samples; engine {m['engine']}; {m['replicates']} "
                 f"replicates per run; {m['cpu_count']} cores. Error unit: {m['error_unit']}.")
    ref = result["reference"]
    lines.append(f"Reference: Sobol, {ref['n_samples']} samples, {ref['wall_time_s']:.2f} s. "
                 f"Skipped (zero spread): {', '.join(ref['skipped_metrics']) or 'none'}.")
    lines.append("")
    lines.append("| " + " | ".join(TABLE_COLUMNS) + " |")
    lines.append("|" + "|".join("---" for _ in TABLE_COLUMNS) + "|")
    for r in result["rows"]:
        lines.append("| " + " | ".join(_fmt(r[c]) for c in TABLE_COLUMNS) + " |")
    cx = result.get("crossover") or {}
    if cx:
        lines += ["", f"Sobol samples matching plain random's error at n = {cx['random_n']}:", ""]
        lines.append("| metric | random error | sobol n | ratio |")
        lines.append("|---|---|---|---|")
        for k, v in cx["metrics"].items():
            lines.append(f"| {k} | {_fmt(v['random_error'])} | {_fmt(v['sobol_n_match'])} | "
                         f"{_fmt(v['ratio'])} |")
    est = result.get("estimators") or {}
    if est:
        lines += ["", "## Estimators against a Monte Carlo reference", ""]
        lines += _reference_lines(est["reference"])
        lines += ["One numba thread; each row RMS over `repeats` independent runs (wall time: "
                  "median; err_bound3_worst: the worst run). Errors: largest over the "
                  "statistics with a spread and their planets of |estimate - reference| / "
                  "max(|reference|, reference std); "
                  "ref_se_*: the reference's own standard error at that largest error, on the "
                  "same scale (an error is resolved when well above it); se_*: the estimator's "
                  "own largest standard errors; max_z: largest |error| / sqrt(SE_est^2 + "
                  "SE_ref^2). Load average (1, 5, 15 min) before and after the rows: "
                  + " / ".join(", ".join(f"{x:.2f}" for x in la) if la else "-"
                               for la in est.get("load_average") or [None]) + ".", ""]
        lines.append("| " + " | ".join(ESTIMATOR_COLUMNS) + " |")
        lines.append("|" + "|".join("---" for _ in ESTIMATOR_COLUMNS) + "|")
        for r in est["rows"]:
            lines.append("| " + " | ".join(_fmt(r[c]) for c in ESTIMATOR_COLUMNS) + " |")
    tp = m.get("kernel_throughput") or {}
    if tp:
        lines += ["", f"Kernel throughput ({tp['n_samples']} plain samples): "
                      f"{tp['one_thread']:.3f} G evaluations/s on one thread, "
                      f"{tp['all_threads']:.3f} on all {m['cpu_count']} ({tp['unit']})"
                      + (f"; the numpy path (no numba; {tp['numpy_n_samples']} samples) "
                         f"{tp['numpy']:.4f}" if "numpy" in tp else "") + "."]
    c3 = result.get("case3") or {}
    if c3:
        lines += ["", f"Case 3, {c3['n_samples']} plain random samples: "
                      f"{c3['wall_time_s']:.2f} s wall (JIT warm-up {m['jit_warmup_s']:.2f} s "
                      "measured separately)."]
    return "\n".join(lines) + "\n"
