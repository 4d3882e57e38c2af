"""OpenSim's own low-pass of coordinate files: reflect-pad, then a third-order IIR run twice.

OpenSim's InverseDynamicsTool and AnalyzeTool filter a coordinates file as
``Storage.pad(n // 2)`` followed by ``Storage.lowpassIIR(cutoff)``
(opensim-core ``OpenSim/Common/Storage.cpp``, ``Signal.cpp``):

* :func:`reflect_pad` -- ``Signal::Pad``: ``p`` samples prepended and appended,
  reflected about the end sample and negated (``2 x_0 - x_k``), so the value
  and the slope at each end are kept; the time column is padded the same way.
* :func:`lowpass_iir` -- ``Signal::LowpassIIR``: a third-order Butterworth
  low-pass by the bilinear transform with pre-warping, ``w_a = tan(pi f_c T)``,
  ``H(z) = w_a^3 (1 + z^-1)^3 / D(z)``, run forwards, then backwards, each pass
  starting with its first three outputs equal to its inputs (OpenSim's start,
  not a steady state).  A cut-off at or above half the sampling rate is
  lowered to 0.49 times the rate, as OpenSim does.

Both work on time-first arrays ``(N,)`` or ``(N, k)``, all columns at once.
"""
from __future__ import annotations

import numpy as np

from ..errors import TrialError

__all__ = ["reflect_pad", "lowpass_iir", "iir_coefficients"]


def reflect_pad(x, pad: int) -> np.ndarray:
    """``x`` (N,) or (N, k) with ``pad`` samples added at each end, reflected and negated about the end
    samples (OpenSim's ``Signal::Pad``); a pad of N or more is built up in steps, as OpenSim does."""
    x = np.asarray(x, dtype=float)
    pad = int(pad)
    if pad <= 0:
        return x
    if x.shape[0] < 2:
        raise TrialError(f"padding needs at least 2 samples, got {x.shape[0]}")
    target = x.shape[0] + 2 * pad
    while x.shape[0] < target:
        p = min((target - x.shape[0]) // 2, x.shape[0] - 1)
        head = 2.0 * x[0] - x[p:0:-1]
        tail = 2.0 * x[-1] - x[-2:-2 - p:-1]
        x = np.concatenate([head, x, tail], axis=0)
    return x


def iir_coefficients(rate: float, cutoff: float) -> tuple[np.ndarray, np.ndarray, float]:
    """``(numerator, denominator, cutoff used)`` of OpenSim's third-order IIR low-pass at ``rate`` Hz."""
    rate, cutoff = float(rate), float(cutoff)
    if not (rate > 0 and cutoff > 0):
        raise TrialError(f"the IIR low-pass needs a positive rate and cut-off, got {rate:g} Hz and {cutoff:g} Hz")
    if cutoff >= 0.5 * rate:
        cutoff = 0.49 * rate
    wa = np.tan(np.pi * cutoff / rate)
    denom = (wa + 1.0) * (wa * wa + wa + 1.0)
    num = np.array([1.0, 3.0, 3.0, 1.0]) * wa ** 3 / denom
    den = np.array([1.0,
                    (3 * wa ** 3 + 2 * wa ** 2 - 2 * wa - 3) / denom,
                    (3 * wa ** 3 - 2 * wa ** 2 - 2 * wa + 3) / denom,
                    (wa - 1) * (wa ** 2 - wa + 1) / denom])
    return num, den, cutoff


def _one_pass(num, den, x: np.ndarray) -> np.ndarray:
    """One forward pass: ``y[0:3] = x[0:3]``, then the recursion from sample 3 on, every column at once."""
    y = np.array(x, dtype=float)
    if x.shape[0] <= 3:
        return y
    b0, b1, b2, b3 = num
    _, a1, a2, a3 = den
    # the feed-forward part at once, the feedback sample by sample (three multiply-adds per row)
    ff = b0 * x[3:] + b1 * x[2:-1] + b2 * x[1:-2] + b3 * x[:-3]
    for i in range(3, x.shape[0]):
        y[i] = ff[i - 3] - a1 * y[i - 1] - a2 * y[i - 2] - a3 * y[i - 3]
    return y


def lowpass_iir(x, *, rate: float, cutoff: float) -> np.ndarray:
    """OpenSim's ``lowpassIIR``: the third-order IIR of :func:`iir_coefficients` forwards then backwards."""
    x = np.asarray(x, dtype=float)
    if x.shape[0] < 4:
        raise TrialError(f"the IIR low-pass needs at least 4 samples, got {x.shape[0]}")
    num, den, _ = iir_coefficients(rate, cutoff)
    y = _one_pass(num, den, x)
    return _one_pass(num, den, y[::-1])[::-1]
