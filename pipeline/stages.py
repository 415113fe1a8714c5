"""The stages a scene runs, and the run itself: scene -> results -> files.

Each stage is a function ``stage(ctx)`` that reads what earlier stages left in
``ctx.results`` and adds its own; :func:`run_scene` runs exactly the stages that
:func:`pipeline.scene.plan` asks for, times each one and records an error estimate where one
exists ("error against run time"). Files are written by :func:`write_outputs`; the HTML
report by :mod:`pipeline.report.validation` (the only place that plots).
"""

from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import MeshphaseWarning, ProcessingWarning
from .jsonable import to_jsonable
from .log import logger
from .recording import ChannelSpec, Recording
from .scene import Scene, plan

__all__ = ["RunContext", "run_scene", "STAGE_FUNCTIONS", "write_outputs", "process_recording",
           "new_output_dir"]


@dataclass
class RunContext:
    """Everything a run produces.

    Attributes
    ----------
    scene : Scene
    results : dict
        Stage outputs by stage name.
    ran : list of str
        Stages that ran, in order.
    timings : dict
        Wall time per stage [s].
    error_estimates : dict
        Per stage, a short text with its error estimate (what "error against run time" lists).
    messages : list of str
        Warnings raised during the run (category: message).
    failed : dict
        Stage -> error message for stages that raised (the run goes on with what it has).
    channels_unused : list of str
        Channels of the recording that no planned stage reads (set by the load stage).
    """

    scene: Scene
    results: dict = field(default_factory=dict)
    ran: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    error_estimates: dict = field(default_factory=dict)
    messages: list = field(default_factory=list)
    failed: dict = field(default_factory=dict)
    progress: Callable | None = None
    channels_unused: list = field(default_factory=list)


# ----------------------------------------------------------------------------- helpers
def _gearset(ctx: RunContext):
    g = ctx.scene.gearset
    if g is None and "load" in ctx.results:
        from .models.gearset import Gearset

        meta = ctx.results["load"]["recording"].meta.get("gearset")
        if meta:
            g = Gearset.from_dict(meta)
    return g


def _channels_present(rec: Recording) -> str:
    """``name (kind), ...`` of every channel of ``rec``, for error messages."""
    return ", ".join(f"{c.name} ({c.kind})" for c in rec.channels) or "none"


def _channel_overrides(names: list[str], specs, overrides: list[dict], source: str | None,
                       present: str) -> tuple[list, list]:
    """The channel specs after the scene's ``[[channels]]`` overrides, and the gains they ask
    for ([(column, gain)], applied in that order); ValueError naming the channels present for
    an unknown name."""
    missing = [o["name"] for o in overrides if o["name"] not in names]
    if missing:
        import difflib

        def near(m):  # a name present inside the one asked for ("sun" in "sun_gauge"), or alike
            inside = [n for n in names if n.lower() in m.lower() or m.lower() in n.lower()]
            return (inside or difflib.get_close_matches(m, names, n=1))[:1]

        hints = [f"{m!r} -> {close[0]!r}?" for m in missing if (close := near(m))]
        raise ValueError(f"{source or 'the recording'}: the scene's [[channels]] name "
                         f"{', '.join(repr(m) for m in missing)} is not in the file; channels "
                         f"present: {present}"
                         + (f" (did you mean {', '.join(hints)})" if hints else ""))
    specs = list(specs)
    gains = []
    for o in overrides:
        i = names.index(o["name"])
        d = specs[i].to_dict()
        d.update({k: v for k, v in o.items() if k != "name"})
        if "kind" in o and "gear" not in o and o["kind"] in ("sun", "ring"):
            d["gear"] = o["kind"]
        specs[i] = ChannelSpec.from_dict(d)
        if "gain" in o:
            gains.append((i, o["gain"]))
    return specs, gains


def _apply_channel_overrides(rec: Recording, overrides: list[dict], source: str | None = None) -> Recording:
    if not overrides:
        return rec
    specs, gains = _channel_overrides(rec.names, rec.channels, overrides, source,
                                      _channels_present(rec))
    data = rec.data
    if gains:
        data = data.copy()
        for o in overrides:
            if "gain" in o:
                data[:, rec.index(o["name"])] *= o["gain"]
    out = Recording(data, rec.fs, specs, rec.t0, rec.start_datetime, rec.meta, rec.history)
    return out.with_history("channel_overrides", channels=[o["name"] for o in overrides])


def _mesh_freq(ctx: RunContext, gear: str) -> float | None:
    sp = ctx.scene.speeds
    g = _gearset(ctx)
    if sp is None or g is None:
        meta = ctx.results.get("load", {}).get("recording")
        if meta is not None and "speeds_nominal" in meta.meta and g is not None:
            from .models.gearset import Speeds

            sp = Speeds(**meta.meta["speeds_nominal"])
        else:
            return None
    w = sp.w_sc if gear == "sun" else sp.w_rc
    z = g.z_sun if gear == "sun" else g.z_ring
    return abs(w) * z / (2 * math.pi) if w else None


# ----------------------------------------------------------------------------- stages
#: channel kinds the onset detector times (the gauges)
_GAUGE_KINDS = ("sun", "ring", "facewidth")


def _check_gauges(ctx: RunContext, rec: Recording, source: str) -> list[str]:
    """Refuse a recording without any gauge when the scene wants measured results; return
    the channels that no planned stage reads."""
    from .scene import plan

    stages = plan(ctx.scene, check=False)
    measured = [r for r in ctx.scene.results if r in ("phasing", "load_sharing", "centroids",
                                                      "compare", "identify")]
    if "onsets" in stages and not any(c.kind in _GAUGE_KINDS for c in rec.channels):
        first = rec.channels[0].name if rec.channels else "CHANNEL"
        raise ValueError(f"{source}: no gauge channel (kind sun, ring or facewidth) for the "
                         f"results {', '.join(measured) or 'wanted'}; channels present: "
                         f"{_channels_present(rec)}; say which channel is which gauge in the "
                         f'scene, e.g. [[channels]] name = "{first}", kind = "sun"')
    used = set()
    if "onsets" in stages:
        used |= {c.name for c in rec.channels if c.kind in _GAUGE_KINDS}
    tacho = [c.name for c in rec.channels if c.kind == "tacho"]
    if "phasing" in stages and tacho:
        used.add(tacho[0])  # the ring pulse that is planet 1, from the first tacho only
    return [c.name for c in rec.channels if c.name not in used]


#: A synthetic recording up to this size [B] is generated whole, once; a longer one is
#: generated block by block again for each pass over its samples (bounded memory).
SYNTHETIC_WHOLE_BYTES = 256 * 2**20


def stage_load(ctx: RunContext) -> None:
    """Open the recording and scan its raw samples (passes 1 and 2 of :mod:`pipeline.stream`):
    the quality of every channel, the tacho's edges, the hum windows. A file is never held
    in memory: the later stages stream it again. A synthetic recording up to
    :data:`SYNTHETIC_WHOLE_BYTES` is generated whole, once; a longer one is generated again,
    block by block, for every pass (the generator is deterministic)."""
    from .stream import BLOCK_SAMPLES, FileSource, GeneratorSource, MemorySource

    inp = ctx.scene.input
    truth = None
    overrides = ctx.scene.channels
    if inp.get("recording"):
        from .exits import recording_read_errors
        from .validate import as_regular_file

        # stat only: a FIFO or device is refused before opening it could block
        path = as_regular_file(inp["recording"], "the recording")
        source = str(inp["recording"])
        with recording_read_errors(path):
            src = FileSource(path, start=inp.get("start"), stop=inp.get("stop"))
            h = src.header
            if overrides:
                specs, gains = _channel_overrides(h.names, h.channels, overrides, source,
                                                  _channels_present(h))
                src = FileSource(path, start=inp.get("start"), stop=inp.get("stop"),
                                 channels=specs, gains=gains, format=src.fmt)
                src.header = src.header.with_history(
                    "channel_overrides", channels=[o["name"] for o in overrides])
        rec = src.header
    else:
        from synthetic import generate_blocks

        minutes = inp.get("minutes")
        # a config built in code (benchmarks, tests) wins over the registered scenario's
        stream = generate_blocks(inp.get("config") or inp["synthetic"],
                                 duration=None if minutes is None else 60.0 * minutes,
                                 seed=inp.get("seed", 0))
        truth = stream.truth
        source = f"synthetic:{inp['synthetic']}"
        size = stream.n_samples * len(stream.channels) * stream.dtype.itemsize
        if size <= SYNTHETIC_WHOLE_BYTES:
            # short: generated once, whole (in memory anyway)
            rec = _apply_channel_overrides(stream.collect(), overrides, source)
            src = MemorySource(rec)
        else:
            # long: generated again, block by block, for every pass over the samples
            specs, gains = _channel_overrides(stream.names, stream.channels, overrides, source,
                                              _channels_present(stream))
            stream.block_samples = BLOCK_SAMPLES       # the blocks the file path reads
            src = GeneratorSource(stream, channels=specs, gains=gains)
            if overrides:
                src.header = src.header.with_history(
                    "channel_overrides", channels=[o["name"] for o in overrides])
            rec = src.header
    ctx.channels_unused = _check_gauges(ctx, rec, source)
    true_errors = None
    if truth is not None and truth.errors is not None:
        from synthetic.config import errors_from_dict

        true_errors = errors_from_dict(truth.errors) if isinstance(truth.errors, dict) else truth.errors
    scan = _scan(src)
    if hasattr(src, "warn_nonfinite"):
        src.warn_nonfinite(scan.results)
    ctx.results["load"] = {"recording": rec, "truth": truth, "source": source,
                           "true_errors": true_errors, "quality": scan.quality,
                           "stream": src, "scan": scan}
    h = src.header
    ctx.error_estimates["load"] = (f"{h.n_samples * h.n_channels / 1e6:.2f} MSamples read "
                                   f"(twice, {scan.n_blocks} block(s) each)")


def _scan(src):
    """Passes 1 and 2 over ``src``: every non-tacho channel may be conditioned, the first
    tacho is timed."""
    from .stream import scan_source

    h = src.header
    tacho = [c.name for c in h.channels if c.kind == "tacho"]
    return scan_source(src, conditioned=[c.name for c in h.channels if c.kind != "tacho"],
                       tacho=tacho[0] if tacho else None)


def _load_stream(ctx: RunContext):
    """(source, scan) of the loaded recording; a load stage that left only a Recording (a
    test feeding one) is scanned here."""
    from .stream import MemorySource

    load = ctx.results["load"]
    src, scan = load.get("stream"), load.get("scan")
    if src is None:
        src = MemorySource(load["recording"])
        scan = _scan(src)
        load["stream"], load["scan"] = src, scan
    return src, scan


def stage_condition(ctx: RunContext) -> None:
    """Condition every non-tacho channel and time the gauges' pulses, in one streamed pass
    (pass 3 of :mod:`pipeline.stream`): the conditioned samples are not kept, only the
    quality reports, the onsets (handed to the onsets stage) and a short excerpt."""
    from .stream import ChannelPlan, condition_stream

    src, scan = _load_stream(ctx)
    rec = src.header
    g = _gearset(ctx)
    plans = []
    for c in rec.channels:
        if c.kind == "tacho":
            continue
        # each gear's gauges with their own mesh frequency (drift window, low-pass corner)
        gear = c.gear if c.gear in ("sun", "ring") else (c.kind if c.kind in ("sun", "ring") else None)
        fm = _mesh_freq(ctx, gear) if gear else None
        # the pulse train's period: one relative revolution of the gauged gear (Z mesh
        # periods), in which every planet passes once
        period = None
        if fm and g is not None:
            period = (g.z_sun if gear == "sun" else g.z_ring) / fm
        onsets = c.kind in _GAUGE_KINDS
        kw = {}
        if onsets:
            og = c.gear or c.kind
            ofm = _mesh_freq(ctx, og) if og in ("sun", "ring") else None
            kw = {"mesh_freq": ofm} if ofm else {}
        plans.append(ChannelPlan(c.name, mesh_freq=fm, pulse_period=period, group=str(gear),
                                 onsets=onsets, onset_kwargs=kw))
    res = condition_stream(src, scan, plans)
    ctx.results["condition"] = {"recording": res.recording, "quality": res.quality,
                                "excerpt": res.excerpt, "onsets": res.onsets,
                                "onset_warnings": res.warnings, "timings": res.timings,
                                "memory": res.memory}
    snr = {k: getattr(q, "snr_db", None) for k, q in res.quality.items()}
    est = "SNR " + ", ".join(f"{k} {v:.1f} dB" for k, v in snr.items()
                             if isinstance(v, (int, float)) and math.isfinite(v))
    ctx.error_estimates["condition"] = (
        est + f"; streamed in {res.n_blocks} block(s), onset detection "
        f"{res.timings.get('onsets_s', 0.0):.2f} s of it")


def stage_onsets(ctx: RunContext) -> None:
    cond = ctx.results["condition"]
    rec = cond["recording"]
    for gear in ("sun", "ring"):
        fm = _mesh_freq(ctx, gear)
        if fm and fm >= 0.35 * rec.fs:
            from .errors import DataQualityWarning

            what = ("pulses are aliased and onset times are not reliable" if fm >= 0.45 * rec.fs
                    else "fewer than 3 samples per mesh period: expect onset bias of several "
                         "1e-3 mesh cycles")
            warnings.warn(f"{gear} gauge: mesh frequency {fm:.4g} Hz is {fm / rec.fs:.2f} fs: {what}",
                          DataQualityWarning, stacklevel=2)
    # the detector ran in the condition stage's pass over the samples: its warnings are
    # this stage's
    for category, message in cond.get("onset_warnings", ()):
        warnings.warn(message, category, stacklevel=2)
    found = cond.get("onsets")
    if found is None:                           # a condition stage that kept the samples
        from .onsets import detect_onsets_recording

        found = {}
        for c in rec.channels:
            if c.kind in _GAUGE_KINDS:
                gear = c.gear or c.kind
                fm = _mesh_freq(ctx, gear) if gear in ("sun", "ring") else None
                found[c.name] = detect_onsets_recording(rec, c.name, quality=cond["quality"].get(c.name),
                                                        **({"mesh_freq": fm} if fm else {}))
    out = {c.name: found[c.name] for c in rec.channels if c.kind in _GAUGE_KINDS and c.name in found}
    scan = ctx.results["load"].get("scan")
    tacho_times = None if scan is None else scan.tacho_times
    ctx.results["onsets"] = {"by_channel": out, "tacho_times": tacho_times}
    n = sum(len(o) for o in out.values())
    jit = []
    for o in out.values():
        if len(o) and np.isfinite(o.corr).any():
            jit.append(float(np.median(o.corr)))
    ctx.error_estimates["onsets"] = (f"{n} onsets; median template correlation "
                                     f"{np.median(jit):.4f}" if jit else f"{n} onsets")


def _main_gauge(rec: Recording, gear: str) -> str | None:
    c = [s.name for s in rec.channels if s.kind == gear]
    return c[0] if c else None


def _timing_centre(tp) -> float:
    """The point of a template the matched filter follows when the pulse stretches
    [template samples]: the centroid of its squared slope, sum(u h'(u)^2) / sum(h'(u)^2).

    A tooth-root pulse lasts a fixed angle, so at another speed it is the template stretched
    in time by s about the engagement; the correlation peak then moves by (s - 1) times that
    centroid's distance from the engagement (d lag / d s = int u h'^2 / int h'^2, implicit
    differentiation of the correlation maximum). The onset the detector reports is that
    centroid plus a template-fixed (time-fixed) offset, so only the centroid sits at a fixed
    angle of the gauged gear under speed ripple."""
    h = np.asarray(tp.samples, dtype=float)
    d = np.gradient(h)
    e = d * d
    tot = float(e.sum())
    if not tot > 0:
        return float(tp.peak)
    return float(np.sum(np.arange(h.size) * e) / tot)


def _pass_times(on) -> np.ndarray:
    """Onset times moved to their template's timing centre [s] (:func:`_timing_centre`): a
    fixed angle of the gauged gear whatever the local speed, near the middle of the tooth's
    contact, i.e. the engagement instant, on every gauge alike."""
    if not len(on) or not on.templates:
        return on.times
    shift = np.array([(tp.ref - _timing_centre(tp)) / tp.rate for tp in on.templates], dtype=float)
    tid = np.clip(on.template_id, 0, shift.size - 1)
    out = on.times - np.where(on.template_id >= 0, shift[tid], 0.0)
    # keep the order strictly increasing (templates may differ between blocks)
    return out if np.all(np.diff(out) > 0) else on.times


def _usable(on, gap_runs, fs: float, t0: float) -> np.ndarray:
    """Onsets to measure phasing with: the clean ones, plus those flagged only for a gap that
    conditioning bridged (a few dropped samples, see condition.filter_signal's ``fill_max``):
    the conditioned signal is finite over the whole pulse, so the timing is not affected.

    ``gap_runs``: the ``[start, stop)`` sample runs where the conditioned channel is not
    finite (``ChannelQuality.conditioned_gap_runs``; its gaps and dropouts when that is
    unknown); a pulse is clean when no run meets ``[i - 2 h, i + 2 h)`` around its onset
    sample ``i``, ``h`` its half width (at least 2 samples)."""
    from .onsets import FLAG_GAP

    ok = on.good.copy()
    gap_only = on.flags == np.uint8(FLAG_GAP)
    if not np.any(gap_only):
        return ok
    r = np.empty((0, 2), dtype=np.int64) if gap_runs is None else \
        np.asarray(gap_runs, dtype=np.int64).reshape(-1, 2)
    if not len(r):
        return ok | gap_only
    half = np.maximum(2, np.ceil(np.nan_to_num(on.width, nan=0.0) * fs)).astype(np.int64)
    i = np.rint((on.times - t0) * fs).astype(np.int64)
    a, b = i - 2 * half, i + 2 * half
    j = np.searchsorted(r[:, 1], a, side="right")          # first run ending after a
    hit = (j < len(r)) & (r[np.minimum(j, len(r) - 1), 0] < b) & (b > a)
    return ok | (gap_only & ~hit)


def _conditioned_gaps(q):
    """The runs where a conditioned channel is not finite, from its quality report."""
    if q is None:
        return None
    runs = getattr(q, "conditioned_gap_runs", None)
    return q.all_gap_runs() if runs is None else runs


#: finest onset timing claimed on noise-free data, as a fraction of the pulse's FWHM [-]
ONSET_RESOLUTION = 1e-4


def _onset_sigma(on, noise_rms: float) -> np.ndarray:
    """Per-onset timing uncertainty [s]: the Cramer-Rao bound for the learnt template at the
    fitted amplitude in white noise of the conditioned channel's RMS, sigma / sqrt(sum (ds/dt)^2)
    (Kay 1993, eq. 3.14); the onset tests hold the detector within ~1.1x of it.

    It never claims better than the detector resolves a noise-free pulse: its sub-sample
    interpolation leaves an error that repeats with the pulse's position on the sample grid,
    ~1e-4 of the pulse's FWHM (noise-free seed rig at 5120 Hz, FWHM 650 samples: 6.6 us sun,
    4.1 us ring RMS; Table 1 at 51.2 kHz, FWHM 34 samples: 0.004 sample), so
    ``ONSET_RESOLUTION`` times the template's FWHM is a floor. NaN without a template."""
    out = np.full(len(on), np.nan)
    if not len(on) or not on.templates:
        return out
    tid = np.clip(on.template_id, 0, len(on.templates) - 1)
    has = on.template_id >= 0
    floor = np.array([ONSET_RESOLUTION * tp.fwhm for tp in on.templates])[tid]
    floor = np.where(has, floor, np.nan)
    if not (isinstance(noise_rms, float) and math.isfinite(noise_rms)) or noise_rms <= 0:
        return floor
    info = []
    for tp in on.templates:
        d = np.gradient(np.asarray(tp.samples, dtype=float)) * tp.rate   # [1/s], peak 1
        info.append(tp.decimation * float(np.sum(d * d)))                 # per original sample
    s2 = np.where(has, np.asarray(info)[tid], np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = noise_rms / (np.abs(on.amplitude) * np.sqrt(s2))
    out = np.fmax(out, floor)
    return np.where(np.isfinite(out), out, np.nan)


def _nominal_speeds(ctx: RunContext):
    """The scene's nominal speeds, else the recording's (synthetic files carry them)."""
    sp = ctx.scene.speeds
    if sp is None:
        meta = ctx.results["load"]["recording"].meta.get("speeds_nominal")
        if meta:
            from .models.gearset import Speeds

            sp = Speeds(**meta)
    return sp


def _tacho_geometry(ctx: RunContext) -> tuple:
    """(key angle [rad] or None, mounts {channel: ground angle [rad]}): the scene's keys, else
    the recording's metadata, else (synthetic input) the generator's configuration."""
    key = ctx.scene.tacho.get("key_angle")
    mounts = dict(ctx.scene.mounts)
    meta = ctx.results["load"]["recording"].meta
    if key is None and meta.get("tacho_key_angle") is not None:
        key = float(meta["tacho_key_angle"])
    for k, v in (meta.get("mount_angles") or {}).items():
        mounts.setdefault(k, float(v))
    truth = ctx.results["load"].get("truth")
    if truth is not None and (key is None or not mounts):
        from synthetic.config import SynthConfig

        cfg = SynthConfig.from_dict(truth.config)
        if cfg.tacho is not None and key is None:
            # the generator's key reaches the probe at carrier angle cfg.tacho_angle():
            # the edge fires at theta_c = -key_angle
            key = -cfg.tacho_angle()
        for gcfg in cfg.gauges:
            # a held member's gauge sits still: its direction at t = 0 is its ground angle
            mounts.setdefault(gcfg.name, cfg.tooth_angle(gcfg))
    return key, mounts


def _gap_intervals(quality: dict) -> np.ndarray:
    """Gap intervals [s] of the conditioned gauge channels (NaN runs and dropouts)."""
    out = []
    for q in quality.values():
        for attr in ("gap_runs", "dropout_runs"):
            runs = getattr(q, attr, None)
            if runs is not None and np.size(runs):
                r = np.asarray(runs, dtype=float).reshape(-1, 2)
                out.append(q.t0 + r / q.fs)
    return np.concatenate(out) if out else np.empty((0, 2))


def stage_phasing(ctx: RunContext) -> None:
    from .angles import held_member
    from .phasing import GaugePasses, PassTable, measure_phasing

    g = _gearset(ctx)
    rec = ctx.results["condition"]["recording"]
    quality = ctx.results["condition"]["quality"]
    ons = ctx.results["onsets"]["by_channel"]
    # the conditioned samples are streamed, not kept: a pulse's window is checked against
    # the runs where the conditioned channel is not finite (its quality report)
    gaps = {name: _conditioned_gaps(q) for name, q in quality.items()}
    passes = []
    mains = {}
    for c in rec.channels:
        if c.kind not in ("sun", "ring", "facewidth") or c.name not in ons:
            continue
        gear = c.gear if c.gear in ("sun", "ring") else (c.kind if c.kind in ("sun", "ring") else "sun")
        on = ons[c.name]
        ok = _usable(on, gaps.get(c.name), rec.fs, rec.t0)
        # pass times at each pulse's timing centre: a fixed angle of the gauged gear near the
        # middle of the tooth's contact, on every gauge alike
        times, amp = _pass_times(on)[ok], on.amplitude[ok]
        sig = _onset_sigma(on, getattr(quality.get(c.name), "noise_rms", float("nan")))[ok]
        main = c.kind in ("sun", "ring") and gear not in mains
        if main:
            mains[gear] = c.name
            if times.size == 0:
                warnings.warn(f"{gear} gauge ({c.name}): no usable pulse ({len(on)} onset(s), all "
                              "flagged or none found): dead gauge, wrong channel or no load; no "
                              "phasing from it", ProcessingWarning, stacklevel=2)
        if times.size:
            passes.append(GaugePasses(c.name, gear, times, amp,
                                      sig if np.any(np.isfinite(sig)) else None, main))
    tacho = ctx.results["onsets"].get("tacho_times")
    sp = _nominal_speeds(ctx)
    # which member is held: the scene's word, else the typed speeds within their precision,
    # and the tacho's count of mesh cycles per carrier turn when there is a tacho
    res_typed = ctx.scene.speeds_resolution if ctx.scene.speeds is not None else None
    stated = ctx.scene.fixed
    if stated is not None:
        fixed, why = (None if stated == "none" else stated), "stated in the scene ([speeds] fixed)"
    else:
        fixed, why = held_member(g.z_sun, g.z_ring, sp, resolution=res_typed)
    key, mounts = _tacho_geometry(ctx)
    res = measure_phasing(passes, g, fixed=fixed, fixed_reason=why, tacho_times=tacho,
                          key_angle=key, mounts=mounts, speeds=sp, gaps=_gap_intervals(quality),
                          check_held=stated is None, speeds_resolution=res_typed)
    for gear in mains:
        # a main gauge without a measurable pass gives an empty table, not a missing one
        res.tables.setdefault(gear, PassTable.empty(gear, ["no usable pass"]))
    for t in res.tables.values():
        t.time_origin = float(rec.t0)
    for gear, lab in res.labels.items():
        if lab.n_unassigned:
            warnings.warn(f"{gear} gauge: {lab.n_unassigned} pulse(s) fit no planet in the pass "
                          "pattern (missing pulses, speed change or spurious detections); they "
                          "are left out", ProcessingWarning, stacklevel=2)
    for gear, rel in res.reliability.items():
        if not rel["reliable"]:
            warnings.warn(f"{gear} gauge: phasing not reliable: " + "; ".join(rel["reasons"]),
                          ProcessingWarning, stacklevel=2)
    ctx.results["phasing"] = {
        "tables": res.tables, "labels": {k: v.as_tuple() for k, v in res.labels.items()},
        "assignment": {k: {"shift_decided_by": v.decided_by, "n_unassigned": v.n_unassigned,
                           "ambiguous": v.decided_by == "first pulse"}
                       for k, v in res.labels.items()},
        "model": res.model, "reliability": res.reliability, "fixed": res.fixed,
        "fixed_reason": res.fixed_reason, "labels_relative": res.labels_relative,
        "notes": res.notes, "result": res}
    est = []
    for gear, t in res.tables.items():
        rel = res.reliability.get(gear, {})
        if len(t):
            est.append(f"{gear}: per-pass sigma {rel.get('error_estimate', float('nan')):.2e} "
                       f"cycles (timing floor {rel.get('floor', float('nan')):.2e})")
    if res.model is not None:
        est.append(f"angle model: {res.model.terms}, rank {res.model.rank}/{res.model.n_parameters}")
    ctx.error_estimates["phasing"] = "; ".join(est)


def stage_load_sharing(ctx: RunContext) -> None:
    from .loads import load_sharing_from_amplitudes
    from .phasing import assign_planets_by_pattern, pass_order

    g = _gearset(ctx)
    labels = ctx.results.get("phasing", {}).get("labels", {})
    if "ring" in labels:
        ch, times, pl, amp, _ = labels["ring"]
    else:
        rec = ctx.results["condition"]["recording"]
        ch = _main_gauge(rec, "ring")
        if ch is None:
            ctx.results["load_sharing"] = None
            ctx.error_estimates["load_sharing"] = "no ring gauge: skipped"
            return
        on = ctx.results["onsets"]["by_channel"][ch]
        times, amp = on.times[on.good], on.amplitude[on.good]
        pl, _ = assign_planets_by_pattern(times, g.angles, pass_order(g.direction, "ring"))
    res = load_sharing_from_amplitudes(np.abs(amp), np.where(pl >= 0, pl + 1, 0), g.n_planets)
    ctx.results["load_sharing"] = res
    se = res.std_error[np.isfinite(res.std_error)]
    ctx.error_estimates["load_sharing"] = (f"max std error {se.max():.2e}" if se.size else
                                           "no standard error (fewer than two passes per planet)")


def stage_centroids(ctx: RunContext) -> None:
    from .loads import facewidth_centroid

    rec = ctx.results["condition"]["recording"]
    g = _gearset(ctx)
    ons = ctx.results["onsets"]["by_channel"]
    fw = [c for c in rec.channels if c.kind == "facewidth"]
    if not fw:
        ctx.results["centroids"] = {}
        ctx.error_estimates["centroids"] = "no face-width gauges: nothing to do"
        return
    b = g.face_width if g is not None and g.face_width else None
    out = {}
    for gear in sorted({c.gear or "sun" for c in fw}):
        chans = [c for c in fw if (c.gear or "sun") == gear and c.face_position is not None]
        if len(chans) < 2 or b is None:
            out[gear] = None
            continue
        # time the passes on the gauge that sees the most load: with partial contact the
        # gauges at the unloaded end of the face read nothing
        ref = max((ons[c.name] for c in chans), key=lambda o: (int(o.good.sum()),
                  float(np.nanmedian(np.abs(o.amplitude))) if len(o) else 0.0))
        # readings per pass: each gauge's amplitude at the pulse nearest the first gauge's
        rows = []
        for t0 in ref.times[ref.good]:
            row = []
            for c in chans:
                o = ons[c.name]
                if len(o) == 0:
                    row.append(0.0)  # no pulse at all on this gauge: unloaded end of the face
                    continue
                j = int(np.argmin(np.abs(o.times - t0)))
                width = float(np.nanmedian(ref.width)) if len(ref) else 0.0
                row.append(abs(o.amplitude[j]) if abs(o.times[j] - t0) < max(width, 1 / rec.fs) else 0.0)
            rows.append(row)
        readings = np.asarray(rows, dtype=float).reshape(-1, len(chans))
        pos = np.array([c.face_position for c in chans])
        readings = readings[np.all(np.isfinite(readings), axis=1)]
        if readings.shape[0] == 0:
            warnings.warn(f"{gear} face-width gauges: no pass seen on any of them; no centroid",
                          ProcessingWarning, stacklevel=2)
        out[gear] = facewidth_centroid(readings, pos, b)
    ctx.results["centroids"] = out
    ctx.error_estimates["centroids"] = "; ".join(
        f"{k}: Z = {v.centroid * 1e3:.3f} ± {v.std_error * 1e3:.3f} mm" for k, v in out.items() if v)


def stage_ideal(ctx: RunContext) -> None:
    from .models.mesh_phasing import assembly_check, classify_phasing, ideal_phasing

    g = _gearset(ctx)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        cls = classify_phasing(g)
    gs, gr = ideal_phasing(g)
    ctx.results["ideal"] = {"gamma_s": gs, "gamma_r": gr, "classification": cls,
                            "assembly": assembly_check(g)}
    ctx.error_estimates["ideal"] = "exact (closed form)"


def _tolerances(ctx: RunContext):
    from .models.tolerance import ToleranceBand, Tolerances

    t = ctx.scene.tolerances
    kw = {}
    for gear in ("sun", "ring", "planet"):
        kw[f"e_{gear}"] = ToleranceBand(mean=t[f"mean_e_{gear}"], band=t[f"e_{gear}"])
        k = t[f"kappa_{gear}"]
        kw[f"kappa_{gear}"] = (ToleranceBand.full_circle() if k == "uniform" else
                               ToleranceBand(mean=k, band=0.0))
    return Tolerances(**kw)


def stage_tolerance(ctx: RunContext) -> None:
    from .models.tolerance import monte_carlo, observation_window

    g = _gearset(ctx)
    t = ctx.scene.tolerances
    sp = ctx.scene.speeds
    window = observation_window(sp) if t.get("window") is None else (0.0, float(t["window"]))
    res = monte_carlo(g, sp, _tolerances(ctx), window, t["samples"], sampler=t["sampler"],
                      rng=t.get("seed", 0))
    ctx.results["tolerance"] = res
    se = float(np.max(res.dev_s.se_bound3)) if res.dev_s.se_bound3.size else float("nan")
    ctx.error_estimates["tolerance"] = (f"{res.n_samples} {res.sampler} samples; std error of the "
                                        f"3-sigma Dev_sn bound {se:.1e} cycles")


def stage_identify(ctx: RunContext) -> None:
    from .compare import identify_errors
    from .phasing import relabel_gauge

    g = _gearset(ctx)
    ph = ctx.results["phasing"]
    tables = {k: t for k, t in ph["tables"].items() if len(t)}
    ident = identify_errors(list(tables.values()), g)
    res = ph.get("result")
    # a gauge whose planet numbering is only relative is tried in every cyclic relabelling:
    # the error model ties the gauges' numberings together (a planet's offset moves its mean
    # phasing on both), and a relabelling is kept only where it halves the joint residual
    relative = [gear for gear in ph.get("labels_relative", []) if gear in tables]
    if res is not None and res.model is not None and len(tables) > 1 and relative:
        for gear in relative[:1]:
            best = (ident.rms_after, 0, ident, None, None)
            for shift in range(1, g.n_planets):
                tab, lab = relabel_gauge(res, gear, shift, g)
                if not len(tab):
                    continue
                cand = identify_errors([tab if k == gear else t for k, t in tables.items()], g)
                if cand.rms_after < best[0]:
                    best = (cand.rms_after, shift, cand, tab, lab)
            if best[1] and best[0] <= 0.5 * ident.rms_after:
                _, shift, ident, tab, lab = best
                lab.decided_by = "identification"
                res.tables[gear], res.labels[gear] = tab, lab
                ph["tables"][gear] = tab
                ph["labels"][gear] = lab.as_tuple()
                ph["assignment"][gear] = {"shift_decided_by": "identification",
                                          "n_unassigned": lab.n_unassigned, "ambiguous": False}
                ph["labels_relative"] = [x for x in ph["labels_relative"] if x != gear]
                ident.notes.append(f"{gear} gauge relabelled by {shift} place(s): the error model "
                                   "fits both gauges only with the planets numbered alike")
    ctx.results["identify"] = ident
    ctx.error_estimates["identify"] = (f"residual RMS {ident.rms_before:.2e} -> {ident.rms_after:.2e} "
                                       f"cycles over {ident.n_passes} passes")


def stage_compare(ctx: RunContext) -> None:
    from .compare import band_coverage, predict_pass_phasing, residual_stats

    g = _gearset(ctx)
    tables = ctx.results["phasing"]["tables"]
    ident = ctx.results.get("identify")
    mc = ctx.results.get("tolerance")
    out = {}
    for gear, tab in sorted(tables.items(), key=lambda kv: kv[0] != "sun"):
        if not len(tab):
            continue
        ideal = predict_pass_phasing(tab, g, None)
        model = predict_pass_phasing(tab, g, ident.errors) if ident is not None else None
        row = {"ideal": ideal, "model": model,
               "vs_ideal": residual_stats(tab.gamma, ideal, tab.planet),
               "vs_model": residual_stats(tab.gamma, model, tab.planet) if model is not None else None}
        if mc is not None:
            ave = mc.ave_s if gear == "sun" else mc.ave_r
            dev = mc.dev_s if gear == "sun" else mc.dev_r
            lo = ave.bound3[0] - dev.bound3[1] / 2
            hi = ave.bound3[1] + dev.bound3[1] / 2
            ideal_pl = ctx.results["ideal"]["gamma_s" if gear == "sun" else "gamma_r"]
            row["band"] = {"lo": lo, "hi": hi}
            row["coverage"] = band_coverage(tab.gamma, tab.planet, ideal_pl, lo, hi)
        out[gear] = row
    truth = ctx.results.get("load", {}).get("truth")
    if truth is not None:
        for gear in ("sun", "ring"):
            if gear in out:
                out[gear]["vs_truth"] = _truth_residual(ctx, tables[gear], truth, gear)
    ctx.results["compare"] = out
    parts = []
    for gear, r in out.items():
        s = r["vs_model"] or r["vs_ideal"]
        parts.append(f"{gear}: RMS vs model {s['rms']:.2e}")
        if "vs_truth" in r and r["vs_truth"]:
            parts.append(f"{gear}: RMS vs truth {r['vs_truth']['rms']:.2e}")
    ctx.error_estimates["compare"] = "; ".join(parts)


def _truth_residual(ctx, tab, truth, gear) -> dict | None:
    """Measured gamma against the synthetic truth, pass by pass
    (:func:`pipeline.compare.truth_comparison`)."""
    from .compare import truth_comparison

    labels = ctx.results["phasing"]["labels"]
    if gear not in labels:
        return None
    ch, times, pl, amp, _ = labels[gear]
    return truth_comparison(tab, truth, ch, times=times, planets=pl)


def stage_bearing_moments(ctx: RunContext) -> None:
    from .models import bearing

    b = ctx.scene.bearing
    case = bearing.seed_case(b["case"])
    geom = case.geometry
    torque = b["input_torque"] if b.get("input_torque") is not None else case.input_torque
    out = {"case": case, "torque": torque}
    if isinstance(geom, bearing.SinglePinion):
        out["concentrated"] = bearing.single_pinion_moments(geom, torque)
        out["with_offsets"] = bearing.single_pinion_moments(geom, torque, b["z_s"], b["z_r"])
        cen = ctx.results.get("centroids") or {}
        if cen.get("sun") is not None and cen.get("ring") is not None:
            z_s, z_r = cen["sun"].centroid, cen["ring"].centroid
            mx, my = bearing.moments_from_offsets(geom, torque, z_s, z_r)
            out["measured"] = bearing.single_pinion_moments(geom, torque, z_s, z_r)
    else:
        out["concentrated"] = bearing.double_pinion_moments(geom, torque)
    ctx.results["bearing_moments"] = out
    ctx.error_estimates["bearing_moments"] = "closed form (seed 001 tables reproduced to print precision)"


def stage_tilt(ctx: RunContext) -> None:
    from .models import bearing
    from .models.tilt import solve_tilt

    b = ctx.scene.bearing
    case = bearing.seed_case(b["case"])
    torque = b["input_torque"] if b.get("input_torque") is not None else case.input_torque
    sols = []
    for k in b["k_tilt"]:
        sols.append((k, solve_tilt(case.geometry, torque, k, c_g=b["c_g"])))
    ctx.results["tilt"] = {"case": case, "torque": torque, "solutions": sols}
    res = max(float(np.max(s.residual)) for _, s in sols)
    its = max(int(np.max(s.iterations)) for _, s in sols)
    ctx.error_estimates["tilt"] = f"max residual {res:.1e} m, <= {its} iterations"


STAGE_FUNCTIONS: dict[str, Callable[[RunContext], None]] = {
    "load": stage_load, "condition": stage_condition, "onsets": stage_onsets,
    "phasing": stage_phasing, "load_sharing": stage_load_sharing, "centroids": stage_centroids,
    "ideal": stage_ideal, "tolerance": stage_tolerance, "identify": stage_identify,
    "compare": stage_compare, "bearing_moments": stage_bearing_moments, "tilt": stage_tilt,
}


def run_scene(scene: Scene, *, progress: Callable[[str, int, int], None] | None = None) -> RunContext:
    """Run the stages the scene's results need, in dependency order.

    A stage that raises is recorded in ``ctx.failed`` and the stages that depend on it are
    skipped (with the reason); the others still run, so a run always returns what it could
    compute. Our warnings (:class:`~pipeline.errors.MeshphaseWarning` and subclasses) are
    collected into ``ctx.messages`` as "stage: Category: message" and not issued again (the
    CLI prints them, the report lists them); other warnings are collected and re-issued.
    """
    from .scene import STAGES

    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene (pipeline.scene.load_scene), got {type(scene).__name__}")
    ctx = RunContext(scene)
    stages = plan(scene)
    for i, name in enumerate(stages):
        blocked = [d for d in STAGES[name] if d in ctx.failed or (d not in ctx.ran)]
        if blocked:
            ctx.failed[name] = f"skipped: needs {', '.join(blocked)}"
            continue
        if name == "centroids" and "load" in ctx.results and not any(
                c.kind == "facewidth" for c in ctx.results["load"]["recording"].channels):
            # only what the scene needs: no face-width gauges, no centroid work
            ctx.failed[name] = "skipped: the recording has no face-width gauges"
            continue
        if progress:
            progress(name, i, len(stages))
        t = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeshphaseWarning)
            try:
                STAGE_FUNCTIONS[name](ctx)
                ctx.ran.append(name)
            except (ValueError, TypeError, FileNotFoundError, KeyError, OSError) as exc:
                ctx.failed[name] = f"{type(exc).__name__}: {exc}"
                # the caller reports ctx.failed (the CLI: one line per cause); the traceback
                # is for developers (meshphase --debug)
                logger.info("stage %s failed: %s", name, exc)
                logger.debug("stage %s traceback", name, exc_info=True)
        ctx.timings[name] = time.perf_counter() - t
        for w in caught:
            msg = f"{name}: {w.category.__name__}: {w.message}"
            if msg not in ctx.messages:
                ctx.messages.append(msg)
            if not issubclass(w.category, MeshphaseWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if progress:
        progress("done", len(stages), len(stages))
    return ctx


def new_output_dir(base: Path, *, overwrite: bool = False) -> Path:
    """``base`` if it does not exist (or ``overwrite``), else ``base-2``, ``base-3``, ...:
    a run never overwrites an earlier one unless asked."""
    base = Path(base)
    if overwrite or not base.exists():
        base.mkdir(parents=True, exist_ok=True)
        return base
    i = 2
    while Path(f"{base}-{i}").exists():
        i += 1
    out = Path(f"{base}-{i}")
    out.mkdir(parents=True)
    return out


def summary_dict(ctx: RunContext) -> dict:
    """The machine-readable summary of a run (JSON-friendly)."""
    from .campaign import phasing_reliability
    from .exits import run_status

    r = ctx.results
    st = run_status(ctx)
    s: dict = {"scene": ctx.scene.name, "status": st["status"],
               "missing_results": st["missing_results"],
               "phasing_reliability": phasing_reliability(ctx),
               "results_requested": ctx.scene.results,
               "stages_ran": ctx.ran, "stages_failed": ctx.failed,
               "timings_s": ctx.timings, "error_estimates": ctx.error_estimates,
               "messages": ctx.messages, "channels_unused": ctx.channels_unused}
    g = _gearset(ctx)
    if g is not None:
        s["gearset"] = g.to_dict()
    if "load" in r:
        rec = r["load"]["recording"]
        s["recording"] = {"source": r["load"]["source"], "fs_hz": rec.fs, "n_samples": rec.n_samples,
                          "duration_s": rec.duration, "channels": [c.to_dict() for c in rec.channels]}
    if "onsets" in r:
        s["onsets"] = {k: o.summary() for k, o in r["onsets"]["by_channel"].items()}
    if "ideal" in r:
        s["ideal"] = {"gamma_s": r["ideal"]["gamma_s"], "gamma_r": r["ideal"]["gamma_r"],
                      "classification": r["ideal"]["classification"]}
    if "phasing" in r:
        ph = r["phasing"]
        s["phasing"] = {k: {"n_passes": len(t), "per_planet": t.summary(), "notes": t.notes,
                            "assignment": ph["assignment"].get(k),
                            "reliability": ph.get("reliability", {}).get(k)}
                        for k, t in ph["tables"].items()}
        rel = ph.get("labels_relative") or []
        s["phasing_labels"] = (
            f"planet labels of the {' and '.join(rel)} gauge(s) are relative: planet 1 is the "
            "first pulse seen (no tacho geometry, unequal spacing or unequal loads named it)"
            if rel else "planet labels absolute")
        s["held_member"] = {"fixed": ph.get("fixed"), "reason": ph.get("fixed_reason")}
        if ph.get("model") is not None:
            s["angle_model"] = ph["model"].summary()
    if r.get("load_sharing") is not None:
        s["load_sharing"] = r["load_sharing"].to_rows()
    if r.get("centroids"):
        s["centroids_m"] = {k: (None if v is None else vars(v)) for k, v in r["centroids"].items()}
    if "tolerance" in r:
        s["tolerance"] = r["tolerance"].to_dict()
    if "identify" in r:
        i = r["identify"]
        s["identify"] = {"table": i.table, "rms_before": i.rms_before, "rms_after": i.rms_after,
                         "n_passes": i.n_passes, "identifiable": i.identifiable, "notes": i.notes,
                         "singular_values": i.singular_values}
    if "compare" in r:
        s["compare"] = {k: {kk: vv for kk, vv in v.items() if kk not in ("ideal", "model")}
                        for k, v in r["compare"].items()}
    if "bearing_moments" in r:
        b = r["bearing_moments"]
        s["bearing_moments"] = {"case": b["case"].name, "input_torque_Nm": b["torque"],
                                "concentrated": _moments_dict(b["concentrated"]),
                                **({"measured": _moments_dict(b["measured"])} if "measured" in b else {})}
    if "tilt" in r:
        s["tilt"] = [{"k_tilt_Nm_per_rad": k, "z_m": sol.z, "converged": sol.converged,
                      "iterations": sol.iterations, "residual_m": sol.residual,
                      "contact_fraction": sol.contact_fraction, "moments": _moments_dict(sol.moments)}
                     for k, sol in r["tilt"]["solutions"]]
    return to_jsonable(s)


def _moments_dict(m) -> dict:
    out = {}
    for k, v in vars(m).items():
        if isinstance(v, (np.ndarray, float, int, np.floating)):
            out[k] = v
    return out


def write_outputs(ctx: RunContext, out_dir: Path, *, report: bool = True) -> dict:
    """Write summary.json, CSV tables, arrays.h5 and (optionally) report.html into ``out_dir``.

    Returns a dict name -> path of what was written.
    """
    import h5py
    import pandas as pd

    if not isinstance(ctx, RunContext):
        raise TypeError(f"ctx must be a RunContext (from run_scene), got {type(ctx).__name__}")
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise FileNotFoundError(f"{out_dir}: output folder does not exist (see new_output_dir)")
    files = {}
    summ = summary_dict(ctx)
    p = out_dir / "summary.json"
    p.write_text(json.dumps(summ, indent=2))
    files["summary"] = p
    r = ctx.results
    if "phasing" in r:
        for gear, t in r["phasing"]["tables"].items():
            df = t.to_dataframe()
            if "compare" in r and gear in r["compare"]:
                df["gamma_ideal"] = r["compare"][gear]["ideal"]
                if r["compare"][gear]["model"] is not None:
                    df["gamma_model"] = r["compare"][gear]["model"]
            p = out_dir / f"passes_{gear}.csv"
            df.to_csv(p, index=False)
            files[f"passes_{gear}"] = p
    if r.get("load_sharing") is not None:
        p = out_dir / "load_sharing.csv"
        pd.DataFrame(r["load_sharing"].to_rows()).to_csv(p, index=False)
        files["load_sharing"] = p
    if "identify" in r:
        p = out_dir / "identified_errors.csv"
        pd.DataFrame(r["identify"].table).to_csv(p, index=False)
        files["identified_errors"] = p
    if "tilt" in r:
        p = out_dir / "tilt.csv"
        pd.DataFrame([{"k_tilt_Nm_per_rad": k, "z_s_m": float(np.ravel(s.z)[0]),
                       "z_r_m": float(np.ravel(s.z)[-1]), "converged": bool(np.all(s.converged)),
                       "iterations": int(np.max(s.iterations)), "residual_m": float(np.max(s.residual))}
                      for k, s in r["tilt"]["solutions"]]).to_csv(p, index=False)
        files["tilt"] = p
    p = out_dir / "stages.csv"
    pd.DataFrame([{"stage": s, "wall_time_s": ctx.timings.get(s, float("nan")),
                   "error_estimate": ctx.error_estimates.get(s, ""),
                   "status": "ran" if s in ctx.ran else ctx.failed.get(s, "")}
                  for s in list(ctx.timings) + [k for k in ctx.failed if k not in ctx.timings]],
                 columns=["stage", "wall_time_s", "error_estimate", "status"]).to_csv(p, index=False)
    files["stages"] = p
    # arrays: onsets per channel, Monte Carlo samples
    arrays = out_dir / "arrays.h5"
    with h5py.File(arrays, "w") as f:
        if "onsets" in r:
            grp = f.create_group("onsets")
            for ch, o in r["onsets"]["by_channel"].items():
                gch = grp.create_group(ch)
                for a in ("times", "corr", "amplitude", "width", "flags"):
                    gch.create_dataset(a, data=getattr(o, a))
        if "tolerance" in r and r["tolerance"].samples is not None:
            grp = f.create_group("monte_carlo")
            for k, v in r["tolerance"].samples.items():
                grp.create_dataset(k, data=v)
    files["arrays"] = arrays
    if report:
        from .report.validation import build_report

        p = build_report(ctx, out_dir)
        files["report"] = p
    return files


def process_recording(path, gearset_scene_path, *, out_dir=None, overwrite=False,
                      progress: Callable[[str, int, int], None] | None = None) -> tuple:
    """``meshphase process FILE --gearset GEARSET.toml``: the recording-processing results
    (phasing, load sharing, centroids, comparison with the ideal and identified model).

    The output folder is reserved before the run (an unwritable location fails at once) and
    removed again when the run raises or is interrupted; when the recording cannot be loaded
    (nothing usable) nothing is written and ``files`` is empty: see
    :func:`pipeline.exits.run_status` for the status of the run.

    Returns (RunContext, files).
    """
    from .exits import OutputDir, run_status
    from .scene import load_scene
    from .validate import as_regular_file

    path = as_regular_file(path, "the recording")  # stat only: a FIFO never blocks here
    scene = load_scene(gearset_scene_path)
    scene.input = {"recording": Path(path).resolve()}
    wanted = ["phasing", "load_sharing", "compare"]
    scene.results = [r for r in dict.fromkeys(list(scene.results) + wanted)
                     if r not in ("tolerance",) or scene.tolerances is not None]
    base = Path(out_dir) if out_dir else Path(path).with_name(Path(path).stem + "-meshphase")
    # staged: the folder is built beside its final name and swapped in whole, so a killed
    # run never leaves a half-written result folder under the name a reader expects
    with OutputDir(base, overwrite=overwrite, staged=True) as out:
        ctx = run_scene(scene, progress=progress)
        if run_status(ctx)["status"] == "failed":
            out.discard()
            return ctx, {}
        written = write_outputs(ctx, out.path, report=False)
        files = {k: out.published(v) for k, v in written.items()}
    return ctx, files
