"""Values pyhrv 0.5.0 and hrv-analysis 1.0.6 compute on the sample NN series (run once).

Neither library is a dependency of HRI Physio: run this with them importable (e.g.
``pip install --target /tmp/refs --no-deps pyhrv==0.5.0 hrv-analysis==1.0.6 biosppy spectrum
six`` and ``PYTHONPATH=/tmp/refs``; hrv-analysis imports ``nolds`` at the top for features not used here,
so a placeholder module stands in for it). Writes ``library_reference.json``.

Frequency domain: pyhrv's ``welch_psd`` with ``window="hann"`` (its default is Hamming), mean
detrending, cubic interpolation at 4 Hz, nfft 4096. Below 5 min of NN intervals pyhrv uses one
segment (the whole series); the tests call HRI Physio's ``band_powers`` with ``segment_seconds``
at least the excerpt's length, so both sides use one segment. Time domain: pyhrv's ``nn50``,
``nn20``, ``sdnn``, ``rmssd`` and hrv-analysis's ``get_time_domain_features``.
"""

from __future__ import annotations

import json
import sys
import types
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent


def excerpts() -> dict[str, list[float]]:
    long = np.load(HERE / "SampleNNISeriesLong.npy").astype(np.float64)
    short = np.load(HERE / "SampleNNISeriesShort.npy").astype(np.float64)
    out = {"short": short.tolist()}
    t = np.cumsum(long) / 1000.0
    for start in (0.0, 900.0, 1800.0, 2700.0):
        sel = (t > start) & (t <= start + 240.0)
        out[f"long_{start:g}s_240s"] = long[sel].tolist()
    return out


def main() -> None:
    sys.modules.setdefault("nolds", types.ModuleType("nolds"))
    warnings.simplefilter("ignore")
    import pyhrv.frequency_domain as fd
    import pyhrv.time_domain as td
    from hrvanalysis import get_time_domain_features

    result = {}
    for name, nn in excerpts().items():
        psd = fd.welch_psd(nni=nn, window="hann", detrend=True, show=False, mode="dev")[0]
        _, lf, hf = psd["fft_abs"]
        nn50 = td.nn50(nni=nn)
        nn20 = td.nn20(nni=nn)
        ha = get_time_domain_features(nn)
        result[name] = {
            "nn_ms": nn,
            "pyhrv": {"lf": float(lf), "hf": float(hf), "pnn50": float(nn50["pnn50"]),
                      "pnn20": float(nn20["pnn20"]), "sdnn": float(td.sdnn(nni=nn)["sdnn"]),
                      "rmssd": float(td.rmssd(nni=nn)["rmssd"])},
            "hrvanalysis": {"pnn50": float(ha["pnni_50"]), "pnn20": float(ha["pnni_20"]),
                            "sdnn": float(ha["sdnn"]), "rmssd": float(ha["rmssd"])},
        }
    (HERE / "library_reference.json").write_text(json.dumps({
        "generator": "tests/data/pyhrv_nni/make_library_reference.py",
        "libraries": "pyhrv 0.5.0 (welch_psd window='hann', nn50, nn20, sdnn, rmssd); "
                     "hrv-analysis 1.0.6 (get_time_domain_features)",
        "series": result}, indent=1))


if __name__ == "__main__":
    main()
