"""The on-disk import cache (pinmsk.io.cache, pinmsk.model.import_osim) and the muscle paths fitted on first use.

A second import of an unchanged .osim (a new process: the in-process cache cleared) is read from the cache
and is the same model (inverse dynamics to 1e-12); a changed file or option, a corrupt entry, and the
environment variables make it import again; inverse dynamics never fits the muscle paths.
"""
from __future__ import annotations

import shutil
import warnings

import numpy as np
import pytest

import pinmsk
import pinmsk.opensim.importer as importer
import test_osim_import as t
from conftest import shared_folder
from pinmsk.dynamics import inverse_dynamics_result
from pinmsk.io import cache
from pinmsk.io.tables import read_trial
from pinmsk.model import clear_import_cache, import_osim
from pinmsk.opensim.muscle_import import DeferredPathFit

GAIT = "opensim-models/Gait10dof18musc"


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    """A fresh cache folder of the test's own, and a count of the imports actually built."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(cache.CACHE_DIR_VARIABLE, str(folder))
    monkeypatch.delenv(cache.NO_CACHE_VARIABLE, raising=False)
    built = []
    real = importer.read_import

    def counting(*args, **kwargs):
        built.append(args[0])
        return real(*args, **kwargs)

    monkeypatch.setattr(importer, "read_import", counting)
    clear_import_cache()
    yield folder, built
    clear_import_cache()


def _fresh(path, **kw):
    """An import as a new process makes it: the in-process cache cleared first."""
    clear_import_cache()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return import_osim(path, **kw)


def _entries(folder, kind="import"):
    return sorted(folder.glob(f"{kind}-*.pkl"))


@pytest.fixture
def leg(tmp_path):
    p = tmp_path / "model" / "leg.osim"
    p.parent.mkdir()
    p.write_text(t.leg())
    return p


def test_second_import_is_read_from_the_cache_and_gives_the_same_inverse_dynamics(cache_dir):
    folder, built = cache_dir
    d = shared_folder(GAIT, "subject01.osim")
    osim = d / "subject01.osim"
    first, report = _fresh(osim)
    assert len(built) == 1 and len(_entries(folder)) == 1
    second, report2 = _fresh(osim)
    assert len(built) == 1                      # read back, not imported again
    assert second is not first and second.nq == first.nq and second.coordinate_order == first.coordinate_order
    assert [e.element for e in report2.entries_so_far] == [e.element for e in report.entries_so_far]
    trial = read_trial(d / "IK/subject01_walk_IK.mot", angular=set(first.rotational_coordinates))
    loads = d / "ExperimentalData/subject01_walk_grf.xml"
    a = inverse_dynamics_result(first, trial, external_loads=loads).trial
    b = inverse_dynamics_result(second, trial, external_loads=loads).trial
    assert a.names == b.names
    np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-12)
    assert np.abs(a.values).max() > 10.0           # real moments, not zeros


def test_inverse_dynamics_fits_no_muscle_path(cache_dir):
    d = shared_folder(GAIT, "subject01.osim")
    model, report = _fresh(d / "subject01.osim")
    runs = DeferredPathFit.runs
    trial = read_trial(d / "IK/subject01_walk_IK.mot", angular=set(model.rotational_coordinates))
    inverse_dynamics_result(model, trial, external_loads=d / "ExperimentalData/subject01_walk_grf.xml")
    assert DeferredPathFit.runs == runs
    assert len(report.pending) == 1 and not model.muscles.path.fitted
    assert not any(e.details.get("kind") == "muscle paths" for e in report.entries_so_far)


def test_cli_id_fits_no_muscle_path(cache_dir, tmp_path, capsys):
    from pinmsk.presentation.cli import main
    d = shared_folder(GAIT, "subject01.osim")
    clear_import_cache()
    runs = DeferredPathFit.runs
    out = tmp_path / "id.sto"
    assert main(["id", str(d / "subject01.osim"), str(d / "IK/subject01_walk_IK.mot"), "--external-loads",
                 str(d / "ExperimentalData/subject01_walk_grf.xml"), "-o", str(out)]) == 0
    assert out.is_file() and DeferredPathFit.runs == runs
    assert "muscle path" not in capsys.readouterr().err
    model, report = import_osim(d / "subject01.osim")       # the command's import, from this process' cache
    assert report.pending and not model.muscles.path.fitted


def test_fitted_paths_are_cached_and_the_same(cache_dir, leg):
    folder, built = cache_dir
    model, report = _fresh(leg)
    runs = DeferredPathFit.runs
    with pytest.warns(UserWarning, match="muscle path"):
        lengths = model.muscles.path.lengths(np.zeros((3, model.nv)))
    assert DeferredPathFit.runs == runs + 1 and len(_entries(folder, "paths")) == 1
    errors = [e.max_error for e in report.entries if e.details.get("kind") == "muscle paths"]
    assert errors and all(e > 0 for e in errors)
    again, report2 = _fresh(leg)
    assert not again.muscles.path.fitted         # lazy again, but the fit is read from the cache
    with pytest.warns(UserWarning, match="muscle path"):
        np.testing.assert_array_equal(again.muscles.path.lengths(np.zeros((3, model.nv))), lengths)
    assert DeferredPathFit.runs == runs + 1 and len(built) == 1
    assert [e.max_error for e in report2.entries if e.details.get("kind") == "muscle paths"] == errors


def test_a_changed_file_or_option_is_imported_again(cache_dir, leg):
    folder, built = cache_dir
    a, _ = _fresh(leg)
    _fresh(leg)
    assert len(built) == 1
    text = leg.read_text()
    assert "<mass>" in text
    i = text.index("<mass>") + len("<mass>")
    changed = text[:i] + "2" + text[i:]          # the first body 2x heavier (a leading digit)
    leg.write_text(changed)
    b, _ = _fresh(leg)
    assert len(built) == 2 and len(_entries(folder)) == 2
    assert b.mass != pytest.approx(a.mass)
    _fresh(leg, nonlinear="fit")                 # an option
    _fresh(leg, gravity=[0.0, -9.81, 0.0])
    assert len(built) == 4
    copy = leg.parent / "copy.osim"              # the same content at another path: its own entry (meta['osim'])
    shutil.copy(leg, copy)
    c, _ = _fresh(copy)
    assert len(built) == 5 and c.meta["osim"] == str(copy)


def test_a_file_the_osim_names_is_part_of_the_key(cache_dir, leg):
    _folder, built = cache_dir
    extra = leg.parent / "reserve.xml"
    extra.write_text("<OpenSimDocument/>")
    text = leg.read_text()
    key1 = _key(leg)
    # an element naming a file by OpenSim's file attribute (the import itself does not read it)
    leg.write_text(text.replace("<BodySet", '<BodySet file="reserve.xml"', 1))
    key2 = _key(leg)
    extra.write_text("<OpenSimDocument><changed/></OpenSimDocument>")
    key3 = _key(leg)
    assert len({key1, key2, key3}) == 3 and built == []


def _key(path):
    from pinmsk.model import _import_key, _stored_key
    from pinmsk.opensim.contacts import contact_hook
    from pinmsk.opensim.muscle_import import DEFAULT_HOOKS
    hooks = (*DEFAULT_HOOKS, contact_hook)
    return _stored_key(path, _import_key(path, "joint", "exact", None, hooks), hooks)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other_key", "bad_pickle"])
def test_a_corrupt_entry_is_rebuilt(cache_dir, leg, damage):
    folder, built = cache_dir
    a, _ = _fresh(leg)
    (entry,) = _entries(folder)
    data = entry.read_bytes()
    if damage == "garbage":
        entry.write_bytes(b"\x00not a cache entry")
    elif damage == "truncated":
        entry.write_bytes(data[: len(data) // 2])
    elif damage == "other_key":                  # another key's entry under this name
        k = entry.name[len("import-"):-len(".pkl")]
        entry.write_bytes(data.replace(k.encode(), b"0" * len(k), 1))
    else:                                        # a sound header and digest over bytes that do not unpickle
        import hashlib
        payload = b"\x80\x05not a pickle."
        head = data[: data.index(b" ", data.index(b"import ") + 7) + 1]
        entry.write_bytes(head + hashlib.blake2b(payload, digest_size=20).hexdigest().encode() + b"\n" + payload)
    b, _ = _fresh(leg)
    assert len(built) == 2                       # rebuilt, not trusted
    assert b.nq == a.nq and b.mass == pytest.approx(a.mass, rel=1e-15)
    assert cache.load("import", entry.name[len("import-"):-len(".pkl")]) is not None     # replaced by a sound one


def test_the_environment_variables(tmp_path, monkeypatch, leg):
    built = []
    real = importer.read_import
    monkeypatch.setattr(importer, "read_import", lambda *a, **k: built.append(1) or real(*a, **k))
    chosen = tmp_path / "chosen"
    monkeypatch.setenv(cache.CACHE_DIR_VARIABLE, str(chosen))
    monkeypatch.delenv(cache.NO_CACHE_VARIABLE, raising=False)
    assert cache.cache_dir() == chosen
    _fresh(leg)
    assert len(_entries(chosen)) == 1
    monkeypatch.setenv(cache.NO_CACHE_VARIABLE, "1")
    assert cache.cache_dir() is None
    _fresh(leg)
    assert len(built) == 2                       # not read from the cache
    monkeypatch.delenv(cache.CACHE_DIR_VARIABLE)
    monkeypatch.delenv(cache.NO_CACHE_VARIABLE)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(cache.sys, "platform", "linux")
    assert cache.cache_dir() == tmp_path / "xdg" / "pinmsk"
    clear_import_cache()


def test_an_unwritable_cache_folder_is_skipped(tmp_path, monkeypatch, leg):
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv(cache.CACHE_DIR_VARIABLE, str(blocker / "cache"))      # below a file: cannot be made
    model, _ = _fresh(leg)
    assert model.nq > 0 and cache.store("import", "0" * 40, 1) is None
    clear_import_cache()


def test_cli_id_of_a_short_trial_imports_no_scipy_signal(tmp_path):
    """``pinmsk id`` on the walk (151 frames) pays for no scipy.signal, scipy.interpolate or scipy.sparse."""
    import subprocess
    import sys
    d = shared_folder(GAIT, "subject01.osim")
    code = ("import sys\n"
            "from pinmsk.presentation.cli import main\n"
            f"assert main(['id', {str(d / 'subject01.osim')!r}, {str(d / 'IK/subject01_walk_IK.mot')!r}, "
            f"'--external-loads', {str(d / 'ExperimentalData/subject01_walk_grf.xml')!r}, "
            f"'-o', {str(tmp_path / 'id.sto')!r}]) == 0\n"
            "print(sorted(m for m in sys.modules if m.startswith(('scipy.signal', 'scipy.interpolate', "
            "'scipy.sparse'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_a_bad_trial_is_named_before_the_model_is_loaded(tmp_path, monkeypatch, capsys):
    from pinmsk.presentation.cli import main
    import pinmsk.model
    loaded = []
    monkeypatch.setattr(pinmsk.model, "load_model", lambda *a, **k: loaded.append(a) or 1 / 0)
    bad = tmp_path / "bad.csv"
    bad.write_text("time,a\n0,1\n0.1\n")
    assert main(["id", "model.osim", str(bad), "-o", str(tmp_path / "out.sto")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and "line 3" in err and loaded == []


def _own_hook(doc, skeleton):
    from pinmsk.opensim.hooks import HookResult
    return HookResult()


def test_an_import_with_a_users_hook_or_fit_over_is_not_stored(cache_dir, leg):
    from pinmsk.model import _import_key, _stored_key
    folder, built = cache_dir
    hooks = (_own_hook,)
    assert _stored_key(leg, _import_key(leg, "joint", "exact", None, hooks), hooks) is None
    _fresh(leg, hooks=hooks)
    assert _entries(folder) == [] and len(built) == 1
