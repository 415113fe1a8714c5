"""What real rig recordings carry besides the gear physics.

Every artefact is switchable and off by default (:class:`meshphase.synthetic.config.Artefacts`); a
scenario that asks for none gets none and pays nothing for them. The functions here are
array functions (numpy in, numpy out); the generator (:mod:`meshphase.synthetic.generate`) applies them
per block in this order::

    strain = (1 + gain_error) * pulses               mechanical strain seen by the gauge
           + drift(t)                                slow thermal apparent strain
           + white + 1/f noise                       at the requested SNR
           + hum(t)                                  mains pick-up, 50/60 Hz and harmonics
    -> clip(clip_level)                              amplifier saturation
    -> quantise(adc_bits, adc_range)                 ADC codes (also clips at the ADC range)
    -> NaN over gaps and dropped samples             data lost by the acquisition

Definitions
-----------
SNR
    ``SNR_dB = 20 log10(A / sigma)`` with ``A`` the gauge's nominal pulse peak strain (equal
    load sharing, centred load, no gain error) and ``sigma`` the RMS of the broadband noise
    (white plus 1/f together). ``pink_fraction`` is the share of the noise power in the 1/f
    part. Hum and drift are given as absolute strains and are not part of sigma.
1/f noise
    White noise through a cascade of first-order pole-zero pairs, two per decade from
    ``pink_fmin`` up to ``fs / 2`` (matched z-transform), which follows -10 dB/decade to
    within about +-0.3 dB in that band and is flat below ``pink_fmin``; scaled to unit
    variance from the numerically integrated filter response. The filter starts from a
    burn-in of ``5 / (2 pi pink_fmin)`` seconds so the first samples are already stationary.
Thermal drift
    ``d(t) = D (1 - exp(-t / T_th))``: the gauge bridge warming towards a new balance
    (amplitude ``D`` [m/m], time constant ``T_th`` [s]); t is the recording time from its
    first sample.
Hum
    ``h(t) = H sum_k c_k sin(2 pi k f_mains t + phi_k)`` with harmonic weights ``c_k``
    (default 1, 0, 0.25: odd harmonics dominate) and random phases per channel.
Quantisation
    ``LSB = 2 R / 2^bits``; samples become ``LSB * clip(rint(x / LSB), -2^(bits-1),
    2^(bits-1) - 1)``, so a quantised channel also clips at the ADC range ``+-R``.
Gaps
    Gaps start as a Poisson process of rate ``gap_rate`` [1/s] with exponentially
    distributed lengths of mean ``gap_length`` [s] (at least one sample); dropped samples are
    single-sample gaps at rate ``dropout_rate`` [1/s]. A gap hits every channel (the DAQ
    lost the frame) and reads NaN.

Reproducibility
---------------
Noise is drawn in fixed chunks of :data:`NOISE_CHUNK` samples, each from its own stream
``SeedSequence(seed, spawn_key=(stream, channel, chunk))``; the samples therefore do not
depend on how the recording is cut into blocks, and the 1/f filter carries its state from
block to block. scipy.signal (the 1/f filter's design and its ``sosfilt``) is imported only
when a channel has 1/f noise: with scipy.stats under it, it was most of this package's
import, which the white-noise scenarios (the demo's among them) paid for nothing.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from meshphase.validate import as_nonnegative, as_positive, as_positive_int

__all__ = ["NOISE_CHUNK", "STREAMS", "stream_rng", "pink_filter", "NoiseSource", "drift",
           "hum", "HumSource", "clip", "quantise", "draw_gaps", "apply_gaps"]

#: Samples per noise chunk (each chunk has its own random stream).
NOISE_CHUNK = 1 << 16

#: Stream identifiers of the random generator (spawn keys).
STREAMS = {"white": 1, "pink": 2, "pink_burn_in": 3, "setup": 4, "gaps": 5, "errors": 6}


def stream_rng(seed: int, stream: str, *keys: int) -> np.random.Generator:
    """Independent generator for one named stream (and sub-keys) of a recording's seed."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(STREAMS[stream],) + tuple(int(k) for k in keys)))


def pink_filter(fs: float, fmin: float) -> tuple[np.ndarray, float]:
    """Second-order sections of a 1/f (pink) shaping filter and its output RMS.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    fmin : float
        Lowest frequency of the 1/f band [Hz]; the spectrum is flat below it. Must be below
        ``fs / 20``.

    Returns
    -------
    sos : ndarray, shape (n_sections, 6)
        Filter sections (scipy.signal layout).
    rms : float
        RMS of the output for unit-variance white input [-].

    Notes
    -----
    Poles at ``fmin 10^(k/2)`` up to ``fs / 2``, each followed by a zero a quarter decade
    higher (matched z-transform ``exp(-2 pi f / fs)``): the magnitude falls 10 dB/decade with
    about +-0.3 dB ripple. The output variance is ``(1/pi) int_0^pi |H(e^jw)|^2 dw``,
    integrated on a fine logarithmic grid.
    """
    fs = as_positive(fs, "fs")
    fmin = as_positive(fmin, "pink_fmin")
    if fmin >= fs / 20.0:
        raise ValueError(f"pink_fmin must be below fs / 20 = {fs / 20.0!r} Hz, got {fmin!r}")
    sos, rms = _pink_filter(fs, fmin)
    return sos.copy(), rms


@functools.lru_cache(maxsize=16)
def _pink_filter(fs: float, fmin: float) -> tuple[np.ndarray, float]:
    from scipy import signal   # only for 1/f noise (module notes)

    n_dec = math.log10(0.5 * fs / fmin)
    n_poles = max(1, int(math.ceil(2.0 * n_dec)))
    fp = fmin * 10.0 ** (0.5 * np.arange(n_poles))
    fz = fp * 10.0 ** 0.25
    p = np.exp(-2.0 * np.pi * fp / fs)
    z = np.exp(-2.0 * np.pi * np.minimum(fz, 0.49 * fs) / fs)
    sos = signal.zpk2sos(z, p, 1.0)
    w = np.concatenate([[0.0], np.geomspace(1e-4 * 2 * np.pi * fmin / fs, np.pi, 40000)])
    _, h = signal.sosfreqz(sos, worN=w)
    var = np.trapezoid(np.abs(h) ** 2, w) / np.pi
    return sos, float(math.sqrt(var))


class NoiseSource:
    """White plus 1/f noise for one channel, produced block by block in sample order.

    Parameters
    ----------
    seed : int
        Seed of the recording.
    channel : int
        Channel index (selects the stream).
    fs : float
        Sample rate [Hz].
    sigma : float
        RMS of the total noise [m/m].
    pink_fraction : float
        Share of the noise power in the 1/f part [-], in [0, 1].
    pink_fmin : float
        Lowest frequency of the 1/f band [Hz].
    """

    def __init__(self, seed: int, channel: int, fs: float, sigma: float,
                 pink_fraction: float = 0.0, pink_fmin: float = 0.05):
        self.seed = int(seed)
        self.channel = int(channel)
        self.fs = as_positive(fs, "fs")
        sigma = as_nonnegative(sigma, "sigma")
        pf = as_nonnegative(pink_fraction, "pink_fraction")
        if pf > 1.0:
            raise ValueError(f"pink_fraction must be in [0, 1], got {pf!r}")
        self.sigma_white = sigma * math.sqrt(1.0 - pf)
        self.sigma_pink = sigma * math.sqrt(pf)
        self._next = 0
        self._buf = {}
        self._tmp = np.empty(NOISE_CHUNK)
        self._zi = None
        if self.sigma_pink > 0.0:
            from scipy.signal import sosfilt   # only for 1/f noise (module notes)

            self._sosfilt = sosfilt
            self.sos, rms = pink_filter(self.fs, pink_fmin)
            self._pink_scale = self.sigma_pink / rms
            n_burn = int(math.ceil(5.0 * self.fs / (2.0 * math.pi * pink_fmin)))
            zi = np.zeros((self.sos.shape[0], 2))
            burn = stream_rng(self.seed, "pink_burn_in", self.channel).standard_normal(n_burn)
            _, self._zi = sosfilt(self.sos, burn, zi=zi)

    def _chunk(self, stream: str, c: int) -> np.ndarray:
        """Normals of chunk ``c`` of ``stream`` (kept in a reused buffer per stream)."""
        buf, cur = self._buf.get(stream, (None, None))
        if buf is None:
            buf = np.empty(NOISE_CHUNK)
        if cur != c:
            stream_rng(self.seed, stream, self.channel, c).standard_normal(out=buf)
        self._buf[stream] = (buf, c)
        return buf

    def add_to(self, out: np.ndarray, i0: int) -> None:
        """Add the noise of samples ``i0 <= i < i0 + len(out)`` to ``out`` (in place).

        Blocks must come in order (``i0`` equal to the end of the previous call): the 1/f
        filter carries its state. A ValueError names the expected start otherwise.
        """
        n = out.shape[0]
        if n == 0:
            return
        if i0 != self._next:
            raise ValueError(f"noise blocks must be sequential: expected start sample {self._next}, got {i0}")
        self._next = i0 + n
        tmp = self._tmp
        c0, c1 = i0 // NOISE_CHUNK, (i0 + n - 1) // NOISE_CHUNK
        for c in range(c0, c1 + 1):
            a = max(i0, c * NOISE_CHUNK)
            b = min(i0 + n, (c + 1) * NOISE_CHUNK)
            ja, jb = a - c * NOISE_CHUNK, b - c * NOISE_CHUNK
            seg = out[a - i0:b - i0]
            t = tmp[:jb - ja]
            if self.sigma_white > 0.0:
                np.multiply(self._chunk("white", c)[ja:jb], self.sigma_white, out=t)
                seg += t
            if self.sigma_pink > 0.0:
                y, self._zi = self._sosfilt(self.sos, self._chunk("pink", c)[ja:jb], zi=self._zi)
                y *= self._pink_scale
                seg += y


def drift(t, amplitude: float, time_constant: float) -> np.ndarray:
    """Thermal drift ``D (1 - exp(-t / T_th))`` [m/m] at times ``t`` [s] from the first sample.

    Parameters
    ----------
    t : array_like
        Times from the first sample [s].
    amplitude : float
        Final drift D [m/m] (any sign).
    time_constant : float
        Thermal time constant T_th [s].
    """
    tc = as_positive(time_constant, "drift_time_constant")
    return float(amplitude) * -np.expm1(-np.asarray(t, dtype=np.float64) / tc)


def hum(i, fs: float, amplitude: float, frequency: float, phases, harmonics=(1.0, 0.0, 0.25)) -> np.ndarray:
    """Mains hum at absolute sample indices ``i`` [m/m] (reference evaluation).

    Parameters
    ----------
    i : array_like of int
        Absolute sample indices (time i / fs from the first sample).
    fs : float
        Sample rate [Hz].
    amplitude : float
        Amplitude H of the fundamental [m/m].
    frequency : float
        Mains frequency f_mains [Hz] (50 or 60).
    phases : array_like, shape (n_harmonics,)
        Phase of each harmonic [rad].
    harmonics : sequence of float
        Weights c_k of harmonics k = 1, 2, ... [-].

    Notes
    -----
    The phase ``k f i / fs`` is reduced modulo one cycle before the sine, so long recordings
    keep full precision. :class:`HumSource` produces the same signal faster, block by block.
    """
    fs = as_positive(fs, "fs")
    f = as_positive(frequency, "hum_frequency")
    ii = np.asarray(i, dtype=np.float64)
    out = np.zeros(ii.shape)
    for k, (c, ph) in enumerate(zip(harmonics, phases), start=1):
        if c == 0.0:
            continue
        cyc = np.mod(ii * (k * f / fs), 1.0)
        out += (amplitude * c) * np.sin(2.0 * np.pi * cyc + ph)
    return out


class HumSource:
    """Mains hum of one recording, evaluated block by block by angle addition.

    Sample ``i = c C + j`` (``C`` = :data:`NOISE_CHUNK`) of harmonic k reads
    ``H c_k Im(exp(i (w_k c C + phi_k)) exp(i w_k j))`` with ``w_k = 2 pi k f / fs``: the
    ``exp(i w_k j)`` table is computed once, the chunk factor once per chunk (phase reduced
    modulo one cycle first). The value of a sample depends only on (c, j), so it does not
    depend on how the recording is cut into blocks. Matches :func:`hum` to ~1e-15 of H.

    Parameters
    ----------
    fs, amplitude, frequency, harmonics
        As :func:`hum`.
    """

    def __init__(self, fs: float, amplitude: float, frequency: float, harmonics=(1.0, 0.0, 0.25)):
        self.fs = as_positive(fs, "fs")
        self.f = as_positive(frequency, "hum_frequency")
        self.amplitude = float(amplitude)
        self.harmonics = tuple(float(c) for c in harmonics)
        j = np.arange(NOISE_CHUNK, dtype=np.float64)
        self._tab = {}
        for k, c in enumerate(self.harmonics, start=1):
            if c != 0.0:
                ang = 2.0 * np.pi * np.mod(j * (k * self.f / self.fs), 1.0)
                self._tab[k] = (np.cos(ang), np.sin(ang))

    def add_to(self, out: np.ndarray, i0: int, phases) -> None:
        """Add the hum of samples ``i0 <= i < i0 + len(out)`` with harmonic ``phases`` [rad]."""
        n = out.shape[0]
        if n == 0 or self.amplitude == 0.0:
            return
        c0, c1 = i0 // NOISE_CHUNK, (i0 + n - 1) // NOISE_CHUNK
        for c in range(c0, c1 + 1):
            a = max(i0, c * NOISE_CHUNK)
            b = min(i0 + n, (c + 1) * NOISE_CHUNK)
            ja, jb = a - c * NOISE_CHUNK, b - c * NOISE_CHUNK
            seg = out[a - i0:b - i0]
            for k, (ct, st) in self._tab.items():
                cyc = math.fmod(float(c * NOISE_CHUNK) * (k * self.f / self.fs), 1.0)
                ph = 2.0 * math.pi * cyc + float(phases[k - 1])
                amp = self.amplitude * self.harmonics[k - 1]
                # Im(z (ct + i st)) with z = amp (cos ph + i sin ph)
                seg += (amp * math.sin(ph)) * ct[ja:jb]
                seg += (amp * math.cos(ph)) * st[ja:jb]


def clip(x: np.ndarray, level: float) -> np.ndarray:
    """Amplifier saturation: ``x`` limited to ``[-level, level]`` [m/m] (in place, returned)."""
    lv = as_positive(level, "clip_level")
    return np.clip(x, -lv, lv, out=x)


def quantise(x: np.ndarray, bits: int, full_scale: float) -> np.ndarray:
    """ADC quantisation to ``bits`` over ``[-full_scale, full_scale]`` (in place, returned).

    Parameters
    ----------
    x : ndarray
        Samples [m/m]; NaN stays NaN.
    bits : int
        ADC resolution [bit], 2..32 (24 for NI 9234-class, 16 for cheaper cards).
    full_scale : float
        Input range R [m/m]: codes span -2^(bits-1) .. 2^(bits-1) - 1 of LSB = 2 R / 2^bits.
    """
    b = as_positive_int(bits, "adc_bits")
    if not 2 <= b <= 32:
        raise ValueError(f"adc_bits must be in [2, 32], got {b!r}")
    fsr = as_positive(full_scale, "adc_range")
    lsb = 2.0 * fsr / 2.0 ** b
    np.divide(x, lsb, out=x)
    np.rint(x, out=x)
    np.clip(x, -(2.0 ** (b - 1)), 2.0 ** (b - 1) - 1.0, out=x)
    np.multiply(x, lsb, out=x)
    return x


def draw_gaps(rng: np.random.Generator, n_samples: int, fs: float, gap_rate: float = 0.0,
              gap_length: float = 0.05, dropout_rate: float = 0.0) -> np.ndarray:
    """Sample ranges lost by the acquisition, as sorted, merged ``[start, stop)`` rows.

    Parameters
    ----------
    rng : numpy.random.Generator
    n_samples : int
        Length of the recording [samples].
    fs : float
        Sample rate [Hz].
    gap_rate : float
        Rate of gaps [1/s] (Poisson).
    gap_length : float
        Mean gap length [s] (exponential, at least one sample).
    dropout_rate : float
        Rate of single dropped samples [1/s] (Poisson).

    Returns
    -------
    ndarray of int64, shape (n_gaps, 2)
    """
    fs = as_positive(fs, "fs")
    rate = as_nonnegative(gap_rate, "gap_rate")
    mean = as_positive(gap_length, "gap_length")
    drop = as_nonnegative(dropout_rate, "dropout_rate")
    n = int(n_samples)
    if n <= 0:
        return np.empty((0, 2), dtype=np.int64)
    dur = n / fs
    k = int(rng.poisson(rate * dur)) if rate > 0 else 0
    starts = rng.integers(0, n, size=k)
    lengths = np.maximum(1, np.rint(rng.exponential(mean * fs, size=k))).astype(np.int64)
    m = int(rng.poisson(drop * dur)) if drop > 0 else 0
    d = rng.integers(0, n, size=m)
    s = np.concatenate([starts, d]).astype(np.int64)
    e = np.minimum(n, np.concatenate([starts + lengths, d + 1])).astype(np.int64)
    if s.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    order = np.argsort(s, kind="stable")
    s, e = s[order], e[order]
    # merge overlapping / touching runs
    run_end = np.maximum.accumulate(e)
    new = np.concatenate([[True], s[1:] > run_end[:-1]])
    grp = np.cumsum(new) - 1
    starts_m = s[new]
    ends_m = np.zeros(starts_m.size, dtype=np.int64)
    np.maximum.at(ends_m, grp, e)
    return np.stack([starts_m, ends_m], axis=1)


def apply_gaps(out: np.ndarray, i0: int, gaps: np.ndarray) -> None:
    """Set the samples of ``out`` (rows = samples ``i0 ...``) inside ``gaps`` to NaN."""
    n = out.shape[0]
    if n == 0 or gaps.size == 0:
        return
    a = int(np.searchsorted(gaps[:, 1], i0, side="right"))
    b = int(np.searchsorted(gaps[:, 0], i0 + n, side="left"))
    for s, e in gaps[a:b]:
        out[max(0, s - i0):max(0, min(n, e - i0))] = np.nan
