"""Signal processing on measured channels: filtering, sampling rate, resampling, EMG.

* :mod:`.filtering` -- zero-lag Butterworth low-pass and differentiation;
* :mod:`.sampling` -- the sampling rate a time column shows, with one tolerance;
* :mod:`.resampling` -- channels onto other times, and aligning recordings at different rates;
* :mod:`.emg` -- EMG envelopes, normalisation and on/off detection.

The functions here work on arrays and Trials and never import a model.
"""
from __future__ import annotations

from .._lazy import lazy_attributes

_EXPORTS = {
    "lowpass": "filtering", "differentiate": "filtering", "filter_padlen": "filtering",
    "measured_rate": "sampling", "check_rate": "sampling", "uniform_rate": "sampling",
    "UNIFORM_TOLERANCE": "sampling",
    "align": "resampling", "common_time": "resampling",
    "envelope": "emg", "envelopes": "emg", "normalize": "emg", "on_off": "emg", "onset_times": "emg",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS, __all__)
