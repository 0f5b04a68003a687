"""Damaged result files: 4 KiB zeroed anywhere in a saved fit.nc or population.nc is refused by
every reader in one line naming the file, never read as other numbers; the checksums a file
carries are those every netCDF reader sees; files written before them are read with a note."""

import contextlib
import io
import json
import shutil
import warnings

import h5py
import numpy as np
import pytest
import xarray as xr

import skinfit
from skinfit.analysis.compare import loo_record
from skinfit.apps.cli import main
from skinfit.errors import IntegrityWarning
from skinfit.io import integrity

SUBJECTS = ("S01", "S02", "S03")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Three subjects of contact_area fitted briefly (converged), saved as a ``fit --by subject``
    run, and contact_area_hertz on S01 beside it (``hertz.nc``); S01's two fits with their
    evidence cached (a comparison reads it, not recomputes it), the rival's LOO too."""
    folder = tmp_path_factory.mktemp("integrity") / "run"
    ds = skinfit.load_dataset("contact_area_synthetic")
    groups = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k, s in enumerate(SUBJECTS):
            sub = ds.subset(ds.frame["subject"].astype(str).to_numpy() == s, f"subject={s}")
            fit = skinfit.fit("contact_area", sub, rng=20 + k, max_steps=600, ess_target=100, n_global=300)
            if s == "S01":  # and its rival on the same data, beside the run
                rival = skinfit.fit("contact_area_hertz", sub, rng=30, max_steps=600, ess_target=100, n_global=300)
                for f in (fit, rival):
                    skinfit.evidence(f)
                loo_record(rival)  # S01's LOO computed by each comparison, from its pointwise groups
                rival.save(folder.parent / "hertz.nc")
            fit.save(folder / s / "fit.nc")
            groups.append({"group": f"subject={s}", "path": f"{s}/fit.nc"})
    (folder / "index.json").write_text(json.dumps({"model": "contact_area", "dataset": "contact_area_synthetic",
                                                   "by": ["subject"], "groups": groups}))
    return folder


def _region(path, where):
    """A byte offset inside ``where`` of the saved fit at ``path``: the posterior's values, the
    prior's values, a root attribute's text (the recipe of the pointwise groups, the
    cached evidence, the sampler record), HDF5's own metadata (the superblock; a group's
    object header)."""
    data = path.read_bytes()
    with h5py.File(path, "r") as f:
        if where == "posterior values":
            return f["posterior"]["m0"].id.get_offset()
        if where == "prior values":
            return f["prior"]["m0"].id.get_offset()
        if where == "group header":
            return h5py.h5o.get_info(f["posterior"].id).addr
    if where == "superblock":
        return 0
    if where == "evidence attribute":
        return data.index(b'"bridge"')
    if where == "sampler attribute":
        return data.index(b'"nwalkers"')
    if where == "pointwise recipe":
        return data.index(b'"walker_step"')
    raise ValueError(where)


def _unsealed(src, dst):
    """A copy of ``src`` without its trailer (the sha256 of its bytes): as HDF5 wrote it."""
    data = src.read_bytes()
    assert data[-81:].startswith(integrity.TRAILER)
    dst.write_bytes(data[:-81])
    return dst


def _zeroed(src, dst, offset, size=4096):
    data = bytearray(src.read_bytes())
    data[offset:offset + size] = bytes(len(data[offset:offset + size]))
    dst.write_bytes(bytes(data))
    return dst


REGIONS = ["posterior values", "pointwise recipe", "evidence attribute", "sampler attribute", "superblock",
           "group header"]


def _refusal(argv):
    """The last line on stderr of the CLI run on ``argv``, which must exit 2."""
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        warnings.simplefilter("ignore")
        code = main(argv)
    assert code == 2, (argv, out.getvalue()[-500:])
    return err.getvalue().strip().splitlines()[-1]


@pytest.mark.parametrize("where", REGIONS)
def test_damaged_fit_file_is_refused_by_every_reader_never_read_as_other_numbers(run, tmp_path, where, no_figures):
    """4 KiB zeroed in the data (the posterior's), the attributes (the recipe of the pointwise
    groups, which compare, report and population may not use; the cached evidence, the sampler record) and
    HDF5's own metadata of a fit.nc: load_fit, `skinfit compare`, `skinfit report` and `skinfit
    population` each refuse it with one line naming the file and what failed, before any of
    its numbers is used."""
    damaged_run = tmp_path / "run"
    shutil.copytree(run, damaged_run)
    path = damaged_run / "S01" / "fit.nc"
    _zeroed(run / "S01" / "fit.nc", path, _region(run / "S01" / "fit.nc", where))
    with pytest.raises(skinfit.InputError) as caught:
        skinfit.load_fit(path)
    assert str(caught.value) == (f"{path}: damaged: its bytes differ from what skinfit wrote (sha256 recorded in its "
                                 "last 81 bytes): the file changed after it was saved (a disk or copy error, or an "
                                 "edit); restore it from a copy or fit again")
    for argv in (["compare", str(path), str(run.parent / "hertz.nc")],
                 ["report", str(damaged_run), "--out", str(tmp_path / "report")],
                 ["population", str(damaged_run), "--params", "m0"]):
        assert _refusal(argv) == f"skinfit: error: {caught.value}", argv[0]
    assert not (tmp_path / "report" / "index.html").exists()
    assert not (damaged_run / "population").exists()


@pytest.mark.parametrize("where", ["posterior values", "prior values"])
def test_damaged_fit_file_without_its_end_is_refused_by_its_content_checksums(run, tmp_path, where):
    """The same damage to the values of a fit.nc whose trailer is gone too (its end lost, or
    written by another tool from skinfit's tree): the checksums of its groups refuse it, naming
    the group. (Not the attributes: HDF5
    2.0 hangs reading a text attribute whose heap was zeroed, which only the trailer, checked
    before HDF5 opens the file, prevents; bench/results/integrity.md.)"""
    path = _zeroed(_unsealed(run / "S01" / "fit.nc", tmp_path / "unsealed.nc"), tmp_path / "fit.nc",
                   _region(run / "S01" / "fit.nc", where))
    with pytest.raises(skinfit.InputError) as caught:
        skinfit.load_fit(path).complete()
    group = "posterior" if where == "posterior values" else "prior"
    assert str(caught.value) == (f"{path}: damaged: the content of group {group} differs from what skinfit wrote "
                                 "(sha256 mismatch): the file changed after it was saved (a disk or copy error, or an "
                                 "edit); restore it from a copy or fit again")


def test_an_undamaged_fit_file_reads_the_numbers_it_was_saved_with(run, capsys):
    """The negative control of the test above: `skinfit compare` on the undamaged files ranks
    them by the evidence and LOO cached in them (read, not recomputed)."""
    paths = [run / "S01" / "fit.nc", run.parent / "hertz.nc"]
    cached = {str(p): json.loads(xr.open_datatree(p).attrs["evidence"])["bridge"]["log_z"] for p in paths}
    capsys.readouterr()
    assert main(["compare", "--json", *map(str, paths)]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert sorted(r["log_z"] for r in rows) == pytest.approx(sorted(cached.values()), abs=1e-9)  # JSON: 10 decimals


def test_the_checksums_are_those_every_netcdf_reader_sees(run):
    """skinfit's reader, h5netcdf and xarray.open_datatree read the same content from a saved
    fit, so each verifies against the same record; a population file likewise."""
    path = run / "S02" / "fit.nc"
    tree = xr.open_datatree(path, engine="h5netcdf").load()
    record = integrity.take(path, tree.attrs, list(tree.children))
    integrity.verify(path, record, groups={n: tree[n].to_dataset(inherit=False) for n in tree.children})
    assert set(record["groups"]) == set(tree.children) and "posterior" in record["groups"]
    ours = skinfit.load_fit(path).partial_tree  # all the file holds (the pointwise groups are computed again)
    xr.testing.assert_identical(ours, tree)
    import h5netcdf

    from skinfit.results.store import decoded

    with h5netcdf.File(path, "r", decode_vlen_strings=True) as h:
        integrity.verify(path, record, groups={g: decoded(h.groups[g]) for g in h.groups})


def test_a_fit_file_from_before_checksums_is_read_with_a_note_and_one_that_lost_them_is_refused(run, tmp_path):
    """A file of schema 1 (no checksums: every fit saved before them) is read as before, with an
    IntegrityWarning naming it; saved again it carries them. A file of schema 2 whose record
    is gone (an attribute lost to damage) is refused."""
    old = _unsealed(run / "S03" / "fit.nc", tmp_path / "old.nc")
    with h5py.File(old, "r+") as f:
        del f.attrs[integrity.RECORD]
        f.attrs[integrity.SCHEMA_ATTR] = np.int64(1)
    with pytest.warns(IntegrityWarning, match=f"{old}: written before skinfit recorded checksums"):
        fit = skinfit.load_fit(old)
    np.testing.assert_array_equal(fit.group("posterior")["m0"].values,
                                  skinfit.load_fit(run / "S03" / "fit.nc").group("posterior")["m0"].values)
    fit.save(tmp_path / "again.nc")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert skinfit.load_fit(tmp_path / "again.nc").attrs[integrity.SCHEMA_ATTR] == integrity.CHECKED_SCHEMA
    lost = _unsealed(run / "S03" / "fit.nc", tmp_path / "lost.nc")
    with h5py.File(lost, "r+") as f:
        del f.attrs[integrity.RECORD]
    with pytest.raises(skinfit.InputError, match="damaged: its checksum record .* is missing"):
        skinfit.load_fit(lost)


def test_an_edited_number_is_refused_a_resaved_fit_is_not(run, tmp_path):
    """One byte of a draw flipped (a disk or copy error that leaves the file readable): refused
    by the sha256 of the file's bytes; a draw changed through HDF5 in a file without those (as
    another tool leaves it): refused by the checksum of the posterior group, named. A fit
    changed through skinfit and saved again reads back."""
    flipped = tmp_path / "flipped.nc"
    data = bytearray((run / "S02" / "fit.nc").read_bytes())
    with h5py.File(run / "S02" / "fit.nc", "r") as f:
        data[f["posterior"]["m0"].id.get_offset() + 3] ^= 0x10
    flipped.write_bytes(bytes(data))
    with pytest.raises(skinfit.InputError, match=f"{flipped}: damaged: its bytes differ"):
        skinfit.load_fit(flipped)
    path = _unsealed(run / "S02" / "fit.nc", tmp_path / "edited.nc")
    with h5py.File(path, "r+") as f:
        f["posterior"]["m0"][0, 0] += 1e-9
    with pytest.raises(skinfit.InputError, match=f"{path}: damaged: the content of group posterior differs"):
        skinfit.load_fit(path)
    fit = skinfit.load_fit(run / "S02" / "fit.nc")
    fit.attrs["evidence"] = json.dumps({"note": "a cache added by a comparison"})
    fit.save(path)
    assert json.loads(skinfit.load_fit(path).attrs["evidence"]) == {"note": "a cache added by a comparison"}


def test_a_damaged_population_file_is_refused(run, tmp_path):
    """population.nc: its checksums are checked on read (load_population, and the report that
    shows it); 4 KiB zeroed in its values is refused in one line naming it."""
    from skinfit.analysis.population.population import population
    from skinfit.analysis.population.result import load_population

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = population(str(run), ["m0"], rng=1, max_sweeps=400)
    path = result.save(tmp_path / "population.nc")
    back = load_population(path)
    np.testing.assert_array_equal(back.mu, result.mu)
    with h5py.File(path, "r") as f:
        offset = f["posterior"]["mu"].id.get_offset()
    damaged = _zeroed(path, tmp_path / "damaged.nc", offset)
    with pytest.raises(skinfit.InputError) as caught:
        load_population(damaged)
    assert str(caught.value).startswith(f"{damaged}: damaged") and "\n" not in str(caught.value)
