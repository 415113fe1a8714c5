"""Fixtures for the reader/writer tests: recordings and TDMS files built in code (no binaries
in git)."""

from __future__ import annotations

import numpy as np
import pytest

from meshphase.recording import ChannelSpec, Recording


def build_recording(n: int = 2000, n_channels: int = 4, *, dtype=np.float64, fs: float = 5120.0,
                    t0: float = 0.0, seed: int = 0, start_datetime: str | None = "2024-05-06T07:08:09.123456+00:00",
                    nan_runs: bool = False) -> Recording:
    """A recording whose channel specs use every ChannelSpec field, with meta and history.

    Samples are strain-like noise (~1e-5 m/m) spread over many decades so that round trips
    exercise every digit; ``nan_runs`` puts two NaN runs and one +inf into channel 1.
    """
    rng = np.random.default_rng(seed)
    data = rng.standard_normal((n, n_channels)) * 10.0 ** rng.integers(-8, 3, size=(n, n_channels))
    data = data.astype(dtype)
    if n and n_channels:
        data[0, 0] = -0.0
    if nan_runs and n >= 40 and n_channels >= 2:
        data[5:9, 1] = np.nan
        data[20, 1] = np.inf
        data[30:32, 1] = np.nan
    kinds = ["sun", "ring", "facewidth", "tacho", "other"]
    specs = []
    for j in range(n_channels):
        kind = kinds[j % len(kinds)]
        specs.append(ChannelSpec(
            name=f"{kind}_{j}", kind=kind, units="m/m" if kind != "tacho" else "V",
            gain=1.0 if j % 2 == 0 else 0.5 + j,
            gear="planet" if kind == "facewidth" else None,
            tooth=j if kind in ("sun", "ring", "facewidth") else None,
            face_position=(-0.0125 + 0.005 * j) if kind == "facewidth" else None,
            description=f"gauge {j} \u00b5 \"quoted\", comma" if j == 1 else ""))
    meta = {"gearset": {"z_sun": 21, "z_ring": 75, "n_planets": 3, "module_m": 0.0025},
            "rig": "B2", "load_Nm": [100.0, 250.5], "notes": None, "flag": True}
    history = [{"step": "acquire", "time": "2024-05-06T07:08:09+00:00", "operator": "rig"},
               {"step": "filter", "band_Hz": [10.0, 2000.0]}]
    return Recording(data, fs, specs, t0=t0, start_datetime=start_datetime, meta=meta, history=history)


@pytest.fixture
def recording():
    """A 2000 x 4 float64 recording at 5120 Hz with every metadata field set."""
    return build_recording()


@pytest.fixture(scope="session")
def make_recording():
    """Factory: ``make_recording(n=..., n_channels=..., dtype=..., fs=..., t0=..., nan_runs=...)``."""
    return build_recording


def write_tdms(path, channels, *, segments: int = 3, file_props=None, group_props=None):
    """Write a TDMS file with npTDMS's TdmsWriter.

    Parameters
    ----------
    path : Path
    channels : list of (group, name, data, properties)
        ``data`` is split into ``segments`` consecutive segments (properties go in the first).
    segments : int
    file_props, group_props : dict, optional
        Root properties; group properties keyed by group name.
    """
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    group_props = group_props or {}
    groups = list(dict.fromkeys(g for g, _, _, _ in channels))
    with TdmsWriter(str(path)) as w:
        for s in range(segments):
            objs = []
            if s == 0:
                objs.append(RootObject(file_props or {}))
                objs += [GroupObject(g, group_props.get(g, {})) for g in groups]
            for g, name, data, props in channels:
                data = np.asarray(data)
                bounds = np.linspace(0, len(data), segments + 1).astype(int)
                part = data[bounds[s]:bounds[s + 1]]
                objs.append(ChannelObject(g, name, part, properties=(props or {}) if s == 0 else {}))
            w.write_segment(objs)
    return path


def linear_scale_props(slope: float, intercept: float) -> dict:
    """NI channel properties of one linear scale applied to the raw data."""
    return {"NI_Scaling_Status": "unscaled", "NI_Number_Of_Scales": 1,
            "NI_Scale[0]_Scale_Type": "Linear", "NI_Scale[0]_Linear_Slope": float(slope),
            "NI_Scale[0]_Linear_Y_Intercept": float(intercept),
            "NI_Scale[0]_Linear_Input_Source": np.uint32(0xFFFFFFFF)}


@pytest.fixture(scope="session")
def tdms_tools():
    """(write_tdms, linear_scale_props) for tests that build TDMS files themselves."""
    return write_tdms, linear_scale_props


@pytest.fixture
def tdms_file(tmp_path):
    """Factory: ``tdms_file(channels, name="x.tdms", **write_tdms options) -> Path``."""
    def make(channels, name="rec.tdms", **kw):
        return write_tdms(tmp_path / name, channels, **kw)
    return make


@pytest.fixture
def rig_tdms(tmp_path):
    """A typical NI rig file: group "Strain" with sun/ring/fw gauges (float64, 3 segments),
    group "Speed" with a tacho; 600 samples at 5120 Hz; returns (path, expected data)."""
    fs = 5120.0
    n = 600
    rng = np.random.default_rng(7)
    data = rng.standard_normal((n, 4)) * 1e-5
    wf = {"wf_increment": 1.0 / fs, "wf_start_offset": 0.0,
          "wf_start_time": np.datetime64("2024-03-01T12:00:00.250000", "us"), "unit_string": "m/m"}
    chans = [("Strain", "sun_1", data[:, 0], dict(wf, meshphase_tooth=3)),
             ("Strain", "Ring_1", data[:, 1], dict(wf)),
             ("Strain", "fw_left", data[:, 2], dict(wf, meshphase_face_position=-0.01)),
             ("Speed", "once_per_rev", data[:, 3], dict(wf, unit_string="V"))]
    path = write_tdms(tmp_path / "rig.tdms", chans, segments=3, file_props={"title": "run 12", "author": "rig"})
    return path, data
