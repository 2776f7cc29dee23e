"""Step detection and cadence from a phone's accelerometer, wherever the phone is carried.

Orientation-free: the magnitude of the specific force is independent of how the phone sits in a
hand, a pocket or a bag. The pipeline is vectorised end to end (numpy, scipy.signal):

1. bad samples (non-finite, or a magnitude below 1 m/s^2: a sensor warming up) are dropped; the
   rest is put on a uniform grid at min(rate, 25 Hz) after an anti-alias low-pass (scipy's
   ``decimate``-style Butterworth, zero phase), so 5-200 Hz inputs take the same path;
2. gravity and slow drift go with a 2 s moving mean;
3. sliding windows (4 s, hop 0.25 s) are Fourier-transformed at once (``numpy.fft.rfft`` over a
   strided view, zero-padded for 0.01 Hz bins): the step rate is the spectral peak in the step
   band (1.2-2.8 Hz, capped below Nyquist) whose harmonic comb (stride f/2 and its multiples)
   holds the most power: a phone in a trouser pocket sees one leg (a strong stride at f/2) and
   its third harmonic (1.5 f), neither of which passes for the step rate;
4. a window is walking when its signal is periodic (share of band power at the step rate and its
   stride) and strong enough, and the short-term (0.75 s) amplitude is above the floor, so
   starts and stops are found to a fraction of a second;
5. steps are the whole cycles of the integrated step phase: ``phase = integral of cadence dt``
   over walking time, so the count does not depend on resolving each impact (5 Hz samples hold
   fewer than three per step).

Below ``4 x step_band_hz[1]`` (11.2 Hz) the sampling folds the gait's harmonics into the step band
(the step's 2nd harmonic can no longer sit below Nyquist) and step 3 changes (``_cadence_aliased``):

- the step rate is looked for in the gait prior ``aliased_band_hz`` (1.4-2.6 Hz, capped below
  Nyquist), narrower than 2:1 so that a stride (half a step rate) is never inside it;
- each candidate's comb has the stride's first ``aliased_harmonics`` harmonics k f/2, each read
  where the sampling folded it; a bin is credited once per candidate (two teeth folded onto the
  same peak are one piece of evidence), and the step fundamental weighs most: at a rate where the
  samples repeat with a short period (f/fs = 3/7: 2.14 Hz at 5 Hz) a 2.14 Hz walk and a 1.43 Hz
  one fold onto the same lines, and only "the step fundamental is the gait's strongest
  component" (true of every carry at 100 Hz) tells them apart;
- the per-window best is replaced by the most likely cadence *path* (Viterbi): a change of pace
  costs ``cadence_change_cost`` per Hz, in units of one window's evidence, so a fold-over that
  wins a few windows by a hair does not become the cadence, while a real change that persists
  does;
- short gaps (< ``aliased_gap_s``) in the 0.75 s amplitude are closed: sampled at a rate close to a
  multiple of the stride rate, the samples miss a sharp impact for seconds at a time (the beat
  between the two), which is not the walker stopping.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage, signal

__all__ = ["StepConfig", "StepResult", "detect_steps"]

_BAD_MAGNITUDE = 1.0


@dataclass(frozen=True, slots=True)
class StepConfig:
    """Step detection parameters (seconds, hertz, m/s^2)."""

    step_band_hz: tuple[float, float] = (1.2, 2.8)
    stride_band_hz: tuple[float, float] = (0.6, 1.2)
    window_s: float = 4.0
    hop_s: float = 0.25
    max_rate_hz: float = 25.0
    """Signals above this rate are low-passed and resampled down to it (steps are < 3 Hz)."""
    min_amplitude_mps2: float = 0.2
    """Std of the gravity-free magnitude below which nobody is walking."""
    min_periodicity: float = 0.25
    """Share of the window's gait-band power at the step rate (and its stride) to be walking."""
    short_window_s: float = 0.75
    min_window_samples: int = 60
    """Spectral windows hold at least this many samples (12 s at 5 Hz): at low rates a 4 s
    window cannot resolve the step peak from the folded harmonics of the stride."""
    relative_amplitude: float = 0.35
    """Share of the walker's median walking amplitude below which a sample is not walking."""
    aliased_band_hz: tuple[float, float] = (1.4, 2.6)
    """Step rates looked for at rates below 4 x ``step_band_hz[1]``, where the gait's harmonics
    fold into the step band: the adult gait prior (84-156 steps/min), narrower than 2:1 so the
    stride (half the step rate) of any walk in it lies below it."""
    aliased_harmonics: int = 6
    """Stride harmonics in a candidate's comb at those rates (k f/2, k = 1..6: up to 3x the step
    rate, where a pocket's impacts still carry power)."""
    aliased_tooth_weight: float = 0.5
    """Weight of each comb tooth other than the step fundamental (weight 1)."""
    cadence_change_cost: float = 30.0
    """Cost of a change of the step rate between windows, per Hz, in units of one window's best
    comb score (the aliased path only): a 0.5 Hz change costs 15 windows (3 s at 5 Hz) of
    evidence. The held-out protocol (``benchmarks/pdr_cadence.py --holdout``) chose 30 on both
    halves; 10 let a back-pocket walk at 1.52 Hz (f / fs near 4/13) be read at 2.3 Hz."""
    aliased_gap_s: float = 3.0
    """Gaps in the short-term amplitude shorter than this are closed at aliased rates."""


@dataclass(frozen=True, slots=True)
class StepResult:
    """Steps of one phone."""

    t_s: np.ndarray
    """Uniform time grid, seconds from the first good sample."""
    cadence_hz: np.ndarray
    """Step rate on the grid (0 when not walking)."""
    step_times_s: np.ndarray
    """Time of each step, seconds from the first good sample."""
    bad_samples: int
    rate_hz: float
    """Rate of the grid."""

    @property
    def steps(self) -> int:
        return len(self.step_times_s)


def _uniform(t_s: np.ndarray, mag: np.ndarray, cfg: StepConfig) -> tuple[np.ndarray, np.ndarray]:
    dt = np.diff(t_s)
    rate = 1.0 / float(np.median(dt)) if len(dt) else 1.0
    out_rate = min(rate, cfg.max_rate_hz)
    grid = np.arange(t_s[0], t_s[-1], 1.0 / out_rate)
    if rate > out_rate * 1.2:
        # anti-alias at the native rate first (jittered samples: interpolate to native uniform)
        native = np.arange(t_s[0], t_s[-1], 1.0 / rate)
        x = np.interp(native, t_s, mag)
        sos = signal.butter(4, 0.4 * out_rate, fs=rate, output="sos")
        x = signal.sosfiltfilt(sos, x) if len(x) > 30 else x
        return grid, np.interp(grid, native, x)
    return grid, np.interp(grid, t_s, mag)


def _moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    n = max(1, min(n, len(x)))
    k = np.ones(n) / n
    pad = np.pad(x, (n // 2, n - 1 - n // 2), mode="edge")
    return np.convolve(pad, k, mode="valid")


def detect_steps(t_s: np.ndarray, accel: np.ndarray, cfg: StepConfig | None = None) -> StepResult:
    """Steps of a phone from its accelerometer: times (N, seconds) and specific force (N, 3,
    m/s^2, gravity included, any device frame)."""
    cfg = cfg or StepConfig()
    t_s = np.asarray(t_s, float)
    acc = np.asarray(accel, float).reshape(-1, 3)
    mag = np.linalg.norm(acc, axis=1)
    good = np.isfinite(mag) & np.isfinite(t_s) & (mag > _BAD_MAGNITUDE)
    good[1:] &= np.diff(t_s) > 0
    bad = int(np.sum(~good))
    t_s, mag = t_s[good], mag[good]
    empty = StepResult(np.empty(0), np.empty(0), np.empty(0), bad, 0.0)
    if len(t_s) < 8:
        return empty
    t0 = t_s[0]
    grid, x = _uniform(t_s - t0, mag, cfg)
    if len(grid) < 8:
        return empty
    rate = 1.0 / (grid[1] - grid[0])
    x = x - _moving_mean(x, int(round(2.0 * rate)))
    aliased = rate < 4 * cfg.step_band_hz[1]
    cadence = _cadence_aliased(x, rate, cfg) if aliased else _cadence(x, rate, cfg)
    short = max(6, int(round(cfg.short_window_s * rate)))
    amp = np.sqrt(np.maximum(_moving_mean(x * x, short) - _moving_mean(x, short) ** 2, 0))
    # a sample walks when its short-term amplitude is a fair share of this walker's typical
    # walking amplitude (relative: a bag damps what a hand carries; handling the phone before
    # and after a walk is periodic-looking but weaker)
    walking = cadence > 0
    typical = float(np.median(amp[walking])) if walking.any() else 0.0
    floor = max(cfg.min_amplitude_mps2, cfg.relative_amplitude * typical)
    loud = amp >= floor
    if aliased and cfg.aliased_gap_s > 0:
        # the samples can miss sharp impacts for seconds (the beat of the stride and the sampling
        # rate): a gap shorter than a pause is not a stop
        gap = np.ones(max(1, int(round(cfg.aliased_gap_s * rate))), bool)
        loud |= ndimage.binary_closing(loud, gap)
    cadence[~loud] = 0.0
    phase = np.concatenate(([0.0], np.cumsum(cadence[:-1] * np.diff(grid))))
    whole = np.floor(phase + 1e-9)
    idx = np.flatnonzero(np.diff(whole) > 0) + 1
    return StepResult(grid, cadence, grid[idx], bad, float(rate))


def _cadence(x: np.ndarray, rate: float, cfg: StepConfig) -> np.ndarray:
    """Step rate at every grid sample (0 where not walking), from windowed spectra."""
    n = len(x)
    # at low rates a 4 s window holds too few samples to resolve the step peak from the alias
    # of its harmonics (a 4th stride harmonic at 3.5 Hz folds to 1.5 Hz at 5 Hz)
    win = max(cfg.min_window_samples, int(round(cfg.window_s * rate)))
    hop = max(1, int(round(cfg.hop_s * rate)))
    if n < win:
        win = n
    frames = np.lib.stride_tricks.sliding_window_view(x, win)[::hop]
    centres = np.arange(len(frames)) * hop + win // 2
    nfft = int(2 ** np.ceil(np.log2(max(rate / 0.01, win))))
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate)
    keep = int(np.searchsorted(freqs, 2 * cfg.step_band_hz[1] + 0.5))  # highest comb tooth
    spec = np.abs(np.fft.rfft(frames * np.hanning(win), n=nfft, axis=1)[:, :keep]) ** 2
    freqs = freqs[:keep]
    nyq = 0.98 * rate / 2
    s_lo, s_hi = cfg.step_band_hz[0], min(cfg.step_band_hz[1], nyq)
    d_lo, d_hi = cfg.stride_band_hz
    step_band = (freqs >= s_lo) & (freqs <= s_hi)
    stride_band = (freqs >= d_lo) & (freqs < d_hi)
    gait = (freqs >= d_lo) & (freqs <= s_hi)
    if not step_band.any() or not stride_band.any():
        return np.zeros(n)
    # harmonic comb: a gait with step rate f has its stride at f/2 and harmonics at k f/2; the
    # step rate is the candidate whose comb (k = 1..4, below Nyquist) holds the most power, so a
    # strong stride (one leg, a pocket) or its third harmonic (1.5 f) does not pass for steps
    cand = freqs[step_band]
    df = freqs[1] - freqs[0]
    score = np.zeros((len(frames), len(cand)))
    last = spec.shape[1] - 1
    for k, w in ((1, 1.0), (2, 1.0), (3, 0.5), (4, 0.5)):
        # a tooth above Nyquist is where the sampling folded it (a phone sampling at 5 Hz
        # without an anti-alias filter keeps the 3rd and 4th stride harmonics, folded)
        fk = _folded(k * cand / 2, rate)
        ok = fk <= nyq
        if k == 1:
            # a "stride" inside the step band is a slower walker's step: crediting it would
            # make every walk with an impact harmonic count double
            ok &= fk < s_lo
        if not ok.any():
            continue
        idx = np.round(fk[ok] / df).astype(int)
        # the peak of each tooth's +-2-bin neighbourhood: teeth need not sit on a bin
        tooth = np.max([spec[:, np.clip(idx + o, 0, last)] for o in (-2, -1, 0, 1, 2)], axis=0)
        score[:, ok] += w * tooth
    best = score.argmax(axis=1)
    kbin = np.flatnonzero(step_band)[best]
    # locate the rate on the comb's stronger tooth: the step peak, or twice the stride peak
    # (at low sample rates harmonics fold onto the step peak, while the stride stays clean)
    khalf = np.clip(np.round(cand[best] / 2 / df).astype(int), 1, last - 1)
    rows = np.arange(len(frames))
    from_step, from_stride = _refine(freqs, spec, kbin), 2 * _refine(freqs, spec, khalf)
    f = np.where(spec[rows, khalf] > spec[rows, kbin], from_stride, from_step)
    f = np.clip(f, s_lo, s_hi)
    # periodicity: power within 0.15 Hz of the step rate and of half of it, over the gait band
    g_spec, g_freqs = spec[:, gait], freqs[gait]
    near = (np.abs(g_freqs[None, :] - f[:, None]) <= 0.15) | (
        np.abs(g_freqs[None, :] - f[:, None] / 2) <= 0.1
    )
    for k in (3, 4):  # the 3rd and 4th stride harmonics where the sampling folded them
        fk = _folded(k * f / 2, rate)
        near |= (fk[:, None] < 0.98 * rate / 2) & (np.abs(g_freqs[None, :] - fk[:, None]) <= 0.1)
    total = g_spec.sum(axis=1)
    periodic = np.sum(np.where(near, g_spec, 0.0), axis=1) / np.maximum(total, 1e-12)
    std = frames.std(axis=1)
    walking = (periodic >= cfg.min_periodicity) & (std >= cfg.min_amplitude_mps2)
    # a step rate holds for seconds: a median over 5 windows removes single-window jumps
    f = signal.medfilt(f, 5) if len(f) >= 5 else f
    return _per_sample(np.where(walking, f, 0.0), centres, n)


def _per_sample(per_window: np.ndarray, centres: np.ndarray, n: int) -> np.ndarray:
    """Each of ``n`` samples takes the value of the window centred nearest to it."""
    pos = np.clip(np.searchsorted(centres, np.arange(n)), 0, len(centres) - 1)
    prev = np.clip(pos - 1, 0, len(centres) - 1)
    nearest = np.where(
        np.abs(centres[prev] - np.arange(n)) < np.abs(centres[pos] - np.arange(n)), prev, pos
    )
    return np.asarray(per_window[nearest], float)


def _spectra(
    x: np.ndarray, rate: float, win: int, hop: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Hann-windowed power spectra of sliding windows: frames, centre samples, freqs, power."""
    frames = np.lib.stride_tricks.sliding_window_view(x, win)[::hop]
    centres = np.arange(len(frames)) * hop + win // 2
    nfft = int(2 ** np.ceil(np.log2(max(rate / 0.01, win))))
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate)
    spec = np.abs(np.fft.rfft(frames * np.hanning(win), n=nfft, axis=1)) ** 2
    return frames, centres, freqs, spec


def _cadence_aliased(x: np.ndarray, rate: float, cfg: StepConfig) -> np.ndarray:
    """Step rate at every grid sample (0 where not walking) when the sampling folds the gait's
    harmonics into the step band: folded harmonic combs, scored per window, and the most likely
    cadence path through the windows."""
    n = len(x)
    win = min(n, max(cfg.min_window_samples, int(round(cfg.window_s * rate))))
    hop = max(1, int(round(cfg.hop_s * rate)))
    frames, centres, freqs, spec = _spectra(x, rate, win, hop)
    nyq = 0.98 * rate / 2
    s_lo, s_hi = cfg.aliased_band_hz[0], min(cfg.aliased_band_hz[1], nyq)
    band = (freqs >= s_lo) & (freqs <= s_hi)
    if not band.any():
        return np.zeros(n)
    cand = freqs[band]
    # two teeth closer than the Hann main lobe's half-width (2 / window) read the same peak
    resolution = 2.0 * rate / win
    score = _folded_comb(spec, freqs, cand, rate, resolution, cfg)
    emit = score / np.maximum(score.max(axis=1, keepdims=True), 1e-12)
    best = _cadence_path(emit, cand, cfg.cadence_change_cost)
    f = np.clip(_refine(freqs, spec, np.flatnonzero(band)[best]), s_lo, s_hi)
    # periodicity: the share of the window's power (above the 2 s detrend) on the comb's teeth
    gait = (freqs >= 0.3) & (freqs <= nyq)
    near = np.zeros(spec.shape, bool)
    for k in range(1, cfg.aliased_harmonics + 1):
        fk = _folded(k * f / 2, rate)
        near |= (fk[:, None] <= nyq) & (np.abs(freqs[None, :] - fk[:, None]) <= resolution / 2)
    near &= gait[None, :]
    total = spec[:, gait].sum(axis=1)
    periodic = np.sum(np.where(near, spec, 0.0), axis=1) / np.maximum(total, 1e-12)
    walking = (periodic >= cfg.min_periodicity) & (frames.std(axis=1) >= cfg.min_amplitude_mps2)
    return _per_sample(np.where(walking, f, 0.0), centres, n)


def _folded_comb(
    spec: np.ndarray,
    freqs: np.ndarray,
    cand: np.ndarray,
    rate: float,
    resolution: float,
    cfg: StepConfig,
) -> np.ndarray:
    """Score (window x candidate step rate) of each candidate's folded stride-harmonic comb."""
    df = freqs[1] - freqs[0]
    last = spec.shape[1] - 1
    nyq = 0.98 * rate / 2

    def tooth(fk: np.ndarray) -> np.ndarray:
        # the peak of each tooth's +-2-bin neighbourhood: teeth need not sit on a bin
        idx = np.round(fk / df).astype(int)
        return np.max([spec[:, np.clip(idx + o, 0, last)] for o in (-2, -1, 0, 1, 2)], axis=0)

    score = tooth(cand)
    placed = [cand]
    for k in range(1, cfg.aliased_harmonics + 1):
        if k == 2:
            continue  # the step fundamental, already scored
        fk = _folded(k * cand / 2, rate)
        ok = fk <= nyq
        for p in placed:
            ok &= np.abs(fk - p) > resolution
        placed.append(np.where(ok, fk, -np.inf))
        score += cfg.aliased_tooth_weight * np.where(ok[None, :], tooth(fk), 0.0)
    return np.asarray(score, float)


def _cadence_path(emit: np.ndarray, cand: np.ndarray, cost_per_hz: float) -> np.ndarray:
    """Index of the candidate of each window on the path maximising the summed evidence minus
    ``cost_per_hz`` per Hz of change between consecutive windows (Viterbi)."""
    n_win, n_cand = emit.shape
    cost = cost_per_hz * np.abs(cand[:, None] - cand[None, :])
    acc = emit[0].copy()
    back = np.zeros((n_win, n_cand), dtype=np.int32)
    cols = np.arange(n_cand)
    for w in range(1, n_win):
        moves = acc[None, :] - cost
        back[w] = moves.argmax(axis=1)
        acc = moves[cols, back[w]] + emit[w]
    path = np.empty(n_win, dtype=np.int64)
    path[-1] = int(acc.argmax())
    for w in range(n_win - 1, 0, -1):
        path[w - 1] = back[w, path[w]]
    return path


def _folded(f: np.ndarray, rate: float) -> np.ndarray:
    """Where frequencies ``f`` appear in a signal sampled at ``rate`` (aliasing)."""
    return np.asarray(np.abs((f + rate / 2) % rate - rate / 2), float)


def _refine(freqs: np.ndarray, spec: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Peak frequencies refined by a parabola through the peak bin and its neighbours."""
    rows = np.arange(len(k))
    k = np.clip(k, 1, spec.shape[1] - 2)
    a, b, c = spec[rows, k - 1], spec[rows, k], spec[rows, k + 1]
    den = a - 2 * b + c
    off = np.where(np.abs(den) > 1e-12, 0.5 * (a - c) / np.where(den == 0, 1, den), 0.0)
    return np.asarray(freqs[k] + np.clip(off, -0.5, 0.5) * (freqs[1] - freqs[0]), float)
