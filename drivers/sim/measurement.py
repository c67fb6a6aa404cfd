"""The simulated DAQ's measurement chain of the phase currents: sensor, interference, filter, ADC.

Each effect is a ``[sim]`` option, off by default (then :class:`CurrentChain` is inactive and the bench
samples the ideal currents exactly as before these options existed). Per channel x (a, b, c):

    analog_x(t) = (1 + g_x)·(i_x(t) + r_x(t)) + dc_x + d_x(t) + h_x(t)

* i_x — the ideal phase current −i_q·sin(θ_e + shift_x);
* r_x — PWM ripple, first-order model of a sine-triangle modulated half bridge: the ripple's
  peak-to-peak is V_dc·d(1−d)/(L·f_pwm), and with the duty d = ½(1 + m·sin(θ_e + shift_x)) that is
  ∝ 1 − m²·sin²(θ_e + shift_x). So r_x = A·(1 − m²·sin²(θ_e + shift_x))·tri(f_pwm·t + φ), with
  A = ``pwm_ripple_A`` and the modulation index m = ``pwm_modulation_at_top``·|ω_m|/(1000 rpm) (back-EMF
  ∝ speed), capped at 1. The envelope puts sidebands at f_pwm ± 2·f_e around every carrier harmonic;
  tri is the unit triangle wave's Fourier series (odd harmonics, 1/k², up to the 15th — the rest is
  below 0.5 % of A);
* g_x — sensor gain error (``current_gain_errors``); dc_x — the bench's DC offsets;
* d_x — slow offset drift ``offset_drift_A``·sin(2π·t/``offset_drift_period_s`` + φ_x), every channel;
* h_x — mains hum on ``mains_phase`` only:
  ``mains_hum_A``·(sin(2π·f·t + φ_1) + Σ a_h·sin(2π·h·f·t + φ_h)), f = ``mains_hz``, a_h = ``mains_harmonics``
  for h = 2, 3, ….

Then the card: with ``daq_antialias`` the analog signal is evaluated at M times the sample rate and
passed through a linear-phase (Kaiser-window FIR) low-pass — passband to 0.45·rate, 80 dB from 0.55·rate,
like a delta-sigma card's digital filter, its group delay compensated (a constant delay would only be a
clock offset) — and every M-th value is kept; ripple harmonics above 0.45·M·rate are left out in that
mode (the card's analog filter has removed them long before). Without it each sample is the analog
value at its instant, so the ripple folds (16 kHz at 10 kS/s lands at 4 kHz). The ADC noise
(``current_noise_A``, added by the bench) follows, then quantisation to ``daq_bits`` over
±``daq_range_A`` (step 2·range/2^bits, clipped to the range). Phases φ come from ``seed``; every
value is a function of the sample index, never of the read pattern.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from drivers.config import SimSettings
from drivers.motion import RPM_TO_RAD_S

TOP_SPEED_RAD_S = 1000.0 * RPM_TO_RAD_S  # the speed at which the modulation index is pwm_modulation_at_top
MAX_RIPPLE_HARMONIC = 15
AA_PASSBAND = 0.45   # × rate: passband edge of the anti-alias filter
AA_STOPBAND = 0.55   # × rate: 80 dB from here
AA_ATTENUATION_DB = 80.0
MIN_OVERSAMPLING = 4


class CurrentChain:
    """Sensor, interference, anti-alias filter and ADC of the simulated DAQ (see the module docstring)."""

    def __init__(self, s: SimSettings, channels: tuple[str, ...], rate_hz: float) -> None:
        self.s, self.channels, self.rate_hz = s, channels, rate_hz
        self.gain = np.array([1.0 + s.current_gain_errors.get(c, 0.0) for c in channels])[:, None]
        self.active = bool(s.daq_antialias or s.daq_bits or s.pwm_ripple_A or s.mains_hum_A or s.offset_drift_A
                           or np.any(self.gain != 1.0))
        rng = np.random.default_rng([s.seed % 2**64, 13])
        self.pwm_phase = float(rng.uniform(0.0, 1.0))
        self.hum_phases_rad = rng.uniform(0.0, 2 * np.pi, 1 + len(s.mains_harmonics))
        self.drift_phases_rad = rng.uniform(0.0, 2 * np.pi, len(channels))[:, None]
        if s.daq_antialias:
            self.oversampling = max(MIN_OVERSAMPLING, math.ceil(4.0 * s.pwm_hz / rate_hz))
            fs = self.oversampling * rate_hz
            numtaps, beta = signal.kaiserord(AA_ATTENUATION_DB, (AA_STOPBAND - AA_PASSBAND) * rate_hz / (fs / 2))
            numtaps |= 1  # odd: a symmetric filter centred on the kept sample
            self.taps = signal.firwin(numtaps, 0.5 * (AA_PASSBAND + AA_STOPBAND) * rate_hz, window=("kaiser", beta),
                                      fs=fs)
            self.max_ripple_harmonic = max(1, math.floor(AA_PASSBAND * fs / s.pwm_hz))
        else:
            self.oversampling, self.taps = 1, np.ones(1)
            self.max_ripple_harmonic = MAX_RIPPLE_HARMONIC
        self.half_taps = self.taps.size // 2
        self.lookback_samples = math.ceil(self.half_taps / self.oversampling)

    def describe(self) -> dict[str, object]:
        """The chain's derived constants for the truth record."""
        return {"active": self.active, "oversampling": self.oversampling, "aa_taps": int(self.taps.size),
                "pwm_phase": self.pwm_phase, "max_ripple_harmonic": self.max_ripple_harmonic,
                "quantum_A": self.quantum_A}

    @property
    def quantum_A(self) -> float:
        """ADC step, A (0 when not quantised)."""
        return 2.0 * self.s.daq_range_A / 2**self.s.daq_bits if self.s.daq_bits else 0.0

    def analog_indices(self, first_index: int, count: int) -> np.ndarray:
        """Fractional DAQ sample indices at which the analog signal is needed for samples ``first_index …``."""
        M, h = self.oversampling, self.half_taps
        return np.arange(first_index * M - h, (first_index + count - 1) * M + h + 1) / M

    def analog(self, t_s: np.ndarray, ideal_a: np.ndarray, angle_rad: np.ndarray, omega_m_rad_s: np.ndarray
               ) -> np.ndarray:
        """Analog sensor outputs (A), shape like ``ideal_a`` (channels, n), at drive times ``t_s`` (s).

        ``angle_rad`` is θ_e + shift per channel, ``omega_m_rad_s`` the motor speed (for the modulation).
        DC offsets are the bench's (added by the caller).
        """
        s = self.s
        out = ideal_a.copy()
        if s.pwm_ripple_A:
            m = np.minimum(s.pwm_modulation_at_top * np.abs(omega_m_rad_s) / TOP_SPEED_RAD_S, 1.0)
            out += s.pwm_ripple_A * (1.0 - m**2 * np.sin(angle_rad) ** 2) * self._triangle(s.pwm_hz * t_s)
        out *= self.gain
        if s.offset_drift_A:
            out += s.offset_drift_A * np.sin(2 * np.pi * t_s / s.offset_drift_period_s + self.drift_phases_rad)
        if s.mains_hum_A and s.mains_phase in self.channels:
            amps = [1.0, *s.mains_harmonics]
            hum = sum(a * np.sin(2 * np.pi * (h + 1) * s.mains_hz * t_s + ph)
                      for h, (a, ph) in enumerate(zip(amps, self.hum_phases_rad)))
            out[self.channels.index(s.mains_phase)] += s.mains_hum_A * hum
        return out

    def _triangle(self, cycles: np.ndarray) -> np.ndarray:
        """Unit triangle wave (peak 1) of phase ``cycles`` (periods), odd harmonics up to the chain's limit."""
        x = 2 * np.pi * (cycles + self.pwm_phase)
        out = np.zeros_like(x)
        for k in range(1, self.max_ripple_harmonic + 1, 2):
            out += (-1) ** ((k - 1) // 2) * np.sin(k * x) / k**2
        return out * (8.0 / np.pi**2)

    def acquire(self, analog_a: np.ndarray) -> np.ndarray:
        """The card's samples (channels, count) from :meth:`analog` at :meth:`analog_indices`: filtered and
        decimated with the anti-alias filter, or the analog values themselves without it."""
        if self.taps.size == 1:
            return analog_a
        return signal.oaconvolve(analog_a, self.taps[None, :], mode="valid", axes=1)[:, ::self.oversampling]

    def digitise(self, y_a: np.ndarray) -> np.ndarray:
        """Quantise to the ADC step and clip to ±range (A); unchanged if not quantised."""
        q = self.quantum_A
        if not q:
            return y_a
        return np.clip(np.round(y_a / q) * q, -self.s.daq_range_A, self.s.daq_range_A - q)
