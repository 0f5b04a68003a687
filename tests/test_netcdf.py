"""A saved fit's groups read with h5py directly (skinfit.results._netcdf) are exactly what h5netcdf and
xarray read; a file of any other layout is read by h5netcdf, as before."""

import warnings

import h5netcdf
import h5py
import numpy as np
import pytest
import xarray as xr

import skinfit
from skinfit.io import integrity
from skinfit.results._netcdf import NotPlain, read_groups
from skinfit.results.store import decoded as _decoded


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


def _assert_read_as_h5netcdf_reads(path):
    """Every group of ``path``: the same names in order, and each variable's dimensions, dtype,
    values, attributes (with their Python types) and encoding as h5netcdf + decode_cf give."""
    order, attrs, groups = read_groups(path, lambda g: True)
    with h5netcdf.File(path, "r", decode_vlen_strings=True) as h:
        assert order == list(h.groups)
        _same_mapping(attrs, {k: (v.decode() if isinstance(v, bytes) else v) for k, v in h.attrs.items()}, "/")
        for g in order:
            ours, theirs = groups[g], _decoded(h.groups[g])
            xr.testing.assert_identical(ours, theirs)
            assert list(ours.variables) == list(theirs.variables) and dict(ours.sizes) == dict(theirs.sizes)
            _same_mapping(ours.attrs, theirs.attrs, g)
            for v in theirs.variables:
                assert ours[v].dims == theirs[v].dims and ours[v].dtype == theirs[v].dtype, (g, v)
                _same_mapping(ours[v].attrs, theirs[v].attrs, (g, v))
                _same_mapping(ours[v].encoding, theirs[v].encoding, (g, v))
    return groups


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


def test_a_saved_fit_reads_as_h5netcdf_reads_it(ea_fit, subject_file, tmp_path):
    groups = _assert_read_as_h5netcdf_reads(ea_fit.save(tmp_path / "ea.nc"))
    assert groups["posterior"]["alpha"].dims == ("chain", "draw")
    groups = _assert_read_as_h5netcdf_reads(subject_file)
    assert groups["constant_data"]["subject"].dtype == object and set(groups["constant_data"]["subject"].values) == {"S02"}
    assert groups["posterior_predictive"]["contact_area"].dims == ("chain", "draw", "obs_id")
    xr.testing.assert_identical(skinfit.load_fit(subject_file).idata, xr.open_datatree(subject_file).load())
    # as h5netcdf < 1.5 and netCDF-C write them: no dimension ids on one-dimensional datasets
    older = _edited(subject_file, tmp_path / "older.nc", lambda f: f.visititems(
        lambda _, d: d.attrs.__delitem__("_Netcdf4Coordinates")
        if isinstance(d, h5py.Dataset) and d.ndim == 1 and "_Netcdf4Coordinates" in d.attrs else None))
    with h5py.File(older) as f:
        assert "_Netcdf4Coordinates" not in f["constant_data"]["normal_force"].attrs
    _assert_read_as_h5netcdf_reads(older)


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
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = xr.open_datatree(path, engine="h5netcdf").load()
            tree.close()  # the values read: the file free for h5py to write
    except (OSError, ValueError, KeyError):
        return path
    integrity.stamp(tree)
    with h5py.File(path, "r+") as f:
        f.attrs[integrity.RECORD] = tree.attrs[integrity.RECORD]
    return path


@pytest.mark.parametrize("edit, why", [
    (lambda f: f["constant_data"]["normal_force"].attrs.__delitem__("DIMENSION_LIST"), "not every axis"),
    (lambda f: f["posterior"]["draw"].attrs.__setitem__("_Netcdf4Dimid", np.int32(0)), "dimension scale"),
    (lambda f: f["prior"].create_group("nested"), "not a dataset"),
    (lambda f: f.create_dataset("at_root", data=np.arange(3.0)), "not only groups"),
])
def test_another_layout_is_read_by_h5netcdf(subject_file, tmp_path, edit, why):
    """Files the direct reader does not know (an axis without a dimension scale, two dimension
    scales with one id, nested groups, a variable at the root) are refused by it and read by
    h5netcdf: the fit is the same tree xarray reads, or refused as before."""
    path = _edited(subject_file, tmp_path / "edited.nc", edit)
    with pytest.raises(NotPlain, match=why):
        read_groups(path, lambda g: True)
    _restamped(path)
    try:
        fit = skinfit.load_fit(path)
    except skinfit.InputError as exc:  # h5netcdf refuses it too: one line naming the file
        assert str(exc).startswith(f"{path}: not a readable skinfit result") and "\n" not in str(exc)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # xarray's note on phony dimensions
        xr.testing.assert_identical(fit.idata, xr.open_datatree(path).load())


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
        a.create("array_type", data=np.arange(6.0).reshape(2, 3), dtype=np.dtype(("f4", (3,))))
        a["nan"] = np.nan
        a[b"not utf-8 \xff"] = 1.0  # h5py names it by its bytes


def test_attributes_are_read_as_h5py_and_h5netcdf_read_them(subject_file, tmp_path):
    """Each attribute read once by the direct reader has the value, type and HDF5 type h5py's
    ``attrs[name]`` and ``attrs.get_id(name)`` give (references compared by what they name),
    for every kind of attribute; the groups are then what h5netcdf reads."""
    from skinfit.results._netcdf import _attributes

    path = _edited(subject_file, tmp_path / "odd.nc", _odd_attributes)
    with h5py.File(path) as f:
        objects = [f["/"]]
        f.visititems(lambda _, o: objects.append(o))
        kinds = set()
        for obj in objects:
            ours = _attributes(obj)
            theirs = [k for k in obj.attrs if k not in ("REFERENCE_LIST", "_NCProperties", "_nc3_strict")]
            assert list(ours) == theirs, obj.name
            for k, (value, dtype) in ours.items():
                expected = obj.attrs[k]
                assert dtype == obj.attrs.get_id(k).dtype and type(value) is type(expected), (obj.name, k)
                kinds.add(k)
                if k == "DIMENSION_LIST":  # references: the same objects named
                    def named(refs):
                        return [[f[r].name for r in axis] for axis in refs]

                    assert named(value) == named(expected)
                elif isinstance(expected, h5py.Empty):
                    assert value == expected
                else:
                    nan = np.asarray(expected).dtype.kind == "f"
                    assert np.array_equal(value, expected, equal_nan=nan), (obj.name, k)
    assert {"empty_text", "empty_float", "vlen_texts", "array_type", "DIMENSION_LIST", "CLASS",
            b"not utf-8 \xff"} <= kinds
    _assert_read_as_h5netcdf_reads(path)
