"""A saved fit reads back as xarray reads it: :func:`skinfit.load_fit` (h5netcdf and
``xarray.decode_cf``, skinfit.results.store) gives the tree ``xarray.open_datatree`` gives, with
the same attributes of the same Python types, for the files Fit.save writes, the layout older
netCDF writers leave, attributes of every kind HDF5 allows, and files of other layouts (read
whole, or refused in one line)."""

import warnings

import h5py
import numpy as np
import pytest
import xarray as xr

import skinfit
from skinfit.io import integrity
from skinfit.results.pointwise import RECIPE
from skinfit.results.store import write_tree


def _same_mapping(a, b, where):
    """Equal keys in order, and values of the same type and value (arrays: dtype, shape, NaNs)."""
    assert list(a) == list(b), where
    for k in a:
        u, w = a[k], b[k]
        assert type(u) is type(w), (where, k, type(u), type(w))
        if isinstance(u, np.ndarray):
            assert u.dtype == w.dtype and np.array_equal(u, w, equal_nan=u.dtype.kind == "f"), (where, k)
        elif not (isinstance(u, float) and np.isnan(u) and np.isnan(w)):
            assert u == w, (where, k)


def _xarray_reads(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # xarray's note on phony dimensions
        with xr.open_datatree(path, engine="h5netcdf") as tree:
            return tree.load()


def _file_groups(full, theirs):
    """``full`` (load_fit's complete tree) with the groups of ``theirs`` (a file as xarray reads
    it) only: the pointwise groups a fit computes again are not in its file."""
    assert {"log_likelihood", "posterior_predictive"} <= set(full.children)
    return xr.DataTree.from_dict({"/": full.to_dataset(inherit=False)}
                                 | {node.relative_to(full): node.to_dataset(inherit=False)
                                    for g in full.children if g in theirs.children for node in full[g].subtree})


def _assert_loads_as_xarray_reads(path):
    """load_fit's complete tree is xarray's, but for the pointwise groups computed again (not
    in the file): groups in the file's order, every variable's
    dimensions, dtype and values, and the attributes of the root, each group and each variable
    with their Python types (text variables as text: skinfit's as str objects, as a fit in
    memory holds them, where xarray may give fixed-width '<U' arrays)."""
    full, theirs = skinfit.load_fit(path).idata, _xarray_reads(path)
    ours = _file_groups(full, theirs)
    xr.testing.assert_identical(ours, theirs)
    assert list(ours.children) == list(theirs.children)
    _same_mapping(ours.attrs, theirs.attrs, "/")
    for g in theirs.children:
        a, b = ours[g].to_dataset(inherit=False), theirs[g].to_dataset(inherit=False)
        assert list(a.variables) == list(b.variables) and dict(a.sizes) == dict(b.sizes), g
        _same_mapping(a.attrs, b.attrs, g)
        for v in b.variables:
            text = a[v].dtype.kind in "OU" and b[v].dtype.kind in "OU"
            assert a[v].dims == b[v].dims and (text or a[v].dtype == b[v].dtype), (g, v)
            _same_mapping(a[v].attrs, b[v].attrs, (g, v))
    return full


@pytest.fixture(scope="module")
def subject_file(tmp_path_factory):
    """A contact_area fit of one subject: text coordinates (subject), a derived group indexed by
    the actuation force, two observables."""
    ds = skinfit.load_dataset("contact_area_synthetic")
    sub = ds.subset(ds.frame["subject"].astype(str).to_numpy() == "S02", "subject=S02")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = skinfit.fit("contact_area", sub, rng=3, max_steps=600, ess_target=100, n_global=300)
    return fit.save(tmp_path_factory.mktemp("subject") / "fit.nc")


def test_a_saved_fit_loads_as_xarray_reads_it(ea_fit, subject_file, tmp_path):
    tree = _assert_loads_as_xarray_reads(ea_fit.save(tmp_path / "ea.nc"))
    assert tree["posterior"]["alpha"].dims == ("chain", "draw")
    tree = _assert_loads_as_xarray_reads(subject_file)
    assert tree["constant_data"]["subject"].dtype == object and set(tree["constant_data"]["subject"].values) == {"S02"}
    assert tree["posterior_predictive"]["contact_area"].dims == ("chain", "draw", "obs_id")
    assert "derived" in tree.children
    # as h5netcdf < 1.5 and netCDF-C write them: no dimension ids on one-dimensional datasets
    older = _edited(subject_file, tmp_path / "older.nc", lambda f: f.visititems(
        lambda _, d: d.attrs.__delitem__("_Netcdf4Coordinates")
        if isinstance(d, h5py.Dataset) and d.ndim == 1 and "_Netcdf4Coordinates" in d.attrs else None))
    with h5py.File(older) as f:
        assert "_Netcdf4Coordinates" not in f["constant_data"]["normal_force"].attrs
    _assert_loads_as_xarray_reads(older)  # the same content: the same checksums


def _edited(src, dst, edit):
    data = src.read_bytes()
    dst.write_bytes(data[:data.rindex(integrity.TRAILER)] if integrity.TRAILER in data[-100:] else data)  # as HDF5 wrote it
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


def _restamped(path):
    """The edited file as another writer of this content would leave it: its checksums
    (skinfit.io.integrity) those of what xarray reads from it, so that skinfit reads it rather
    than refusing it as damaged; unchanged when xarray cannot read it."""
    try:
        tree = _xarray_reads(path)
    except (OSError, ValueError, KeyError):
        return path
    integrity.stamp(tree)
    with h5py.File(path, "r+") as f:
        f.attrs[integrity.RECORD] = tree.attrs[integrity.RECORD]
    return path


@pytest.mark.parametrize("edit", [
    lambda f: f["constant_data"]["normal_force"].attrs.__delitem__("DIMENSION_LIST"),  # an axis without a scale
    lambda f: f["posterior"]["draw"].attrs.__setitem__("_Netcdf4Dimid", np.int32(0)),  # two scales, one id
    lambda f: f["prior"].create_group("nested"),  # a group inside a group
    lambda f: f.create_dataset("at_root", data=np.arange(3.0)),  # a variable at the root
], ids=["no dimension scale", "dimension ids", "nested group", "root variable"])
def test_a_file_of_another_layout_is_read_as_xarray_reads_it_or_refused(subject_file, tmp_path, edit):
    """Files Fit.save does not write: the fit is the tree xarray reads, or refused in one line
    naming the file."""
    path = _restamped(_edited(subject_file, tmp_path / "edited.nc", edit))
    try:
        fit = skinfit.load_fit(path)
        fit.complete()
    except skinfit.InputError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # xarray's note on phony dimensions
        theirs = _xarray_reads(path)
        xr.testing.assert_identical(_file_groups(fit.idata, theirs), theirs)


def _odd_attributes(f):
    """Attributes of every kind HDF5 and h5py allow, on the root, a group and a variable."""
    for obj in (f, f["constant_data"], f["constant_data"]["normal_force"]):
        a = obj.attrs
        a["empty_text"] = h5py.Empty(h5py.string_dtype("ascii", 1))
        a["empty_float"] = h5py.Empty("f8")
        a["fixed_text"] = np.bytes_("newtons")
        a["fixed_texts"] = np.array([b"N", b"mm^2"], dtype="S4")
        a["one_fixed_char"] = np.bytes_("N")
        a["vlen_text"] = "Zoë"
        a["vlen_texts"] = np.array(["Zoë", "Zoé"], dtype=h5py.string_dtype())
        a["one_element"] = np.array([2.5])
        a["ints"] = np.array([1, 2, 3], dtype="i2")
        a["matrix"] = np.arange(6.0).reshape(2, 3)
        a["nan"] = np.nan


def test_attributes_of_every_kind_load_as_xarray_reads_them(subject_file, tmp_path):
    """Text (fixed and variable length, empty, arrays of it), numbers, one-element and
    multi-dimensional arrays and NaN on the root, a group and a variable: load_fit gives each
    with the value and Python type xarray gives, so the file's checksums (of what xarray reads)
    verify."""
    path = _restamped(_edited(subject_file, tmp_path / "odd.nc", _odd_attributes))
    tree = _assert_loads_as_xarray_reads(path)
    assert tree.attrs["fixed_text"] == "newtons" and tree.attrs["vlen_texts"] == ["Zoë", "Zoé"]
    assert tree["constant_data"]["normal_force"].attrs["fixed_text"] == "newtons"


def test_a_pointwise_group_of_a_loaded_fit_is_read_from_its_file_only_when_used(subject_file, tmp_path):
    """The pointwise groups of a file that holds them (an earlier skinfit's) stay in the file until used; zeroed there (a file without its
    trailer, so that the damage is found by the group's checksum), they are refused when read,
    naming the group, while the rest of the fit reads."""
    fit = skinfit.load_fit(subject_file)
    tree = fit.idata.copy()
    del tree.attrs[RECIPE]  # as an earlier skinfit saved it: with its pointwise groups, float64
    path = _edited(write_tree(tree, tmp_path / "stored.nc"), tmp_path / "late.nc", lambda f: None)
    with h5py.File(path, "r") as f:
        offset = f["log_likelihood"]["contact_area"].id.get_offset()
    data = bytearray(path.read_bytes())
    data[offset + 1000:offset + 5096] = bytes(4096)
    path.write_bytes(bytes(data))
    fit = skinfit.load_fit(path)
    assert "log_likelihood" not in fit.partial_tree.children and fit.group("posterior").sizes["draw"] > 0
    with pytest.raises(skinfit.InputError, match=f"{path}: damaged: the content of group log_likelihood differs"):
        fit.complete()
