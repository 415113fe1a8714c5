"""A corpus of faulty inputs for the ``meshphase`` command, generated in code.

Each :class:`FaultCase` says how to make one fault in a fresh folder (from small valid
recordings written here: 5 s of the seed rig as HDF5, MCAP, CSV with and without the
meshphase preamble, and NI TDMS written by npTDMS's ``TdmsWriter``), which CLI commands to
run on it, and which exit codes are acceptable (``pipeline/run/exits.py``). The runner
(``test_fault_corpus.py``) checks what every case must show: no traceback, no exit 0 on a
faulty input, a code from the documented table, one error line naming the file (and the key
and line for scenes), nothing left behind, no hang.

Categories (:func:`corpus` builds them; cases marked ``slow`` form the ``-m slow`` sweep):

``truncation``
    Every format cut at named offsets (1 and 8 bytes: inside the header; the middle of the
    first metadata region; the middle of the data; one byte short of the end) and, in the
    full sweep, at evenly spaced and seeded random offsets.
``byteflip``
    One byte XOR-ed with a seeded non-zero mask, at a seeded offset inside a named region:
    ``data`` (sample chunks / chunk records), ``metadata`` (HDF5 object headers, B-trees and
    heaps; MCAP schema, channel, metadata and summary records; TDMS lead-in tag and offsets;
    the CSV preamble and header), ``checksum`` (HDF5 fletcher32 fields and the superblock
    checksum; MCAP chunk, data-section and summary CRC32 fields). A flip of a byte the file
    never reads (HDF5 free space) is harmless: such a case may exit 0, but only when the
    flipped file reads back identical to the original (samples and metadata).
    Not in the corpus, because the format stores nothing that could reveal them: TDMS
    sample bytes, ToC flags, version and property values; CSV sample digits (a digit flipped
    to another digit) and preamble string values. CSV flips are therefore structural: a
    byte of a row or of the preamble replaced by a delimiter, a line break, a quote, a NUL or
    a letter.
``special``
    A FIFO, a directory, ``/dev/null``, a symbolic-link loop, a dangling link, a path
    through a regular file (ENOTDIR), a 300-character name, an unreadable file (EACCES
    injected: the tests run as root, which ignores permission bits) and ``/proc/self/mem``
    (a regular file whose read fails with EIO), each given where a recording, a scene or a
    gearset file is expected.
``scene``
    Hostile scene files: empty, binary garbage, not UTF-8 (latin-1, UTF-16), deeply nested
    arrays and inline tables, a 10 MB scene, TOML syntax errors, duplicate keys, unknown keys
    and tables, a wrong type for every kind of key (one per kind by default, every key of
    ``data_schemas/scene.schema.json`` in the full sweep), absurd values (NaN, inf, huge,
    tiny, negative, reversed windows) and recordings named by the scene that are faulty.
``output``
    Hostile output locations: a parent that is a regular file, a 300-character name, an
    existing output, a FIFO or a device node given with ``--overwrite``, a read-only folder
    (EACCES and EROFS injected by monkeypatching ``os``), a full disk (``statvfs``
    monkeypatched).

``declared``
    Files whose bytes are intact but whose header declares what is not there: HDF5 chunks
    never written (the dataset created at full length, some chunk slices never written),
    an HDF5 declaring 1e12-1e13 samples with none stored, a CSV header of thousands to
    millions of columns, a sample rate of 1e300 Hz, a channel name holding a line break
    that would forge an output line, a TDMS file of another tool cut at a segment boundary
    with its ``.tdms_index`` beside it.
``signal``
    ``process`` terminated (SIGTERM) or killed (SIGKILL, then run again) while it runs, and
    ``campaign`` interrupted by Ctrl-C (SIGINT to its process group, workers included).

Every run of a case is classified (:data:`OUTCOMES`): ``clean`` (what the runner requires),
``silent`` (exit 0, or no error line, for a faulty input), ``traceback``, ``hang`` (no
answer within the case's timeout), ``leak`` (an output, staging folder or temporary file
left behind), ``other`` (a wrong exit code or message). ``python -m pytest
tests/faults/test_fault_corpus.py`` ends with that table by category.

Nothing here imports pytest: the corpus can be listed and run by hand
(``python tests/faults/fault_corpus.py`` prints it).
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import stat
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["FaultCase", "Originals", "build_originals", "corpus", "toml_dumps", "BASE_SCENE",
           "SCENE_RESULTS_CHEAP", "schema_leaf_keys", "INFO", "PROCESS", "CONVERT", "RUN",
           "CAMPAIGN", "GEARSET_RUN", "OUTCOMES", "outcome_table", "hdf5_without_chunks"]

EXIT_ERROR = 1  # meshphase.run.exits.EXIT_ERROR; the corpus is plain data, the runner imports pipeline

# --------------------------------------------------------------------------- commands
#: argv templates; ``{name}`` is replaced by the case's value of that name
INFO = ("info", "--quality", "{input}")   # every sample read: a damaged one must show
PROCESS = ("process", "{input}", "--gearset", "{gearset}", "--out", "{out}/proc")
CONVERT = ("convert", "{input}", "{out}/conv.h5")
RUN = ("run", "{scene}", "--out", "{out}/run", "--no-report")
GEARSET_RUN = ("process", "{recording}", "--gearset", "{scene}", "--out", "{out}/proc")
CAMPAIGN = ("campaign", "{scene}", "{recording}", "--out", "{out}/camp", "--workers", "1")

#: outputs of the commands above; none may exist after a run that exits 1
OUTPUTS = ("{out}/proc", "{out}/conv.h5", "{out}/run", "{out}/camp")

#: how a run of a case went: what the runner requires, or the first way it fell short
OUTCOMES = ("clean", "silent", "traceback", "hang", "leak", "other")


# --------------------------------------------------------------------------- the case type
@dataclass(frozen=True)
class FaultCase:
    """One fault and what the command must do with it.

    Attributes
    ----------
    name : str
        Unique id (``category/format/what``), the pytest id.
    category : str
        ``truncation``, ``byteflip``, ``special``, ``scene``, ``output``, ``declared`` or
        ``signal``.
    make : callable
        ``make(ws) -> dict``: builds the fault in ``ws.tmp`` and returns the values of the
        placeholders in ``commands`` (``input``, ``scene``, ``recording``, ``gearset``,
        ``out`` have defaults: see :meth:`Originals.defaults`).
    commands : tuple of argv templates
        Each is run on its own (``-q`` is added).
    expect : frozenset of int
        Acceptable exit codes.
    names : tuple of str
        Placeholders whose file name (last path component) the error line must contain.
    contains : tuple of str
        Further text the error line must contain (a scene key, ``"line"``).
    may_be_harmless : bool
        A byte flip the reader may legitimately never see: exit 0 is accepted when the file
        reads back identical to the original.
    patch : callable, optional
        ``patch(monkeypatch, values)``: an OS fault injected in-process (read-only folder,
        disk full, EACCES as root).
    runner : {"inprocess", "subprocess"}
        ``subprocess`` for cases that could hang inside compiled code, where only killing a
        child process bounds the time.
    timeout : float
        Seconds per case (pytest-timeout in-process; the child is killed for subprocess).
    slow : bool
        Only in the ``-m slow`` sweep.
    xfail : str, optional
        A known product fault outside the CLI/io scope: the reason names the file to fix;
        the case is run with ``xfail(strict=True)`` so the fix shows up as XPASS.
    after : callable, optional
        ``after(values)``: further checks once the commands ran (e.g. a FIFO given as the
        output is still a FIFO).
    max_line : int, optional
        The error line's most characters: an input of any size gets a message of bounded
        size.
    signal : tuple, optional
        ``(signal name, rerun)``: the first command runs as the real command in a session of
        its own and gets that signal (SIGINT to the whole process group, as Ctrl-C sends it)
        once its staging folder exists; with ``rerun`` the same command is then run again to
        the end and must exit 0 with its output under its own name and nothing else left.
    """

    name: str
    category: str
    make: Callable[["Workspace"], dict]
    commands: tuple
    expect: frozenset = frozenset({EXIT_ERROR})
    names: tuple = ("input",)
    contains: tuple = ()
    may_be_harmless: bool = False
    patch: Callable | None = None
    runner: str = "inprocess"
    timeout: float = 10.0
    slow: bool = False
    xfail: str | None = None
    after: Callable | None = None
    max_line: int | None = None
    signal: tuple | None = None


@dataclass
class Originals:
    """The valid inputs every fault starts from (built once per session).

    Attributes
    ----------
    dir : Path
    recordings : dict
        Format key (``hdf5``, ``mcap``, ``csv``, ``csv_plain``, ``tdms``) -> Path.
    regions : dict
        Format key -> region name -> list of ``(start, stop)`` byte ranges.
    gearset : Path
        The seed rig's gearset scene (valid for ``process --gearset``).
    scene : Path
        :data:`BASE_SCENE` naming the HDF5 recording (valid for ``run``).
    rec : meshphase.recording.Recording
        The recording all files hold.
    """

    dir: Path
    recordings: dict
    regions: dict
    gearset: Path
    scene: Path
    rec: object = None
    blobs: dict = field(default_factory=dict)

    def blob(self, fmt: str) -> bytes:
        if fmt not in self.blobs:
            self.blobs[fmt] = self.recordings[fmt].read_bytes()
        return self.blobs[fmt]


@dataclass
class Workspace:
    """Where a case builds its fault: ``orig`` (read only) and ``tmp`` (its own folder);
    ``cleanups``: functions the runner calls when the case is over (unmounting)."""

    orig: Originals
    tmp: Path
    cleanups: list = field(default_factory=list)

    def defaults(self) -> dict:
        out = self.tmp / "out"
        out.mkdir(exist_ok=True)
        return {"input": str(self.orig.recordings["hdf5"]), "recording": str(self.orig.recordings["hdf5"]),
                "gearset": str(self.orig.gearset), "scene": str(self.orig.scene), "out": str(out)}


SUFFIX = {"hdf5": ".h5", "mcap": ".mcap", "csv": ".csv", "csv_plain": ".csv", "tdms": ".tdms"}
FORMATS = tuple(SUFFIX)


# --------------------------------------------------------------------------- originals
SEED_RIG_GEARSET = """\
name = "seed rig gearset (fault corpus)"

[gearset]
name = "seed 000 rig"
z_sun = 25
z_ring = 87
z_planet = 31
n_planets = 4
carrier_radius_mm = 112.5
face_width_mm = 40
direction = "cw"

[speeds]
sun_rpm = 18.19
carrier_rpm = 1.06
"""


def build_originals(directory) -> Originals:
    """Write the valid recordings and the gearset scene into ``directory``.

    5 s of the ``seed_rig`` scenario (seed 0, 3 channels at 5120 Hz): HDF5, MCAP and CSV by
    :func:`meshphase.io.write`, a plain CSV (the same file without its ``# meshphase``
    preamble: what a spreadsheet exports), and NI TDMS in five 1-s segments by
    :func:`meshphase.synthetic.tdms_export.write_tdms` (npTDMS ``TdmsWriter``).
    """
    import meshphase.io as pio
    from meshphase.synthetic import generate
    from meshphase.synthetic.tdms_export import write_tdms

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    rec, _ = generate("seed_rig", duration=5.0, seed=0)
    paths = {}
    for fmt in ("hdf5", "mcap", "csv"):
        paths[fmt] = Path(pio.write(rec, d / f"rig{SUFFIX[fmt]}"))
    text = paths["csv"].read_bytes()
    plain = d / "plain.csv"
    plain.write_bytes(text[text.index(b"\n") + 1:])
    paths["csv_plain"] = plain
    paths["tdms"] = write_tdms(list(rec.blocks(1.0)), d / "rig.tdms", n_samples=rec.n_samples)
    gearset = d / "gearset.toml"
    gearset.write_text(SEED_RIG_GEARSET, encoding="utf-8")
    scene = d / "scene.toml"
    scene.write_text(toml_dumps(dict(BASE_SCENE, input={"recording": str(paths["hdf5"])})),
                     encoding="utf-8")
    regions = {"hdf5": hdf5_regions(paths["hdf5"]), "mcap": mcap_regions(paths["mcap"]),
               "tdms": tdms_regions(paths["tdms"]), "csv": csv_regions(paths["csv"], preamble=True),
               "csv_plain": csv_regions(paths["csv_plain"], preamble=False)}
    return Originals(dir=d, recordings=paths, regions=regions, gearset=gearset, scene=scene, rec=rec)


# --------------------------------------------------------------------------- files never finished
def hdf5_without_chunks(src, dst, skip, *, chunk: int | None = None, n_samples: int | None = None) -> Path:
    """A copy of the HDF5 recording ``src`` (meshphase layout) in chunks of ``chunk`` samples
    (default: those of ``src``) in which the chunks with an index in ``skip`` (every channel)
    were never written: the dataset is created at its full length and only the other chunks'
    slices are written. ``n_samples`` declares a longer recording (every channel and the root
    attribute) whose extra chunks are never written either."""
    import h5py

    with h5py.File(src, "r") as a, h5py.File(dst, "w", libver=("v110", "v110")) as b:
        for k, v in a.attrs.items():
            b.attrs[k] = v
        n = int(a.attrs["n_samples"] if n_samples is None else n_samples)
        b.attrs["n_samples"] = n
        g = b.create_group("channels")
        for name, ds in a["channels"].items():
            c = int(chunk or ds.chunks[0])
            # a longer declared length: an extensible chunk index (a fixed one would be
            # allocated for every chunk the length declares)
            d = g.create_dataset(name, shape=(n,), dtype=ds.dtype, chunks=(c,), fletcher32=ds.fletcher32,
                                 maxshape=(None,) if n_samples is not None else None)
            for k, v in ds.attrs.items():
                d.attrs[k] = v
            data = ds[()]
            for i, c0 in enumerate(range(0, data.shape[0], c)):
                if i not in skip:
                    piece = data[c0:c0 + c]
                    d[c0:c0 + piece.shape[0]] = piece
    return Path(dst)


# --------------------------------------------------------------------------- byte regions
def _complement(ranges, size):
    out, pos = [], 0
    for a, b in sorted(ranges):
        if a > pos:
            out.append((pos, a))
        pos = max(pos, b)
    if pos < size:
        out.append((pos, size))
    return out


def _minus(ranges, holes):
    """``ranges`` with the byte ranges ``holes`` cut out."""
    out = []
    for a, b in ranges:
        pieces = [(a, b)]
        for h0, h1 in holes:
            nxt = []
            for p0, p1 in pieces:
                if h1 <= p0 or h0 >= p1:
                    nxt.append((p0, p1))
                    continue
                if p0 < h0:
                    nxt.append((p0, h0))
                if h1 < p1:
                    nxt.append((h1, p1))
            pieces = nxt
        out.extend(pieces)
    return [r for r in out if r[1] > r[0]]


def hdf5_regions(path) -> dict:
    """Byte ranges of an HDF5 recording written by :mod:`meshphase.io.hdf5`.

    ``data``: the stored sample chunks without their 4-byte fletcher32 checksum (found
    through h5py's chunk index); ``checksum``: those fletcher32 fields and the superblock
    checksum; ``strings``: the global heap collections (``GCOL``) that hold the
    variable-length string attributes; ``metadata``: everything else (superblock, object
    headers, B-trees, fractal heaps, free-space records; unused bytes among them are never
    read, so a flip there may be harmless); ``header``: the 48-byte superblock.
    """
    import h5py

    chunks = []
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and obj.chunks:
                for i in range(obj.id.get_num_chunks()):
                    ci = obj.id.get_chunk_info(i)
                    chunks.append((int(ci.byte_offset), int(ci.byte_offset + ci.size)))
        f.visititems(visit)
    blob = Path(path).read_bytes()
    outside = _complement(chunks, len(blob))
    strings = []
    for a, b in outside:
        for m in re.finditer(b"GCOL", blob[a:b]):
            start = a + m.start()
            (size,) = struct.unpack_from("<Q", blob, start + 8)
            strings.append((start, min(start + size, len(blob))))
    return {"header": [(0, 44)], "data": [(a, b - 4) for a, b in chunks],
            "checksum": [(b - 4, b) for a, b in chunks] + [(44, 48)],
            "strings": strings, "metadata": _minus(outside, strings + [(44, 48)]),
            "meta_section": [(max(a, 48), b) for a, b in outside if b > 48]}


def mcap_regions(path) -> dict:
    """Byte ranges of an MCAP recording: ``data`` (the records inside every chunk),
    ``checksum`` (each chunk's uncompressed CRC32, the data-section CRC32 of DataEnd and the
    summary CRC32 of the footer), ``metadata`` (all other bytes after the leading magic:
    header, schema, channel and metadata records, chunk record headers, the summary
    section, the footer), ``header`` (leading magic and header record)."""
    from mcap.reader import make_reader

    blob = Path(path).read_bytes()
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    data, crcs = [], []
    for ci in summary.chunk_indexes:
        c0 = ci.chunk_start_offset
        (clen,) = struct.unpack_from("<I", blob, c0 + 9 + 28)
        records = c0 + 9 + 32 + clen + 8
        data.append((records, c0 + ci.chunk_length))
        crcs.append((c0 + 9 + 24, c0 + 9 + 28))
    footer = len(blob) - 8 - 29                      # opcode, length, 2 offsets, CRC
    (summary_start,) = struct.unpack_from("<Q", blob, footer + 9)
    crcs.append((summary_start - 4, summary_start))  # DataEnd's data_section_crc
    crcs.append((len(blob) - 8 - 4, len(blob) - 8))  # the footer's summary_crc
    first_chunk = min(ci.chunk_start_offset for ci in summary.chunk_indexes)
    return {"header": [(0, 8)], "data": data, "checksum": crcs,
            "metadata": _minus(_complement(data, len(blob)), crcs + [(0, 8)]),
            "meta_section": [(8, first_chunk), (summary_start, len(blob) - 8)]}


def tdms_regions(path) -> dict:
    """Byte ranges of a TDMS file: per segment the 28-byte lead-in, its metadata and its raw
    data. ``metadata`` here is what a reader must check structurally: the ``TDSm`` tag and
    the next-segment and raw-data offsets of every lead-in (the ToC flags, the version and
    the property values carry no checksum and are not in the corpus); ``meta_section``: the
    metadata sections (object paths, properties; used for truncation offsets)."""
    blob = Path(path).read_bytes()
    pos, tags, offsets, metas, datas = 0, [], [], [], []
    while pos + 28 <= len(blob):
        if blob[pos:pos + 4] != b"TDSm":
            raise ValueError(f"{path}: no TDMS lead-in at byte {pos}")
        _toc, _ver, nxt, raw = struct.unpack_from("<IIQQ", blob, pos + 4)
        tags.append((pos, pos + 4))
        offsets.append((pos + 12, pos + 28))
        metas.append((pos + 28, pos + 28 + raw))
        datas.append((pos + 28 + raw, pos + 28 + nxt))
        pos += 28 + nxt
    return {"header": [(0, 28)], "metadata": tags + offsets, "meta_section": metas, "data": datas}


def csv_regions(path, *, preamble: bool) -> dict:
    """Byte ranges of a CSV recording: ``metadata`` (the preamble line, when there is one,
    and the column header line), ``data`` (the rows)."""
    blob = Path(path).read_bytes()
    end1 = blob.index(b"\n") + 1
    if preamble:
        end2 = blob.index(b"\n", end1) + 1
        meta = [(0, end1 - 1), (end1, end2 - 1)]
    else:
        end2 = end1
        meta = [(0, end1 - 1)]
    return {"header": [(0, end2)], "metadata": meta, "data": [(end2, len(blob))]}


def _pick(ranges, rng) -> int:
    """A uniformly drawn byte offset from a list of ranges."""
    sizes = np.array([b - a for a, b in ranges], dtype=np.int64)
    k = int(rng.integers(int(sizes.sum())))
    i = int(np.searchsorted(np.cumsum(sizes), k, side="right"))
    return int(ranges[i][0] + k - (np.cumsum(sizes)[i - 1] if i else 0))


# --------------------------------------------------------------------------- truncation
#: named cut points: (name, function of (size, regions) -> number of bytes kept)
def _mid(ranges):
    a, b = ranges[0]
    return (a + b) // 2


CUTS = {
    "header-1": lambda size, reg: 1,
    "header-8": lambda size, reg: 8,
    # the first metadata after the header (HDF5 object headers, MCAP schema/channel records,
    # the first TDMS segment's metadata, the CSV preamble) ...
    "mid-metadata": lambda size, reg: _mid((reg.get("meta_section") or reg["metadata"])[:1]),
    "mid-data": lambda size, reg: _mid([(reg["data"][0][0], reg["data"][-1][1])]),
    # ... and the last (HDF5 metadata after the chunks, the MCAP summary section, the last
    # TDMS segment's metadata, the CSV column header)
    "late-metadata": lambda size, reg: _mid((reg.get("meta_section") or reg["metadata"])[-1:]),
    "last-byte": lambda size, reg: size - 1,
}


def _plain_csv_cut(blob: bytes, cut: int) -> int:
    """A plain CSV (no row count stored) cut exactly after a line break is a valid shorter
    file; move such a cut one byte back so it falls inside a row."""
    while cut > 1 and blob[cut - 1:cut] == b"\n":
        cut -= 1
    return cut


def _truncate(fmt: str, where: str | int):
    def make(ws):
        blob = ws.orig.blob(fmt)
        cut = where if isinstance(where, int) else CUTS[where](len(blob), ws.orig.regions[fmt])
        cut = min(max(1, cut), len(blob) - 1)
        if fmt == "csv_plain":
            cut = _plain_csv_cut(blob, cut)
        p = ws.tmp / f"cut{SUFFIX[fmt]}"
        p.write_bytes(blob[:cut])
        return {"input": str(p), "recording": str(p), "offset": cut}
    return make


def truncation_cases() -> list[FaultCase]:
    cases = []
    for fmt in FORMATS:
        for where in CUTS:
            cases.append(FaultCase(f"truncation/{fmt}/{where}", "truncation", _truncate(fmt, where),
                                   (INFO, PROCESS, CONVERT)))
        for k in range(1, 40):           # the -m slow sweep: evenly spaced cuts
            cases.append(FaultCase(f"truncation/{fmt}/at-{k}-of-40", "truncation",
                                   _truncate_fraction(fmt, k / 40), (INFO, CONVERT), slow=True))
        for seed in range(20):           # ... and seeded random ones
            cases.append(FaultCase(f"truncation/{fmt}/seed-{seed}", "truncation",
                                   _truncate_seeded(fmt, seed), (INFO, PROCESS), slow=True))
    return cases


def _truncate_fraction(fmt, frac):
    def make(ws):
        return _truncate(fmt, int(len(ws.orig.blob(fmt)) * frac))(ws)
    return make


def _truncate_seeded(fmt, seed):
    def make(ws):
        rng = np.random.default_rng([seed, 7])
        return _truncate(fmt, int(rng.integers(1, len(ws.orig.blob(fmt)))))(ws)
    return make


# --------------------------------------------------------------------------- byte flips
#: (format, region) pairs the formats can reveal (see the module docstring for the others)
FLIP_REGIONS = {
    "hdf5": ("data", "metadata", "checksum"),
    "mcap": ("data", "metadata", "checksum"),
    "tdms": ("metadata",),
    "csv": ("data", "metadata"),
    "csv_plain": ("data", "metadata"),
}
#: what a structural CSV flip writes in place of the byte, per region (the format has no
#: checksum: a digit turned into another digit, or a letter of a channel name or of a
#: preamble string into another letter, is a valid file)
CSV_HOSTILE = {"data": (b",", b"\n", b'"', b"\x00", b"x", b";"), "metadata": (b"\n",)}


def _flip(fmt: str, region: str, seed: int):
    def make(ws):
        blob = bytearray(ws.orig.blob(fmt))
        rng = np.random.default_rng([seed, FORMATS.index(fmt), len(region)])
        off = _pick(ws.orig.regions[fmt][region], rng)
        if fmt.startswith("csv"):
            choices = [c for c in CSV_HOSTILE[region] if c != blob[off:off + 1]]
            new = choices[int(rng.integers(len(choices)))]
            blob[off:off + 1] = new
        else:
            blob[off] ^= int(rng.integers(1, 256))
        p = ws.tmp / f"flip{SUFFIX[fmt]}"
        p.write_bytes(bytes(blob))
        return {"input": str(p), "recording": str(p), "offset": off, "original": str(ws.orig.recordings[fmt])}
    return make


def _flip_string_attr(ws):
    """HDF5: one letter of a channel description (a text attribute) changed to another
    letter: valid text, a different value. meshphase writes text attributes fixed-length,
    in the object header that HDF5 checksums, so the change must be caught there."""
    blob = bytearray(ws.orig.blob("hdf5"))
    off = blob.index(b"tooth-root")
    blob[off] ^= 0x20                               # 't' -> 'T'
    p = ws.tmp / "desc.h5"
    p.write_bytes(bytes(blob))
    return {"input": str(p), "recording": str(p), "offset": off,
            "original": str(ws.orig.recordings["hdf5"])}


def byteflip_cases() -> list[FaultCase]:
    cases = []
    seeds = range(20)                  # 0 and 1 in the default selection
    for fmt, regions in FLIP_REGIONS.items():
        for region in regions:
            for seed in seeds:
                cmds = (INFO, PROCESS, CONVERT) if seed == 0 else (INFO,)
                cases.append(FaultCase(f"byteflip/{fmt}/{region}/seed-{seed}", "byteflip",
                                       _flip(fmt, region, seed), cmds, may_be_harmless=True,
                                       slow=seed >= 2))
    cases.append(FaultCase(
        "byteflip/hdf5/string-attribute", "byteflip", _flip_string_attr, (INFO, PROCESS),
        may_be_harmless=True))
    return cases


# --------------------------------------------------------------------------- special files
def _special_path(kind: str, role: str = "recording"):
    """A path of ``kind`` in ws.tmp, where a ``role`` file (recording, scene) is expected."""
    def make(ws):
        t = ws.tmp
        if kind == "fifo":
            p = t / "pipe.h5"
            os.mkfifo(p)
        elif kind == "directory":
            p = t / "folder.h5"
            p.mkdir()
        elif kind == "devnull":
            p = Path(os.devnull)
        elif kind == "symlink-loop":
            p = t / "loop_a.h5"
            os.symlink(t / "loop_b.h5", p)
            os.symlink(p, t / "loop_b.h5")
        elif kind == "dangling-symlink":
            p = t / "dangling.h5"
            os.symlink(t / "gone.h5", p)
        elif kind == "parent-is-file":
            blocker = t / "plain_file"
            blocker.write_text("x")
            p = blocker / "rec.h5"
        elif kind == "name-too-long":
            p = t / ("r" * 300 + ".h5")
        elif kind == "missing":
            p = t / "missing.h5"
        elif kind == "proc-mem":
            p = Path("/proc/self/mem")
        elif kind == "eacces":                  # valid content: only the permission is wrong
            if role == "scene":
                p = t / "locked.toml"
                p.write_bytes(ws.orig.scene.read_bytes())
            else:
                p = t / "locked.h5"
                p.write_bytes(ws.orig.blob("hdf5"))
        else:  # pragma: no cover - a typo in the corpus
            raise ValueError(kind)
        return {"path": str(p)}
    return make


def _deny_reading(target_key: str):
    """Simulated ``chmod 000`` for root: opening the file for reading raises EACCES, whether
    Python (``open``, ``os.open``, ``Path.read_text``) or HDF5 opens it (h5py's File is
    patched at its Python entry point)."""
    def patch(mp, values):
        import builtins
        import h5py

        target = os.path.realpath(values[target_key])

        def denied(p):
            return PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fspath(p))

        def hits(p):
            try:
                return os.path.realpath(os.fspath(p)) == target
            except TypeError:
                return False

        real_open, real_os_open, real_h5 = builtins.open, os.open, h5py.File.__init__

        def fake_open(file, *a, **k):
            if not isinstance(file, int) and hits(file):
                raise denied(file)
            return real_open(file, *a, **k)

        def fake_os_open(p, flags, *a, **k):
            if hits(p):
                raise denied(p)
            return real_os_open(p, flags, *a, **k)

        def fake_h5(self, name, *a, **k):
            if isinstance(name, (str, os.PathLike)) and hits(name):
                raise denied(name)
            return real_h5(self, name, *a, **k)

        import io

        mp.setattr(builtins, "open", fake_open)
        mp.setattr(io, "open", fake_open)                     # pathlib opens through io.open
        mp.setattr(os, "open", fake_os_open)
        mp.setattr(h5py.File, "__init__", fake_h5)
    return patch


#: (role, kind) -> reason: known faults outside the CLI/io scope
SPECIAL_XFAIL: dict = {}

SPECIAL_KINDS = ("fifo", "directory", "devnull", "symlink-loop", "dangling-symlink",
                 "parent-is-file", "name-too-long", "missing", "proc-mem", "eacces")


def _reading_raises(exc_type):
    """Every read of a recording raises ``exc_type`` (out of memory, Ctrl-C while reading)."""
    def patch(mp, values):
        import meshphase.io as pio

        def boom(*a, **k):
            raise exc_type("Unable to allocate 7.32 GiB for an array" if exc_type is MemoryError else "")

        def boom_iter(*a, **k):
            boom()
            yield  # pragma: no cover
        # the public functions and the format modules' own (the streamed load reads a file
        # through its format module, block by block: meshphase.run.stream.FileSource)
        mods = [pio]
        for fmt in ("hdf5", "mcap", "csv", "tdms"):
            try:
                mods.append(pio.get_format(fmt))
            except ImportError:         # an optional reader missing: nothing to patch
                pass
        for mod in mods:
            for name in ("read", "read_info"):
                if hasattr(mod, name):
                    mp.setattr(mod, name, boom)
            if hasattr(mod, "iter_blocks"):
                mp.setattr(mod, "iter_blocks", boom_iter)
    return patch


def _valid_copy(ws):
    p = ws.tmp / "rec.h5"
    p.write_bytes(ws.orig.blob("hdf5"))
    return {"input": str(p), "recording": str(p)}


def _valid_folder(ws, n: int = 24):
    """A folder of ``n`` copies of the valid recording: a campaign that runs for several
    seconds after its staging folder appears (one 5-s recording is done in under a second,
    so a Ctrl-C 2 s into the run could land after the end)."""
    d = ws.tmp / "recs"
    d.mkdir(exist_ok=True)
    blob = ws.orig.blob("hdf5")
    for i in range(n):
        (d / f"rec{i:02d}.h5").write_bytes(blob)
    return {"input": str(d / "rec00.h5"), "recording": str(d)}


def special_cases() -> list[FaultCase]:
    cases = [
        FaultCase("special/recording/out-of-memory", "special", _valid_copy, (INFO, PROCESS, CONVERT),
                  names=(), contains=("out of memory",), patch=_reading_raises(MemoryError)),
        FaultCase("special/recording/interrupted", "special", _valid_copy, (INFO, PROCESS, CONVERT),
                  expect=frozenset({130}), names=(), patch=_reading_raises(KeyboardInterrupt)),
    ]
    for kind in SPECIAL_KINDS:
        patch = _deny_reading("path") if kind == "eacces" else None
        cases.append(FaultCase(
            f"special/recording/{kind}", "special", _rename(_special_path(kind), "input", "recording"),
            (INFO, PROCESS, CONVERT), patch=patch))
        cases.append(FaultCase(
            f"special/scene/{kind}", "special", _rename(_special_path(kind, "scene"), "scene"), (RUN, CAMPAIGN),
            names=("scene",), patch=patch, xfail=SPECIAL_XFAIL.get(("scene", kind))))
        cases.append(FaultCase(
            f"special/gearset/{kind}", "special", _rename(_special_path(kind, "scene"), "gearset"), (PROCESS,),
            names=("gearset",), patch=patch, xfail=SPECIAL_XFAIL.get(("gearset", kind))))
        # a scene that names the special file as its recording
        # refused when the scene is checked (the scene, its key and line are named), or, when
        # the file looks fine until it is read, when the recording is read (it is named)
        at_read = kind in ("eacces", "proc-mem")
        cases.append(FaultCase(
            f"special/scene-input/{kind}", "special", _scene_naming(kind), (RUN,),
            names=("recording",) if at_read else ("scene",), contains=() if at_read else ("input.recording",),
            patch=_deny_reading("recording") if kind == "eacces" else None,
            xfail=SPECIAL_XFAIL.get(("scene-input", kind))))
    return cases


def _rename(make, *keys):
    def wrapped(ws):
        v = make(ws)
        return {"path": v["path"], **{k: v["path"] for k in keys}}
    return wrapped


def _scene_naming(kind: str):
    def make(ws):
        v = _special_path(kind)(ws)
        scene = dict(BASE_SCENE, results=["phasing"])
        scene["input"] = {"recording": v["path"]}
        p = ws.tmp / "names_special.toml"
        p.write_text(toml_dumps(scene), encoding="utf-8")
        return {"scene": str(p), "recording": v["path"]}
    return make


# --------------------------------------------------------------------------- scenes
#: a scene with every table of the schema; its results need no recording (fast)
BASE_SCENE = {
    "name": "fault corpus base scene",
    "description": "every table of the scene schema",
    "results": ["ideal_phasing"],
    "gearset": {"name": "seed 000 rig", "z_sun": 25, "z_ring": 87, "z_planet": 31, "n_planets": 4,
                "carrier_radius_mm": 112.5, "face_width_mm": 40.0, "direction": "cw"},
    "speeds": {"sun_rpm": 18.19, "carrier_rpm": 1.06},
    "channels": [{"name": "sun", "kind": "sun", "gear": "sun", "tooth": 0, "gain": 1.0}],
    "input": {"recording": "RECORDING", "start_s": 0.0, "stop_s": 5.0},
    "processing": {"block_s": 1.0, "refine": True},
    "tolerances": {"e_sun_mm": 0.2, "e_ring_mm": 0.2, "e_planet_mm": 0.2, "kappa_sun_deg": "uniform",
                   "samples": 64, "sampler": "sobol", "seed": 1},
    "bearing": {"case": "1", "input_torque_Nm": 1378.7, "k_tilt_Nm_per_rad": [8.8e6, 8.8e4, 8.8e3],
                "c_g_N_per_mm_um": 20.0},
    "tacho": {"channel": "tacho", "key_angle_deg": 0.0},
}
#: results that exercise each table's keys cheaply (the recording is 5 s)
SCENE_RESULTS_CHEAP = {"gearset": ["ideal_phasing"], "speeds": ["ideal_phasing"],
                       "tolerances": ["tolerance"], "bearing": ["bearing_moments", "tilt"],
                       "input": ["phasing"], "processing": ["phasing"], "channels": ["phasing"],
                       "tacho": ["phasing"]}


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)               # JSON string escapes are valid TOML basic strings
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def toml_dumps(doc: dict) -> str:
    """A scene dict as TOML: scalars first, then ``[table]``s and ``[[array of tables]]``
    (only the shapes a scene has; a dict or list of dicts in a table is written inline)."""
    lines, tables = [], []
    for k, v in doc.items():
        if isinstance(v, dict):
            tables.append((k, v, False))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            tables.append((k, v, True))
        else:
            lines.append(f"{k} = {_toml_value(v)}")
    for k, v, many in tables:
        for item in (v if many else [v]):
            lines.append("")
            lines.append(f"[[{k}]]" if many else f"[{k}]")
            lines.extend(f"{kk} = {_toml_value(vv)}" for kk, vv in item.items())
    return "\n".join(lines) + "\n"


def _scene(ws, scene: dict, name="scene.toml") -> dict:
    scene = json.loads(json.dumps(scene, allow_nan=True))     # deep copy
    if isinstance(scene.get("input"), dict) and scene["input"].get("recording") == "RECORDING":
        scene["input"]["recording"] = str(ws.orig.recordings["hdf5"])
    p = ws.tmp / name
    p.write_text(toml_dumps(scene), encoding="utf-8")
    return {"scene": str(p)}


def _scene_text(text: str | bytes, name="scene.toml", *, mark: str | None = None):
    """A scene file with ``text``; with ``mark``, ``line`` is the line the mark is on."""
    def make(ws):
        p = ws.tmp / name
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text, encoding="utf-8")
        out = {"scene": str(p)}
        if mark is not None:
            out["line"] = 1 + text[:text.index(mark)].count("\n")
        return out
    return make


def _scene_with(path: tuple, value, results=None, *, drop: bool = False):
    """BASE_SCENE with the key at ``path`` set to ``value`` (or removed)."""
    def make(ws):
        scene = json.loads(json.dumps(BASE_SCENE))
        if results is not None:
            scene["results"] = results
        node = scene
        for i, k in enumerate(path[:-1]):
            if isinstance(node, dict) and k not in node:   # a table the base scene leaves out
                node[k] = json.loads(json.dumps(_OPTIONAL_TABLES[tuple(path[:i + 1])]))
            node = node[k]
        if drop:
            node.pop(path[-1], None)
        else:
            node[path[-1]] = value
            if path in _EXCLUSIVE:                 # the schema allows one of the two
                node.pop(_EXCLUSIVE[path], None)
        return _scene(ws, scene)
    return make


#: tables BASE_SCENE leaves out (they need another kind of recording, or pin what the data
#: decide), with a valid content for the keys under them: ``[input.mcap]`` maps the topics of
#: an MCAP file of another tool, ``[input.csv]`` says how to read a DAQ's text export,
#: ``[labels]`` pins a gauge's planet labels, ``[onsets]`` names the onset detector
_OPTIONAL_TABLES = {("input", "mcap"): {"channels": [{"name": "sun", "topic": "/rig/strain",
                                                      "field": "gauges.sun"}]},
                    ("input", "csv"): {"header_row": 1},
                    ("labels",): {"sun_shift": 0},
                    ("onsets",): {"detector": "matched"}}

#: keys the scene schema allows only instead of another (``oneOf``)
_EXCLUSIVE = {("gearset", "planet_angles_deg"): "n_planets"}


def schema_leaf_keys() -> list[tuple[tuple, dict]]:
    """Every key of the scene schema with its schema: ``(path, subschema)``; array-of-table
    items appear with index 0 (``("channels", 0, "tooth")``)."""
    from meshphase.data_schemas import load_schema

    out = []

    def walk(prefix, sch):
        for k, sub in sch.get("properties", {}).items():
            path = prefix + (k,)
            if sub.get("type") == "object":
                out.append((path, sub))
                walk(path, sub)
            elif sub.get("type") == "array" and sub.get("items", {}).get("type") == "object":
                out.append((path, sub))
                walk(path + (0,), sub["items"])
            else:
                out.append((path, sub))
    walk((), load_schema("scene"))
    return out


def _kind(sub: dict) -> str:
    if "enum" in sub:
        return "enum"
    if "oneOf" in sub:
        return "oneOf"                       # a number, or "uniform" / an array of numbers
    return sub.get("type", "any")


#: a value of the wrong type for each kind of key
WRONG = {"string": 42, "integer": "7", "number": "fast", "boolean": "yes", "array": 3,
         "enum": 3, "object": 5, "oneOf": {"a": 1}}
#: one key per kind for the default selection
DEFAULT_WRONG_TYPE_KEYS = {("gearset", "name"), ("gearset", "z_sun"), ("gearset", "carrier_radius_mm"),
                           ("processing", "refine"), ("results",), ("gearset", "direction"),
                           ("gearset",), ("channels",), ("tolerances", "kappa_sun_deg"),
                           ("bearing", "k_tilt_Nm_per_rad")}


def _wrong_type_cases() -> list[FaultCase]:
    cases = []
    for path, sub in schema_leaf_keys():
        kind = _kind(sub)
        value = WRONG.get(kind, 42)
        if kind == "array" and sub.get("items", {}).get("type") == "object":
            value = "sun"                      # [[channels]] given as a string
        key = ".".join(str(p) for p in path)
        slow = path not in DEFAULT_WRONG_TYPE_KEYS
        cases.append(FaultCase(
            f"scene/wrong-type/{key}", "scene", _scene_with(path, value), (RUN,) if slow else (RUN, CAMPAIGN),
            names=("scene",), contains=(str(path[-1] if not isinstance(path[-1], int) else path[0]), "line"),
            slow=slow))
    # an integer key given a float, an integer array item given a string
    cases.append(FaultCase("scene/wrong-type/gearset.z_sun-float", "scene",
                           _scene_with(("gearset", "z_sun"), 25.5), (RUN,), names=("scene",),
                           contains=("z_sun", "line")))
    cases.append(FaultCase("scene/wrong-type/bearing.k_tilt-item", "scene",
                           _scene_with(("bearing", "k_tilt_Nm_per_rad"), [8.8e6, "stiff"]), (RUN,),
                           names=("scene",), contains=("k_tilt_Nm_per_rad", "line")))
    return cases


_RANGE = ("pipeline/run/scene.py (item 5: range checks up front with key and line): ")


def _big_scene(kind: str):
    def make(ws):
        head = toml_dumps(dict(json.loads(json.dumps(BASE_SCENE)),
                               input={"recording": str(ws.orig.recordings["hdf5"])}))
        p = ws.tmp / "big.toml"
        with open(p, "w", encoding="utf-8") as fh:
            if kind == "comment":
                fh.write(head)
                fh.write(("# " + "x" * 97 + "\n") * 100_000)      # 10 MB of comments
                fh.write("\n[speeds2]\nsun_rpm = 1.0\n")             # then an unknown table
            else:                                                   # 10 MB of [[channels]]
                scene = dict(json.loads(json.dumps(BASE_SCENE)), results=["phasing"])
                scene.pop("channels")
                scene["input"] = {"recording": str(ws.orig.recordings["hdf5"])}
                fh.write(toml_dumps(scene))
                for i in range(200_000):
                    fh.write(f'\n[[channels]]\nname = "gauge_{i:07d}"\nkind = "sun"\n')
        return {"scene": str(p)}
    return make


def _absurd(path, value, results, reason=None, *, runner="inprocess", slow=False, timeout=10.0,
            key=None):
    """A value that passes the schema's type checks but no physical range check."""
    key = key or str(path[-1])
    text = f"{value:g}" if isinstance(value, float) else json.dumps(value).replace(" ", "")
    for x, y in (("[", "("), ("]", ")"), ("{", "("), ("}", ")"), ('"', ""), (":", "=")):
        text = text.replace(x, y)                         # ids without brackets or quotes
    label = ".".join(str(p) for p in path) + "=" + text
    return FaultCase(f"scene/absurd/{label}", "scene", _scene_with(path, value, results), (RUN,),
                     names=("scene",), contains=(key, "line"),
                     xfail=(_RANGE + reason) if reason else None, runner=runner, slow=slow,
                     timeout=timeout)


def _absurd_cases() -> list[FaultCase]:
    ph = ["phasing"]
    return [
        _absurd(("speeds", "sun_rpm"), math.nan, ["ideal_phasing"]),
        _absurd(("speeds", "sun_rpm"), 1e308, ["ideal_phasing"]),
        _absurd(("gearset", "carrier_radius_mm"), math.inf, ["ideal_phasing"]),
        _absurd(("gearset", "carrier_radius_mm"), 1e-300, ["tolerance"]),
        _absurd(("gearset", "carrier_radius_mm"), 1e300, ["ideal_phasing"]),
        _absurd(("gearset", "planet_angles_deg"), [0.0, 0.0, 0.0], ["ideal_phasing"]),
        _absurd(("gearset", "z_sun"), 100_000_000_000, ["ideal_phasing"]),
        _absurd(("tolerances", "samples"), 10**12, ["tolerance"],
                runner="subprocess", timeout=8.0),
        _absurd(("tolerances", "e_sun_mm"), 1e6, ["tolerance"]),
        _absurd(("tolerances", "seed"), -5, ["tolerance"]),
        _absurd(("tolerances", "window_s"), 1e300, ["tolerance"]),
        _absurd(("bearing", "input_torque_Nm"), math.inf, ["bearing_moments"]),
        _absurd(("bearing", "input_torque_Nm"), -1e30, ["bearing_moments"]),
        _absurd(("tacho", "key_angle_deg"), math.nan, ["ideal_phasing"]),
        _absurd(("input", "stop_s"), -1.0, ph),
        _absurd(("processing", "block_s"), 1e-300, ph),
        _absurd(("processing", "notch_hz"), 1e9, ph),
        _absurd(("channels", 0, "tooth"), 1_000_000_000, ph),
        _absurd(("channels", 0, "gain"), 0.0, ph),
        _absurd(("channels", 0, "gain"), math.nan, ph),
        _absurd(("input",), {"synthetic": "seed_rig", "minutes": 1e9}, ph, key="minutes"),
        # refused by the coaxiality check, whose message names Z_r (on z_planet's line)
        _absurd(("gearset", "z_ring"), 25_000_000, ["ideal_phasing"], key="Z_r",
                runner="subprocess", timeout=20.0, slow=True),
    ]


def scene_cases() -> list[FaultCase]:
    nested_arrays = "a = " + "[" * 5000 + "]" * 5000 + "\n"
    nested_tables = "a = " + "{b = " * 3000 + "1" + "}" * 3000 + "\n"
    base_text = toml_dumps(BASE_SCENE).replace('"RECORDING"', '"rig.h5"')
    latin1 = base_text.replace("seed 000 rig", "Prüfstand 3").encode("latin-1")
    cases = [
        FaultCase("scene/empty", "scene", _scene_text(""), (RUN, CAMPAIGN, GEARSET_RUN), names=("scene",)),
        FaultCase("scene/whitespace-and-comments", "scene", _scene_text("\n  \n# nothing here\n"),
                  (RUN,), names=("scene",)),
        FaultCase("scene/binary-garbage", "scene",
                  _scene_text(bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8))),
                  (RUN, CAMPAIGN, GEARSET_RUN), names=("scene",)),
        FaultCase("scene/ascii-garbage", "scene", _scene_text("}{ ][ = = \n\x7f\x01 ]]\n"), (RUN,),
                  names=("scene",), contains=("line",)),
        FaultCase("scene/nul-bytes", "scene", _scene_text(base_text.replace("\n[speeds]", "\n\x00\x00[speeds]")),
                  (RUN,), names=("scene",), contains=("line",)),
        FaultCase("scene/not-utf8-latin1", "scene", _scene_text(latin1), (RUN, CAMPAIGN, GEARSET_RUN),
                  names=("scene",)),
        FaultCase("scene/not-utf8-utf16", "scene", _scene_text(base_text.encode("utf-16")), (RUN,),
                  names=("scene",)),
        FaultCase("scene/deeply-nested-arrays", "scene", _scene_text(nested_arrays), (RUN, GEARSET_RUN),
                  names=("scene",)),
        FaultCase("scene/deeply-nested-inline-tables", "scene", _scene_text(nested_tables), (RUN,),
                  names=("scene",)),
        FaultCase("scene/10MB-comments-then-unknown-table", "scene", _big_scene("comment"), (RUN,),
                  names=("scene",), contains=("speeds2", "line 1000")),
        FaultCase("scene/10MB-of-channels-not-in-the-file", "scene", _big_scene("channels"), (RUN,),
                  names=("scene",), contains=("channels", "more is not in the file"), runner="subprocess",
                  timeout=20.0, slow=True, max_line=3000),   # 3.4 MB of names before the list was capped
        FaultCase("scene/toml-syntax-error", "scene",
                  _scene_text(base_text.replace("z_sun = 25", "z_sun = "), mark="z_sun = "),
                  (RUN, GEARSET_RUN), names=("scene",), contains=("line {line}",)),
        FaultCase("scene/unterminated-string", "scene",
                  _scene_text(base_text.replace('"seed 000 rig"', '"seed 000 rig')), (RUN,),
                  names=("scene",), contains=("line",)),
        FaultCase("scene/duplicate-key", "scene",
                  _scene_text(base_text.replace("z_sun = 25", "z_sun = 25\nz_sun = 26")), (RUN,),
                  names=("scene",), contains=("line",)),
        FaultCase("scene/duplicate-table", "scene", _scene_text(base_text + "\n[speeds]\nsun_rpm = 1.0\n"),
                  (RUN,), names=("scene",), contains=("line",)),
        FaultCase("scene/unknown-top-level-key", "scene", _scene_with(("colour",), "red"), (RUN, CAMPAIGN),
                  names=("scene",), contains=("colour", "line")),
        FaultCase("scene/unknown-table", "scene", _scene_with(("extras",), {"a": 1}), (RUN,),
                  names=("scene",), contains=("extras", "line")),
        FaultCase("scene/unknown-key-in-gearset", "scene", _scene_with(("gearset", "teeth"), 3), (RUN, GEARSET_RUN),
                  names=("scene",), contains=("teeth", "line")),
        FaultCase("scene/unknown-key-in-channels", "scene", _scene_with(("channels", 0, "polarity"), 1), (RUN,),
                  names=("scene",), contains=("polarity", "line")),
        FaultCase("scene/missing-required-z_ring", "scene", _scene_with(("gearset", "z_ring"), None, drop=True),
                  (RUN, GEARSET_RUN), names=("scene",), contains=("z_ring", "line")),
        FaultCase("scene/unknown-result", "scene", _scene_with(("results",), ["phasing", "everything"]),
                  (RUN,), names=("scene",), contains=("results", "line")),
        FaultCase("scene/no-results", "scene", _scene_with(("results",), None, drop=True), (RUN,),
                  names=("scene",), contains=("results",)),
        FaultCase("scene/recording-missing", "scene", _scene_with(("input", "recording"), "nowhere.h5", ["phasing"]),
                  (RUN,), names=("scene",), contains=("input.recording", "line")),
        FaultCase("scene/recording-truncated", "scene", _scene_naming_truncated, (RUN,),
                  names=("recording",)),
    ]
    return cases + _wrong_type_cases() + _absurd_cases()


def _scene_naming_truncated(ws):
    v = _truncate("hdf5", "mid-data")(ws)
    scene = json.loads(json.dumps(BASE_SCENE))
    scene["results"] = ["phasing"]
    scene["input"] = {"recording": v["input"]}
    out = _scene(ws, scene)
    out["recording"] = v["input"]
    return out


# --------------------------------------------------------------------------- outputs
def _out_at(kind: str):
    def make(ws):
        t = ws.tmp
        if kind == "parent-is-file":
            blocker = t / "plain_file"
            blocker.write_text("x")
            target = blocker / "sub"
        elif kind == "name-too-long":
            target = t / ("o" * 300)
        elif kind == "exists":
            target = t / "existing"
            target.mkdir()
        elif kind == "fifo":
            target = t / "fifo_out"
            os.mkfifo(target)
        elif kind == "device":
            target = t / "null_dev"
            try:
                os.mknod(target, 0o666 | stat.S_IFCHR, os.makedev(1, 3))   # a private /dev/null
            except (PermissionError, AttributeError) as exc:
                raise Skip(f"cannot create a device node here ({exc})")
        elif kind in ("read-only", "disk-full-preflight"):
            target = t / "ro" / "out"
            target.parent.mkdir()
        elif kind in ("tiny-fs", "ro-fs"):
            target = _mount_tmpfs(ws, "size=16k" if kind == "tiny-fs" else "ro,size=16k") / "out"
        else:  # pragma: no cover
            raise ValueError(kind)
        return {"target": str(target), "out": str(t / "unused")}
    return make


def _mount_tmpfs(ws, options: str) -> Path:
    """A real tmpfs (16 KiB, or read-only) at ws.tmp/mnt, unmounted when the case ends."""
    import subprocess

    mnt = ws.tmp / "mnt"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode:
        raise Skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    ws.cleanups.append(lambda: subprocess.run(["umount", "-l", str(mnt)], check=False,
                                              capture_output=True))
    return mnt


class Skip(Exception):
    """A case that cannot be built on this machine (the runner skips it)."""


def _read_only(err: int):
    """Simulated read-only folder ``ro``: every call that would create, link, rename or
    remove something in it raises ``err`` (EACCES: permissions; EROFS: read-only mount)."""
    def patch(mp, values):
        folder = os.path.realpath(Path(values["target"]).parent)

        def inside(p):
            try:
                q = os.path.realpath(os.fspath(p))
            except TypeError:
                return False
            return q == folder or q.startswith(folder + os.sep)

        def guard(fn, creates=lambda *a, **k: True):
            def wrapper(p, *a, **k):
                if inside(p) and creates(p, *a, **k):
                    raise OSError(err, os.strerror(err), os.fspath(p))
                return fn(p, *a, **k)
            return wrapper

        def two(fn):
            def wrapper(src, dst, *a, **k):
                for p in (src, dst):
                    if inside(p):
                        raise OSError(err, os.strerror(err), os.fspath(p))
                return fn(src, dst, *a, **k)
            return wrapper

        writes = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND
        mp.setattr(os, "open", guard(os.open, lambda p, flags, *a, **k: bool(flags & writes)))
        mp.setattr(os, "mkdir", guard(os.mkdir))
        mp.setattr(os, "unlink", guard(os.unlink))
        for name in ("link", "rename", "replace"):
            mp.setattr(os, name, two(getattr(os, name)))
    return patch


def _disk_full(mp, values):
    """``statvfs`` reports no free space on the target's file system."""
    real = os.statvfs

    class _Full:
        def __init__(self, st):
            self._st = st

        def __getattr__(self, name):
            if name in ("f_bavail", "f_bfree"):
                return 0
            return getattr(self._st, name)

    mp.setattr(os, "statvfs", lambda p: _Full(real(p)))


def _still(kind: str):
    test = {"fifo": stat.S_ISFIFO, "device": stat.S_ISCHR, "dir": stat.S_ISDIR}[kind]

    def after(values):
        st = os.lstat(values["target"])
        assert test(st.st_mode), f"{values['target']} was replaced (mode {oct(st.st_mode)})"
    return after


def _not_created(values):
    assert not os.path.lexists(values["target"]) and not os.path.lexists(values["target"] + ".h5"), \
        f"{values['target']} was created by a failed command"
    folder = Path(values["target"]).parent
    if folder.is_dir():
        left = [p.name for p in folder.iterdir() if p.name.endswith(".partial")]
        assert not left, f"temporary files left in {folder}: {left}"


def output_cases() -> list[FaultCase]:
    conv = ("convert", "{input}", "{target}.h5")
    conv_exact = ("convert", "{input}", "{target}", "--format", "hdf5")
    proc = ("process", "{input}", "--gearset", "{gearset}", "--out", "{target}")
    scene_run = ("run", "{scene}", "--out", "{target}", "--no-report")
    cases = [
        FaultCase("output/parent-is-file", "output", _out_at("parent-is-file"), (conv, proc),
                  names=("target",), after=_not_created),
        FaultCase("output/name-too-long", "output", _out_at("name-too-long"), (conv, proc),
                  names=("target",), after=_not_created),
        FaultCase("output/exists-no-overwrite", "output", _out_at("exists"), (conv_exact,),
                  names=("target",), after=_still("dir")),
        FaultCase("output/fifo-with-overwrite", "output", _out_at("fifo"),
                  (conv_exact + ("--overwrite",),), names=("target",), after=_still("fifo")),
        FaultCase("output/device-node-with-overwrite", "output", _out_at("device"),
                  (conv_exact + ("--overwrite",),), names=("target",), after=_still("device")),
        FaultCase("output/read-only-folder", "output", _out_at("read-only"), (conv, proc, scene_run),
                  names=("target",), patch=_read_only(errno.EACCES), after=_not_created),
        FaultCase("output/read-only-file-system-injected", "output", _out_at("read-only"), (conv, proc),
                  names=("target",), patch=_read_only(errno.EROFS), after=_not_created),
        FaultCase("output/read-only-file-system-real", "output", _out_at("ro-fs"), (conv, proc),
                  names=("target",), after=_not_created),
        FaultCase("output/disk-full-preflight", "output", _out_at("disk-full-preflight"), (conv,),
                  names=("target",), patch=_disk_full, after=_not_created),
        FaultCase("output/disk-full-real", "output", _out_at("tiny-fs"), (conv, proc),
                  names=("target",), after=_not_created),
    ]
    return cases


# --------------------------------------------------------------------------- declared, not there
def _unwritten(skip, n_samples=None):
    """HDF5 in chunks of 4096 samples (7 for the 25600 samples of the originals) with the
    chunks ``skip`` never written; ``n_samples`` declares a longer recording."""
    def make(ws):
        p = hdf5_without_chunks(ws.orig.recordings["hdf5"], ws.tmp / "unwritten.h5", set(skip),
                                chunk=4096 if n_samples is None else None, n_samples=n_samples)
        return {"input": str(p), "recording": str(p)}
    return make


def _wide_csv(k: int):
    """A plain CSV whose header has ``k`` channel columns (no units), and two rows."""
    def make(ws):
        p = ws.tmp / "wide.csv"
        with open(p, "w") as f:
            f.write("time [s]," + ",".join(f"c{i}" for i in range(k)) + "\n")
            for r in range(2):
                f.write(f"{r / 5120}," + ",".join(["0.1"] * k) + "\n")
        return {"input": str(p), "recording": str(p)}
    return make


def _absurd_fs(fmt: str, fs: float):
    """The original with its stated sample rate replaced (the header's checks kept valid)."""
    def make(ws):
        src = ws.orig.recordings[fmt]
        p = ws.tmp / f"fs{SUFFIX[fmt]}"
        if fmt == "hdf5":
            import h5py

            p.write_bytes(ws.orig.blob(fmt))
            with h5py.File(p, "r+") as f:
                f.attrs["fs"] = fs
        else:                                   # the CSV preamble's JSON
            first, rest = src.read_bytes().split(b"\n", 1)
            pre = json.loads(first[len(b"# meshphase "):])
            pre["fs"] = fs
            p.write_bytes(b"# meshphase " + json.dumps(pre).encode() + b"\n" + rest)
        return {"input": str(p), "recording": str(p)}
    return make


FORGED = "sun\nmeshphase process: error: fake"


def _forged_name(fmt: str):
    """A channel named :data:`FORGED` in a file of another tool (HDF5 dataset, TDMS channel)."""
    def make(ws):
        data = np.zeros(25600)
        if fmt == "hdf5":
            import h5py

            p = ws.tmp / "forged.h5"
            with h5py.File(p, "w") as f:
                f.create_dataset(FORGED, data=data).attrs["fs"] = 5120.0
        else:
            from nptdms import ChannelObject, TdmsWriter

            p = ws.tmp / "forged.tdms"
            with TdmsWriter(str(p)) as w:
                w.write_segment([ChannelObject("g", FORGED, data, properties={"wf_increment": 1 / 5120})])
        return {"input": str(p), "recording": str(p)}
    return make


def _tdms_cut_at_segment(ws):
    """A TDMS file of another tool (npTDMS, five 1-s segments, its ``.tdms_index`` written
    beside it) cut after its fourth segment: a valid shorter file but for the index."""
    from nptdms import ChannelObject, TdmsWriter

    p = ws.tmp / "segments.tdms"
    rec = ws.orig.rec
    with TdmsWriter(str(p), index_file=True) as w:
        for k in range(5):
            w.write_segment([ChannelObject("g", c.name, rec.data[k * 5120:(k + 1) * 5120, j],
                                           properties={"wf_increment": 1 / rec.fs})
                             for j, c in enumerate(rec.channels)])
    ends = [b for _, b in tdms_regions(p)["data"]]
    with open(p, "r+b") as fh:
        fh.truncate(ends[3])
    return {"input": str(p), "recording": str(p)}


def declared_cases() -> list[FaultCase]:
    cmds = (INFO, PROCESS, CONVERT)
    cases = [FaultCase(f"declared/hdf5/unwritten-{name}", "declared", _unwritten(skip), cmds,
                       contains=("never written",))
             for name, skip in (("chunk-1", (1,)), ("chunks-1-2", (1, 2)), ("chunk-0", (0,)),
                                ("last-chunk", (6,)))]
    cases += [
        FaultCase("declared/hdf5/1e12-samples-none-stored", "declared", _unwritten((), 10 ** 12), cmds,
                  contains=("never written",)),
        FaultCase("declared/hdf5/1e13-samples-none-stored", "declared", _unwritten((), 10 ** 13), cmds,
                  contains=("never written",), runner="subprocess", timeout=60.0),
        FaultCase("declared/csv/2000-columns", "declared", _wide_csv(2000), cmds,
                  contains=("channel columns",), max_line=400),
        FaultCase("declared/csv/10-million-columns", "declared", _wide_csv(10_000_000), (INFO, CONVERT),
                  contains=("longer than",), max_line=400, runner="subprocess", timeout=60.0, slow=True),
        FaultCase("declared/tdms/cut-at-segment-with-index", "declared", _tdms_cut_at_segment, cmds,
                  contains=(".tdms_index",)),
    ]
    for fmt in ("hdf5", "csv"):
        cases.append(FaultCase(f"declared/{fmt}/fs-1e300", "declared", _absurd_fs(fmt, 1e300), cmds,
                               contains=("outside the physical range",)))
    for fmt in ("hdf5", "tdms"):
        cases.append(FaultCase(f"declared/{fmt}/newline-in-channel-name", "declared", _forged_name(fmt), cmds,
                               contains=("control character",)))
    return cases


def signal_cases() -> list[FaultCase]:
    return [
        FaultCase("signal/process/sigterm", "signal", _valid_copy, (PROCESS,), expect=frozenset({143}),
                  names=(), signal=("SIGTERM", False), runner="subprocess", timeout=120.0),
        FaultCase("signal/process/sigkill-then-rerun", "signal", _valid_copy, (PROCESS,),
                  expect=frozenset({-9}), names=(), signal=("SIGKILL", True), runner="subprocess",
                  timeout=120.0, slow=True),
        FaultCase("signal/campaign/ctrl-c", "signal", _valid_folder, (CAMPAIGN,), expect=frozenset({130}),
                  names=(), signal=("SIGINT", False), runner="subprocess", timeout=180.0, slow=True),
    ]


# --------------------------------------------------------------------------- the corpus
def corpus() -> list[FaultCase]:
    """Every case: the default selection (``slow=False``) and the ``-m slow`` sweep (more
    offsets, seeds and keys)."""
    cases = (truncation_cases() + byteflip_cases() + special_cases() + scene_cases() + output_cases()
             + declared_cases() + signal_cases())
    names = [c.name for c in cases]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ValueError(f"duplicate case names: {sorted(dup)}")
    return cases


def outcome_table(runs) -> str:
    """The table of outcomes by category: ``runs`` is an iterable of (category, outcome)
    pairs (:data:`OUTCOMES`), one per case run; a row per category (in :func:`corpus`'s
    order), a column per outcome, and the totals."""
    order = ["truncation", "byteflip", "special", "scene", "output", "declared", "signal"]
    counts: dict = {}
    for cat, outcome in runs:
        if outcome not in OUTCOMES:
            raise ValueError(f"outcome {outcome!r} of a {cat!r} case is none of {OUTCOMES}")
        if cat not in order:
            order.append(cat)
        counts[cat, outcome] = counts.get((cat, outcome), 0) + 1
    cats = [c for c in order if any((c, o) in counts for o in OUTCOMES)]
    head = f"{'category':<12}" + "".join(f"{o:>10}" for o in OUTCOMES) + f"{'total':>8}"
    lines = ["fault corpus: outcome of every case run, by category", head]
    for c in cats + ["all"]:
        row = [sum(counts.get((k, o), 0) for k in (cats if c == "all" else [c])) for o in OUTCOMES]
        lines.append(f"{c:<12}" + "".join(f"{n:>10}" for n in row) + f"{sum(row):>8}")
    return "\n".join(lines)


def _count(cases) -> dict:
    out = {}
    for c in cases:
        out[c.category] = out.get(c.category, 0) + 1
    return out


if __name__ == "__main__":  # pragma: no cover - a listing for people
    every = corpus()
    default = [c for c in every if not c.slow]
    print(f"{len(default)} default cases {_count(default)}; {len(every)} in the full sweep {_count(every)}")
    for c in every:
        flags = ("slow " if c.slow else "") + ("xfail " if c.xfail else "")
        print(f"{c.name:<64} {flags}{' | '.join(' '.join(cmd) for cmd in c.commands)}")
