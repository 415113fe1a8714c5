"""The stages a scene runs, and the run itself: scene -> results -> files.

Each stage is a short function ``stage(ctx)``: it checks what it needs, reads the typed
results of the stages before it from the run context (``ctx.load``, ``ctx.phasing``, ...),
calls the functions of the modules that hold the algorithms (:mod:`meshphase.run.stream`,
:mod:`meshphase.kinematics.passes`, :mod:`meshphase.kinematics.phasing`, :mod:`meshphase.kinematics.loads`,
:mod:`meshphase.compare.predict`, :mod:`meshphase.models`, ...) and returns ONE frozen dataclass of
:mod:`meshphase.run.results`, which the context records (:meth:`RunContext.record`).
:func:`run_scene` runs exactly the stages that :func:`meshphase.run.scene.plan` asks for, times
each one and keeps its error estimate ("error against run time"). Files are written by
:mod:`meshphase.run.outputs` (:func:`write_outputs`, :func:`summary_dict`, also importable from
here); the HTML report by :mod:`meshphase.report.validation` (the only place that plots).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..kinematics.angles import held_member
from ..io.bridge import bridge_recording
from ..io.sources import BridgeSource, generator
from ..io.channels import (GAUGE_KINDS, apply_channel_overrides, bridge_configs, channels_present,
                           check_gauges, entry_values, map_channels, mapped_specs, overridden,
                           unmapped_message)
from ..compare.predict import band_coverage, identify_errors, predict_pass_phasing, residual_stats
from ..kinematics.encoder import edge_timing_sigma
from ..errors import DataQualityWarning, MeshphaseWarning, ProcessingWarning, SceneWarning
from .exits import recording_read_errors, run_status
from ..kinematics.loads import facewidth_centroid, facewidth_readings, load_sharing_from_amplitudes
from ..runtime.log import logger
from ..kinematics.member_speeds import mean_mesh_rate, member_speeds, tacho_rate
from ..models.gearset import Speeds
from ..models.mesh_phasing import assembly_check, classify_phasing, ideal_phasing
from ..onsets import ONSET_RESOLUTION, detect_recording  # noqa: F401 (ONSET_RESOLUTION was here)
from ..onsets.results import Onsets, empty_onsets
from .outputs import new_output_dir, summary_dict, write_outputs  # noqa: F401 (public here)
from ..kinematics.passes import gap_intervals_of, gauge_passes
from ..kinematics.pass_rates import pass_rate_warnings, two_level_train, wiring_findings
from ..kinematics.phasing import (PassTable, assign_planets_by_pattern, measure_phasing, pass_order,
                                  relabel_gauge)
from ..recording import Recording, RecordingHeader
from .context import RunContext
from .declare import STAGE_REGISTRY
from .outdir import OutputDir, output_write_errors
from .results import (BearingStage, CentroidsStage, CompareStage, ConditionStage,
                      GaugeComparison, IdealStage, IdentifyStage, LoadSharingStage, LoadStage,
                      OnsetsStage, PhasingStage, StageResult, TiltStage,
                      ToleranceStage)
from .scene import STAGES, Scene, SceneError, load_scene, plan, read_options, with_recording
from .state import RunMessage, StageFailure, flagged_warning
from .stream import (BLOCK_SAMPLES, ChannelPlan, FileSource, GeneratorSource, MemorySource,
                     condition_stream, scan_source)
from ..runtime.lazy import load_all
from ..runtime.threads import blas_single_thread
from ..compare.truth import phasing_vs_truth, tacho_geometry, true_errors
from ..io.units import gauge_unit_gains
from ..validate import as_regular_file

if TYPE_CHECKING:  # the model modules of bearing, tilt and tolerance load in their stages:
    # `meshphase process` runs none of them (nor does a scene that does not ask for them)
    from ..models.tolerance import Tolerances

__all__ = ["RunContext", "run_scene", "STAGE_FUNCTIONS", "write_outputs", "process_recording", "run_to_folder",
           "new_output_dir"]


#: stage name -> its function, as :func:`runs` binds them (in definition order)
_BOUND: dict[str, Callable] = {}


def runs(name: str):
    """Bind the decorated function to the declared stage ``name``
    (:data:`meshphase.run.declare.STAGE_REGISTRY`); the function records what it returns in
    the run context (:meth:`RunContext.record`)."""
    if name not in STAGES:
        raise ValueError(f"no declared stage {name!r} (meshphase.run.declare.STAGE_REGISTRY)")
    if name in _BOUND:
        raise ValueError(f"stage {name!r} is bound to a function twice")

    def deco(fn):
        @functools.wraps(fn)
        def stage(ctx: RunContext):
            return ctx.record(name, fn(ctx))
        _BOUND[name] = stage
        return stage
    return deco


# ----------------------------------------------------------------------------- helpers
def _inputs(ctx: RunContext, *names: str) -> tuple:
    """The typed results of the stages ``names`` that a stage reads; a RuntimeError naming
    those that have not run (a stage called out of :func:`run_scene`'s order is a bug, not
    a failed stage)."""
    got = tuple(ctx.result(n) for n in names)
    missing = [n for n, r in zip(names, got) if r is None]
    if missing:
        raise RuntimeError(f"this stage reads the results of {', '.join(missing)}, which did not "
                           "run (run_scene runs the stages in meshphase.run.scene.plan's order)")
    return got


def _nominal_speeds(ctx: RunContext):
    """The scene's nominal speeds, else the recording's (synthetic files carry them)."""
    sp = ctx.scene.speeds
    if sp is None and ctx.load is not None:
        meta = ctx.load.recording.meta.get("speeds_nominal")
        if meta:
            sp = Speeds(**meta)
    return sp


def _mesh_freq(ctx: RunContext, gear: str) -> float | None:
    sp = ctx.scene.speeds
    g = ctx.gearset
    if sp is None or g is None:
        meta = ctx.load.recording if ctx.load is not None else None
        if meta is not None and "speeds_nominal" in meta.meta and g is not None:
            sp = Speeds(**meta.meta["speeds_nominal"])
        else:
            return None
    w = sp.w_sc if gear == "sun" else sp.w_rc
    z = g.z_sun if gear == "sun" else g.z_ring
    return abs(w) * z / (2 * math.pi) if w else None


def _main_gauge(rec: Recording, gear: str) -> str | None:
    c = [s.name for s in rec.channels if s.kind == gear]
    return c[0] if c else None


def _tacho_geometry(ctx: RunContext) -> tuple:
    """(key angle [rad] or None, mounts {channel: ground angle [rad]}): the scene's keys, else
    the recording's metadata, else (synthetic input) the generator's configuration."""
    key = ctx.scene.tacho.get("key_angle")
    mounts = dict(ctx.scene.mounts)
    rec = ctx.load.recording
    if ctx.scene.channels:   # entries by pattern: the channels they matched
        for k, v in entry_values(map_channels(rec.names, ctx.scene.channels),
                                 "mount_angle").items():
            mounts.setdefault(k, v)
    meta = rec.meta
    if key is None and meta.get("tacho_key_angle") is not None:
        key = float(meta["tacho_key_angle"])
    for k, v in (meta.get("mount_angles") or {}).items():
        mounts.setdefault(k, float(v))
    truth = ctx.load.truth
    if truth is not None and (key is None or not mounts):
        truth_key, truth_mounts = tacho_geometry(truth)
        if key is None:
            key = truth_key
        for k, v in truth_mounts.items():
            mounts.setdefault(k, v)
    return key, mounts


# ----------------------------------------------------------------------------- stages
#: channel kinds that are pulse trains (timed in the scan, never conditioned)
PULSE_KINDS = ("tacho", "encoder")
#: A synthetic recording up to this size [B] is generated whole, once; a longer one is
#: generated block by block again for each pass over its samples (bounded memory).
SYNTHETIC_WHOLE_BYTES = 256 * 2**20


@runs("load")
def stage_load(ctx: RunContext) -> LoadStage:
    """Open the recording and scan its raw samples in one read (the scan of
    :mod:`meshphase.run.stream`): the quality of every channel, the tacho's edges, the hum
    windows. A file is never held in memory: the condition stage streams it again. A synthetic recording up to
    :data:`SYNTHETIC_WHOLE_BYTES` is generated whole, once; a longer one is generated again,
    block by block, for every pass (the generator is deterministic)."""
    if ctx.scene.input.get("recording"):
        src, rec, source, truth = _open_file(ctx.scene)
    elif ctx.scene.input.get("memory") is not None:
        src, rec, source, truth = _open_memory(ctx.scene)
    else:
        src, rec, source, truth = _open_synthetic(ctx.scene)
    # said at once: a recording whose samples then fail to read still names them
    ctx.channels_unused = check_gauges(rec, plan(ctx.scene, check=False), ctx.scene.results,
                                       source)
    errors = true_errors(truth)
    scan = _scan(src)
    if hasattr(src, "warn_nonfinite"):
        src.warn_nonfinite(scan.results)
    h = src.header
    return LoadStage(recording=rec, source=source, quality=scan.quality, truth=truth,
                     true_errors=errors, stream=src, scan=scan,
                     channels_unused=tuple(ctx.channels_unused),
                     pulse_trains=_pulse_trains(h.channels, scan.hum_window),
                     error_estimate=(f"{h.n_samples * h.n_channels / 1e6:.2f} MSamples read "
                                     f"({_times(scan.n_reads)}, {scan.n_blocks} block(s) "
                                     f"{'each' if scan.n_reads > 1 else 'in all'})"))


def _times(k: int) -> str:
    return {1: "once", 2: "twice"}.get(k, f"{k} times")


def _open_file(scene: Scene) -> tuple:
    """(source, header, name, None) of the scene's recording file, with its channel
    mapping (and bridge channels in strain); a FIFO or device is refused before opening it
    could block."""
    inp = scene.input
    path = as_regular_file(inp["recording"], "the recording")   # stat only
    source = str(inp["recording"])
    start, stop = inp.get("start"), inp.get("stop")
    with recording_read_errors(path):
        opts = read_options(scene) or None
        src = FileSource(path, start=start, stop=stop, options=opts)
        fmt = src.fmt
        src = _mapped_source(
            src.header, scene.channels, source,
            lambda specs, gains: FileSource(path, start=start, stop=stop, channels=specs,
                                            gains=gains, format=fmt, options=opts),
            lambda specs, gains: FileSource(path, channels=specs, gains=gains, format=fmt,
                                            options=opts)) or src
    return src, src.header, source, None


#: What a Recording given in memory is called in the run's messages and load result.
MEMORY_NAME = "<Recording in memory>"


def _open_memory(scene: Scene) -> tuple:
    """(source, header, name, None) of the Recording the scene's ``input["memory"]`` holds
    (:func:`meshphase.process`), read as a file is: the same channel mapping, unit gains,
    bridge conversion and NaN/inf warnings, named :data:`MEMORY_NAME`."""
    rec = scene.input["memory"]
    if not isinstance(rec, Recording):
        raise TypeError(f"input memory must be a Recording, got {type(rec).__name__}")

    def make(specs, gains):
        return MemorySource(rec, specs, gains, label=MEMORY_NAME, nonfinite_warnings=True)

    src = _mapped_source(RecordingHeader.of(rec), scene.channels, MEMORY_NAME, make, make) \
        or make(None, None)
    return src, src.header, MEMORY_NAME, None


def _mapped_source(header, entries: list, source: str, make: Callable, make_whole: Callable):
    """The source with the scene's ``[[channels]]`` applied (:mod:`meshphase.io.channels`) and
    the gauges' units converted to m/m as read (:func:`meshphase.io.units.gauge_unit_gains`, a
    ``units_to_si`` history step): ``make(specs, gains)`` opens it; unmapped channels said as
    a SceneWarning; bridge channels converted to strain as read
    (:class:`meshphase.io.sources.BridgeSource`, the null windows read from
    ``make_whole(specs, gains)``, the whole recording). None when there is nothing to apply
    (no entries, every gauge in m/m)."""
    cmap = bridges = None
    if entries:
        cmap = map_channels(header.names, entries, source, channels_present(header))
        specs, gains = mapped_specs(header.channels, cmap)
        bridges = bridge_configs(cmap)
    else:
        specs, gains = list(header.channels), []
    specs, unit_gains, converted = gauge_unit_gains(specs, bridges, source,
                                                    _bridge_units(header, cmap, bridges))
    if cmap is None and not converted:
        return None
    gains = gains + unit_gains
    src = make(specs, gains)
    if cmap is not None:
        src.header = src.header.with_history("channel_overrides", channels=overridden(cmap))
        _say_unmapped(cmap, specs, source)
    if converted:
        src.header = src.header.with_history("units_to_si", channels=converted)
    if bridges:
        src = BridgeSource(src, bridges, make_whole(specs, gains))
    return src


def _bridge_units(header, cmap, bridges) -> dict:
    """{bridge channel: its unit as the scene's entry (``units``) or else the file gives it}."""
    given = {c.name: c.units for c in header.channels}
    return {n: cmap.entries[cmap.match_of(n).entry].get("units", given[n]) for n in bridges or ()}


def _say_unmapped(cmap, specs, source: str) -> None:
    msg = unmapped_message(cmap, specs)
    if msg:
        warnings.warn(f"{source}: {msg}", SceneWarning, stacklevel=3)


def _open_synthetic(scene: Scene) -> tuple:
    """(source, header, name, truth) of the scene's synthetic recording: generated whole up
    to :data:`SYNTHETIC_WHOLE_BYTES`, else again block by block for every pass."""
    inp, entries = scene.input, scene.channels
    minutes = inp.get("minutes")
    gen = generator("synthetic")
    if gen is None:
        raise ValueError(f"synthetic scenario {inp['synthetic']!r}: no generator 'synthetic' is "
                         "installed (the meshphase.sources entry point of meshphase.synthetic)")
    # a config built in code (benchmarks, tests) wins over the registered scenario's
    stream = gen.stream(inp.get("config") or inp["synthetic"],
                        duration=None if minutes is None else 60.0 * minutes,
                        seed=inp.get("seed", 0))
    source = f"synthetic:{inp['synthetic']}"
    size = stream.n_samples * len(stream.channels) * stream.dtype.itemsize
    if size <= SYNTHETIC_WHOLE_BYTES:
        whole = stream.collect()
        rec = apply_channel_overrides(whole, entries, source)
        cmap = map_channels(stream.names, entries, source) if entries else None
        if cmap is not None:
            _say_unmapped(cmap, rec.channels, source)
        bridges = bridge_configs(cmap) if cmap is not None else {}
        specs, gains, converted = gauge_unit_gains(rec.channels, bridges, source,
                                                   _bridge_units(whole, cmap, bridges))
        if converted:
            factors = np.ones(rec.n_channels, dtype=rec.data.dtype)
            for j, g in gains:
                factors[j] *= g
            rec = Recording(rec.data * factors, rec.fs, specs, rec.t0, rec.start_datetime,
                            rec.meta, rec.history).with_history("units_to_si", channels=converted)
        if bridges:
            rec = bridge_recording(rec, bridges)
        return MemorySource(rec), rec, source, stream.truth
    stream.block_samples = BLOCK_SAMPLES       # the blocks the file path reads
    src = _mapped_source(stream, entries, source,
                         lambda specs, gains: GeneratorSource(stream, channels=specs, gains=gains),
                         lambda specs, gains: GeneratorSource(stream, channels=specs, gains=gains)
                         ) or GeneratorSource(stream)
    return src, src.header, source, stream.truth


def _scan(src):
    """The scan of ``src`` (one read): every channel but the pulse trains (tacho, encoders) may
    be conditioned, the first tacho and every encoder are timed."""
    h = src.header
    tacho = [c.name for c in h.channels if c.kind == "tacho"]
    return scan_source(src, conditioned=[c.name for c in h.channels if c.kind not in PULSE_KINDS],
                       tacho=tacho[0] if tacho else None,
                       encoders=[c.name for c in h.channels if c.kind == "encoder"])


def _load_stream(ctx: RunContext):
    """(source, scan) of the loaded recording; a load result that holds only a Recording (a
    test feeding one) is scanned here."""
    load, = _inputs(ctx, "load")
    if load.stream is None:
        src = MemorySource(load.recording)
        return src, _scan(src)
    return load.stream, load.scan


#: Largest raw sample magnitude a gauge's onsets are detected from: beyond it the squares of
#: its samples (pulse energies, template fits) overflow float64 (max 1.8e308). No strain gauge
#: reads this; a wrong gain or scaling does.
MAX_GAUGE_ABS = 1e150


def _overflowing_gauges(ctx: RunContext) -> dict:
    """Gauge channel -> its largest finite |sample| (raw quality of the load stage), for the
    gauges above :data:`MAX_GAUGE_ABS`."""
    if ctx.load is None:
        return {}
    kinds = {c.name: c.kind for c in ctx.load.recording.channels}
    out = {}
    for q in ctx.load.quality or ():
        name = q.get("channel")
        big = max(abs(float(q.get("min", float("nan")))), abs(float(q.get("max", float("nan")))))
        if kinds.get(name) in GAUGE_KINDS and big > MAX_GAUGE_ABS:
            out[name] = big
    return out


@runs("condition")
def stage_condition(ctx: RunContext) -> ConditionStage:
    """Condition every non-tacho channel and time the gauges' pulses, in one streamed pass
    (the last read of :mod:`meshphase.run.stream`): the conditioned samples are not kept, only the
    quality reports, the onsets (handed to the onsets stage) and a short excerpt. A gauge
    with samples beyond :data:`MAX_GAUGE_ABS` gives no onsets (a DataQualityWarning says
    so)."""
    src, scan = _load_stream(ctx)
    too_big = _overflowing_gauges(ctx)
    for name, big in too_big.items():
        warnings.warn(f"channel {name!r}: samples up to {big:.3g}, beyond {MAX_GAUGE_ABS:g}: their "
                      "squares overflow float64, no onsets are detected from it (a wrong gain or "
                      "unit scaling?)", DataQualityWarning, stacklevel=3)
    res = condition_stream(src, scan, _channel_plans(ctx, src.header))
    if too_big and res.onsets is not None:
        h = src.header
        # empty onsets with the detector's default reference point (Onsets' defaults)
        found = {**res.onsets, **{n: empty_onsets(h.fs, h.t0, n, Onsets.reference, Onsets.level)
                                  for n in too_big}}
        res = dataclasses.replace(res, onsets={c.name: found[c.name] for c in h.channels
                                               if c.name in found})
    snr = {k: getattr(q, "snr_db", None) for k, q in res.quality.items()}
    est = "SNR " + ", ".join(f"{k} {v:.1f} dB" for k, v in snr.items()
                             if isinstance(v, (int, float)) and math.isfinite(v))
    return ConditionStage(recording=res.recording, quality=res.quality, excerpt=res.excerpt,
                          onsets=res.onsets, onset_warnings=res.warnings, timings=res.timings,
                          memory=res.memory, scan=scan,
                          error_estimate=(est + f"; streamed in {res.n_blocks} block(s), onset "
                                          f"detection {res.timings.get('onsets_s', 0.0):.2f} s of it"))


def _channel_plans(ctx: RunContext, rec) -> list:
    """What the last read does to each non-tacho channel: each gear's gauges with their own mesh
    frequency (drift window, low-pass corner) and pulse period (one relative revolution of
    the gauged gear, Z mesh periods, in which every planet passes once); onsets for the
    gauges."""
    g = ctx.gearset
    plans = []
    too_big = _overflowing_gauges(ctx)
    for c in rec.channels:
        if c.kind in PULSE_KINDS:
            continue
        gear = c.gear if c.gear in ("sun", "ring") else (c.kind if c.kind in ("sun", "ring") else None)
        fm = _mesh_freq(ctx, gear) if gear else None
        period = None
        if fm and g is not None:
            period = (g.z_sun if gear == "sun" else g.z_ring) / fm
        onsets = c.kind in GAUGE_KINDS and c.name not in too_big
        kw = {}
        if onsets:
            og = c.gear or c.kind
            ofm = _mesh_freq(ctx, og) if og in ("sun", "ring") else None
            kw = {"mesh_freq": ofm} if ofm else {}
        plans.append(ChannelPlan(c.name, mesh_freq=fm, pulse_period=period, group=str(gear),
                                 onsets=onsets, onset_kwargs=kw, detector=ctx.scene.onset_detector))
    return plans


@runs("onsets")
def stage_onsets(ctx: RunContext) -> OnsetsStage:
    """The gauges' onsets: found in the condition stage's pass (its warnings are issued
    here), or detected now from a condition result that kept the samples."""
    cond, = _inputs(ctx, "condition")
    rec = cond.recording
    _warn_aliased(ctx, rec.fs)
    for category, message in cond.onset_warnings:
        warnings.warn(message, category, stacklevel=2)
    found = cond.onsets
    if found is None:                           # a condition stage that kept the samples
        found = {}
        for c in rec.channels:
            if c.kind in GAUGE_KINDS:
                gear = c.gear or c.kind
                fm = _mesh_freq(ctx, gear) if gear in ("sun", "ring") else None
                found[c.name] = detect_recording(rec, c.name, detector=ctx.scene.onset_detector,
                                                 quality=cond.quality.get(c.name),
                                                 **({"mesh_freq": fm} if fm else {}))
    out = {c.name: found[c.name] for c in rec.channels if c.kind in GAUGE_KINDS and c.name in found}
    scan = cond.scan if cond.scan is not None else ctx.load.scan
    n = sum(len(o) for o in out.values())
    jit = [float(np.median(o.corr)) for o in out.values() if len(o) and np.isfinite(o.corr).any()]
    # a gauge whose pulses were found upside down (the compressive fillet, or a bridge wired
    # the other way round) is said to be: the amplitudes in its tables are negative
    neg = [nm for nm, o in out.items() if len(o) and o.polarity < 0]
    note = f"{n} onsets" + (f"; median template correlation {np.median(jit):.4f}" if jit else "")
    if neg:
        note += f"; negative (compressive) pulses on {', '.join(neg)}"
    return OnsetsStage(by_channel=out, tacho_times=None if scan is None else scan.tacho_times,
                       encoder_times={} if scan is None else dict(scan.encoder_times),
                       error_estimate=note)


def _warn_aliased(ctx: RunContext, fs: float) -> None:
    """A DataQualityWarning for a gear whose mesh frequency comes near Nyquist."""
    for gear in ("sun", "ring"):
        fm = _mesh_freq(ctx, gear)
        if fm and fm >= 0.35 * fs:
            what = ("pulses are aliased and onset times are not reliable" if fm >= 0.45 * fs
                    else "fewer than 3 samples per mesh period: expect onset bias of several "
                         "1e-3 mesh cycles")
            warnings.warn(f"{gear} gauge: mesh frequency {fm:.4g} Hz is {fm / fs:.2f} fs: {what}",
                          DataQualityWarning, stacklevel=3)


@runs("phasing")
def stage_phasing(ctx: RunContext) -> PhasingStage:
    """Measured phasing of every gauged gear (:func:`meshphase.kinematics.phasing.measure_phasing`) from
    the gauges' usable passes (:func:`meshphase.kinematics.passes.gauge_passes`)."""
    _inputs(ctx, "load")
    cond, ons = _inputs(ctx, "condition", "onsets")
    g = ctx.gearset
    rec = cond.recording
    passes, mains = gauge_passes(rec.channels, ons.by_channel, cond.quality, rec.fs, rec.t0,
                                 excerpt=cond.excerpt)
    sp = _nominal_speeds(ctx)
    # channels swapped or mis-kinded, speeds typed far off: the pass rates say so up front
    for msg in pass_rate_warnings(passes, g, sp):
        warnings.warn(msg, ProcessingWarning, stacklevel=2)
    # which member is held: the scene's word, else the typed speeds within their precision,
    # and the tacho's count of mesh cycles per carrier turn when there is a tacho
    res_typed = ctx.scene.speeds_resolution if ctx.scene.speeds is not None else None
    stated = ctx.scene.fixed
    if stated is not None:
        fixed, why = (None if stated == "none" else stated), "stated in the scene ([speeds] fixed)"
    else:
        fixed, why = held_member(g.z_sun, g.z_ring, sp, resolution=res_typed)
    key, mounts = _tacho_geometry(ctx)
    res = measure_phasing(passes, g, fixed=fixed, fixed_reason=why, tacho_times=ons.tacho_times,
                          key_angle=key, mounts=mounts, speeds=sp, label_shifts=ctx.scene.labels,
                          gaps=gap_intervals_of(cond.quality), check_held=stated is None,
                          speeds_resolution=res_typed,
                          encoders=_encoder_inputs(rec, ons.encoder_times))
    for gear in mains:
        # a main gauge without a measurable pass gives an empty table, not a missing one
        res.tables.setdefault(gear, PassTable.empty(gear, ["no usable pass"]))
    for t in res.tables.values():
        t.time_origin = float(rec.t0)
    # a gauge wired or mapped as the wrong kind: named as its gear's unreliable cause
    _wiring_unreliable(res, wiring_findings(passes, g, sp, ons.tacho_times,
                                            getattr(ctx.load, "pulse_trains", None)))
    _warn_phasing(res)
    return PhasingStage(tables=res.tables, labels=dict(res.labels), model=res.model,
                        reliability=res.reliability, fixed=res.fixed,
                        fixed_reason=res.fixed_reason, labels_relative=res.labels_relative,
                        notes=res.notes, result=res, error_estimate=_phasing_estimate(res),
                        member_speeds=_member_speeds(res, g, sp, ons.tacho_times))


def _member_speeds(res, g, sp, tacho_times) -> dict | None:
    """Every member's measured speed (:func:`meshphase.kinematics.member_speeds.member_speeds`) from the
    angle model's mean mesh frequency; None without a model or a mesh frequency."""
    if res.model is None:
        return None
    rate = mean_mesh_rate(res.model)
    if not (math.isfinite(rate) and rate > 0):
        return None
    carrier = float("nan")
    if res.fixed is None and tacho_times is not None:   # a differential: the tacho's count
        try:
            carrier = tacho_rate(tacho_times)
        except ValueError:      # edges out of order: the nominal ratio gives the carrier
            pass
    return member_speeds(g, rate, fixed=res.fixed, speeds=sp, carrier_rate=carrier)


def _pulse_trains(channels, hum: dict) -> dict:
    """{gauge channel: (gear, low, high)} of the gauges whose raw samples (``hum``: the scan's
    first ``HUM_SECONDS`` of each conditioned channel) are a two-level pulse train
    (:func:`meshphase.kinematics.pass_rates.two_level_train`)."""
    out = {}
    for c in channels:
        if c.kind in GAUGE_KINDS and c.name in hum:
            lv = two_level_train(hum[c.name])
            if lv is not None:
                out[c.name] = (c.gear if c.gear in ("sun", "ring") else c.kind, *lv)
    return out


def _wiring_unreliable(res, findings: dict) -> None:
    """A gear whose gauge channels look wired or mapped as the wrong kind
    (:func:`meshphase.kinematics.pass_rates.wiring_findings`) has its phasing flagged unreliable, the
    findings first among the reasons (the run's status names the channel and the fix)."""
    for gear, msgs in findings.items():
        rel = res.reliability.setdefault(gear, {"reliable": True, "reasons": []})
        rel["reliable"] = False
        rel["reasons"] = list(msgs) + [r for r in rel.get("reasons", []) if r not in msgs]


def _encoder_inputs(rec, times: dict) -> list:
    """(name, shaft, pulses per revolution, edge times [s], edge sigma [s]) of every timed
    encoder channel; one without its shaft or pulses per revolution is left out with a
    ProcessingWarning naming it."""
    out = []
    for c in rec.channels:
        if c.kind != "encoder" or c.name not in times:
            continue
        if c.shaft is None or c.pulses_per_rev is None:
            missing = [k for k in ("shaft", "pulses_per_rev") if getattr(c, k) is None]
            warnings.warn(f"encoder channel {c.name!r}: no {' and no '.join(missing)} (give them "
                          "in its [[channels]] entry); it is not used", ProcessingWarning,
                          stacklevel=3)
            continue
        out.append((c.name, c.shaft, c.pulses_per_rev, times[c.name], edge_timing_sigma(rec.fs)))
    return out


def _warn_phasing(res) -> None:
    """ProcessingWarnings for pulses no planet fits, for planet labels in doubt and for
    phasing that is not reliable."""
    for gear, lab in res.labels.items():
        if lab.n_unassigned:
            warnings.warn(f"{gear} gauge: {lab.n_unassigned} pulse(s) fit no planet in the pass "
                          "pattern (missing pulses, speed change or spurious detections); they "
                          "are left out", ProcessingWarning, stacklevel=3)
        if lab.caution:
            warnings.warn(f"{gear} gauge: planet labels in doubt: {lab.caution}",
                          ProcessingWarning, stacklevel=3)
    for gear, rel in res.reliability.items():
        if not rel["reliable"]:
            warnings.warn(flagged_warning(ProcessingWarning, f"{gear} gauge: phasing not reliable: "
                                          + "; ".join(rel["reasons"]), gauge=gear, unreliable=True),
                          stacklevel=3)


def _phasing_estimate(res) -> str:
    est = []
    for gear, t in res.tables.items():
        rel = res.reliability.get(gear, {})
        if len(t):
            est.append(f"{gear}: per-pass sigma {rel.get('error_estimate', float('nan')):.2e} "
                       f"cycles (timing floor {rel.get('floor', float('nan')):.2e})")
    if res.model is not None:
        est.append(f"angle model: {res.model.terms}, rank {res.model.rank}/{res.model.n_parameters}")
    est.extend(n.split(" (", 1)[0] + ":" + n.rsplit(":", 1)[-1] for n in res.notes
               if n.startswith("encoder ") and " edges, " in n)
    return "; ".join(est)


@runs("load_sharing")
def stage_load_sharing(ctx: RunContext) -> LoadSharingStage:
    """Planet load sharing from the ring gauge's pulse amplitudes, labelled by the phasing
    (else by the pass pattern of its clean onsets)."""
    cond, ons = _inputs(ctx, "condition", "onsets")
    g = ctx.gearset
    lab = ctx.phasing.labels.get("ring") if ctx.phasing is not None else None
    if lab is not None:
        ch, times, pl, amp = lab.channel, lab.times, lab.planet, lab.amplitude
    else:
        ch = _main_gauge(cond.recording, "ring")
        if ch is None:
            return LoadSharingStage(sharing=None, error_estimate="no ring gauge: skipped")
        on = ons.by_channel[ch]
        times, amp = on.times[on.good], on.amplitude[on.good]
        pl, _ = assign_planets_by_pattern(times, g.angles, pass_order(g.direction, "ring"))
    res = load_sharing_from_amplitudes(np.abs(amp), np.where(pl >= 0, pl + 1, 0), g.n_planets)
    se = res.std_error[np.isfinite(res.std_error)]
    return LoadSharingStage(sharing=res, channel=ch, error_estimate=(
        f"max std error {se.max():.2e}" if se.size else
        "no standard error (fewer than two passes per planet)"))


@runs("centroids")
def stage_centroids(ctx: RunContext) -> CentroidsStage:
    """Face-width load centroid of each gear with two or more positioned face-width gauges
    (:func:`meshphase.kinematics.loads.facewidth_readings`, :func:`meshphase.kinematics.loads.facewidth_centroid`)."""
    cond, onsets = _inputs(ctx, "condition", "onsets")
    rec, ons = cond.recording, onsets.by_channel
    g = ctx.gearset
    fw = [c for c in rec.channels if c.kind == "facewidth"]
    if not fw:
        return CentroidsStage(by_gear={}, error_estimate="no face-width gauges: nothing to do")
    b = g.face_width if g is not None and g.face_width else None
    out = {}
    for gear in sorted({c.gear or "sun" for c in fw}):
        chans = [c for c in fw if (c.gear or "sun") == gear and c.face_position is not None]
        if len(chans) < 2 or b is None:
            out[gear] = None
            continue
        on = [ons[c.name] for c in chans]
        readings = facewidth_readings([o.times for o in on], [o.amplitude for o in on],
                                      [o.good for o in on], [o.width for o in on], rec.fs)
        if readings.shape[0] == 0:
            warnings.warn(f"{gear} face-width gauges: no pass seen on any of them; no centroid",
                          ProcessingWarning, stacklevel=2)
        out[gear] = facewidth_centroid(readings, np.array([c.face_position for c in chans]), b)
    return CentroidsStage(by_gear=out, error_estimate="; ".join(
        f"{k}: Z = {v.centroid * 1e3:.3f} ± {v.std_error * 1e3:.3f} mm" for k, v in out.items() if v))


@runs("ideal")
def stage_ideal(ctx: RunContext) -> IdealStage:
    """The gearset's ideal phasing and its class (Parker & Lin 2004)."""
    g = ctx.gearset
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        cls = classify_phasing(g)
    gs, gr = ideal_phasing(g)
    return IdealStage(gamma_s=gs, gamma_r=gr, classification=cls, assembly=assembly_check(g),
                      error_estimate="exact (closed form)")


def _tolerances(ctx: RunContext, tolerance) -> "Tolerances":
    """The scene's tolerance bands as :class:`meshphase.models.tolerance.Tolerances`
    (``tolerance``: that module, loaded by the stage)."""
    ToleranceBand = tolerance.ToleranceBand
    t = ctx.scene.tolerances
    kw = {}
    for gear in ("sun", "ring", "planet"):
        kw[f"e_{gear}"] = ToleranceBand(mean=t[f"mean_e_{gear}"], band=t[f"e_{gear}"])
        k = t[f"kappa_{gear}"]
        kw[f"kappa_{gear}"] = (ToleranceBand.full_circle() if k == "uniform" else
                               ToleranceBand(mean=k, band=0.0))
    return tolerance.Tolerances(**kw)


@runs("tolerance")
def stage_tolerance(ctx: RunContext) -> ToleranceStage:
    """Monte Carlo phasing statistics under the scene's tolerances."""
    # scipy.special and numba's kernels behind it: loaded only by a scene that asks for the Monte Carlo
    from ..models import tolerance

    g = ctx.gearset
    t = ctx.scene.tolerances
    sp = ctx.scene.speeds
    window = (tolerance.observation_window(sp) if t.get("window") is None
              else (0.0, float(t["window"])))
    res = tolerance.monte_carlo(g, sp, _tolerances(ctx, tolerance), window, t["samples"], sampler=t["sampler"],
                      rng=t.get("seed", 0))
    se = float(np.max(res.dev_s.se_bound3)) if res.dev_s.se_bound3.size else float("nan")
    return ToleranceStage(monte_carlo=res, error_estimate=(
        f"{res.n_samples} {res.sampler} samples; std error of the 3-sigma Dev_sn bound "
        f"{se:.1e} cycles"))


@runs("identify")
def stage_identify(ctx: RunContext) -> IdentifyStage:
    """Shaft hole errors from the measured phasing (:func:`meshphase.compare.predict.identify_errors`).

    A gauge whose planet numbering is only relative is tried in every cyclic relabelling: the
    error model ties the gauges' numberings together (a planet's offset moves its mean
    phasing on both), and a relabelling is kept only where it halves the joint residual; the
    relabelled phasing then supersedes the phasing stage's."""
    ph, = _inputs(ctx, "phasing")
    g = ctx.gearset
    tables = {k: t for k, t in ph.tables.items() if len(t)}
    ident = identify_errors(list(tables.values()), g)
    relative = [gear for gear in ph.labels_relative if gear in tables]
    res = ph.result
    if res is None or res.model is None or len(tables) < 2 or not relative:
        return _identified(ident)
    gear = relative[0]
    best = (ident.rms_after, 0, ident, None, None)
    for shift in range(1, g.n_planets):
        tab, lab = relabel_gauge(res, gear, shift, g)
        if not len(tab):
            continue
        cand = identify_errors([tab if k == gear else t for k, t in tables.items()], g,
                               suggest=False)
        if cand.rms_after < best[0]:
            best = (cand.rms_after, shift, cand, tab, lab)
    if not (best[1] and best[0] <= 0.5 * ident.rms_after):
        return _identified(ident)
    _, shift, ident, tab, lab = best
    # the kept relabelling, now with what would identify its blind offsets
    ident = identify_errors([tab if k == gear else t for k, t in tables.items()], g)
    ident.notes.append(f"{gear} gauge relabelled by {shift} place(s): the error model "
                       "fits both gauges only with the planets numbered alike")
    lab = dataclasses.replace(lab, decided_by="identification")
    return _identified(ident, relabelled=((gear, shift),), phasing=ph.relabelled(gear, tab, lab))


def _identified(ident, **kw) -> IdentifyStage:
    return IdentifyStage(identification=ident, error_estimate=(
        f"residual RMS {ident.rms_before:.2e} -> {ident.rms_after:.2e} cycles over "
        f"{ident.n_passes} passes"), **kw)


@runs("compare")
def stage_compare(ctx: RunContext) -> CompareStage:
    """Each gauge's measured phasing against the ideal, the identified model, the Monte
    Carlo band and (synthetic input) the truth."""
    ph, ideal_stage = _inputs(ctx, "phasing", "ideal")
    g = ctx.gearset
    errors = ctx.identify.identification.errors if ctx.identify is not None else None
    out = {}
    for gear, tab in sorted(ph.tables.items(), key=lambda kv: kv[0] != "sun"):
        if not len(tab):
            continue
        ideal = predict_pass_phasing(tab, g, None)
        model = predict_pass_phasing(tab, g, errors) if ctx.identify is not None else None
        row = GaugeComparison(
            ideal=ideal, model=model, vs_ideal=residual_stats(tab.gamma, ideal, tab.planet),
            vs_model=residual_stats(tab.gamma, model, tab.planet) if model is not None else None)
        if ctx.tolerance is not None:
            lo, hi = ctx.tolerance.band(gear)
            row = row.with_band(lo, hi, band_coverage(tab.gamma, tab.planet,
                                                      ideal_stage.gamma(gear), lo, hi))
        out[gear] = row
    truth = ctx.load.truth if ctx.load is not None else None
    if truth is not None:
        for gear in ("sun", "ring"):
            if gear in out:
                out[gear] = dataclasses.replace(
                    out[gear], scored_against_truth=True,
                    vs_truth=phasing_vs_truth(ph.tables[gear], ph.labels.get(gear), truth))
    parts = []
    for gear, r in out.items():
        s = r.vs_model or r.vs_ideal
        parts.append(f"{gear}: RMS vs model {s['rms']:.2e}")
        if r.vs_truth:
            parts.append(f"{gear}: RMS vs truth {r.vs_truth['rms']:.2e}")
    return CompareStage(by_gear=out, error_estimate="; ".join(parts))


def _bearing_case(ctx: RunContext) -> tuple:
    """(seed 001 case, input torque [N·m]) of the scene's [bearing] table."""
    # the bearing and tilt models load only for a scene that asks for them
    from ..models import bearing

    b = ctx.scene.bearing
    case = bearing.seed_case(b["case"])
    return case, (b["input_torque"] if b.get("input_torque") is not None else case.input_torque)


@runs("bearing_moments")
def stage_bearing_moments(ctx: RunContext) -> BearingStage:
    """Bearing moments of the scene's seed 001 case: concentrated, with the scene's centroid
    offsets and (single pinion) with the measured centroids."""
    from ..models import bearing

    b = ctx.scene.bearing
    case, torque = _bearing_case(ctx)
    est = "closed form (seed 001 tables reproduced to print precision)"
    geom = case.geometry
    if not isinstance(geom, bearing.SinglePinion):
        return BearingStage(case=case, torque=torque, error_estimate=est,
                            concentrated=bearing.double_pinion_moments(geom, torque))
    concentrated = bearing.single_pinion_moments(geom, torque)
    with_offsets = bearing.single_pinion_moments(geom, torque, b["z_s"], b["z_r"])
    cen = ctx.centroids.by_gear if ctx.centroids is not None else {}
    measured = None
    if cen.get("sun") is not None and cen.get("ring") is not None:
        measured = bearing.single_pinion_moments(geom, torque, cen["sun"].centroid,
                                                 cen["ring"].centroid)
    return BearingStage(case=case, torque=torque, concentrated=concentrated,
                        with_offsets=with_offsets, measured=measured, error_estimate=est)


@runs("tilt")
def stage_tilt(ctx: RunContext) -> TiltStage:
    """The coupled tilt / load-distribution solve at each of the scene's tilt stiffnesses."""
    # the bearing and tilt models load only for a scene that asks for them
    from ..models.tilt import solve_tilt

    b = ctx.scene.bearing
    case, torque = _bearing_case(ctx)
    sols = [(k, solve_tilt(case.geometry, torque, k_tilt_Nm_per_rad=k, c_g=b["c_g"])) for k in b["k_tilt"]]
    res = max(float(np.max(s.residual)) for _, s in sols)
    its = max(int(np.max(s.iterations)) for _, s in sols)
    return TiltStage(case=case, torque=torque, solutions=sols,
                     error_estimate=f"max residual {res:.1e} m, <= {its} iterations")


_UNBOUND = [s.name for s in STAGE_REGISTRY if s.name not in _BOUND]
if _UNBOUND:
    raise ImportError(f"declared stages without a function (@runs): {', '.join(_UNBOUND)}")

#: stage name -> the function that runs it (and records its result in the run context), in
#: the registry's order
STAGE_FUNCTIONS: dict[str, Callable[[RunContext], StageResult]] = {
    s.name: _BOUND[s.name] for s in STAGE_REGISTRY}

#: what a stage raises for bad input or data (SceneError and RecordingFileError are
#: ValueErrors): recorded in ``ctx.failed``; anything else (a KeyError, an AttributeError)
#: is a bug and propagates
STAGE_ERRORS = (ValueError, TypeError, OSError)


def run_scene(scene: Scene, *, progress: Callable[[str, int, int], None] | None = None) -> RunContext:
    """Run the stages the scene's results need, in dependency order.

    A stage that raises one of :data:`STAGE_ERRORS` (bad input or data: ValueError, among
    them SceneError and RecordingFileError, TypeError, OSError) is recorded in
    ``ctx.failed`` (a :class:`meshphase.run.state.StageFailure`) and the stages that depend on
    it are skipped (with the stages that blocked them); the others
    still run, so a run always returns what it could compute. Any other exception (a KeyError
    or AttributeError is a bug, not a failed stage) propagates. Our warnings
    (:class:`~meshphase.errors.MeshphaseWarning` and subclasses) are collected into
    ``ctx.messages`` (:class:`meshphase.run.state.RunMessage`, "stage: Category: message")
    and not issued again (the CLI prints
    them, the report lists them); other warnings are collected and re-issued.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene (meshphase.run.scene.load_scene), got {type(scene).__name__}")
    ctx = RunContext(scene)
    stages = plan(scene)
    # the stages' scipy modules (their BLAS among them) load before BLAS is held to one thread
    load_all()
    with blas_single_thread():          # meshphase.runtime.threads: tall, narrow least squares
        _run_stages(ctx, stages, progress)
    if progress:
        progress("done", len(stages), len(stages))
    return ctx


def _run_stages(ctx: RunContext, stages: list, progress) -> None:
    """:func:`run_scene`'s loop over the planned stages."""
    for i, name in enumerate(stages):
        blocked = [d for d in STAGES[name] if d in ctx.failed or (d not in ctx.ran)]
        if blocked:
            ctx.fail(StageFailure.blocked(name, blocked))
            continue
        if name == "centroids" and ctx.load is not None and not any(
                c.kind == "facewidth" for c in ctx.load.recording.channels):
            # only what the scene needs: no face-width gauges, no centroid work
            ctx.fail(StageFailure.not_applicable(name, "the recording has no face-width gauges"))
            continue
        if progress:
            progress(name, i, len(stages))
        t = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeshphaseWarning)
            try:
                STAGE_FUNCTIONS[name](ctx)
                ctx.ran.append(name)
            except STAGE_ERRORS as exc:
                ctx.fail(StageFailure.raised(name, exc))
                # the caller reports ctx.failed (the CLI: one line per cause); the traceback
                # is for developers (meshphase --debug)
                logger.info("stage %s failed: %s", name, exc)
                logger.debug("stage %s traceback", name, exc_info=True)
        ctx.timings[name] = time.perf_counter() - t
        _collect_warnings(ctx, name, caught)


def _collect_warnings(ctx: RunContext, stage: str, caught) -> None:
    """Our warnings into ``ctx.messages`` once each (typed:
    :class:`meshphase.run.state.RunMessage`); others issued again."""
    for w in caught:
        msg = RunMessage.of_warning(stage, w.message, w.category)
        if msg not in ctx.messages:
            ctx.messages.append(msg)
        if not issubclass(w.category, MeshphaseWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


#: what ``meshphase process`` computes (compare pulls in ideal and identify)
PROCESS_RESULTS = ("phasing", "load_sharing", "compare")


def process_recording(path, gearset_scene_path, *, out_dir=None, overwrite=False,
                      progress: Callable[[str, int, int], None] | None = None,
                      tolerance: bool = False, options: dict | None = None) -> tuple:
    """``meshphase process FILE --gearset GEARSET.toml``: the recording-processing results
    (phasing, load sharing, comparison with the ideal and identified model; face-width
    centroids too when the gearset file's ``results`` name them).

    The gearset file's other results (bearing moments, tilt, tolerance) are not computed:
    ``meshphase run`` a scene for those. No Monte Carlo runs unless ``tolerance`` (the band
    coverage of the comparison then comes with it), even when the file has ``[tolerances]``.

    The output folder is reserved before the run (an unwritable location fails at once) and
    removed again when the run raises or is interrupted; when the recording cannot be loaded
    (nothing usable) nothing is written and ``files`` is empty: see
    :func:`meshphase.run.exits.run_status` for the status of the run.

    Parameters
    ----------
    path : str or Path
        The recording.
    gearset_scene_path : str, Path or Scene
        A scene file with ``[gearset]``, ``[speeds]``, ``[[channels]]`` ... (its reading keys
        ``[input.mcap]``, ``[input.csv]``, ``fs_Hz`` read the recording), or such a Scene.
    out_dir : str or Path, optional
        Output folder (default: ``STEM-meshphase`` in the current directory; an existing
        folder gets ``-2``, ``-3``, ... unless ``overwrite``).
    overwrite : bool
        Replace the output folder (atomically, when the run finishes).
    progress : callable, optional
        ``progress(stage, i, n)``.
    tolerance : bool
        Also run the tolerance Monte Carlo (needs ``[tolerances]`` in the gearset file).
    options : dict, optional
        Format options of the recording's reads (``topics``, ``fs``, ``header_row`` ...),
        over the scene's tables (:func:`meshphase.run.scene.with_recording`).

    Returns
    -------
    (RunContext, dict)
        The run and the files written (name -> path).
    """
    path = as_regular_file(path, "the recording")  # stat only: a FIFO never blocks here
    scene = (gearset_scene_path if isinstance(gearset_scene_path, Scene)
             else load_scene(gearset_scene_path, recording_given=True))  # FILE replaces [input]
    if tolerance and scene.tolerances is None:
        raise SceneError(gearset_scene_path, "tolerances", "--tolerance (tolerance=True) needs a "
                         "[tolerances] table in the gearset file")
    scene.input = with_recording(scene, Path(path).resolve(), options)
    # only what process's outputs need: without tolerance=True the scene's [tolerances]
    # are set aside, so compare pulls in no Monte Carlo (plan adds it when tolerances exist)
    scene.results = (list(PROCESS_RESULTS) + (["centroids"] if "centroids" in scene.results else [])
                     + (["tolerance"] if tolerance else []))
    if not tolerance:
        scene.tolerances = None
    base = Path(out_dir) if out_dir else Path.cwd() / (Path(path).stem + "-meshphase")
    return run_to_folder(scene, base, overwrite=overwrite, report=False, progress=progress)


def run_to_folder(scene, base, *, overwrite: bool = False, report: bool = True,
                  progress: Callable[[str, int, int], None] | None = None) -> tuple:
    """Run ``scene`` into the output folder ``base``: reserved first, written unless nothing is
    usable, published whole.

    The folder is staged beside its final name and swapped in when complete, so a killed run
    never leaves a half-written folder under the name a reader expects; a failed or
    interrupted run leaves none (:class:`meshphase.run.outdir.OutputDir`).

    Parameters
    ----------
    scene : Scene or callable
        The scene, or a function of the staging folder returning one (the demo writes its
        scene file there first).
    base : str or Path
        The output folder (an existing one gets ``-2``, ``-3``, ... unless ``overwrite``).
    overwrite : bool
        Replace an existing folder (atomically, when the run finishes).
    report : bool
        Also write report.html.
    progress : callable, optional
        ``progress(stage, i, n)``.

    Returns
    -------
    (RunContext, dict)
        The run and the files written (name -> path, after publishing); no files when the
        run failed.
    """
    base = Path(base)
    with OutputDir(base, overwrite=overwrite, staged=True) as out:
        if callable(scene):
            scene = scene(out.path)
        ctx = run_scene(scene, progress=progress)
        if run_status(ctx)["status"] == "failed":
            out.discard()
            return ctx, {}
        with output_write_errors(base):
            written = write_outputs(ctx, out.path, report=report)
    # after publishing: the folder's name is settled then (another run may have taken it)
    return ctx, {k: out.published(v) for k, v in written.items()}
