"""The pandas bridge of Trial: a round trip, a lab's DataFrame with a time column, and a clear error
without pandas (pinmsk does not need it)."""
import sys

import numpy as np
import pytest

from pinmsk import Trial
from pinmsk.errors import MissingDependencyError, PinmskError, TrialError


def _trial():
    t = np.linspace(0.0, 1.0, 11)
    return Trial(t, {"knee_r": np.sin(t), "knee_r_moment": 3 * t}, units={"knee_r_moment": "N*m"},
                 meta={"source": "lab.sto"})


def test_to_pandas_and_back():
    import pandas as pd
    tr = _trial()
    df = tr.to_pandas()
    assert isinstance(df, pd.DataFrame) and list(df.columns) == ["knee_r", "knee_r_moment"]
    assert df.index.name == "time" and df.attrs["units"] == {"knee_r_moment": "N*m"}
    np.testing.assert_array_equal(df.index.to_numpy(), tr.time)
    np.testing.assert_array_equal(df["knee_r"].to_numpy(), tr["knee_r"])
    df.iloc[0, 0] = 99.0                                   # a copy: the trial is untouched
    assert tr["knee_r"][0] == 0.0
    back = Trial.from_pandas(tr.to_pandas())
    np.testing.assert_array_equal(back.values, tr.values)
    np.testing.assert_array_equal(back.time, tr.time)
    assert back.names == tr.names and dict(back.units) == {"knee_r_moment": "N*m"}
    assert back.meta["source"] == "lab.sto"


def test_from_pandas_with_a_time_column_in_ms():
    import pandas as pd
    df = pd.DataFrame({"Time (ms)": [0.0, 10.0, 20.0], "hip": [0.1, 0.2, 0.3]})
    tr = Trial.from_pandas(df)
    np.testing.assert_allclose(tr.time, [0.0, 0.01, 0.02])
    assert tr.names == ("hip",)
    tr2 = Trial.from_pandas(pd.DataFrame({"stamp": [0.0, 0.5], "hip": [1.0, 2.0]}), time="stamp")
    np.testing.assert_array_equal(tr2.time, [0.0, 0.5])
    with pytest.raises(TrialError, match=r"column\(s\) 'side' are not numeric"):
        Trial.from_pandas(pd.DataFrame({"time": [0.0, 1.0], "side": ["r", "l"]}))
    with pytest.raises(TrialError, match="time is not strictly increasing at row 1"):
        Trial.from_pandas(pd.DataFrame({"time": [1.0, 0.0], "hip": [1.0, 2.0]}))
    with pytest.raises(TrialError, match="needs a pandas.DataFrame"):
        Trial.from_pandas({"time": [0.0]})


def test_without_pandas_the_error_says_how_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)       # import pandas now raises ImportError
    with pytest.raises(MissingDependencyError, match=r"Trial.to_pandas needs pandas.*pip install pandas"):
        _trial().to_pandas()
    with pytest.raises(PinmskError, match=r"Trial.from_pandas needs pandas"):
        Trial.from_pandas(object())
